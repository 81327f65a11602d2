// Global injectivity (global_injectivity.h): the verdict against sampled truth — the winding number of the
// deformed surface at the images of interior points counts their preimages — and its invariance.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <random>
#include <sstream>

#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/exact_winding.h"
#include "lidef/geometry.h"
#include "lidef/global_injectivity.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/mesh_queries.h"
#include "lidef/internal/rest_solid.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/model_check.h"
#include "lidef/procedural_models.h"
#include "lidef/projected_newton.h"
#include "lidef/self_intersections.h"
#include "test_beam.h"
#include "test_cli_outputs.h"
#include "test_support.h"

namespace lidef {
namespace {

using Verdict = GlobalInjectivity::Verdict;

// Coefficients of the cage map p ↦ g(p) for a smooth g with Jacobian Jg: y_v = g(v), y_t = Jg(centroid) n_t
// (exact for affine g, MATH-NOTES; a smooth g is reproduced approximately, which is all a test map needs).
template <class G, class JG>
MatX3d coefficients_of(const Cage& cage, G g, JG jg) {
  MatX3d y(cage.num_coeffs(), 3);
  for (int v = 0; v < cage.num_vertices(); ++v) y.row(v) = g(Vec3(cage.V.row(v))).transpose();
  for (int t = 0; t < cage.num_faces(); ++t) {
    const Vec3 c =
        (Vec3(cage.V.row(cage.F(t, 0))) + Vec3(cage.V.row(cage.F(t, 1))) + Vec3(cage.V.row(cage.F(t, 2)))) /
        3.0;
    y.row(cage.num_vertices() + t) = (jg(c) * Vec3(cage.N.row(t))).transpose();
  }
  return y;
}

// A gentle bend (of a model whose long axis is z, |x| < 1/κ) about the y axis: angle κ z, radius 1/κ.
MatX3d bend_coefficients(const Cage& cage, double kappa) {
  auto g = [kappa](const Vec3& p) {
    const double a = kappa * p.z(), r = 1.0 / kappa - p.x();
    return Vec3(1.0 / kappa - r * std::cos(a), p.y(), r * std::sin(a));
  };
  auto jg = [kappa](const Vec3& p) {
    const double a = kappa * p.z(), r = 1.0 / kappa - p.x();
    Mat3 J;
    J << std::cos(a), 0, r * kappa * std::sin(a), 0, 1, 0, -std::sin(a), 0, r * kappa * std::cos(a);
    return J;
  };
  return coefficients_of(cage, g, jg);
}

// The largest winding number of the deformed (piecewise-linear) surface at the images of grid points inside
// the rest solid, at least `clearance` from its surface: the number of preimages of those image points.
double max_image_winding(const Cage& cage, const TriMesh& mesh, const MatX3d& y, double spacing,
                         double clearance) {
  const WindingNumber rest(mesh.V, mesh.F);
  const TriangleGrid near(mesh.V, mesh.F, clearance);
  const Vec3 lo = mesh.V.colwise().minCoeff().transpose(), hi = mesh.V.colwise().maxCoeff().transpose();
  std::vector<Vec3> inside;
  for (double x = lo.x() + spacing / 2; x < hi.x(); x += spacing)
    for (double yy = lo.y() + spacing / 2; yy < hi.y(); yy += spacing)
      for (double z = lo.z() + spacing / 2; z < hi.z(); z += spacing) {
        const Vec3 p(x, yy, z);
        if (rest.at(p) >= 0.5 && !near.any_within(p, clearance)) inside.push_back(p);
      }
  MatX3d P(inside.size(), 3);
  for (size_t i = 0; i < inside.size(); ++i) P.row(i) = inside[i].transpose();
  const HarmonicBasis basis(cage);
  const MatX3d fP = basis.map_values(y, P);
  const MatX3d fV = basis.map_values(y, mesh.V);
  const WindingNumber deformed(fV, mesh.F);
  double w = 0;
  for (Eigen::Index i = 0; i < fP.rows(); ++i) w = std::max(w, deformed.at(fP.row(i)));
  return w;
}

// The model and the map y moved by t and scaled by s: x ↦ s f((x − t)/s) + t, whose vertex coefficients
// (y_v = g(v)) move like the points and whose face coefficients (J n) stay.
struct MovedModel {
  Cage cage;
  TriMesh mesh;
  MatX3d y;
};
MovedModel moved_and_scaled(const Model& m, const MatX3d& y, double s, const Vec3& t) {
  TriMesh cm;
  cm.V = (m.cage.V * s).rowwise() + t.transpose();
  cm.F = m.cage.F;
  TriMesh mesh = m.mesh;
  mesh.V = (m.mesh.V * s).rowwise() + t.transpose();
  MatX3d ys = y;
  const int nv = m.cage.num_vertices();
  ys.topRows(nv) = (y.topRows(nv) * s).rowwise() + t.transpose();
  return {Cage(cm), mesh, ys};
}

TEST(GlobalInjectivity, IdentityAndGentleBendOfSpotAreInjectiveAndNoImagePointIsCoveredTwice) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("spot"));
  const GlobalInjectivityChecker checker(m.cage, m.mesh);
  const GlobalInjectivity id = checker.check(m.cage.identity_coefficients());
  EXPECT_EQ(id.verdict, Verdict::kInjective) << id.reason;
  const MatX3d y = bend_coefficients(m.cage, 0.8);
  const GlobalInjectivity g = checker.check(y);
  EXPECT_EQ(g.verdict, Verdict::kInjective) << g.reason;
  EXPECT_GT(g.candidate_pairs, 0);
  EXPECT_LT(max_image_winding(m.cage, m.mesh, y, 0.05, 0.02), 1.5);
}

TEST(GlobalInjectivity, OpenSurfaceIsNotDecided) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
  TriMesh open = m.mesh;
  open.F.conservativeResize(open.F.rows() - 1, 3);
  const GlobalInjectivity g = check_global_injectivity(m.cage, open, m.cage.identity_coefficients());
  EXPECT_EQ(g.verdict, Verdict::kNotDecided);
  EXPECT_NE(g.reason.find("not a closed manifold"), std::string::npos) << g.reason;
}

// A mesh whose vertex of largest x is moved to `tip` (inside the cage): its triangles form a cone into the
// body.
TriMesh with_largest_x_vertex_at(const TriMesh& mesh, const Vec3& tip) {
  TriMesh out = mesh;
  Eigen::Index v = 0;
  out.V.col(0).maxCoeff(&v);
  out.V.row(v) = tip.transpose();
  return out;
}

