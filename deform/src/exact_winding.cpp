// Built with CGAL's flags (-frounding-math) in the lidef_cgal object library (deform/CMakeLists.txt).
#include "lidef/exact_winding.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace lidef {

namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
}  // namespace

std::optional<int> exact_winding_number(const MatX3d& V, const MatX3i& F, const std::vector<int>& faces,
                                        const Vec3& p) {
  if (faces.empty()) return 0;
  // The farthest corner of the faces' bounding box from p: a segment from p longer than twice that distance
  // ends beyond every triangle, so the ray's crossings are the segment's.
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int f : faces)
    for (int k = 0; k < 3; ++k) {
      lo = lo.cwiseMin(V.row(F(f, k)).transpose());
      hi = hi.cwiseMax(V.row(F(f, k)).transpose());
    }
  const double reach = std::max((lo - p).cwiseAbs().cwiseMax((hi - p).cwiseAbs()).norm(), 1e-300);
  const Point P(p.x(), p.y(), p.z());
  // Fixed directions (deterministic), none along a coordinate axis or diagonal, where mesh edges often lie.
  static const std::array<Vec3, 12> kDirections{
      Vec3(0.8113, 0.4127, 0.4143),   Vec3(-0.3171, 0.8893, 0.3297),  Vec3(0.2203, -0.3307, 0.9177),
      Vec3(-0.6581, -0.5113, 0.5527), Vec3(0.5839, -0.7717, -0.2521), Vec3(-0.4379, 0.2293, -0.8693),
      Vec3(0.9291, -0.1733, 0.3267),  Vec3(-0.1459, -0.9587, 0.2441), Vec3(0.3461, 0.6277, -0.6971),
      Vec3(-0.8867, 0.1039, -0.4507), Vec3(0.1277, 0.2909, 0.9481),   Vec3(-0.5297, -0.6121, -0.5871)};
  for (const Vec3& d : kDirections) {
    const Vec3 q = p + (2.5 * reach / d.norm()) * d;
    const Point Q(q.x(), q.y(), q.z());
    int w = 0;
    bool degenerate = false;
    for (size_t i = 0; i < faces.size() && !degenerate; ++i) {
      const int f = faces[i];
      const Point a(V(F(f, 0), 0), V(F(f, 0), 1), V(F(f, 0), 2));
      const Point b(V(F(f, 1), 0), V(F(f, 1), 1), V(F(f, 1), 2));
      const Point c(V(F(f, 2), 0), V(F(f, 2), 1), V(F(f, 2), 2));
      if (CGAL::collinear(a, b, c)) continue;
      const CGAL::Orientation op = CGAL::orientation(a, b, c, P), oq = CGAL::orientation(a, b, c, Q);
      if (op == oq && op != CGAL::ZERO) continue;  // both ends on one side: no crossing
      if (op == CGAL::ZERO || oq == CGAL::ZERO) {
        degenerate = true;  // an end in the triangle's plane
        break;
      }
      const CGAL::Orientation s[3] = {CGAL::orientation(P, Q, a, b), CGAL::orientation(P, Q, b, c),
                                      CGAL::orientation(P, Q, c, a)};
      const bool has_pos = s[0] == CGAL::POSITIVE || s[1] == CGAL::POSITIVE || s[2] == CGAL::POSITIVE;
      const bool has_neg = s[0] == CGAL::NEGATIVE || s[1] == CGAL::NEGATIVE || s[2] == CGAL::NEGATIVE;
      if (has_pos && has_neg) continue;  // the line passes beside the closed triangle
      if (s[0] == CGAL::ZERO || s[1] == CGAL::ZERO || s[2] == CGAL::ZERO) {
        degenerate = true;  // the line meets an edge or a corner
        break;
      }
      // A transversal crossing of the interior. orientation(a, b, c, p) is the sign of
      // det(b − a, c − a, p − a): negative when p lies behind the counter-clockwise side, i.e. the segment
      // leaves through the triangle's front: +1.
      w += op == CGAL::NEGATIVE ? 1 : -1;
    }
    if (!degenerate) return w;
  }
  return std::nullopt;
}

}  // namespace lidef
