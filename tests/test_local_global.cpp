// The reduced local/global solve (local_global.h) against independent truths: with no rotation term it is the
// smoothed least-squares fit of the handles (solved here by QR of the stacked system, not the normal
// equations); a rigid motion of the targets is reproduced (the rigid map's coefficients come from the affine
// coefficient formula, projected by the solver); closest_rotation on known polar factors; and
// DeformationSolver::set_reduced_map accepts a certified map and refuses one that folds, keeping the map.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <cstdio>
#include <random>

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

// The far end face turned by 150° about the beam's axis: a solver at the identity, its local/global solver
// (λ1 = 1e5, λ2 = 0.1) and the targets in the normalized frame.
struct Twist150 {
  static MatX3d targets() {
    MatX3d tgt = ends();
    for (int i = 5; i < 10; ++i)
      tgt.row(i) = (rotation(150, Vec3(1, 0, 0)) * ends().row(i).transpose()).transpose();
    return tgt;
  }
  static DeformationSolver& with_handles(DeformationSolver& s) {
    s.set_handles(ends(), targets());
    return s;
  }
  DeformationSolver solver{beam().model.cage, small(), beam().cache.str()};
  LocalGlobalSolver lg{with_handles(solver).energy_function(), {1e5, 0.1}};
  MatX3d Q = solver.frame().points_to_normalized(targets());
};

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

TEST(LocalGlobal, ClosestRotationAgreesWithTheSvdOnRandomMatrices) {
  // Near rotations (the Newton polar iteration), general and nearly singular matrices with det > 0 (Newton or
  // its SVD fallback) and reflections (the SVD): the polar factor U Vᵀ with the weakest direction flipped
  // where det < 0, computed here from Eigen's SVD independently.
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  auto random = [&] {
    Mat3 A;
    for (int k = 0; k < 9; ++k) A(k) = normal(rng);
    return A;
  };
  auto reference = [](const Mat3& M) {
    Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Mat3 U = svd.matrixU();
    if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1;
    return Mat3(U * svd.matrixV().transpose());
  };
  const double scales[] = {1e-3, 0.02, 0.1, 0.3, 1.0, 3.0};
  for (int i = 0; i < 6000; ++i) {
    const Mat3 R = reference(random());
    Mat3 M = 1.7 * R * (Mat3::Identity() + scales[i % 6] * random());
    if (i % 50 == 0) M.col(2) = M.col(0) + 1e-9 * M.col(2);      // nearly singular: the SVD
    if (i % 50 == 1) M = R * Vec3(2.0, 1.0, 0.05).asDiagonal();  // σ3/σ1 = 0.025: Newton
    const Mat3 Q = closest_rotation(M);
    ASSERT_LT((Q - reference(M)).norm(), 1e-11) << i << "\n" << M;
    ASSERT_LT((Q.transpose() * Q - Mat3::Identity()).norm(), 1e-13) << i;
    ASSERT_NEAR(Q.determinant(), 1, 1e-13) << i;
  }
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
  const Twist150 t;
  const LocalGlobalSolver& lg = t.lg;
  const MatX3d& Q = t.Q;
  MatS3 y = t.solver.reduced_coefficients();
  double prev = lg.energy(y, Q);
  for (int k = 0; k < 20; ++k) {
    y = lg.solve(y, Q, 1, 0).y;
    const double e = lg.energy(y, Q);
    EXPECT_LE(e, prev * (1 + 1e-10)) << k;
    prev = e;
  }
}