// ∂D of a rest mesh that intersects itself, checked independently: beside the centroid of every boundary
// piece (rounded to double), the exact winding number of the mesh itself (exact_winding.cpp, another code
// path) is 0 on the side the piece faces and 1 behind it. Returns the number of pieces checked (some rays are
// degenerate).
int check_boundary_sides(const TriMesh& mesh, const RestSolidBoundary& b) {
  std::vector<int> all(mesh.F.rows());
  std::iota(all.begin(), all.end(), 0);
  int checked = 0;
  for (Eigen::Index i = 0; i < b.F.rows(); ++i) {
    const Vec3 p0 = b.points.row(b.F(i, 0)), p1 = b.points.row(b.F(i, 1)), p2 = b.points.row(b.F(i, 2));
    const Vec3 n = (p1 - p0).cross(p2 - p0);
    const double shortest = std::min({(p1 - p0).norm(), (p2 - p1).norm(), (p0 - p2).norm()});
    const Vec3 c = (p0 + p1 + p2) / 3.0, h = 1e-3 * shortest * n.normalized();
    const auto out = exact_winding_number(mesh.V, mesh.F, all, c + h),
               in = exact_winding_number(mesh.V, mesh.F, all, c - h);
    if (!out || !in) continue;
    EXPECT_EQ(*out, 0) << "boundary piece " << i;
    EXPECT_EQ(*in, 1) << "boundary piece " << i;
    ++checked;
  }
  return checked;
}

// A rest mesh that intersects itself is decided on D = closure{w ≥ 1} where ∂D, computed exactly, is one
// closed manifold (Step G1): spot's vertex of largest x pushed through the body to beyond the smallest x (a
// tunnel through the solid; the cone's tip pokes out of the far side, where w = -1). The identity is
// injective, a shear too, and no image point is covered twice (dense winding numbers of the deformed
// surface). The cone's tip placed exactly on a far triangle pinches ∂D at that point: not decided.
TEST(GlobalInjectivity, RestMeshThatIntersectsItselfIsDecidedWhereTheBoundaryOfItsSolidIsOneManifold) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("spot"));
  ASSERT_TRUE(find_self_intersections(m.mesh.V, m.mesh.F).empty());
  const double x_max = m.mesh.V.col(0).maxCoeff(), x_min = m.mesh.V.col(0).minCoeff();
  Eigen::Index vmin = 0;
  m.mesh.V.col(0).minCoeff(&vmin);
  const Vec3 far = m.mesh.V.row(vmin).transpose();
  const TriMesh crossed = with_largest_x_vertex_at(m.mesh, far - Vec3(0.05 * (x_max - x_min), 0, 0));
  const auto pairs = find_self_intersections(crossed.V, crossed.F);
  ASSERT_FALSE(pairs.empty());
  const RestSolidBoundary b = rest_solid_boundary(crossed.V, crossed.F, pairs);
  ASSERT_EQ(b.problem, "");
  EXPECT_GT(b.split_triangles, 0);
  EXPECT_LT(b.F.rows(), b.pieces);  // the tip's pieces outside the body (w = -1 beyond them) are not in ∂D
  EXPECT_GT(check_boundary_sides(crossed, b), 0.9 * b.F.rows());
  const GlobalInjectivityChecker checker(m.cage, crossed);
  const GlobalInjectivity id = checker.check(m.cage.identity_coefficients());
  EXPECT_EQ(id.verdict, Verdict::kInjective) << id.reason;
  EXPECT_EQ(id.rest_intersecting_pairs, static_cast<long>(pairs.size()));
  // A shear (the cone's triangles span the body: a bend leaves them unproven at the depth limit, null).
  Mat3 A;
  A << 1, 0.3, 0, 0, 1, 0, 0.2, 0, 1.1;
  const MatX3d y = coefficients_of(
      m.cage, [&](const Vec3& p) { return Vec3(A * p); }, [&](const Vec3&) { return A; });
  const GlobalInjectivity g = checker.check(y);
  EXPECT_EQ(g.verdict, Verdict::kInjective) << g.reason;
  EXPECT_LT(max_image_winding(m.cage, crossed, y, 0.05, 0.02), 1.5);

  // The tip on a corner of the far side: two sheets of ∂D meet only at that point.
  const TriMesh touching = with_largest_x_vertex_at(m.mesh, far);
  const auto touching_pairs = find_self_intersections(touching.V, touching.F);
  ASSERT_FALSE(touching_pairs.empty());
  const GlobalInjectivity t = check_global_injectivity(m.cage, touching, m.cage.identity_coefficients());
  EXPECT_EQ(t.verdict, Verdict::kNotDecided) << t.reason;
  EXPECT_NE(t.reason.find("rest-state mesh intersects itself"), std::string::npos) << t.reason;
  EXPECT_NE(t.reason.find("the boundary of its solid is not decided"), std::string::npos) << t.reason;
}

// The shared bar mesh intersects itself (exact predicates: its triangle 14036 crosses four triangles of the
// side y = -0.17, two of them sharing no vertex with it: a thin fold of its surface). Its solid's boundary is
// one closed manifold, so the identity and a bend are decided — wherever the model is moved or scaled.
TEST(GlobalInjectivity, SharedBarMeshIntersectsItselfAndIsDecidedOnTheBoundaryOfItsSolid) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
  const auto pairs = find_self_intersections(m.mesh.V, m.mesh.F);
  ASSERT_EQ(pairs.size(), 4u);
  const RestSolidBoundary b = rest_solid_boundary(m.mesh.V, m.mesh.F, pairs);
  ASSERT_EQ(b.problem, "");
  EXPECT_EQ(b.split_triangles, 5);
  EXPECT_LT(b.F.rows(), b.pieces);  // the pieces inside the fold (w = 2 behind them) are not in ∂D
  EXPECT_GT(check_boundary_sides(m.mesh, b), 0.9 * b.F.rows());
  const MatX3d y = bend_coefficients(m.cage, 0.8);
  EXPECT_LT(max_image_winding(m.cage, m.mesh, y, 0.03, 0.02), 1.5);
  for (const double s : {1e-2, 1.0, 40.0}) {
    const MovedModel mm = moved_and_scaled(m, y, s, s == 1.0 ? Vec3::Zero() : Vec3(-250.0, 3.5, 1e2));
    const GlobalInjectivityChecker checker(mm.cage, mm.mesh);
    const GlobalInjectivity id = checker.check(mm.cage.identity_coefficients());
    EXPECT_EQ(id.verdict, Verdict::kInjective) << "scale " << s << ": " << id.reason;
    EXPECT_EQ(id.rest_intersecting_pairs, 4);
    const GlobalInjectivity g = checker.check(mm.y);
    EXPECT_EQ(g.verdict, Verdict::kInjective) << "scale " << s << ": " << g.reason;
  }
}

TEST(GlobalInjectivity, VerdictIsInvariantUnderTranslationAndScale) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("spot"));
  const MatX3d y = bend_coefficients(m.cage, 0.8);
  for (const double s : {1e-3, 250.0}) {
    const MovedModel mm = moved_and_scaled(m, y, s, Vec3(1e3, -37.5, 4.25));
    const GlobalInjectivity g = check_global_injectivity(mm.cage, mm.mesh, mm.y);
    EXPECT_EQ(g.verdict, Verdict::kInjective) << "scale " << s << ": " << g.reason;
  }
}

