// CGAL for lidef_cage: polygon soup readers, 3D alpha wrapping, edge-collapse simplification with a clearance
// filter. The only translation unit of lidef_cage that includes CGAL (cage/CMakeLists.txt says why).
#include "auto_cage_cgal.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/IO/OBJ.h>
#include <CGAL/IO/OFF.h>
#include <CGAL/IO/PLY.h>
#include <CGAL/IO/STL.h>
#include <CGAL/Orthogonal_k_neighbor_search.h>
#include <CGAL/Search_traits_3.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Bounded_normal_change_filter.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_cost.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_placement.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>
#include <CGAL/alpha_wrap_3.h>

#include <array>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>

#include "lidef/internal/stopwatch.h"

namespace lidef::cage_cgal {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Triangle = K::Triangle_3;
using Mesh = CGAL::Surface_mesh<Point>;
using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<Triangle>::const_iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
using KdSearch = CGAL::Orthogonal_k_neighbor_search<CGAL::Search_traits_3<K>>;

// Squared distance from a point to the input: its triangles (AABB tree) and its points not on a triangle
// (k-d tree; a point cloud has only those).
class InputDistance {
 public:
  InputDistance(const std::vector<Triangle>& triangles, const std::vector<Point>& lone_points)
      : tree_(triangles.begin(), triangles.end()),
        kd_(lone_points.begin(), lone_points.end()),
        has_triangles_(!triangles.empty()),
        has_points_(!lone_points.empty()) {
    if (has_triangles_) tree_.accelerate_distance_queries();
  }
  double squared(const Point& p) const {
    double d = std::numeric_limits<double>::infinity();
    if (has_triangles_) d = tree_.squared_distance(p);
    if (has_points_) {
      const KdSearch search(kd_, p, 1);
      d = std::min(d, search.begin()->second);
    }
    return d;
  }

 private:
  Tree tree_;
  KdSearch::Tree kd_;
  bool has_triangles_, has_points_;
};
namespace SMS = CGAL::Surface_mesh_simplification;

// Sound test "every point of triangle (a, b, c) is at least `clearance` from the mesh": the ball of radius R
// around the centroid g covers the triangle, so dist(g) >= clearance + R proves it; dist(g) < clearance
// disproves it; otherwise the triangle is split in four and the parts tested. Triangles still undecided when
// R < clearance / 64 count as too close (conservative).
class ClearanceTest {
 public:
  ClearanceTest(const InputDistance& tree, double clearance) : tree_(tree), clearance_(clearance) {}

  bool triangle_clear(const Point& a, const Point& b, const Point& c) const {
    const Point g = CGAL::centroid(a, b, c);
    const double r = std::sqrt(
        std::max({CGAL::squared_distance(g, a), CGAL::squared_distance(g, b), CGAL::squared_distance(g, c)}));
    const double d = std::sqrt(tree_.squared(g));
    if (d < clearance_) return false;
    if (d >= clearance_ + r) return true;
    if (r < clearance_ / 64) return false;
    const Point ab = CGAL::midpoint(a, b), bc = CGAL::midpoint(b, c), ca = CGAL::midpoint(c, a);
    return triangle_clear(a, ab, ca) && triangle_clear(ab, b, bc) && triangle_clear(ca, bc, c) &&
           triangle_clear(ab, bc, ca);
  }

 private:
  const InputDistance& tree_;
  double clearance_;
};

// Edge-collapse filter: refuses a collapse when a triangle of the new vertex's star would come closer than
// the clearance to the mesh. (Bounded_normal_change_filter around it refuses normal flips.)
struct ClearanceFilter {
  const ClearanceTest* test = nullptr;

  template <typename Profile>
  boost::optional<typename Profile::Point> operator()(const Profile& profile,
                                                      boost::optional<typename Profile::Point> op) const {
    if (!op) return op;
    const auto& vpm = profile.vertex_point_map();
    const auto& triangles = profile.triangles();
    auto it = triangles.begin();
    // The triangles incident to the edge come first and disappear with it.
    if (profile.left_face_exists()) ++it;
    if (profile.right_face_exists()) ++it;
    for (; it != triangles.end(); ++it)  // the second vertex of each is the one that moves to *op
      if (!test->triangle_clear(get(vpm, it->v0), *op, get(vpm, it->v2)))
        return boost::optional<typename Profile::Point>();
    return op;
  }
};

}  // namespace