// The accelerated solve (Anderson, local_global.cpp) against the plain iteration it accelerates:
// one-iteration solves are plain (no history), run here until the solve's own stopping rule holds. The
// accelerated result must be a fixed point of the plain iteration (one more plain step barely moves it), at
// an E_LG no higher than the plain one's, reached in fewer iterations.
TEST(LocalGlobal, AcceleratedIterationsReachThePlainIterationsFixedPoint) {
  const Twist150 t;
  const LocalGlobalSolver& lg = t.lg;
  const MatX3d& Q = t.Q;
  const MatS3 y0 = t.solver.reduced_coefficients();
  constexpr double kTolerance = 1e-8;
  MatS3 plain = y0;
  double e_plain = lg.energy(plain, Q);
  int plain_iterations = 0;
  for (; plain_iterations < 2000; ++plain_iterations) {
    const LocalGlobalResult step = lg.solve(plain, Q, 1, 0);
    const bool done = e_plain - step.energy <= kTolerance * e_plain;
    plain = step.y;
    e_plain = step.energy;
    if (done) break;
  }
  const LocalGlobalResult fast = lg.solve(y0, Q, 2000, kTolerance);
  ASSERT_TRUE(fast.converged);
  EXPECT_LT(fast.iterations, plain_iterations) << "plain " << plain_iterations;
  EXPECT_LE(fast.energy, e_plain * (1 + 1e-9)) << fast.energy << " against " << e_plain;
  const MatS3 next = lg.solve(fast.y, Q, 1, 0).y;
  EXPECT_LT((next - fast.y).norm(), 1e-3 * (fast.y - y0).norm());
  EXPECT_LT((fast.y - plain).norm(), 2e-2 * (fast.y - y0).norm());
  std::printf(
      "local/global to %g relative decrease: plain %d iterations, E_LG %.10g; accelerated %d, %.10g\n",
      kTolerance, plain_iterations + 1, e_plain, fast.iterations, fast.energy);
}

TEST(LocalGlobal, AStopRequestEndsTheSolveAtTheLastIterate) {
  const Twist150 t;
  const LocalGlobalSolver& lg = t.lg;
  const MatX3d& Q = t.Q;
  const MatS3 y0 = t.solver.reduced_coefficients();
  std::atomic<bool> stop{true};
  const LocalGlobalResult stopped = lg.solve(y0, Q, 50, 0, &stop);
  EXPECT_TRUE(stopped.interrupted);
  EXPECT_EQ(stopped.iterations, 0);
  EXPECT_EQ(stopped.y, y0);
  stop = false;
  const LocalGlobalResult ran = lg.solve(y0, Q, 50, 0, &stop);
  EXPECT_FALSE(ran.interrupted);
  EXPECT_GT(ran.iterations, 0);
  EXPECT_LT(ran.energy, lg.energy(y0, Q));
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

TEST(LocalGlobal, SetReducedMapUnderADistortionTargetHasTheFullCertificatesVerdict) {
  // Under a distortion target a map is refused at once where a probe proves it beyond the target (its sample
  // farthest beyond it); the verdict must be the full certificate's on every map, refused or not.
  DeformParams p = small();
  p.max_distortion = 1.2;
  DeformationSolver s(beam().model.cage, p, beam().cache.str());
  s.set_handles(ends(), ends());
  const MatS3 id = s.reduced_coefficients();
  int refused = 0, accepted = 0;
  for (const double stretch : {1.5, 1.25, 1.21, 1.19, 1.1, 1.0}) {
    SCOPED_TRACE("stretched by " + std::to_string(stretch));
    MatS3 y = id;
    y.col(0) *= stretch;
    const Certificate full = s.certifier().certify_reduced(y, certify_params_of(s.params(), false, false));
    const MatS3 before = s.reduced_coefficients();
    std::string why;
    const bool set = s.set_reduced_map(y, &why);
    EXPECT_EQ(set, full.certified) << why << " / " << full.reason;
    EXPECT_EQ(s.reduced_coefficients(), set ? y : before);
    if (!set) {
      EXPECT_NE(why.find("distortion bound 1.2 not proven"), std::string::npos) << why;
    }
    (set ? accepted : refused)++;
  }
  EXPECT_GE(refused, 3);   // 1.5, 1.25, 1.21: beyond K at every point
  EXPECT_GE(accepted, 2);  // 1.1 and the identity
}