// The bar bent into a tight U whose free end is laid onto its fixed half (data/scenarios/
// bar_fold_onto_itself.json; the coefficients are the map `lidef deform` wrote for it, certified locally
// injective): the shape passes through itself.
MatX3d fold_coefficients(const Cage& cage) {
  return read_coefficients(test::project_data() + "/scenarios/bar_fold_onto_itself.coefficients.txt", cage);
}

// The fold passes through itself (the winding numbers below) and the verdict says so — proven by a crossing
// of two triangles disjoint at rest (no common vertex, not among the bar mesh's own intersecting pairs), at a
// point on both deformed triangles — wherever the model is moved or scaled. (The bar's rest mesh intersects
// itself; a crossing is proven only between triangles disjoint at rest.)
TEST(GlobalInjectivity, BarFoldedOntoItselfIsProvenToOverlapWhereverTheModelIsMovedOrScaled) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
  const MatX3d y = fold_coefficients(m.cage);
  EXPECT_GT(max_image_winding(m.cage, m.mesh, y, 0.03, 0.02), 1.5);
  const auto rest_pairs = find_self_intersections(m.mesh.V, m.mesh.F);
  const double diag = (m.cage.bbox_max - m.cage.bbox_min).norm();
  for (const double s : {1e-2, 1.0, 40.0}) {
    const MovedModel mm = moved_and_scaled(m, y, s, s == 1.0 ? Vec3::Zero() : Vec3(-250.0, 3.5, 1e2));
    const Cage& cage = mm.cage;
    const TriMesh& mesh = mm.mesh;
    const MatX3d& ys = mm.y;
    const GlobalInjectivity g = check_global_injectivity(cage, mesh, ys);
    ASSERT_EQ(g.verdict, Verdict::kOverlap) << "scale " << s << ": " << g.reason;
    const int a = g.overlap_face_a, b = g.overlap_face_b;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_NE(mesh.F(a, i), mesh.F(b, j)) << "the triangles share a vertex";
    EXPECT_FALSE(std::binary_search(rest_pairs.begin(), rest_pairs.end(),
                                    std::make_pair(std::min(a, b), std::max(a, b))))
        << "the triangles intersect at rest";
    // The point lies on both deformed triangles, up to their tubes (far below the bar's size).
    const HarmonicBasis basis(cage);
    for (const int f : {a, b}) {
      MatX3d P(3, 3);
      for (int k = 0; k < 3; ++k) P.row(k) = mesh.V.row(mesh.F(f, k));
      const MatX3d fP = basis.map_values(ys, P);
      const Vec3 c = (fP.row(0) + fP.row(1) + fP.row(2)).transpose() / 3.0;
      const double r = std::max({(fP.row(0).transpose() - c).norm(), (fP.row(1).transpose() - c).norm(),
                                 (fP.row(2).transpose() - c).norm()});
      EXPECT_LT((g.overlap_point - c).norm(), r + 1e-3 * s * diag) << "scale " << s << ", triangle " << f;
    }
  }
}

// --- Surfaces of several components (docs/certificate.md, Step G5): the nesting of their images.

// The union of two surfaces (b's vertex indices shifted), b's orientation reversed when `flip_b`.
TriMesh join(const TriMesh& a, const TriMesh& b, bool flip_b = false) {
  TriMesh t;
  t.V.resize(a.V.rows() + b.V.rows(), 3);
  t.V << a.V, b.V;
  t.F.resize(a.F.rows() + b.F.rows(), 3);
  MatX3i fb = b.F.array() + static_cast<int>(a.V.rows());
  if (flip_b) fb.col(1).swap(fb.col(2));
  t.F << a.F, fb;
  return t;
}

TriMesh moved(TriMesh t, const Vec3& by) {
  t.V.rowwise() += by.transpose();
  return t;
}

// The exact winding number against the cases it must get right: nested boxes, a reversed surface, points
// outside, and a point on the surface (not decided rather than a guess).
TEST(ExactWindingNumber, CountsNestedAndReversedSurfacesAndRefusesPointsOnTheSurface) {
  const TriMesh outer = box_surface(Vec3(-1, -1, -1), Vec3(1, 1, 1), Eigen::Vector3i(3, 3, 3));
  const TriMesh inner = box_surface(Vec3(-0.5, -0.5, -0.5), Vec3(0.5, 0.5, 0.5), Eigen::Vector3i(2, 2, 2));
  for (const bool flip : {false, true}) {
    const TriMesh t = join(outer, inner, flip);
    std::vector<int> all(t.F.rows()), in_only;
    std::iota(all.begin(), all.end(), 0);
    for (int f = static_cast<int>(outer.F.rows()); f < t.F.rows(); ++f) in_only.push_back(f);
    const int s = flip ? -1 : 1;
    EXPECT_EQ(exact_winding_number(t.V, t.F, all, Vec3(0, 0, 0)), 1 + s);  // mesh vertices lie on this axis
    EXPECT_EQ(exact_winding_number(t.V, t.F, all, Vec3(0.75, 0.1, -0.3)), 1);
    EXPECT_EQ(exact_winding_number(t.V, t.F, all, Vec3(3, 0.2, 0.1)), 0);
    EXPECT_EQ(exact_winding_number(t.V, t.F, in_only, Vec3(0.1, 0.2, 0.3)), s);
    EXPECT_EQ(exact_winding_number(t.V, t.F, in_only, Vec3(0.75, 0, 0)), 0);
    EXPECT_FALSE(exact_winding_number(t.V, t.F, in_only, Vec3(0.5, 0.1, 0.2)).has_value());  // on a face
  }
}

// A ball with a cavity (outer sphere outward, cavity sphere facing into the cavity) in the ball's cage.
struct HollowBall {
  Model ball = make_ball({1.0, 0.1, 3, 2});
  TriMesh mesh;
  explicit HollowBall(const Vec3& cavity_center, double cavity_radius = 0.35, bool flip = true) {
    mesh = join(ball.mesh, moved(icosphere(cavity_radius, 2), cavity_center), flip);
  }
};

// The identity, an affine shear, and a smooth map pushing the (off-center) cavity towards the outer surface
// while it stays inside: all proven injective, and the winding numbers of the deformed surface at the images
// of interior points (an independent count of preimages) never reach 2.
TEST(GlobalInjectivity, BallWithACavityIsInjectiveUnderTheIdentityAShearAndAPushOfTheCavity) {
  const HollowBall h(Vec3(0.2, 0, 0));
  const Cage& cage = h.ball.cage;
  const GlobalInjectivityChecker checker(cage, h.mesh);
  const GlobalInjectivity id = checker.check(cage.identity_coefficients());
  EXPECT_EQ(id.verdict, Verdict::kInjective) << id.reason;
  Mat3 A;
  A << 1.1, 0.15, 0, 0, 0.95, 0.1, 0.05, 0, 1.0;
  const MatX3d shear = coefficients_of(
      cage, [&](const Vec3& p) -> Vec3 { return A * p; }, [&](const Vec3&) { return A; });
  // p + 0.3 (1 − |p|²) e_x: det J = 1 − 0.6 p_x > 0 inside the ball; the cavity moves by up to ~0.27.
  auto push = [](const Vec3& p) -> Vec3 { return p + 0.3 * (1 - p.squaredNorm()) * Vec3::UnitX(); };
  auto push_j = [](const Vec3& p) -> Mat3 {
    Mat3 J = Mat3::Identity();
    J.row(0) -= 0.6 * p.transpose();
    return J;
  };
  const MatX3d pushed = coefficients_of(cage, push, push_j);
  for (const MatX3d* y : {&shear, &pushed}) {
    const GlobalInjectivity g = checker.check(*y);
    EXPECT_EQ(g.verdict, Verdict::kInjective) << g.reason;
    EXPECT_LT(max_image_winding(cage, h.mesh, *y, 0.08, 0.03), 1.5);
  }
}