bool read_polygon_soup(const std::string& path, const std::string& format, PolygonSoup& soup) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::vector<Point> points;
  std::vector<std::vector<std::size_t>> polygons;
  const auto np = CGAL::parameters::verbose(false);
  bool ok = false;
  try {
    if (format == "obj")
      ok = CGAL::IO::read_OBJ(in, points, polygons, np);
    else if (format == "off")
      ok = CGAL::IO::read_OFF(in, points, polygons, np);
    else if (format == "ply")
      ok = CGAL::IO::read_PLY(in, points, polygons, np);
    else if (format == "stl")
      ok = CGAL::IO::read_STL(in, points, polygons, np);
  } catch (
      const std::exception&) {  // CGAL's readers throw on some malformed input (bad_alloc on huge counts)
    ok = false;
  }
  if (!ok) return false;
  soup.points.resize(static_cast<Eigen::Index>(points.size()), 3);
  for (std::size_t i = 0; i < points.size(); ++i)
    for (int k = 0; k < 3; ++k) soup.points(static_cast<Eigen::Index>(i), k) = points[i][k];
  soup.polygons = std::move(polygons);
  return true;
}

WrapResult wrap_and_simplify(const TriMesh& mesh, double alpha, double offset, double clearance,
                             int target_faces) {
  WrapResult result;
  auto t0 = Clock::now();
  std::vector<Point> points;
  points.reserve(static_cast<std::size_t>(mesh.V.rows()));
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i)
    points.emplace_back(mesh.V(i, 0), mesh.V(i, 1), mesh.V(i, 2));
  std::vector<std::array<std::size_t, 3>> faces;
  std::vector<Triangle> triangles;
  std::vector<char> on_face(points.size(), 0);
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const std::array<std::size_t, 3> t = {static_cast<std::size_t>(mesh.F(f, 0)),
                                          static_cast<std::size_t>(mesh.F(f, 1)),
                                          static_cast<std::size_t>(mesh.F(f, 2))};
    faces.push_back(t);
    for (std::size_t v : t) on_face[v] = 1;
    const Triangle tri(points[t[0]], points[t[1]], points[t[2]]);
    if (!tri.is_degenerate()) triangles.push_back(tri);
  }

  std::vector<Point> lone_points;
  for (std::size_t v = 0; v < points.size(); ++v)
    if (!on_face[v]) lone_points.push_back(points[v]);

  Mesh wrap;
  if (faces.empty())  // a point cloud: CGAL wraps the point set itself
    CGAL::alpha_wrap_3(points, alpha, offset, wrap);
  else
    CGAL::alpha_wrap_3(points, faces, alpha, offset, wrap);
  result.wrap_faces = static_cast<int>(wrap.number_of_faces());
  result.seconds_wrap = seconds_since(t0);

  t0 = Clock::now();
  const InputDistance tree(triangles, lone_points);
  const ClearanceTest test(tree, clearance);
  if (static_cast<int>(wrap.number_of_faces()) > target_faces) {
    // A closed triangle mesh has 3F/2 edges.
    const SMS::Count_stop_predicate<Mesh> stop(static_cast<std::size_t>(target_faces) * 3 / 2);
    const SMS::Bounded_normal_change_filter<ClearanceFilter> filter(ClearanceFilter{&test});
    SMS::edge_collapse(wrap, stop,
                       CGAL::parameters::get_cost(SMS::LindstromTurk_cost<Mesh>())
                           .get_placement(SMS::LindstromTurk_placement<Mesh>())
                           .filter(filter));
  }
  wrap.collect_garbage();
  for (const Mesh::Face_index f : wrap.faces()) {
    const Mesh::Halfedge_index h = wrap.halfedge(f);
    if (!test.triangle_clear(wrap.point(wrap.source(h)), wrap.point(wrap.target(h)),
                             wrap.point(wrap.target(wrap.next(h)))))
      ++result.faces_within_clearance;
  }
  result.seconds_simplify = seconds_since(t0);

  TriMesh& cage = result.cage;
  cage.V.resize(static_cast<Eigen::Index>(wrap.number_of_vertices()), 3);
  for (const Mesh::Vertex_index v : wrap.vertices()) {
    const Point& p = wrap.point(v);
    for (int k = 0; k < 3; ++k) cage.V(static_cast<Eigen::Index>(v.idx()), k) = p[k];
  }
  cage.F.resize(static_cast<Eigen::Index>(wrap.number_of_faces()), 3);
  for (const Mesh::Face_index f : wrap.faces()) {
    int k = 0;
    for (const Mesh::Vertex_index v : CGAL::vertices_around_face(wrap.halfedge(f), wrap))
      if (k < 3) cage.F(static_cast<Eigen::Index>(f.idx()), k++) = static_cast<int>(v.idx());
  }
  return result;
}

}  // namespace lidef::cage_cgal
