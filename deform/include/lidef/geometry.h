// Small geometric primitives shared by the basis, the validator and the sampler.
#pragma once
#include <algorithm>
#include <cmath>

#include "lidef/types.h"

namespace lidef {

// Signed solid angle of triangle (a,b,c) seen from p, divided by 4π (van Oosterom & Strackee 1983).
// Positive when p lies on the side opposite to the normal (b-a)x(c-a), i.e. inside a closed
// outward-oriented surface; the sum over a closed surface is the winding number.
inline double solid_angle_fraction(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& p) {
  const Vec3 la = a - p, lb = b - p, lc = c - p;
  const double na = la.norm(), nb = lb.norm(), nc = lc.norm();
  const double num = la.dot(lb.cross(lc));
  const double den = na * nb * nc + la.dot(lb) * nc + lb.dot(lc) * na + lc.dot(la) * nb;
  return std::atan2(num, den) / (2.0 * M_PI);
}

// z component of the 2D cross product (a × b).
inline double cross2(double ax, double ay, double bx, double by) {
  return ax * by - ay * bx;
}

// Squared distance from (px,py) to the closed 2D segment [(ax,ay), (bx,by)].
inline double seg_dist2_2d(double px, double py, double ax, double ay, double bx, double by) {
  const double dx = bx - ax, dy = by - ay, dd = dx * dx + dy * dy;
  double t = dd > 0 ? ((px - ax) * dx + (py - ay) * dy) / dd : 0.0;
  t = std::min(1.0, std::max(0.0, t));
  const double ex = ax + t * dx - px, ey = ay + t * dy - py;
  return ex * ex + ey * ey;
}

// Squared distance from p to the closed segment [a,b].
inline double point_segment_dist2(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 d = b - a;
  const double dd = d.squaredNorm();
  double t = dd > 0 ? (p - a).dot(d) / dd : 0.0;
  t = std::min(1.0, std::max(0.0, t));
  return (a + t * d - p).squaredNorm();
}

// The point of the closed triangle (a,b,c) closest to p and its barycentric coordinates (u,v,w), u+v+w = 1
// (Ericson, Real-Time Collision Detection 5.1.5). A vertex or edge region returns that vertex or edge point.
struct TriangleClosestPoint {
  Vec3 point;
  Vec3 barycentric;
};
TriangleClosestPoint closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// Signed volume enclosed by a closed triangle mesh (V: #V by 3, F: #F by 3 valid indices), positive when the
// faces are oriented outward. The tetrahedra are summed from a local origin (the bounding-box center), so
// that the rounding error scales with the model's size and not with its distance from the coordinate origin
// (a cage moved by 1e6 keeps its volume to ~1e-10 relative instead of losing its sign).
double signed_volume(const MatX3d& V, const MatX3i& F);

// Squared distance from p to the closed triangle (a,b,c).
double point_triangle_dist2(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// An upper bound of max(|a − o|, |b − o|, |c − o|) for a point o, made as small as the candidates allow: the
// centroid, the edge midpoints (the smallest enclosing ball of an obtuse or right triangle) and the
// circumcenter (of an acute one), so at most the radius of the smallest enclosing ball plus rounding. Any o
// bounds the linear interpolation error, Σ λ_i |x − v_i|² ≤ max_i |v_i − o|² (docs/certificate.md, Step
// G3), so o needs no exactness: only the distances are rounded up (relative 1e-12 and 1e-15 of the largest
// coordinate).
double triangle_enclosing_radius(const Vec3& a, const Vec3& b, const Vec3& c);

}  // namespace lidef