// The cavity's triangles facing out of the cavity: the winding number is 2 inside it, so the surface does
// not bound one solid as oriented and nothing is decided (not even the identity).
TEST(GlobalInjectivity, CavityOrientedLikeTheOuterSurfaceIsNotDecided) {
  const HollowBall h(Vec3(0.2, 0, 0), 0.35, false);
  const GlobalInjectivity g =
      check_global_injectivity(h.ball.cage, h.mesh, h.ball.cage.identity_coefficients());
  EXPECT_EQ(g.verdict, Verdict::kNotDecided);
  EXPECT_NE(g.reason.find("not oriented as the boundary of one solid"), std::string::npos) << g.reason;
}

// Two separate boxes, a large one A and a small one B, each in a box cage of its own (one cage of two
// components). A map that is the identity on A's cage and a translation on B's is exactly that map on each
// solid (Green coordinates reproduce an affine map per component, and a component's boundary integrals
// vanish outside it).
struct TwoBoxes {
  TriMesh a = box_surface(Vec3(-1, -0.5, -0.5), Vec3(0.1, 0.5, 0.5), Eigen::Vector3i(8, 6, 6));
  TriMesh b = box_surface(Vec3(0.5, -0.2, -0.2), Vec3(0.9, 0.2, 0.2), Eigen::Vector3i(3, 3, 3));
  TriMesh mesh = join(a, b);
  Cage cage{join(box_surface(Vec3(-1.1, -0.6, -0.6), Vec3(0.2, 0.6, 0.6), Eigen::Vector3i(2, 2, 2)),
                 box_surface(Vec3(0.4, -0.3, -0.3), Vec3(1.0, 0.3, 0.3), Eigen::Vector3i(2, 2, 2)))};
  MatX3d move_b(const Vec3& t) const {
    MatX3d y = cage.identity_coefficients();
    const int split = static_cast<int>(cage.V.rows()) / 2;  // both cage boxes have the same vertex count
    y.block(split, 0, cage.V.rows() - split, 3).rowwise() += t.transpose();
    return y;
  }
};

TEST(GlobalInjectivity, TwoBoxesAreInjectiveApartAndOverlapWhenOneIsMovedIntoOrInsideTheOther) {
  const TwoBoxes tb;
  ASSERT_EQ(tb.cage.V.rows() % 2, 0);
  const GlobalInjectivityChecker checker(tb.cage, tb.mesh);
  const int first_b = static_cast<int>(tb.a.F.rows());
  // Apart: the identity, and B moved towards A but not into it.
  for (const Vec3& t : {Vec3(0, 0, 0), Vec3(-0.3, 0.1, 0)}) {
    const MatX3d y = tb.move_b(t);
    const GlobalInjectivity g = checker.check(y);
    EXPECT_EQ(g.verdict, Verdict::kInjective) << g.reason;
    EXPECT_LT(max_image_winding(tb.cage, tb.mesh, y, 0.05, 0.02), 1.5);
  }
  // B half into A: the surfaces cross (the pair stage proves it, between a triangle of each box).
  {
    const MatX3d y = tb.move_b(Vec3(-0.6, 0, 0));
    const GlobalInjectivity g = checker.check(y);
    ASSERT_EQ(g.verdict, Verdict::kOverlap) << g.reason;
    EXPECT_NE(g.reason.find("mesh triangles"), std::string::npos) << g.reason;
    EXPECT_EQ(std::min(g.overlap_face_a, g.overlap_face_b) < first_b,
              std::max(g.overlap_face_a, g.overlap_face_b) >= first_b);
    EXPECT_GT(max_image_winding(tb.cage, tb.mesh, y, 0.05, 0.02), 1.5);
  }
  // B entirely inside A: no two triangles' images meet, yet every point of B's image has two preimages.
  {
    const MatX3d y = tb.move_b(Vec3(-1.2, 0.05, 0));
    const GlobalInjectivity g = checker.check(y);
    ASSERT_EQ(g.verdict, Verdict::kOverlap) << g.reason;
    EXPECT_NE(g.reason.find("the image of surface component 1 (mesh triangle " + std::to_string(first_b) +
                            ") lies inside the image of surface component 0 (mesh triangle 0)"),
              std::string::npos)
        << g.reason;
    EXPECT_EQ(g.overlap_face_a, first_b);
    EXPECT_EQ(g.overlap_face_b, 0);
    // The reported point is on B's image, inside A.
    EXPECT_GT(g.overlap_point.x(), -1.0);
    EXPECT_LT(g.overlap_point.x(), -0.25);
    EXPECT_GT(max_image_winding(tb.cage, tb.mesh, y, 0.05, 0.02), 1.5);
  }
}

// Step G6: a checker keeps the margins of the last map it proved injective and clears pairs of later maps by
// the motion since then. Two boxes with triangles fine enough that none is split (their balls are clear of
// the cage); a checker that keeps margins and audits every reused one against the map itself
// (GlobalInjectivityParams::audit_violations), beside checks of their own.
struct FineTwoBoxes : TwoBoxes {
  FineTwoBoxes() {
    a = box_surface(Vec3(-1, -0.5, -0.5), Vec3(0.1, 0.5, 0.5), Eigen::Vector3i(16, 12, 12));
    b = box_surface(Vec3(0.5, -0.2, -0.2), Vec3(0.9, 0.2, 0.2), Eigen::Vector3i(6, 6, 6));
    mesh = join(a, b);
  }
};

