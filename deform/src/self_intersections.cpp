// One of the two translation units that include CGAL, with exact_winding.cpp (its headers are heavy and its
// interface needs -frounding-math, which must not reach the numeric code; see deform/CMakeLists.txt).
#include "lidef/self_intersections.h"

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/corefinement.h>
#include <CGAL/Surface_mesh.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>

#include "lidef/internal/exact_crossing.h"
#include "lidef/internal/rest_solid.h"

namespace lidef {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

// Exact test for one candidate pair, by how many vertex indices the faces share (any CGAL kernel's points).
template <class Point>
bool faces_intersect(const MatX3i& F, const std::vector<Point>& P, int i, int j) {
  using Kernel = typename CGAL::Kernel_traits<Point>::Kernel;
  using Segment = typename Kernel::Segment_3;
  using Triangle = typename Kernel::Triangle_3;
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

// The pairs of faces of F (indices into P) that share a point they are not supposed to share
// (find_self_intersections' rules), found by a sort-and-sweep over closed boxes that contain the exact faces.
template <class Point>
std::vector<std::pair<int, int>> intersecting_pairs(const MatX3i& F, const std::vector<Point>& P) {
  const int nf = static_cast<int>(F.rows());
  // Faces that are not proper triangles have no well-defined plane; CGAL's predicates require proper ones.
  std::vector<char> usable(nf, 1);
  std::vector<CGAL::Bbox_3> box(nf);
  for (int t = 0; t < nf; ++t) {
    const int a = F(t, 0), b = F(t, 1), c = F(t, 2);
    if (a == b || b == c || a == c || CGAL::collinear(P[a], P[b], P[c])) usable[t] = 0;
    box[t] = P[a].bbox() + P[b].bbox() + P[c].bbox();  // the exact coordinates, or intervals around them
  }
  // Sort-and-sweep along the axis of the largest extent (the fewest boxes overlap along it: a long thin mesh
  // swept across its length would compare most pairs). The boxes are closed and contain the exact faces, so
  // no pair that touches is lost; the result, sorted, does not depend on the axis.
  CGAL::Bbox_3 all;
  for (const CGAL::Bbox_3& b : box) all += b;
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (all.max(k) - all.min(k) > all.max(axis) - all.min(axis)) axis = k;
  const int o1 = (axis + 1) % 3, o2 = (axis + 2) % 3;
  std::vector<int> order(nf);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int p, int q) {
    return box[p].min(axis) < box[q].min(axis) || (box[p].min(axis) == box[q].min(axis) && p < q);
  });
  std::vector<std::pair<int, int>> hits;
  for (int oi = 0; oi < nf; ++oi) {
    const int i = order[oi];
    if (!usable[i]) continue;
    for (int oj = oi + 1; oj < nf && box[order[oj]].min(axis) <= box[i].max(axis); ++oj) {
      const int j = order[oj];
      if (!usable[j]) continue;
      if (box[j].min(o1) > box[i].max(o1) || box[i].min(o1) > box[j].max(o1) ||
          box[j].min(o2) > box[i].max(o2) || box[i].min(o2) > box[j].max(o2))
        continue;
      if (faces_intersect(F, P, i, j)) hits.emplace_back(std::min(i, j), std::max(i, j));
    }
  }
  std::sort(hits.begin(), hits.end());
  return hits;
}

}  // namespace

std::vector<std::pair<int, int>> find_self_intersections(const MatX3d& V, const MatX3i& F) {
  std::vector<K::Point_3> P(V.rows());
  for (Eigen::Index v = 0; v < V.rows(); ++v) P[v] = K::Point_3(V(v, 0), V(v, 1), V(v, 2));
  return intersecting_pairs(F, P);
}

