// Built with CGAL's flags (-frounding-math) in the lidef_cgal object library (deform/CMakeLists.txt).
#include "lidef/exact_winding.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "lidef/internal/exact_crossing.h"

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
  for (const auto& dd : kRayDirections) {
    const Vec3 d(dd[0], dd[1], dd[2]);
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
      switch (segment_crossing(a, b, c, P, Q)) {
        case Crossing::kLeaves:
          ++w;
          break;
        case Crossing::kEnters:
          --w;
          break;
        case Crossing::kDegenerate:
          degenerate = true;
          break;
        case Crossing::kNone:
          break;
      }
    }
    if (!degenerate) return w;
  }
  return std::nullopt;
}

}  // namespace lidef