struct KeptAndOwn {
  const Cage& cage;
  const TriMesh& mesh;
  GlobalInjectivityChecker kept{cage, mesh};
  std::atomic<long> violations{0};
  long replayed = 0;
  // The kept checker's verdict on y, with the same verdict, place and triangles as a check of its own where
  // that one proves an overlap (a pair with a crossing is never cleared by a margin, so the first crossing
  // in pair order is the same pair), and no image point covered twice where it says injective.
  GlobalInjectivity check(const MatX3d& y, const std::string& what) {
    GlobalInjectivityParams audited, own;
    audited.audit_violations = &violations;
    own.reuse_margins = false;
    const GlobalInjectivity g = kept.check(y, audited);
    const GlobalInjectivity h = GlobalInjectivityChecker(cage, mesh).check(y, own);
    EXPECT_EQ(h.replayed_pairs, 0) << what;
    replayed += g.replayed_pairs;
    if (g.verdict == Verdict::kInjective) {
      EXPECT_LT(max_image_winding(cage, mesh, y, 0.05, 0.02), 1.5) << what;
    }
    if (h.verdict == Verdict::kOverlap) {
      EXPECT_EQ(g.verdict, Verdict::kOverlap) << what << ": " << g.reason;
      EXPECT_EQ(g.overlap_face_a, h.overlap_face_a) << what;
      EXPECT_EQ(g.overlap_face_b, h.overlap_face_b) << what;
      EXPECT_EQ(g.overlap_point, h.overlap_point) << what;
    }
    return g;
  }
};

// Box A turned 45° about z, box B (its cage component moved rigidly: reproduced exactly) pushed along x in
// steps of 0.01 past A's edge until they cross: pairs between A and B become candidates while apart, keep
// their separation margins, and must give them up when B crosses A.
TEST(GlobalInjectivity, KeptMarginsClearOnlyPairsTheMotionCannotHaveBroughtTogether) {
  const FineTwoBoxes tb;
  const int split_v = static_cast<int>(tb.cage.V.rows()) / 2,
            split_f = static_cast<int>(tb.cage.F.rows()) / 2;
  const Mat3 M = Eigen::AngleAxisd(std::acos(-1.0) / 4, Vec3::UnitZ()).toRotationMatrix();
  const Vec3 ca(-0.45, 0, 0);
  KeptAndOwn k{tb.cage, tb.mesh};
  int first_overlap = -1;
  for (const int i : {0, 2, 4, 6, 7, 8, 10}) {
    MatX3d y = tb.cage.identity_coefficients();
    for (int v = 0; v < split_v; ++v) y.row(v) = (M * (Vec3(tb.cage.V.row(v)) - ca) + ca).transpose();
    for (int t = 0; t < split_f; ++t)
      y.row(tb.cage.num_vertices() + t) = (M * Vec3(tb.cage.N.row(t))).transpose();
    for (int v = split_v; v < tb.cage.V.rows(); ++v) y(v, 0) += -0.2 - 0.01 * i, y(v, 1) += 0.3;
    if (k.check(y, "step " + std::to_string(i)).verdict == Verdict::kOverlap && first_overlap < 0)
      first_overlap = i;
  }
  EXPECT_EQ(k.violations.load(), 0);
  EXPECT_GT(k.replayed, 0);
  EXPECT_GT(first_overlap, 1) << "B must start apart from A and reach it";
}

// J changing: the cage vertex at the center of B's far face pushed into B until B's surface crosses itself;
// the injectivity balls' margins must absorb the change of J (the audit evaluates each reused ball anew).
TEST(GlobalInjectivity, KeptMarginsFollowTheChangeOfJAsACageVertexIsPushedThroughTheSurface) {
  const FineTwoBoxes tb;
  Eigen::Index pushed = 0;
  (tb.cage.V.rowwise() - Eigen::RowVector3d(1.0, 0, 0)).rowwise().norm().minCoeff(&pushed);
  KeptAndOwn k{tb.cage, tb.mesh};
  bool overlap = false;
  for (const int i : {0, 1, 2, 20, 21}) {
    MatX3d y = tb.cage.identity_coefficients();
    y(pushed, 0) -= 0.1 * i;
    y(pushed, 1) += 0.03 * i;
    overlap = overlap || k.check(y, "push " + std::to_string(i)).verdict == Verdict::kOverlap;
  }
  EXPECT_EQ(k.violations.load(), 0);
  EXPECT_GT(k.replayed, 0);
  EXPECT_TRUE(overlap);
}

// A small motion of spot's bend is cleared mostly by the kept margins, with the verdict of a check of its
// own.
TEST(GlobalInjectivity, KeptMarginsOfSpotClearMostPairsOfASmallMotion) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("spot"));
  KeptAndOwn k{m.cage, m.mesh};
  ASSERT_EQ(k.check(bend_coefficients(m.cage, 0.8), "bend 0.8").verdict, Verdict::kInjective);
  const GlobalInjectivity g = k.check(bend_coefficients(m.cage, 0.801), "bend 0.801");
  EXPECT_EQ(g.verdict, Verdict::kInjective) << g.reason;
  EXPECT_GT(2 * g.replayed_pairs, g.candidate_pairs - g.replayed_pairs);
  EXPECT_EQ(k.violations.load(), 0);
}

// Two cases checked under several settings that must not change the result: spot bent (injective; 32,000
// cell entries) and the two boxes crossing (an overlap). Each: the cage, the mesh, the map, the verdict.
struct SpotAndCrossingBoxes {
  const Model spot = load_model(test::shared_model("spot"));
  const FineTwoBoxes tb;
  struct Case {
    const Cage& cage;
    const TriMesh& mesh;
    MatX3d y;
    Verdict verdict;
  };
  std::vector<Case> cases() const {
    MatX3d crossing = tb.cage.identity_coefficients();
    for (int v = static_cast<int>(tb.cage.V.rows()) / 2; v < tb.cage.V.rows(); ++v) crossing(v, 0) -= 0.7;
    return {{spot.cage, spot.mesh, bend_coefficients(spot.cage, 0.8), Verdict::kInjective},
            {tb.cage, tb.mesh, crossing, Verdict::kOverlap}};
  }
};

// A check of its own (no margins kept or used).
GlobalInjectivity check_alone(const GlobalInjectivityChecker& checker, const MatX3d& y) {
  GlobalInjectivityParams own;
  own.reuse_margins = false;
  return checker.check(y, own);
}

// g has ref's verdict, reason, place, triangles, candidate pairs and tube radius.
void expect_same_result(const GlobalInjectivity& g, const GlobalInjectivity& ref, const std::string& what) {
  EXPECT_EQ(g.verdict, ref.verdict) << what;
  EXPECT_EQ(g.reason, ref.reason) << what;
  EXPECT_EQ(g.overlap_point, ref.overlap_point) << what;
  EXPECT_EQ(g.overlap_face_a, ref.overlap_face_a) << what;
  EXPECT_EQ(g.overlap_face_b, ref.overlap_face_b) << what;
  EXPECT_EQ(g.candidate_pairs, ref.candidate_pairs) << what;
  EXPECT_EQ(g.max_tube_radius, ref.max_tube_radius) << what;
}

