// The reduced local/global solve (local_global.h) against independent truths: with no rotation term it is the
// smoothed least-squares fit of the handles (solved here by QR of the stacked system, not the normal
// equations); a rigid motion of the targets is reproduced (the rigid map's coefficients come from the affine
// coefficient formula, projected by the solver); closest_rotation on known polar factors; and
// DeformationSolver::set_reduced_map accepts a certified map and refuses one that folds, keeping the map.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/QR>

#include "lidef/local_global.h"
#include "lidef/model_check.h"
#include "lidef/projected_newton.h"
#include "test_beam.h"
#include "test_support.h"

using namespace lidef;

namespace {

using lidef::test::beam;

DeformParams small() {
  DeformParams p;
  p.samples = 2000;
  p.reduced_dof = 40;
  return p;
}

// Both end faces of the beam: 4 corners and the centre at x = -1 and x = +1.
MatX3d ends() {
  MatX3d s(10, 3);
  const double c[5][2] = {{-0.2, -0.2}, {0.2, -0.2}, {0.2, 0.2}, {-0.2, 0.2}, {0, 0}};
  for (int e = 0; e < 2; ++e)
    for (int k = 0; k < 5; ++k) s.row(5 * e + k) << (e ? 1.0 : -1.0), c[k][0], c[k][1];
  return s;
}

Mat3 rotation(double deg, const Vec3& axis) {
  return Eigen::AngleAxisd(deg * 3.14159265358979323846 / 180, axis.normalized()).toRotationMatrix();
}

}  // namespace

TEST(LocalGlobal, ClosestRotationIsThePolarFactor) {
  const Mat3 R = rotation(70, Vec3(1, 2, -0.5));
  Mat3 S;
  S << 2.0, 0.3, 0.1, 0.3, 1.5, -0.2, 0.1, -0.2, 0.7;  // symmetric positive definite
  EXPECT_LT((closest_rotation(R * S) - R).norm(), 1e-12);
  // A reflection: the closest rotation flips the weakest direction (here z, scaled by 0.1).
  const Mat3 M = R * Vec3(1.0, 0.8, -0.1).asDiagonal();
  const Mat3 Q = closest_rotation(M);
  EXPECT_NEAR(Q.determinant(), 1, 1e-12);
  EXPECT_LT((Q - R).norm(), 1e-12);
}

TEST(LocalGlobal, WithoutRotationsItIsTheSmoothedLeastSquaresFit) {
  DeformationSolver s(beam().model.cage, small(), beam().cache.str());
  MatX3d tgt = ends();
  tgt.row(7) += Eigen::RowVector3d(0.1, 0.3, -0.2);
  s.set_handles(ends(), tgt);
  const EnergyWeights w{1e3, 0.5};
  const LocalGlobalSolver lg(s.energy_function(), w, 0.0);
  const MatX3d Q = s.frame().points_to_normalized(tgt);
  const LocalGlobalResult r = lg.solve(s.reduced_coefficients(), Q, 5);
  // Truth: min λ1 ‖D y − Q‖² + (λ2/|E|) Σ μ_j ‖y_j‖² as one stacked least-squares problem, by QR.
  const DeformationEnergy& e = s.energy_function();
  const int n = e.reduced_size(), h = e.num_handles();
  MatXd M(h + n, n);
  M.topRows(h) = std::sqrt(w.p2p) * e.handle_matrix();
  M.bottomRows(n) = (w.smooth / e.num_edges() * e.smooth_eigenvalues()).cwiseSqrt().asDiagonal();
  MatXd rhs = MatXd::Zero(h + n, 3);
  rhs.topRows(h) = std::sqrt(w.p2p) * Q;
  const MatXd truth = M.colPivHouseholderQr().solve(rhs);
  EXPECT_LT((r.y - truth).norm(), 1e-9 * truth.norm());
  EXPECT_LE(r.iterations, 2);  // the fit does not depend on the start: the second iteration changes nothing
}