// --- The boundary of the solid of a mesh that intersects itself (docs/certificate.md, Step G1).
namespace {

using EK = CGAL::Exact_predicates_exact_constructions_kernel;
using EPoint = EK::Point_3;
using EVector = EK::Vector_3;
using EMesh = CGAL::Surface_mesh<EPoint>;

// Records, for every face the autorefinement creates, the mesh triangle it was cut from.
struct ParentTracker : CGAL::Polygon_mesh_processing::Corefinement::Default_visitor<EMesh> {
  EMesh::Property_map<EMesh::Face_index, int>* parent = nullptr;
  int current = -1;
  void before_subface_creations(EMesh::Face_index f, const EMesh&) { current = (*parent)[f]; }
  void after_subface_created(EMesh::Face_index f, const EMesh&) { (*parent)[f] = current; }
};

// The closed triangle (a, b, c) contains the point q of its plane.
bool contains_coplanar(const EPoint& a, const EPoint& b, const EPoint& c, const EPoint& q) {
  return CGAL::coplanar_orientation(a, b, c, q) != CGAL::NEGATIVE &&
         CGAL::coplanar_orientation(b, c, a, q) != CGAL::NEGATIVE &&
         CGAL::coplanar_orientation(c, a, b, q) != CGAL::NEGATIVE;
}

// A piece of the split mesh: its mesh triangle and its corners (indices into SplitMesh::points).
struct Piece {
  int parent;
  std::array<int, 3> corner;
};

// The mesh split along its intersection curves: its pieces, their distinct exact corners, and the pieces of
// each mesh triangle.
struct SplitMesh {
  std::vector<EPoint> points;
  std::map<EPoint, int, bool (*)(const EPoint&, const EPoint&)> index_of{
      [](const EPoint& a, const EPoint& b) { return CGAL::compare_xyz(a, b) == CGAL::SMALLER; }};
  std::vector<Piece> pieces;
  std::vector<std::vector<int>> pieces_of;
  int point_index(const EPoint& p) {
    const auto [it, fresh] = index_of.emplace(p, static_cast<int>(points.size()));
    if (fresh) points.push_back(p);
    return it->second;
  }
};

// Stage 1: CGAL's autorefinement (exact constructions) of the mesh (P0 #V points, F #F by 3) near its
// intersections, each new face traced back to its mesh triangle. Only the triangles of intersecting pairs and
// those sharing a corner with one are refined together: every intersection point lies in two triangles of a
// pair, so a new corner falls on an edge of a pair's triangle, whose other triangle shares its corners (the
// other triangles stay whole; stage 2 verifies every one). Where those triangles do not form a halfedge
// surface (two fans at a corner), the whole mesh is refined. Returns "" or why it failed.
std::string split_along_intersections(const std::vector<EPoint>& P0, const MatX3i& F,
                                      const std::vector<std::pair<int, int>>& intersecting, SplitMesh* s) {
  const int nf = static_cast<int>(F.rows());
  std::vector<char> near_corner(P0.size(), 0), refined(nf, 0);
  for (const auto& [a, b] : intersecting)
    for (int t : {a, b})
      for (int c = 0; c < 3; ++c) near_corner[F(t, c)] = 1;
  for (int t = 0; t < nf; ++t)
    refined[t] = near_corner[F(t, 0)] || near_corner[F(t, 1)] || near_corner[F(t, 2)];

  EMesh m;
  auto parent = m.add_property_map<EMesh::Face_index, int>("f:lidef_parent", -1).first;
  auto build = [&]() {
    m.clear_without_removing_property_maps();
    std::vector<EMesh::Vertex_index> vi(P0.size(), EMesh::null_vertex());
    for (int f = 0; f < nf; ++f) {
      if (!refined[f]) continue;
      std::array<EMesh::Vertex_index, 3> corners;
      for (int c = 0; c < 3; ++c) {
        if (vi[F(f, c)] == EMesh::null_vertex()) vi[F(f, c)] = m.add_vertex(P0[F(f, c)]);
        corners[c] = vi[F(f, c)];
      }
      const EMesh::Face_index fi = m.add_face(corners[0], corners[1], corners[2]);
      if (fi == EMesh::null_face()) return f;
      parent[fi] = f;
    }
    return -1;
  };
  if (build() >= 0) {  // not a halfedge surface near the intersections: refine the whole mesh
    std::fill(refined.begin(), refined.end(), 1);
    if (const int f = build(); f >= 0)
      return "the mesh could not be split along its intersections (triangle " + std::to_string(f) +
             " does not fit a halfedge structure)";
  }
  try {
    ParentTracker tracker;
    tracker.parent = &parent;
    CGAL::Polygon_mesh_processing::experimental::autorefine(m, CGAL::parameters::visitor(tracker));
  } catch (const std::exception& e) {
    return std::string("the mesh could not be split along its intersections (") + e.what() + ")";
  }
  s->pieces_of.assign(nf, {});
  auto add_piece = [&](const Piece& pc) {
    s->pieces_of[pc.parent].push_back(static_cast<int>(s->pieces.size()));
    s->pieces.push_back(pc);
  };
  for (EMesh::Face_index f : m.faces()) {
    Piece pc{parent[f], {}};
    if (pc.parent < 0 || pc.parent >= nf || !refined[pc.parent])
      return "the split left a piece without its mesh triangle";
    int k = 0;
    for (EMesh::Vertex_index v : CGAL::vertices_around_face(m.halfedge(f), m)) {
      if (k == 3) return "the split left a piece that is not a triangle";
      pc.corner[k++] = s->point_index(m.point(v));
    }
    if (k != 3) return "the split left a piece that is not a triangle";
    add_piece(pc);
  }
  for (int t = 0; t < nf; ++t)
    if (!refined[t])
      add_piece({t, {s->point_index(P0[F(t, 0)]), s->point_index(P0[F(t, 1)]), s->point_index(P0[F(t, 2)])}});
  return "";
}

// Stage 2: the split verified on its own. A mesh triangle left whole is its only piece (the same corners in
// the same cyclic order); the pieces of a split one lie in it, face its way (positive area along its normal),
// and their vector areas sum to its own, so that — not overlapping (stage 3) — they cover it. Marks as
// special the pieces of split triangles and of triangles in intersecting pairs, counts the split triangles.
std::string verify_split(const std::vector<EPoint>& P0, const MatX3i& F, SplitMesh* s,
                         std::vector<char>* special, int* split_triangles) {
  const int nf = static_cast<int>(F.rows());
  for (int t = 0; t < nf; ++t) {
    const EPoint &A = P0[F(t, 0)], &B = P0[F(t, 1)], &C = P0[F(t, 2)];
    const std::vector<int>& own = s->pieces_of[t];
    if (own.empty()) return "the split lost mesh triangle " + std::to_string(t);
    if (own.size() == 1) {
      const Piece& pc = s->pieces[own[0]];
      const std::array<int, 3> whole{s->point_index(A), s->point_index(B), s->point_index(C)};
      bool same = false;
      for (int r = 0; r < 3; ++r)
        same = same || (pc.corner[0] == whole[r] && pc.corner[1] == whole[(r + 1) % 3] &&
                        pc.corner[2] == whole[(r + 2) % 3]);
      if (!same) return "the split changed mesh triangle " + std::to_string(t) + " without cutting it";
      continue;
    }
    ++*split_triangles;
    const EVector normal = CGAL::cross_product(B - A, C - A);
    EVector sum = CGAL::NULL_VECTOR;
    for (int k : own) {
      (*special)[k] = 1;
      const Piece& pc = s->pieces[k];
      const EPoint &a = s->points[pc.corner[0]], &b = s->points[pc.corner[1]], &c = s->points[pc.corner[2]];
      for (const EPoint* q : {&a, &b, &c})
        if (CGAL::orientation(A, B, C, *q) != CGAL::COPLANAR || !contains_coplanar(A, B, C, *q))
          return "a piece of mesh triangle " + std::to_string(t) + " does not lie in it";
      const EVector area = CGAL::cross_product(b - a, c - a);
      if (!CGAL::is_positive(area * normal))
        return "a piece of mesh triangle " + std::to_string(t) + " is flat or turned over";
      sum = sum + area;
    }
    if (sum != normal) return "the pieces of mesh triangle " + std::to_string(t) + " do not cover it";
  }
  return "";
}

// Stage 3: the special pieces meet only in common corners and edges (the exact test of
// find_self_intersections on them). Every other piece is a whole mesh triangle in no intersecting pair: it
// meets every triangle properly, hence every piece of one, except where a new corner of a split triangle lies
// on their common edge — which leaves that edge used an odd number of times in ∂D's structure test.
std::string check_special_pieces_meet_properly(const SplitMesh& s, const std::vector<char>& special) {
  std::vector<int> near;
  for (size_t k = 0; k < s.pieces.size(); ++k)
    if (special[k]) near.push_back(static_cast<int>(k));
  MatX3i FN(near.size(), 3);
  for (size_t i = 0; i < near.size(); ++i)
    for (int c = 0; c < 3; ++c) FN(i, c) = s.pieces[near[i]].corner[c];
  const auto bad = intersecting_pairs(FN, s.points);
  if (bad.empty()) return "";
  return "the pieces of mesh triangles " + std::to_string(s.pieces[near[bad[0].first]].parent) + " and " +
         std::to_string(s.pieces[near[bad[0].second]].parent) + " still intersect after the split";
}

enum class Ray { kCounted, kDegenerate, kOnAnotherTriangle };

// The winding number of the mesh (P0, F) just beside p, a point of triangle `own` only, on the side of q: the
// signed crossings of the segment [p, q] (q beyond every triangle) with the other triangles.
Ray count_crossings(const std::vector<EPoint>& P0, const MatX3i& F, int own, const EPoint& p, const EPoint& q,
                    int* w) {
  *w = 0;
  for (int t = 0; t < F.rows(); ++t) {
    if (t == own) continue;
    const EPoint &a = P0[F(t, 0)], &b = P0[F(t, 1)], &c = P0[F(t, 2)];
    if (CGAL::collinear(a, b, c)) continue;  // no area: no crossing changes the winding number
    if (CGAL::orientation(a, b, c, p) == CGAL::ZERO) {
      if (contains_coplanar(a, b, c, p)) return Ray::kOnAnotherTriangle;
      if (CGAL::orientation(a, b, c, q) == CGAL::ZERO) return Ray::kDegenerate;  // the segment in the plane
      continue;  // it touches the plane only at p, outside the triangle
    }
    switch (segment_crossing(a, b, c, p, q)) {
      case Crossing::kLeaves:
        ++*w;
        break;
      case Crossing::kEnters:
        --*w;
        break;
      case Crossing::kDegenerate:
        return Ray::kDegenerate;
      case Crossing::kNone:
        break;
    }
  }
  return Ray::kCounted;
}

// Stage 4: the winding number on the outer (counter-clockwise) side of every piece, counted exactly from its
// centroid along the first of kRayDirections (turned to that side) that meets no edge or corner. Two pieces
// that are the only ones along an edge (corners identified exactly) and traverse it in opposite directions
// have their outer sides in one cell of the complement next to it (after stage 3 no other piece touches the
// edge's interior): one count serves each set of pieces joined that way.
std::string outer_winding_numbers(const std::vector<EPoint>& P0, const MatX3i& F, const SplitMesh& s,
                                  std::vector<int>* outer) {
  std::vector<int> patch(s.pieces.size());
  std::iota(patch.begin(), patch.end(), 0);
  auto find = [&](int x) {
    while (patch[x] != x) x = patch[x] = patch[patch[x]];
    return x;
  };
  std::vector<std::array<int, 4>> edges;  // (smaller corner, larger corner, direction +1/-1, piece)
  edges.reserve(3 * s.pieces.size());
  for (size_t k = 0; k < s.pieces.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      const int a = s.pieces[k].corner[c], b = s.pieces[k].corner[(c + 1) % 3];
      edges.push_back({std::min(a, b), std::max(a, b), a < b ? 1 : -1, static_cast<int>(k)});
    }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j][0] == edges[i][0] && edges[j][1] == edges[i][1]) ++j;
    if (j - i == 2 && edges[i][2] != edges[i + 1][2]) patch[find(edges[i][3])] = find(edges[i + 1][3]);
    i = j;
  }
  // Segments longer than 4 diagonals of the mesh's box (the directions' lengths are within 2e-4 of 1) end
  // beyond every triangle.
  CGAL::Bbox_3 box;
  for (const EPoint& p : P0) box += p.bbox();
  const double reach =
      4 * std::hypot(box.xmax() - box.xmin(), box.ymax() - box.ymin(), box.zmax() - box.zmin()) + 1;
  outer->assign(s.pieces.size(), 0);
  std::vector<char> counted(s.pieces.size(), 0);
  for (size_t k = 0; k < s.pieces.size(); ++k) {
    const int root = find(static_cast<int>(k));
    if (!counted[root]) {
      const Piece& pc = s.pieces[root];
      const EPoint p = CGAL::centroid(s.points[pc.corner[0]], s.points[pc.corner[1]], s.points[pc.corner[2]]);
      const EPoint &A = P0[F(pc.parent, 0)], &B = P0[F(pc.parent, 1)], &C = P0[F(pc.parent, 2)];
      const EVector normal = CGAL::cross_product(B - A, C - A);
      Ray result = Ray::kDegenerate;
      for (const auto& dd : kRayDirections) {
        EVector d(dd[0] * reach, dd[1] * reach, dd[2] * reach);
        if (CGAL::is_zero(d * normal)) continue;
        if (CGAL::is_negative(d * normal)) d = -d;
        int w = 0;
        result = count_crossings(P0, F, pc.parent, p, p + d, &w);
        if (result == Ray::kCounted) (*outer)[root] = w;
        if (result != Ray::kDegenerate) break;
      }
      if (result == Ray::kOnAnotherTriangle)
        return "a piece of mesh triangle " + std::to_string(pc.parent) + " lies on another triangle";
      if (result == Ray::kDegenerate)
        return "no ray from a piece of mesh triangle " + std::to_string(pc.parent) +
               " avoids the others' edges";
      counted[root] = 1;
    }
    (*outer)[k] = (*outer)[root];
  }
  return "";
}

}  // namespace