// The check's result does not depend on the number of threads (the candidate pairs' cells are built, sorted
// in up to 3 chunks and merged, and scanned over the threads; the pairs are examined in parallel): 1, 2
// and 3.
TEST(GlobalInjectivity, ResultIsTheSameForAnyNumberOfThreads) {
  LIDEF_REQUIRE_SHARED();
  const SpotAndCrossingBoxes sc;
  const int saved = omp_get_max_threads();
  for (const auto& c : sc.cases()) {
    omp_set_num_threads(1);
    const GlobalInjectivity one = check_alone(GlobalInjectivityChecker(c.cage, c.mesh), c.y);
    EXPECT_EQ(one.verdict, c.verdict) << one.reason;
    for (const int threads : {2, 3}) {
      omp_set_num_threads(threads);
      const GlobalInjectivity g = check_alone(GlobalInjectivityChecker(c.cage, c.mesh), c.y);
      expect_same_result(g, one, std::to_string(threads) + " threads");
      EXPECT_EQ(g.pair_tests, one.pair_tests) << threads;
      EXPECT_EQ(g.max_depth_used, one.max_depth_used) << threads;
    }
  }
  omp_set_num_threads(saved);
}

// What a checker keeps for every check (the vertices' basis values and gradients, the balls' factor rows)
// changes no verdict, place or candidate pair: nothing kept, the values only, and the default (256 MB: all of
// it for these models).
TEST(GlobalInjectivity, CacheBudgetChangesNoVerdict) {
  LIDEF_REQUIRE_SHARED();
  const SpotAndCrossingBoxes sc;
  for (const auto& c : sc.cases()) {
    const GlobalInjectivity all = check_alone(GlobalInjectivityChecker(c.cage, c.mesh), c.y);
    EXPECT_EQ(all.verdict, c.verdict) << all.reason;
    // The vertices' basis values only: #V by #V+#F doubles, less than the gradients' 3 #V by #V+#F floats.
    const double values_mb =
        1.01 * static_cast<double>(c.mesh.V.rows()) * (c.cage.V.rows() + c.cage.F.rows()) * 8 / 1048576.0;
    for (const double mb : {0.0, values_mb}) {
      expect_same_result(check_alone(GlobalInjectivityChecker(c.cage, c.mesh, mb), c.y), all,
                         std::to_string(mb) + " MB");
    }
  }
}

// Two tetrahedra touching at one shared vertex (a bow tie): every edge is used once in each direction, yet
// the surface is not a manifold at that vertex, where Jordan–Brouwer (Step G1) fails: surfaces touching at a
// point may be nested without any two triangles' images crossing. Nothing is decided, not even the identity;
// the same tetrahedra moved apart (two components, Step G5) are decided.
TEST(GlobalInjectivity, SurfacePinchedAtAVertexIsNotDecided) {
  const Model ball = make_ball({1.0, 0.1, 3, 2});
  const Vec3 a[3] = {Vec3(-0.6, 0.3, -0.2), Vec3(-0.6, -0.3, -0.2), Vec3(-0.6, 0.0, 0.35)};
  auto tetrahedra = [&](bool share_apex) {
    TriMesh t;
    t.V.resize(share_apex ? 7 : 8, 3);
    t.V.row(0) = Vec3::Zero().transpose();
    const Vec3 shift = share_apex ? Vec3::Zero() : Vec3(0.05, 0, 0);
    for (int k = 0; k < 3; ++k) {
      t.V.row(1 + k) = a[k].transpose();
      t.V.row(4 + k) = (shift - a[k]).transpose();  // the point reflection: the second one on the other side
    }
    const int apex_b = share_apex ? 0 : 7;
    if (!share_apex) t.V.row(7) = shift.transpose();
    t.F.resize(8, 3);
    t.F << 0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2,  //
        apex_b, 4, 5, apex_b, 5, 6, apex_b, 6, 4, 4, 6, 5;
    // Orient each tetrahedron outward (positive volume).
    for (int half = 0; half < 2; ++half) {
      const Eigen::Index first = 4 * half;
      TriMesh part;
      part.V = t.V;
      part.F = t.F.middleRows(first, 4);
      if (signed_volume(part.V, part.F) < 0)
        for (Eigen::Index f = first; f < first + 4; ++f) std::swap(t.F(f, 1), t.F(f, 2));
    }
    return t;
  };
  const TriMesh pinched = tetrahedra(true);
  ASSERT_TRUE(find_self_intersections(pinched.V, pinched.F).empty());
  const GlobalInjectivity g = check_global_injectivity(ball.cage, pinched, ball.cage.identity_coefficients());
  EXPECT_EQ(g.verdict, Verdict::kNotDecided);
  EXPECT_NE(g.reason.find("pinched at vertex 0 (its triangles there form 2 fans"), std::string::npos)
      << g.reason;

  const TriMesh apart = tetrahedra(false);
  const GlobalInjectivity h = check_global_injectivity(ball.cage, apart, ball.cage.identity_coefficients());
  EXPECT_EQ(h.verdict, Verdict::kInjective) << h.reason;
}

// Step G3's tube: the linear interpolation error on a triangle is at most ½ max‖D²f‖ Σλ_i|x − v_i|², and
// Σλ_i|x − v_i|² ≤ r² for r = triangle_enclosing_radius. For f(x) = ½|x|² (D²f = I) the error is exactly
// ½ Σλ_i|x − v_i|², whose maximum over the triangle is ½ r_min² (r_min: the smallest enclosing ball's
// radius): sampled, it stays below ½ r² and comes within 0.2% of it; r is r_min computed independently (half
// the longest side of an obtuse triangle, abc / 4·area of an acute one), and below the diameter's bound.
TEST(GlobalInjectivity, TriangleEnclosingRadiusBoundsTheInterpolationErrorAndIsTheSmallestBall) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<std::array<Vec3, 3>> tris = {
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, std::sqrt(0.75), 0)},                          // equilateral
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},                                          // right
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 0.05, 0)},                                     // obtuse, flat
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1e-3, 1e-3, 0)},                                    // needle
      {Vec3(1e3, 1e3, 1e3), Vec3(1e3 + 1e-2, 1e3, 1e3), Vec3(1e3, 1e3 + 1e-2, 1e3 + 1e-2)}};  // far away
  for (int i = 0; i < 40; ++i)
    tris.push_back(
        {Vec3(u(rng), u(rng), u(rng)), Vec3(u(rng), u(rng), u(rng)), Vec3(u(rng), u(rng), u(rng))});
  for (const auto& t : tris) {
    const double r = triangle_enclosing_radius(t[0], t[1], t[2]);
    const double a = (t[1] - t[2]).norm(), b = (t[2] - t[0]).norm(), c = (t[0] - t[1]).norm();
    const double longest = std::max({a, b, c});
    const double others2 = a * a + b * b + c * c - longest * longest;
    const double area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).norm();
    const double r_min = longest * longest >= others2 ? longest / 2 : a * b * c / (4 * area);
    EXPECT_GE(r, r_min * (1 - 1e-9));
    EXPECT_LE(r, r_min * (1 + 1e-9) + 1e-12 * t[0].cwiseAbs().maxCoeff());
    EXPECT_LE(r * r, longest * longest / 3 * (1 + 1e-9));  // Jung: r_min ≤ diam / √3
    double worst = 0;
    constexpr int n = 400;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const double l0 = double(i) / n, l1 = double(j) / n, l2 = 1 - l0 - l1;
        const Vec3 x = l0 * t[0] + l1 * t[1] + l2 * t[2];
        worst = std::max(worst, l0 * (x - t[0]).squaredNorm() + l1 * (x - t[1]).squaredNorm() +
                                    l2 * (x - t[2]).squaredNorm());
      }
    EXPECT_LE(worst, r * r);
    EXPECT_GE(worst, r * r * 0.998);
  }
}