TEST(LocalGlobal, ReproducesARigidMotionOfTheTargets) {
  DeformationSolver s(beam().model.cage, small(), beam().cache.str());
  const Mat3 R = rotation(75, Vec3(0.3, 1, 0.4));
  const Vec3 t(0.2, -0.1, 0.3);
  const MatX3d src = ends();
  const MatX3d tgt = (src * R.transpose()).rowwise() + t.transpose();
  s.set_handles(src, tgt);
  // The rigid map's full coefficients: vertex rows R v + t, face rows R n (cage.h), projected by the solver.
  MatX3d y = beam().model.cage.identity_coefficients() * R.transpose();
  y.topRows(beam().model.cage.num_vertices()).rowwise() += t.transpose();
  DeformationSolver rigid(beam().model.cage, small(), beam().cache.str());
  rigid.set_handles(src, tgt);
  rigid.set_initial_map(y, "rigid map");
  const MatS3 truth = rigid.reduced_coefficients();
  const LocalGlobalSolver lg(s.energy_function(), {1e5, 0.1});
  const MatX3d Q = s.frame().points_to_normalized(tgt);
  // From the rigid map itself: the local step finds R everywhere and the global step returns the map.
  const LocalGlobalResult fixed = lg.solve(truth, Q, 1);
  EXPECT_LT((fixed.y - truth).norm(), 1e-6 * truth.norm());
  // From a perturbed rigid map: the iteration goes back toward it (an attracting fixed point; ARAP-like
  // iterations converge linearly, slowly, so the check is a 100-fold reduction of the distance).
  MatS3 perturbed = truth;
  perturbed.bottomRows(20) += 0.01 * MatS3::Ones(20, 3);
  const LocalGlobalResult back = lg.solve(perturbed, Q, 300, 1e-14);
  EXPECT_LT((back.y - truth).norm(), 0.01 * (perturbed - truth).norm()) << back.iterations << " iterations";
  // From the identity: the iteration turns the whole beam into the rigid motion: handles met, the energy
  // (E_LG > 0.5 at the identity) near 0.
  const double e_start = lg.energy(s.reduced_coefficients(), Q);
  const LocalGlobalResult r = lg.solve(s.reduced_coefficients(), Q, 300, 1e-14);
  EXPECT_LT((s.energy_function().handle_matrix() * r.y - Q).rowwise().norm().maxCoeff(), 1e-5);
  EXPECT_LT(r.energy, 1e-4 * e_start);
  EXPECT_LT((r.y - truth).norm(), 0.05 * truth.norm());
}

TEST(LocalGlobal, EnergyNeverIncreases) {
  DeformationSolver s(beam().model.cage, small(), beam().cache.str());
  MatX3d tgt = ends();
  for (int i = 5; i < 10; ++i)
    tgt.row(i) = (rotation(150, Vec3(1, 0, 0)) * ends().row(i).transpose()).transpose();
  s.set_handles(ends(), tgt);
  const LocalGlobalSolver lg(s.energy_function(), {1e5, 0.1});
  const MatX3d Q = s.frame().points_to_normalized(tgt);
  MatS3 y = s.reduced_coefficients();
  double prev = lg.energy(y, Q);
  for (int k = 0; k < 20; ++k) {
    y = lg.solve(y, Q, 1, 0).y;
    const double e = lg.energy(y, Q);
    EXPECT_LE(e, prev * (1 + 1e-10)) << k;
    prev = e;
  }
}

TEST(LocalGlobal, SetReducedMapAcceptsOnlyCertifiedMaps) {
  DeformationSolver s(beam().model.cage, small(), beam().cache.str());
  s.set_handles(ends(), ends());
  const MatS3 id = s.reduced_coefficients();
  // A mirror image (x -> -x): det J = -1 everywhere, refused with the certificate's reason; the map is kept.
  MatS3 mirror = id;
  mirror.col(0) *= -1;
  std::string why;
  EXPECT_FALSE(s.set_reduced_map(mirror, &why));
  EXPECT_FALSE(why.empty());
  EXPECT_EQ(s.reduced_coefficients(), id);
  EXPECT_TRUE(s.certificate().certified);
  // A scaled copy is certified and becomes the map, with its certificate.
  const MatS3 scaled = 1.1 * id;
  EXPECT_TRUE(s.set_reduced_map(scaled, &why)) << why;
  EXPECT_EQ(s.reduced_coefficients(), scaled);
  EXPECT_TRUE(s.certificate().certified);
  MatS3 bad = id;
  bad(0, 0) = std::nan("");
  EXPECT_FALSE(s.set_reduced_map(bad, &why));
  EXPECT_EQ(s.reduced_coefficients(), scaled);
}
