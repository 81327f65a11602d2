// Global injectivity (global_injectivity.h): the verdict against sampled truth — the winding number of the
// deformed surface at the images of interior points counts their preimages — and its invariance.
#include <gtest/gtest.h>

#include <cmath>

#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/geometry.h"
#include "lidef/global_injectivity.h"
#include "lidef/green_coordinates.h"
#include "lidef/mesh_queries.h"
#include "lidef/model_check.h"
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

// A gentle bend of the bar (its long axis is z) about the y axis: angle κ z, radius 1/κ.
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

TEST(GlobalInjectivity, IdentityAndGentleBendOfTheBarAreInjectiveAndNoImagePointIsCoveredTwice) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
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

TEST(GlobalInjectivity, VerdictIsInvariantUnderTranslationAndScale) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
  const MatX3d y = bend_coefficients(m.cage, 0.8);
  for (const double s : {1e-3, 1.0, 250.0}) {
    const Vec3 t(1e3, -37.5, 4.25);
    TriMesh cm;
    cm.V = (m.cage.V * s).rowwise() + t.transpose();
    cm.F = m.cage.F;
    const Cage cage(cm);
    TriMesh mesh = m.mesh;
    mesh.V = (m.mesh.V * s).rowwise() + t.transpose();
    MatX3d ys = y;
    const int nv = m.cage.num_vertices();
    ys.topRows(nv) = (y.topRows(nv) * s).rowwise() + t.transpose();  // y_v = g(v): moved like the points
    const GlobalInjectivity g = check_global_injectivity(cage, mesh, ys);
    EXPECT_EQ(g.verdict, Verdict::kInjective) << "scale " << s << ": " << g.reason;
  }
}

// The bar bent into a tight U whose free end is laid onto its fixed half (data/scenarios/
// bar_fold_onto_itself.json; the coefficients are the map `lidef deform` wrote for it, certified locally
// injective): the shape passes through itself.
MatX3d fold_coefficients(const Cage& cage) {
  return read_coefficients(test::project_data() + "/scenarios/bar_fold_onto_itself.coefficients.txt", cage);
}

TEST(GlobalInjectivity, BarFoldedOntoItselfOverlapsAndTheOverlapIsSeenByWindingNumbers) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
  const MatX3d y = fold_coefficients(m.cage);
  const GlobalInjectivity g = check_global_injectivity(m.cage, m.mesh, y);
  ASSERT_EQ(g.verdict, Verdict::kOverlap) << g.reason;
  EXPECT_NE(g.reason.find("overlaps itself near"), std::string::npos) << g.reason;
  ASSERT_GE(g.overlap_face_a, 0);
  ASSERT_GE(g.overlap_face_b, 0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NE(m.mesh.F(g.overlap_face_a, i), m.mesh.F(g.overlap_face_b, j));
  // The point lies near both triangles' images.
  const HarmonicBasis basis(m.cage);
  const MatX3d fV = basis.map_values(y, m.mesh.V);
  const double size = (fV.colwise().maxCoeff() - fV.colwise().minCoeff()).norm();
  for (const int f : {g.overlap_face_a, g.overlap_face_b}) {
    const double d2 = point_triangle_dist2(g.overlap_point, fV.row(m.mesh.F(f, 0)), fV.row(m.mesh.F(f, 1)),
                                           fV.row(m.mesh.F(f, 2)));
    EXPECT_LT(std::sqrt(d2), 0.05 * size);
  }
  // Independent: some interior point's image is covered twice.
  EXPECT_GT(max_image_winding(m.cage, m.mesh, y, 0.03, 0.02), 1.5);
}

TEST(GlobalInjectivity, BarFoldedOntoItselfOverlapsWhereverTheModelIsMovedOrScaled) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("bar"));
  const MatX3d y = fold_coefficients(m.cage);
  for (const double s : {1e-2, 40.0}) {
    const Vec3 t(-250.0, 3.5, 1e2);
    TriMesh cm;
    cm.V = (m.cage.V * s).rowwise() + t.transpose();
    cm.F = m.cage.F;
    const Cage cage(cm);
    TriMesh mesh = m.mesh;
    mesh.V = (m.mesh.V * s).rowwise() + t.transpose();
    MatX3d ys = y;
    const int nv = m.cage.num_vertices();
    ys.topRows(nv) = (y.topRows(nv) * s).rowwise() + t.transpose();
    const GlobalInjectivity g = check_global_injectivity(cage, mesh, ys);
    EXPECT_EQ(g.verdict, Verdict::kOverlap) << "scale " << s << ": " << g.reason;
  }
}

}  // namespace
}  // namespace lidef
