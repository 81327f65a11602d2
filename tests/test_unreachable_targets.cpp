// The proof that no certified map reaches a set of targets (unreachable_targets.h): on the project's beam
// mirrored by 1000 handles it proves that every reaching map folds, and the statement is checked on maps that
// reach the targets — random ones and ones along the bound's worst direction — by evaluating their Jacobian
// at the proof's point with the basis directly; it proves nothing where it must not (few handles, reachable
// targets); the residual form agrees with an independent least-squares solve. Slow: `lidef deform` on the
// mirror ends blocked by the certificate with the last certified map written and certified again by `lidef
// certify`.
#include <gtest/gtest.h>

#include <Eigen/QR>
#include <Eigen/SVD>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "lidef/coefficients.h"
#include "lidef/continuation.h"
#include "lidef/green_coordinates.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"
#include "lidef/signed_svd.h"
#include "lidef/unreachable_targets.h"
#include "test_beam.h"
#include "test_cli_outputs.h"
#include "test_support.h"

using namespace lidef;
using lidef::test::beam;

namespace {

DeformParams small_params() {
  DeformParams p;
  p.samples = 2000;
  p.reduced_dof = 40;
  return p;
}

const Scenario& mirror() {
  static const Scenario sc = read_scenario(lidef::test::project_data() + "/scenarios/beam_mirror.json");
  return sc;
}

// The Jacobian at the model-unit point x of the map with reduced coefficients y (normalized frame), from the
// normalized basis directly (not through the proof's reduced gradients).
Mat3 jacobian_at(const DeformationSolver& s, const MatS3& y, const Vec3& x) {
  const MatX3d xn = s.frame().points_to_normalized(MatX3d(x.transpose()));
  const MatXd g = s.normalized_basis().gradient_matrix(xn);  // 3 by #V+#F
  return (g * (s.subspace().basis * y)).transpose();
}

double max_handle_error(const DeformationSolver& s, const MatS3& y) {
  const DeformationEnergy& e = s.energy_function();
  return (e.handle_matrix() * y - e.targets()).rowwise().norm().maxCoeff();
}

}  // namespace