RestSolidBoundary rest_solid_boundary(const MatX3d& V, const MatX3i& F,
                                      const std::vector<std::pair<int, int>>& intersecting) {
  RestSolidBoundary out;
  std::vector<EPoint> P0(V.rows());
  for (Eigen::Index v = 0; v < V.rows(); ++v) P0[v] = EPoint(V(v, 0), V(v, 1), V(v, 2));
  SplitMesh split;
  out.problem = split_along_intersections(P0, F, intersecting, &split);
  if (!out.problem.empty()) return out;
  std::vector<char> special(split.pieces.size(), 0);  // pieces near the intersections
  for (const auto& [a, b] : intersecting)
    for (int t : {a, b})
      for (int k : split.pieces_of[t]) special[k] = 1;
  out.problem = verify_split(P0, F, &split, &special, &out.split_triangles);
  if (out.problem.empty()) out.problem = check_special_pieces_meet_properly(split, special);
  std::vector<int> outer;
  if (out.problem.empty()) out.problem = outer_winding_numbers(P0, F, split, &outer);
  if (!out.problem.empty()) return out;

  // ∂D: the pieces with winding number 0 outside; crossing a piece of one triangle adds 1, so 1 inside.
  std::vector<int> boundary;
  for (size_t k = 0; k < split.pieces.size(); ++k)
    if (outer[k] == 0) boundary.push_back(static_cast<int>(k));
  out.F.resize(boundary.size(), 3);
  for (size_t i = 0; i < boundary.size(); ++i)
    for (int c = 0; c < 3; ++c) out.F(i, c) = split.pieces[boundary[i]].corner[c];
  out.num_points = static_cast<int>(split.points.size());
  out.points.resize(out.num_points, 3);
  for (int i = 0; i < out.num_points; ++i)
    for (int c = 0; c < 3; ++c) out.points(i, c) = CGAL::to_double(split.points[i][c]);
  out.pieces = static_cast<int>(split.pieces.size());
  if (boundary.empty()) out.problem = "no piece of the mesh has winding number 0 outside and 1 inside";
  return out;
}

}  // namespace lidef
