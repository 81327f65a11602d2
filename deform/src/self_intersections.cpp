// One of the two translation units that include CGAL, with exact_winding.cpp (its headers are heavy and its
// interface needs -frounding-math, which must not reach the numeric code; see deform/CMakeLists.txt).
#include "lidef/self_intersections.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <algorithm>
#include <numeric>

namespace lidef {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Segment = K::Segment_3;
using Triangle = K::Triangle_3;

// Exact test for one candidate pair, by how many vertex indices the faces share.
bool faces_intersect(const MatX3i& F, const std::vector<Point>& P, int i, int j) {
  int si[3], sj[3], ns = 0;  // local positions of the shared vertices in i and j
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b)
      if (F(i, a) == F(j, b)) si[ns] = a, sj[ns] = b, ++ns;
  auto corner = [&](int f, int k) { return P[F(f, k)]; };
  const Triangle ti(corner(i, 0), corner(i, 1), corner(i, 2)), tj(corner(j, 0), corner(j, 1), corner(j, 2));
  switch (ns) {
    case 0:
      return CGAL::do_intersect(ti, tj);
    case 1: {
      // Both triangles contain the shared vertex s. Their intersection is convex, so it holds another point
      // iff the edge opposite s in one triangle meets the other triangle (the intersection's far end lies on
      // such an edge in both the transversal and the coplanar case).
      const Segment oi(corner(i, (si[0] + 1) % 3), corner(i, (si[0] + 2) % 3));
      const Segment oj(corner(j, (sj[0] + 1) % 3), corner(j, (sj[0] + 2) % 3));
      return CGAL::do_intersect(oi, tj) || CGAL::do_intersect(oj, ti);
    }
    case 2: {
      // Sharing edge (s0,s1): non-coplanar planes meet exactly in the edge's line, which each triangle cuts
      // only in the shared edge; so they overlap iff coplanar with both apexes on the same side (folded
      // over).
      const Point& s0 = P[F(i, si[0])];
      const Point& s1 = P[F(i, si[1])];
      const Point& a = corner(i, 3 - si[0] - si[1]);
      const Point& b = corner(j, 3 - sj[0] - sj[1]);
      return CGAL::coplanar(s0, s1, a, b) && CGAL::coplanar_orientation(s0, s1, a, b) == CGAL::POSITIVE;
    }
    default:
      return true;  // the same three vertices: a duplicate face
  }
}

}  // namespace

std::vector<std::pair<int, int>> find_self_intersections(const MatX3d& V, const MatX3i& F) {
  const int nf = static_cast<int>(F.rows());
  std::vector<Point> P(V.rows());
  for (Eigen::Index v = 0; v < V.rows(); ++v) P[v] = Point(V(v, 0), V(v, 1), V(v, 2));

  // Faces that are not proper triangles have no well-defined plane; CGAL's predicates require proper ones.
  std::vector<char> usable(nf, 1);
  Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::RowMajor> box(nf, 6);  // min xyz, max xyz
  for (int t = 0; t < nf; ++t) {
    const int a = F(t, 0), b = F(t, 1), c = F(t, 2);
    if (a == b || b == c || a == c || CGAL::collinear(P[a], P[b], P[c])) usable[t] = 0;
    for (int k = 0; k < 3; ++k) {
      box(t, k) = std::min({V(a, k), V(b, k), V(c, k)});
      box(t, 3 + k) = std::max({V(a, k), V(b, k), V(c, k)});
    }
  }

  // Sort-and-sweep along x. Boxes are closed and built from the exact coordinates, so no pair that touches
  // is lost to round-off.
  std::vector<int> order(nf);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](int p, int q) { return box(p, 0) < box(q, 0) || (box(p, 0) == box(q, 0) && p < q); });
  std::vector<std::pair<int, int>> hits;
  for (int oi = 0; oi < nf; ++oi) {
    const int i = order[oi];
    if (!usable[i]) continue;
    for (int oj = oi + 1; oj < nf && box(order[oj], 0) <= box(i, 3); ++oj) {
      const int j = order[oj];
      if (!usable[j]) continue;
      if (box(j, 1) > box(i, 4) || box(i, 1) > box(j, 4) || box(j, 2) > box(i, 5) || box(i, 2) > box(j, 5))
        continue;
      if (faces_intersect(F, P, i, j)) hits.emplace_back(std::min(i, j), std::max(i, j));
    }
  }
  std::sort(hits.begin(), hits.end());
  return hits;
}

}  // namespace lidef