TEST(UnreachableTargets, MirroredBeamEveryReachingMapFoldsAtTheProofsPoint) {
  DeformationSolver s(beam().model.cage, small_params(), beam().cache.str());
  s.set_handles(mirror().sources, mirror().targets, "mirror");
  const UnreachabilityProof p = prove_targets_unreachable(s);
  ASSERT_TRUE(p.proven) << p.reason;
  EXPECT_EQ(p.kind, "orientation");
  EXPECT_EQ(p.handles, 1000);
  EXPECT_EQ(p.reduced_size, 40);
  // The reflection is affine, hence in the subspace: the least-squares map meets the targets up to rounding
  // and is the reflection itself (σ_min 1 everywhere).
  EXPECT_LT(p.residual, 1e-9);
  EXPECT_NEAR(p.sigma_min, 1.0, 1e-6);
  EXPECT_LE(2 * p.jacobian_bound, p.sigma_min);
  const Vec3 x = p.point;
  const Mat3 J0 = jacobian_at(s, p.least_squares, x);
  EXPECT_LT(J0.determinant(), 0);

  // Maps that reach the targets: ỹ₀ plus a combination of the subspace's directions, scaled so that every
  // handle stays within the tolerance. Their Jacobian at x stays within the bound of J₀ and is
  // orientation-reversing, for random directions and for the worst one of the bound (the top singular pair
  // of G_x D̃⁺, pushed to the tolerance).
  const MatXd& D = s.energy_function().handle_matrix();
  const Eigen::JacobiSVD<MatXd> svd(D, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const double tau = s.params().handle_tolerance;
  std::mt19937 rng(7);
  std::normal_distribution<double> n01;
  int reaching = 0;
  auto check = [&](const MatS3& dir) {
    // The largest multiple of dir whose handles all stay within τ of the targets (the residual is ~0).
    const double t = 0.999 * tau / (D * dir).rowwise().norm().maxCoeff();
    const MatS3 y = p.least_squares + t * dir;
    ASSERT_LE(max_handle_error(s, y), tau);
    const Mat3 J = jacobian_at(s, y, x);
    EXPECT_LE((J - J0).norm(), p.jacobian_bound * (1 + 1e-9));  // Frobenius ≥ spectral: stricter
    EXPECT_LT(J.determinant(), 0);
    ++reaching;
  };
  for (int k = 0; k < 200; ++k)
    check(MatS3::NullaryExpr(D.cols(), 3, [&](Eigen::Index, Eigen::Index) { return n01(rng); }));
  // The worst direction: the one of the subspace that moves J(x) most per unit of ‖D̃ δ‖.
  const MatXd Gx =
      s.normalized_basis().gradient_matrix(s.frame().points_to_normalized(MatX3d(x.transpose()))) *
      s.subspace().basis;  // 3 by s
  const MatXd W = svd.matrixV() * svd.singularValues().cwiseInverse().asDiagonal();
  const Eigen::JacobiSVD<MatXd> top(Gx * W, Eigen::ComputeThinU | Eigen::ComputeThinV);
  for (int a = 0; a < 3; ++a) {
    MatS3 dir = MatS3::Zero(D.cols(), 3);
    dir.col(a) = W * top.matrixV().col(0);
    check(dir);
    // Scaled to ‖D̃ δ‖_F = ε (the radius of step 4, beyond what a reaching map can use) the change of J(x)
    // is b itself: the proof's norm is the right one and attained.
    const MatS3 at_radius = p.least_squares + p.radius / (D * dir).norm() * dir;
    const Eigen::JacobiSVD<Mat3> change(jacobian_at(s, at_radius, x) - J0);
    EXPECT_NEAR(change.singularValues()(0), p.jacobian_bound, 1e-6 * p.jacobian_bound);
  }
  EXPECT_EQ(reaching, 203);
}

TEST(UnreachableTargets, ProvesNothingWithFewHandlesOrReachableTargets) {
  DeformationSolver s(beam().model.cage, small_params(), beam().cache.str());
  // beam_bend's 10 handles cannot pin 40 coefficients per coordinate.
  const Scenario bend = read_scenario(lidef::test::project_data() + "/scenarios/beam_bend.json");
  s.set_handles(bend.sources, bend.targets, "bend");
  UnreachabilityProof p = prove_targets_unreachable(s);
  EXPECT_FALSE(p.proven);
  EXPECT_NE(p.reason.find("fix at most 10 of the 40"), std::string::npos) << p.reason;
  // The mirror's 1000 points left in place, and turned rigidly by 180 degrees about the beam's axis:
  // reachable (orientation-preserving), so nothing may be proven.
  MatX3d turned = mirror().sources;
  turned.col(1) *= -1;
  turned.col(2) *= -1;
  for (const MatX3d& targets : {mirror().sources, turned}) {
    s.set_handles(mirror().sources, targets, "points");
    p = prove_targets_unreachable(s);
    EXPECT_FALSE(p.proven) << p.reason;
    EXPECT_NE(p.reason.find("orientation-preserving at every voxel center"), std::string::npos) << p.reason;
    EXPECT_LT(p.residual, 1e-9);
  }
}

// Targets that the start map reaches (every target at its source) with a handle tolerance of 0 or below the
// rounding of evaluating the handles: the computed least-squares residual is rounding (~1e-14), an upper
// bound of the exact one, so no residual proof may be built on it: its lower bound stays below the floor.
TEST(UnreachableTargets, ReachedTargetsAreNeverProvenUnreachableWhateverTheTolerance) {
  for (const double tolerance : {0.0, 4e-16, 1e-12}) {
    DeformParams params = small_params();
    params.handle_tolerance = tolerance;
    DeformationSolver s(beam().model.cage, params, beam().cache.str());
    s.set_handles(mirror().sources, mirror().sources, "in place");
    const UnreachabilityProof p = prove_targets_unreachable(s);
    EXPECT_FALSE(p.proven) << "tolerance " << tolerance << ": " << p.reason;
    EXPECT_GT(p.residual, 0) << "the computed residual is rounding, not zero";
    EXPECT_LE(p.residual_lower, p.residual) << tolerance;
    EXPECT_LT(p.residual_lower, 2 * p.rounding_floor) << tolerance;
    EXPECT_GE(p.residual_upper, p.residual);
  }
}

TEST(UnreachableTargets, ResidualFormAgreesWithAnIndependentLeastSquaresSolve) {
  DeformationSolver s(beam().model.cage, small_params(), beam().cache.str());
  // The mirror's 1000 points, each target moved at random by up to 0.05: no map of 40 coefficients per
  // coordinate follows 1000 independent moves.
  MatX3d targets = mirror().sources;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  for (Eigen::Index i = 0; i < targets.rows(); ++i)
    for (int a = 0; a < 3; ++a) targets(i, a) += u(rng);
  s.set_handles(mirror().sources, targets, "noisy points");
  const UnreachabilityProof p = prove_targets_unreachable(s);
  ASSERT_TRUE(p.proven) << p.reason;
  EXPECT_EQ(p.kind, "residual");
  const MatXd& D = s.energy_function().handle_matrix();
  const MatX3d& Q = s.energy_function().targets();
  const MatS3 y = D.colPivHouseholderQr().solve(Q);
  const double min_residual = (D * y - Q).norm();
  EXPECT_NEAR(p.residual, min_residual, 1e-9 * min_residual);
  // The bounds enclose it, and the rounding taken off is far below the residual here.
  EXPECT_LE(p.residual_lower, min_residual);
  EXPECT_GE(p.residual_upper, p.residual);
  EXPECT_GT(p.residual_lower, (1 - 1e-6) * min_residual);
  // The statement: every map misses some handle by more than τ — the best one by its residual / √#h.
  const double tau = s.params().handle_tolerance;
  EXPECT_GT(min_residual / std::sqrt(static_cast<double>(D.rows())), tau);
  EXPECT_GT(max_handle_error(s, y), tau);
}

// Slow (label "slow"): the whole run on the mirror through the CLI, ~1 min.
TEST(DeformSlow, MirroredBeamEndsBlockedWithTheLastCertifiedMapWritten) {
  lidef::test::TempDir dir;
  const std::string out = dir.str() + "/out";
  std::string log;
  const int rc = lidef::test::run_lidef_cli(
      "deform " + lidef::test::shell_quote(lidef::test::project_data() + "/scenarios/beam_mirror.json") +
          " --out " + lidef::test::shell_quote(out) + " --reduced-dof 40 --samples 2000 --threads 2 --quiet",
      &log);
  ASSERT_EQ(rc, 1) << log;  // stopped early, outputs written
  const nlohmann::json sj = nlohmann::json::parse(lidef::test::read_text(out + "/summary.json"));
  EXPECT_EQ(sj["stop_reason"], "blocked_by_certificate") << log;
  EXPECT_TRUE(sj["unreachable"]["proven"].get<bool>());
  EXPECT_EQ(sj["unreachable"]["kind"], "orientation");
  EXPECT_FALSE(sj["handles_reached"].get<bool>());
  EXPECT_TRUE(sj["certified"].get<bool>());
  ASSERT_EQ(sj["continuation"]["strategies"].size(), 1u);
  EXPECT_NE(log.find("PROVEN: every map of the subspace that reaches the targets folds"), std::string::npos)
      << log;
  // The written map is certified again from its file by `lidef certify`.
  std::string cert_log;
  EXPECT_EQ(lidef::test::run_lidef_cli(
                "certify " + lidef::test::shell_quote(lidef::test::project_data() + "/models/beam") +
                    " --coeffs " + lidef::test::shell_quote(out + "/coefficients.txt") + " --out " +
                    lidef::test::shell_quote(dir.str() + "/cert") + " --grid 0 --samples 2000 --threads 2",
                &cert_log),
            0)
      << cert_log;
  EXPECT_NE(cert_log.find("CERTIFIED"), std::string::npos) << cert_log;
  // Dense sampling of the certified domain (the beam's solid): det J > 0 at 5000 random points.
  const MatX3d y = read_coefficients(out + "/coefficients.txt", beam().model.cage);
  const HarmonicBasis basis(beam().model.cage);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(-1, 1), uyz(-0.2, 0.2);
  MatX3d P(5000, 3);
  for (Eigen::Index i = 0; i < P.rows(); ++i) P.row(i) << ux(rng), uyz(rng), uyz(rng);
  const MatXd g = basis.gradient_matrix(P) * y;  // rows 3i..3i+2: J(p_i)ᵀ
  int folded = 0;
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    if (!(Mat3(g.middleRows(3 * i, 3)).determinant() > 0)) ++folded;
  EXPECT_EQ(folded, 0);
}