// Step G3 on a harmonic map: per mesh triangle, the distance of sampled points' images from the affine
// triangle on the mapped corners never exceeds ρ = ½ L₁ r² + ε, L₁ = Σ_e ‖δ_e‖ Γ_e(B) over the triangle's
// ball (recomputed here from the public factor rows), on a bend of spot that makes the tubes matter.
TEST(GlobalInjectivity, TubeRadiiBoundTheSampledDistanceOfTriangleImagesFromTheirAffineTriangles) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("spot"));
  const MatX3d y = bend_coefficients(m.cage, 1.0);
  const HarmonicBasis basis(m.cage);
  const HarmonicBasis::FaceMatrices fm = basis.face_matrices(y);
  std::vector<Vec3> u, w;
  for (const CageEdge& e : m.cage.edges) u.push_back(m.cage.V.row(e.v0)), w.push_back(m.cage.V.row(e.v1));
  const EdgeArrays edges(u, w);
  std::vector<double> delta(m.cage.edges.size());
  for (size_t e = 0; e < delta.size(); ++e)
    delta[e] = (fm.A[m.cage.edges[e].f0] - fm.A[m.cage.edges[e].f1]).norm();
  const WindingNumber cage_winding(m.cage.V, m.cage.F);
  const TriangleGrid cage_grid(m.cage.V, m.cage.F, 0.05);
  constexpr int n = 6;  // barycentric grid per triangle
  MatX3d P(m.mesh.F.rows() * (n + 1) * (n + 2) / 2, 3), B(P.rows(), 3);
  for (Eigen::Index f = 0, k = 0; f < m.mesh.F.rows(); ++f)
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j, ++k) {
        B.row(k) << double(i) / n, double(j) / n, 1 - double(i + j) / n;
        P.row(k) = B(k, 0) * m.mesh.V.row(m.mesh.F(f, 0)) + B(k, 1) * m.mesh.V.row(m.mesh.F(f, 1)) +
                   B(k, 2) * m.mesh.V.row(m.mesh.F(f, 2));
      }
  const MatX3d fP = basis.map_values(y, P), fV = basis.map_values(y, m.mesh.V);
  std::vector<float> row(edges.size());
  double worst_ratio = 0, worst_deviation = 0, largest_rho = 0;
  long tubes = 0;
  for (Eigen::Index f = 0, k = 0; f < m.mesh.F.rows(); ++f) {
    std::array<Vec3, 3> p, q;
    for (int c = 0; c < 3; ++c) p[c] = m.mesh.V.row(m.mesh.F(f, c)), q[c] = fV.row(m.mesh.F(f, c));
    const Vec3 center = (p[0] + p[1] + p[2]) / 3.0;
    double R = 0;
    for (const Vec3& v : p) R = std::max(R, (v - center).norm());
    double deviation = 0;
    for (int s = 0; s < (n + 1) * (n + 2) / 2; ++s, ++k) {
      const Vec3 affine = B(k, 0) * q[0] + B(k, 1) * q[1] + B(k, 2) * q[2];
      deviation = std::max(deviation, (Vec3(fP.row(k)) - affine).norm());
    }
    worst_deviation = std::max(worst_deviation, deviation);
    const bool clear = !cage_grid.any_within(center, R) && std::abs(cage_winding.at(center) - 1) < 1e-6;
    if (!clear || !factor_row(edges, EdgeFactor::kSharpFirstOrder, center, R, row.data())) continue;
    double L1 = 0;
    for (size_t e = 0; e < delta.size(); ++e) L1 += delta[e] * row[e];
    const double r = triangle_enclosing_radius(p[0], p[1], p[2]);
    const double rho = 0.5 * L1 * r * r + 1e-12;
    largest_rho = std::max(largest_rho, rho);
    ++tubes;
    worst_ratio = std::max(worst_ratio, deviation / rho);
  }
  EXPECT_GT(tubes, m.mesh.F.rows() / 2);
  EXPECT_GT(worst_deviation, 1e-5);  // the map bends the triangles: the test measures something
  EXPECT_LE(worst_ratio, 1.0);
  // The checker's own tubes are these (its largest over the unsplit triangles, computed in the cage's
  // normalized frame with its rounding allowances).
  const GlobalInjectivity g = check_global_injectivity(m.cage, m.mesh, y);
  EXPECT_EQ(g.verdict, Verdict::kInjective) << g.reason;
  EXPECT_NEAR(g.max_tube_radius, largest_rho, 1e-6 * largest_rho);
  std::cout << "tubes " << tubes << " of " << m.mesh.F.rows() << ", largest sampled deviation / radius "
            << worst_ratio << ", largest deviation " << worst_deviation << "\n";
}

// The solver's mode (deform_params.h `injectivity`): a table row with its two names, local by default.
TEST(GlobalInjectivityMode, IsAParameterWithTwoNamesAndLocalByDefault) {
  const ParamInfo* p = find_param("injectivity");
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(std::string(p->group), "certificate");
  EXPECT_EQ(param_flag(*p), "--injectivity");
  EXPECT_EQ(param_choices(*p), (std::vector<std::string>{"local", "global"}));
  DeformParams d;
  EXPECT_EQ(d.injectivity, InjectivityMode::kLocal);
  set_param_from_text(d, "injectivity", "global", "--injectivity");
  EXPECT_EQ(d.injectivity, InjectivityMode::kGlobal);
  EXPECT_THROW(set_param_from_text(d, "injectivity", "globl", "--injectivity"), InputError);
}

