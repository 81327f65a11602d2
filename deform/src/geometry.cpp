#include "lidef/geometry.h"

#include <algorithm>
#include <array>
#include <limits>

namespace lidef {

TriangleClosestPoint closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {a, {1, 0, 0}};
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {b, {0, 1, 0}};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {a + v * ab, {1 - v, v, 0}};
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {c, {0, 0, 1}};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {a + w * ac, {1 - w, 0, w}};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {b + w * (c - b), {0, 1 - w, w}};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {a + ab * v + ac * w, {1 - v - w, v, w}};
}

double signed_volume(const MatX3d& V, const MatX3i& F) {
  if (V.rows() == 0) return 0;
  const Vec3 o = 0.5 * (V.colwise().minCoeff() + V.colwise().maxCoeff()).transpose();
  double volume = 0;
  for (Eigen::Index t = 0; t < F.rows(); ++t) {
    const Vec3 a = V.row(F(t, 0)).transpose() - o, b = V.row(F(t, 1)).transpose() - o,
               c = V.row(F(t, 2)).transpose() - o;
    volume += a.dot(b.cross(c));
  }
  return volume / 6.0;
}

double point_triangle_dist2(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (closest_point_on_triangle(p, a, b, c).point - p).squaredNorm();
}

double triangle_enclosing_radius(const Vec3& a, const Vec3& b, const Vec3& c) {
  const std::array<Vec3, 3> p{a, b, c};
  std::array<Vec3, 5> o{(a + b + c) / 3.0, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a), Vec3::Zero()};
  int count = 4;
  const Vec3 u = b - a, w = c - a, n = u.cross(w);
  if (const double n2 = n.squaredNorm(); n2 > 0) {  // circumcenter a + (|u|² w × n + |w|² n × u) / (2|n|²)
    const Vec3 cc = a + (u.squaredNorm() * w.cross(n) + w.squaredNorm() * n.cross(u)) / (2 * n2);
    if (cc.allFinite()) o[count++] = cc;
  }
  double magnitude = 0;
  for (const Vec3& v : p) magnitude = std::max(magnitude, v.cwiseAbs().maxCoeff());
  double best = std::numeric_limits<double>::infinity();
  for (int k = 0; k < count; ++k) {
    double r = 0;
    for (const Vec3& v : p) r = std::max(r, (v - o[k]).norm());
    best = std::min(best, r + 1e-15 * std::max(magnitude, o[k].cwiseAbs().maxCoeff()));
  }
  return best * (1 + 1e-12);
}

}  // namespace lidef