// Global mode never acts as local: where the verdict cannot be decided (a rest mesh that intersects itself
// where the boundary of its solid is not one manifold, the voxel grid as domain), the first step says why and
// changes nothing; local mode steps as before.
TEST(GlobalInjectivityMode, RefusesToStartWhereGlobalInjectivityCannotBeDecided) {
  const Model& m = test::beam().model;
  // A vertex of the end x = max moved through the beam onto the vertex of its other end (x = min) nearest to
  // its axis: its triangles meet the end face x = min at that point, where ∂D is pinched.
  const double x_min = m.mesh.V.col(0).minCoeff();
  Eigen::Index vmin = -1;
  for (Eigen::Index v = 0; v < m.mesh.V.rows(); ++v)
    if (m.mesh.V(v, 0) == x_min &&
        (vmin < 0 || m.mesh.V.row(v).tail<2>().norm() < m.mesh.V.row(vmin).tail<2>().norm()))
      vmin = v;
  const TriMesh crossed = with_largest_x_vertex_at(m.mesh, m.mesh.V.row(vmin).transpose());
  ASSERT_FALSE(find_self_intersections(crossed.V, crossed.F).empty());
  DeformParams p;
  p.samples = 3000;
  p.reduced_dof = 40;
  p.injectivity = InjectivityMode::kGlobal;
  MatX3d src(2, 3), dst(2, 3);
  src << -0.9, 0, 0, 0.9, 0, 0;
  dst << -0.9, 0, 0, 0.9, 0.05, 0;
  struct Case {
    const TriMesh* mesh;
    DomainKind domain;
    const char* reason;
  };
  for (const Case& c : {Case{&crossed, DomainKind::kMesh, "the boundary of its solid is not decided"},
                        Case{&m.mesh, DomainKind::kVoxels, "the voxel grid"}}) {
    p.domain = c.domain;
    p.injectivity = InjectivityMode::kGlobal;
    DeformationSolver solver(m.cage, *c.mesh, p, test::beam().cache.str());
    solver.set_handles(src, dst);
    const MatS3 y0 = solver.reduced_coefficients();
    try {
      solver.step();
      ADD_FAILURE() << "global mode stepped although its verdict cannot be decided (" << c.reason << ")";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("global injectivity cannot be decided: "), std::string::npos) << what;
      EXPECT_NE(what.find(c.reason), std::string::npos) << what;
    }
    EXPECT_TRUE(solver.reduced_coefficients() == y0);
    EXPECT_TRUE(solver.history().empty());
    p.injectivity = InjectivityMode::kLocal;
    solver.set_params(p);
    EXPECT_TRUE(solver.step().accepted);
  }
}

// The beam bent into a tight U whose free end is laid onto its fixed half (data/scenarios/
// beam_fold_onto_itself.json; the beam's rest mesh is embedded, so the verdict is decided). Local mode
// reaches the handles with a map that is locally injective but passes through itself, and the report says so
// with the place; the winding number of the deformed surface at the images of interior points (an independent
// count of preimages) reaches 2. Global mode: the next test.
TEST(DeformSlow, BeamFoldPassesThroughItselfInLocalModeAndTheReportSaysWhere) {
  test::TempDir tmp;
  const std::string scenario = test::project_data() + "/scenarios/beam_fold_onto_itself.json";
  const std::string local = tmp.str() + "/local";
  std::string out;
  test::run_lidef_cli("deform " + test::shell_quote(scenario) + " --out " + test::shell_quote(local) +
                          " --models " + test::shell_quote(test::project_data() + "/models") +
                          " --quiet --cache-dir " + test::shell_quote(tmp.str() + "/cache"),
                      &out);
  std::ifstream in(local + "/certificate.json");
  ASSERT_TRUE(in.good()) << out;
  const nlohmann::json lc = nlohmann::json::parse(in);
  EXPECT_EQ(lc["certified"], true) << out;
  EXPECT_EQ(lc["globally_injective"], false) << out;
  ASSERT_TRUE(lc.contains("overlap")) << out;
  EXPECT_EQ(lc["overlap"]["point"].size(), 3u);
  EXPECT_NE(lc["global_reason"].get<std::string>().find("overlaps itself near ("), std::string::npos);
  const Model m = load_model(test::project_data() + "/models/beam");
  EXPECT_GT(
      max_image_winding(m.cage, m.mesh, read_coefficients(local + "/coefficients.txt", m.cage), 0.03, 0.02),
      1.5);
}

// Global mode on the same scenario, from the map its global-mode run reaches after 8 iterations
// (data/scenarios/ beam_fold_onto_itself.near_contact.coefficients.txt, written by `lidef deform
// beam_fold_onto_itself.json
// --injectivity global --max-iterations 5 --threads 2`: the free end turned most of the way, handle error
// 0.73; the whole run takes minutes, one check of the beam's tight cage tens of seconds). One Newton
// iteration toward the targets with the weights that run ended with and 4 halvings: every trial is refused by
// the global check (global_rejections in iterations.csv; near contact it proves a crossing or cannot separate
// two triangles), the solve stops "blocked" with the reason, the written map is certified locally and
// globally injective, and the independent dense count of preimages stays below 2 — where local mode (the test
// above) writes a map that passes through itself.
TEST(DeformSlow, BeamFoldInGlobalModeRefusesStepsThroughItselfAndWritesAnInjectiveMap) {
  test::TempDir tmp;
  const std::string scenario = test::project_data() + "/scenarios/beam_fold_onto_itself.json";
  const std::string init =
      test::project_data() + "/scenarios/beam_fold_onto_itself.near_contact.coefficients.txt";
  const std::string out_dir = tmp.str() + "/global";
  std::string out;
  test::run_lidef_cli(
      "deform " + test::shell_quote(scenario) + " --out " + test::shell_quote(out_dir) + " --models " +
          test::shell_quote(test::project_data() + "/models") + " --init " + test::shell_quote(init) +
          " --injectivity global --max-iterations 1 --continuation false --lambda-p2p 100"
          " --lambda-smooth 100 --dynamic-weighting false --max-halvings 4 --quiet --cache-dir " +
          test::shell_quote(tmp.str() + "/cache"),
      &out);
  std::ifstream in(out_dir + "/certificate.json");
  ASSERT_TRUE(in.good()) << out;
  const nlohmann::json gc = nlohmann::json::parse(in);
  EXPECT_EQ(gc["certified"], true) << out;
  EXPECT_EQ(gc["globally_injective"], true) << out;
  // The refused trials: the global_rejections column of iterations.csv.
  std::ifstream it(out_dir + "/iterations.csv");
  std::string header, line, field;
  ASSERT_TRUE(std::getline(it, header)) << out;
  std::vector<std::string> names;
  for (std::stringstream hs(header); std::getline(hs, field, ',');) names.push_back(field);
  const auto col = std::find(names.begin(), names.end(), "global_rejections") - names.begin();
  ASSERT_LT(col, static_cast<long>(names.size())) << header;
  long rejections = 0, rows = 0;
  while (std::getline(it, line)) {
    std::vector<std::string> f;
    for (std::stringstream ls(line); std::getline(ls, field, ',');) f.push_back(field);
    ASSERT_GT(f.size(), static_cast<size_t>(col)) << line;
    rejections += std::stol(f[col]);
    ++rows;
  }
  EXPECT_EQ(rows, 1);
  EXPECT_GT(rejections, 0) << out;
  std::ifstream sin(out_dir + "/summary.json");
  const nlohmann::json summary = nlohmann::json::parse(sin);
  EXPECT_EQ(summary["stop_reason"], "blocked_by_certificate") << out;
  const std::string message = summary["message"];
  EXPECT_TRUE(message.rfind("blocked: the shape would pass through itself near (", 0) == 0 ||
              message.rfind("blocked: global injectivity not proven (", 0) == 0)
      << message;
  const Model m = load_model(test::project_data() + "/models/beam");
  EXPECT_LT(
      max_image_winding(m.cage, m.mesh, read_coefficients(out_dir + "/coefficients.txt", m.cage), 0.03, 0.02),
      1.5);
}

}  // namespace
}  // namespace lidef
