// The combined Lipschitz bound (docs/certificate.md, Step 3b) and the per-edge evaluation of octree children
// (edge_jet.h) against independent truths: the per-face differential representation and the basis, sampled
// maxima of |σ3(q) − σ3(c)| on random balls (also balls reaching the cage's clearance), sampled directions of
// the Hessian tensor, and whole certificates under dense sampling.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <limits>
#include <random>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/analysis/interval_verification.h"
#include "lidef/internal/edge_jet.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"
#include "test_cages.h"

using namespace lidef;
using lidef::test::perturbed_map;

namespace {

Vec3 random_unit(std::mt19937& rng) {
  std::normal_distribution<double> N01;
  return Vec3(N01(rng), N01(rng), N01(rng)).normalized();
}

// The whole-certificate tests' sampling: about 1,500 base voxels.
VoxelSampling about_1500_voxels(const Cage& cage) {
  SamplingParams sp;
  sp.target_count = 1500;
  sp.count_tolerance = 0.1;
  return sample_voxels(cage, sp);
}

// A uniformly random rotation (a normalized Gaussian quaternion).
Mat3 random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> N01;
  const Eigen::Quaterniond q(N01(rng), N01(rng), N01(rng), N01(rng));
  return Mat3(q.normalized().toRotationMatrix());
}
}  // namespace

TEST(EdgeJet, MatchesPerFaceRepresentationAndPerEdgeFactors) {
  const Cage cage(lidef::test::icosphere(1, 0.2, 3));
  const HarmonicBasis B(cage);
  const EdgeJet ej(cage);
  const MatX3d y = perturbed_map(cage, 0.2, 5);
  const auto fm = B.face_matrices(y);
  const EdgeJet::MapData md = ej.prepare(fm);
  VecXd delta(cage.num_edges());
  for (int e = 0; e < cage.num_edges(); ++e)
    delta(e) = (fm.A[cage.edges[e].f0] - fm.A[cage.edges[e].f1]).norm();
  const MatX3d P = lidef::test::interior_points(cage, 20, 0.05);
  for (int i = 0; i < P.rows(); ++i) {
    const Vec3 p = P.row(i);
    const double r = 0.5 * cage.distance(p);
    double sJ = 0, sH = 0;
    const MapJet ref = B.differential_jet(fm, p, 2, &sJ, &sH);
    const MapJet basis = B.map_jet(y, p, 2);
    EdgeJet::Values v;
    ej.evaluate(md, p, r, true, true, true, v);
    EXPECT_LT((v.J - ref.J).norm(), 1e-12 * sJ);
    EXPECT_LT((v.J - basis.J).norm(), 1e-9 * basis.J.norm());
    double dH = 0;
    for (int a = 0; a < 3; ++a) dH += (v.H[a] - ref.H[a]).squaredNorm();
    EXPECT_LT(std::sqrt(dH), 1e-12 * sH);
    EXPECT_NEAR(v.scale_J, sJ, 1e-9 * sJ);
    EXPECT_NEAR(v.scale_H, sH, 1e-9 * sH);
    double t1 = 0, t3 = 0;
    for (int e = 0; e < cage.num_edges(); ++e) {
      const Vec3 u = cage.V.row(cage.edges[e].v0), w = cage.V.row(cage.edges[e].v1);
      t1 += delta(e) * first_order_edge_factor(u, w, p, r);
      t3 += delta(e) * third_order_edge_factor(u, w, p, r);
    }
    EXPECT_NEAR(v.T_first, t1, 1e-12 * t1);
    EXPECT_NEAR(v.T_third, t3, 1e-12 * t3);
  }
}

TEST(CombinedBound, HessianOperatorNormBoundsEverySampledDirection) {
  std::mt19937 rng(8);
  std::normal_distribution<double> N01;
  for (int trial = 0; trial < 200; ++trial) {
    std::array<Mat3, 3> H;
    for (int a = 0; a < 3; ++a) {
      const Mat3 M = Mat3::Random() * std::pow(10.0, N01(rng));
      H[a] = M + M.transpose();  // Hessians are symmetric
    }
    if (trial % 5 == 0) H[1] = 1e-8 * H[0];  // nearly rank-deficient Gram matrices
    const double op = hessian_operator_norm(H);
    const double frob = std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
    EXPECT_LE(op, frob);
    double best = 0;
    for (int k = 0; k < 2000; ++k) {
      const Vec3 v = random_unit(rng);
      Mat3 M;  // Σ_k v_k H_k with (H_k)_ab = H[a](b, k)
      for (int a = 0; a < 3; ++a) M.row(a) = (H[a] * v).transpose();
      best = std::max(best, M.norm());
      ASSERT_LE(M.norm(), op * (1 + 1e-14));
    }
    EXPECT_GT(best, 0.99 * op);  // and it is tight: the sampled supremum comes within 1%
  }
}

// Step 3c alone: ℓ = taylor_sigma3_lower_bound(J, H, r) ≤ σ3ˢ(J + H[v]) for every sampled |v| ≤ r, on random
// J of every kind (well conditioned, σ2 ≈ σ3 with no spectral gap, nearly singular, det ≤ 0 → −∞) and random
// symmetric H, radii from tiny to large; and for small radii it is nearly exact (loss within 10% of the
// sampled one when there is a gap).
TEST(CombinedBound, TaylorSigma3LowerBoundHoldsOnSampledDirections) {
  std::mt19937 rng(31);
  std::normal_distribution<double> N01;
  std::uniform_real_distribution<double> U(0, 1);
  auto rotation = [&] { return random_rotation(rng); };
  int positive = 0, tight = 0, tight_cases = 0;
  for (int trial = 0; trial < 400; ++trial) {
    Vec3 sv(1 + U(rng), 0.5 + 0.5 * U(rng), 0.1 + 0.4 * U(rng));
    const int kind = trial % 4;
    if (kind == 1) sv(2) = sv(1) * (1 - 1e-9 * U(rng));  // no gap between σ2 and σ3
    if (kind == 2) sv(2) = 1e-6 * U(rng);                // nearly singular
    Mat3 J = rotation() * sv.asDiagonal() * rotation();
    if (trial % 23 == 0) J.col(0) = -J.col(0);  // det < 0: no bound
    std::array<Mat3, 3> H;
    const double scale = std::pow(10.0, N01(rng));
    for (int a = 0; a < 3; ++a) {
      Mat3 M;
      for (int k = 0; k < 9; ++k) M.data()[k] = scale * (2 * U(rng) - 1);  // the test's own generator
      H[a] = M + M.transpose();
    }
    const double r = sv(2) / scale * std::pow(10.0, -3 + 3 * U(rng));
    const double lb = taylor_sigma3_lower_bound(J, H, r);
    if (J.determinant() <= 0) {
      EXPECT_EQ(lb, -std::numeric_limits<double>::infinity());
      continue;
    }
    const double s0 = signed_singular_values(J)(2);
    EXPECT_LE(lb, s0 * (1 + 1e-12));
    if (!(lb > 0)) continue;
    ++positive;
    double smin = s0;
    for (int k = 0; k < 2000; ++k) {
      const Vec3 v = r * (k % 2 ? 1.0 : std::cbrt(U(rng))) * random_unit(rng);
      Mat3 E;
      for (int a = 0; a < 3; ++a) E.row(a) = (H[a] * v).transpose();
      const double s = signed_singular_values(J + E)(2);
      smin = std::min(smin, s);
      ASSERT_GE(s, lb - 1e-14 * s0) << "trial " << trial << ", kind " << kind << ", r " << r;
    }
    if (kind == 0 && sv(1) - sv(2) > 0.2 && r * scale < 1e-2 * sv(2)) {
      // A spectral gap and a small ball: the loss is nearly the first-order one, σ3 − ℓ ≈ r‖∇σ3‖, which
      // the sampled directions (1000 on the sphere) approach within a few percent.
      ++tight_cases;
      if (s0 - lb <= 1.2 * (s0 - smin) + 1e-12 * s0) ++tight;
    }
  }
  std::cout << positive << " positive bounds; nearly exact on " << tight << " of " << tight_cases
            << " small balls with a spectral gap\n";
  EXPECT_GT(positive, 150);
  EXPECT_GT(tight_cases, 5);
  EXPECT_GE(tight, tight_cases * 9 / 10);
}

// Step 3d: σ1(J + H[v]) ≤ upper1 + g1·v and σ3ˢ(J + H[v]) ≥ lower3 + g3·v at every sampled |v| ≤ r, and the
// bounds of σ1, σ3 and σ1/σ3 hold for J + H[v] + R with any ‖R‖₂ ≤ ρ; on random J of every kind (gaps,
// σ1 = σ2, σ2 = σ3, near-isotropic, det < 0 → not valid) and random symmetric H, radii from tiny to large.
// With gaps and small balls the bound of K is nearly exact: its excess over K(c) within 20% of the sampled
// one, and below the quotient of Lipschitz bounds' (which loses r(1 + K)‖H‖_op/σ3 to first order where this
// one loses r|∇K|).
TEST(CombinedBound, TaylorDistortionBoundHoldsOnSampledDirections) {
  std::mt19937 rng(37);
  std::normal_distribution<double> N01;
  std::uniform_real_distribution<double> U(0, 1);
  auto rotation = [&] { return random_rotation(rng); };
  int valid = 0, finite_k = 0, tight = 0, tight_cases = 0, beats_quotient = 0;
  for (int trial = 0; trial < 400; ++trial) {
    Vec3 sv(1 + U(rng), 0.5 + 0.5 * U(rng), 0.1 + 0.4 * U(rng));
    const int kind = trial % 4;
    if (kind == 1) sv(2) = sv(1) * (1 - 1e-9 * U(rng));  // σ2 = σ3
    if (kind == 2) sv(1) = sv(0) * (1 - 1e-9 * U(rng));  // σ1 = σ2
    if (kind == 3) sv = Vec3(1, 1 - 1e-3 * U(rng), 1 - 2e-3 * U(rng));
    Mat3 J = rotation() * sv.asDiagonal() * rotation();
    if (trial % 23 == 0) J.col(0) = -J.col(0);
    std::array<Mat3, 3> H;
    const double scale = std::pow(10.0, N01(rng));
    for (int a = 0; a < 3; ++a) {
      Mat3 M;
      for (int k = 0; k < 9; ++k) M.data()[k] = scale * (2 * U(rng) - 1);
      H[a] = M + M.transpose();
    }
    const double r = sv(2) / scale * std::pow(10.0, -3 + 3 * U(rng));
    const TaylorSingularBounds t = taylor_singular_bounds(J, H, r);
    if (J.determinant() <= 0) {
      EXPECT_FALSE(t.valid);
      continue;
    }
    if (!t.valid) continue;
    ++valid;
    const double rho = (trial / 4) % 2 ? 0.0 : 0.05 * r * scale * U(rng);
    const double K = taylor_distortion_bound(t, r, rho);
    const double S1 = taylor_sigma1_upper_bound(t, r, rho), S3 = taylor_sigma3_lower_bound(t, r, rho);
    const Vec3 c = signed_singular_values(J);
    EXPECT_GE(S1, c(0) * (1 - 1e-12));
    EXPECT_LE(S3, c(2) * (1 + 1e-12));
    if (std::isfinite(K)) {
      ++finite_k;
      EXPECT_GE(K, c(0) / c(2) * (1 - 1e-12));
    }
    double kmax = c(0) / c(2);
    for (int k = 0; k < 2000; ++k) {
      const Vec3 v = r * (k % 2 ? 1.0 : std::cbrt(U(rng))) * random_unit(rng);
      Mat3 E;
      for (int a = 0; a < 3; ++a) E.row(a) = (H[a] * v).transpose();
      const Vec3 s = signed_singular_values(J + E);
      const double tol = 1e-13 * c(0);
      ASSERT_LE(s(0), t.upper1 + t.g1.dot(v) + tol) << "trial " << trial << ", kind " << kind;
      ASSERT_GE(s(2), t.lower3 + t.g3.dot(v) - tol) << "trial " << trial << ", kind " << kind;
      kmax = std::max(kmax, s(0) / s(2));
      // A perturbation of spectral norm ρ (a random direction, rescaled by its largest singular value).
      Mat3 R;
      for (int q = 0; q < 9; ++q) R.data()[q] = N01(rng);
      R *= rho / signed_singular_values(R).cwiseAbs().maxCoeff();
      const Vec3 sr = signed_singular_values(J + E + R);
      ASSERT_LE(sr(0), S1 + tol);
      ASSERT_GE(sr(2), S3 - tol);
      if (std::isfinite(K)) {
        ASSERT_LE(sr(0) / sr(2), K * (1 + 1e-12)) << "trial " << trial << ", kind " << kind;
      }
    }
    if (kind == 0 && rho == 0 && sv(0) - sv(1) > 0.2 && sv(1) - sv(2) > 0.2 && r * scale < 1e-2 * sv(2)) {
      ++tight_cases;
      const double k0 = c(0) / c(2);
      if (K - k0 <= 1.2 * (kmax - k0) + 1e-12 * k0) ++tight;
      // The quotient of the per-leaf Lipschitz bounds with the operator norm of H (the best of Steps 3-3b).
      const double hop = hessian_operator_norm(H);
      if (K < (c(0) + r * hop) / (c(2) - r * hop)) ++beats_quotient;
    }
  }
  std::cout << valid << " valid, " << finite_k << " finite K bounds; nearly exact on " << tight << " of "
            << tight_cases << " small balls with gaps; below the quotient on " << beats_quotient << "\n";
  EXPECT_GT(valid, 200);
  EXPECT_GT(finite_k, 180);
  EXPECT_GT(tight_cases, 5);
  EXPECT_GE(tight, tight_cases * 9 / 10);
  EXPECT_EQ(beats_quotient, tight_cases);
}

// For balls around random interior points, with radius from the distance to the cage over a safety factor
// (1.0: the ball touches the cage, as the clearance allows at the limit), the Taylor form and the first-order
// bound hold at sampled points: |σ3(q) − σ3(c)| ≤ |q−c| ‖H(c)‖_op + ½|q−c|² T3 and ≤ |q−c| T1, and so does
// the spectral bound (Step 3c): σ3(q) ≥ ℓ − ½|q−c|² T3.
TEST(CombinedBound, HoldsOnSampledPointsOfRandomBallsUpToTheClearance) {
  const Cage cage(lidef::test::icosphere(1, 0.2, 3));
  const HarmonicBasis B(cage);
  const EdgeJet ej(cage);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> U(0, 1);
  int balls = 0, tight_taylor = 0;
  long spectral_checked = 0;
  double worst = 0;
  for (double amp : {0.02, 0.1, 0.3}) {
    const MatX3d y = perturbed_map(cage, amp, 10 + static_cast<unsigned>(100 * amp));
    const EdgeJet::MapData md = ej.prepare(B.face_matrices(y));
    const MatX3d P = lidef::test::interior_points(cage, 25, 0.02, 11);
    for (int i = 0; i < P.rows(); ++i)
      for (double safety : {1.0, 1.5, 3.0}) {
        const Vec3 c = P.row(i);
        const double r = cage.distance(c) / safety * (1 - 1e-9);
        EdgeJet::Values v;
        ej.evaluate(md, c, r, true, true, true, v);
        if (!std::isfinite(v.T_third) || !std::isfinite(v.T_first)) continue;
        ++balls;
        const double s0 = signed_singular_values(B.map_jet(y, c, 1).J)(2);
        const double hop = hessian_operator_norm(v.H);
        const double lb = taylor_sigma3_lower_bound(v.J, v.H, r);
        for (int k = 0; k < 300; ++k) {
          const double s = r * (k % 2 ? 1.0 : std::cbrt(U(rng)));
          const Vec3 q = c + s * random_unit(rng);
          const double diff = std::abs(signed_singular_values(B.map_jet(y, q, 1).J)(2) - s0);
          const double taylor = s * hop + 0.5 * s * s * v.T_third;
          ASSERT_LE(diff, taylor * (1 + 1e-9) + 1e-12) << "Taylor form";
          ASSERT_LE(diff, s * v.T_first * (1 + 1e-9) + 1e-12) << "first order";
          // Step 3c: σ3(q) ≥ ℓ(J(c), H(c), r) − ½|q−c|² T3 (ℓ a lower bound on the ball of radius r).
          if (lb > -1e300) {
            const double s3q = signed_singular_values(B.map_jet(y, q, 1).J)(2);
            ASSERT_GE(s3q, lb - 0.5 * s * s * v.T_third * (1 + 1e-9) - 1e-12) << "spectral (Taylor sigma3)";
            ++spectral_checked;
          }
          worst = std::max(worst, diff / std::min(taylor, s * v.T_first));
          if (taylor < s * v.T_first) ++tight_taylor;
        }
      }
  }
  std::cout << balls << " balls; largest sampled |Δσ3| / bound = " << worst << "\n";
  EXPECT_GT(balls, 150);
  EXPECT_GT(tight_taylor, 0);  // both terms of the minimum decide somewhere
  EXPECT_GT(spectral_checked, 10000) << "the Taylor sigma3 bound should be positive on most of these balls";
}

// Leaf by leaf: combined ≤ min(first, third), spectral ≤ combined; and whole certificates of both under dense
// sampling.
TEST(CombinedBound, CertificatesAreNoWeakerThanEitherBoundAndHoldUnderDenseSampling) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  const VoxelSampling samp = about_1500_voxels(cage);
  const OctreeCertifier cert(cage, samp);
  int certified = 0;
  for (double amp : {0.005, 0.02}) {
    const MatX3d y = lidef::test::anisotropic_perturbed_map(cage, amp, 20);
    CertifyParams p;
    p.max_depth = 0;
    p.bound = LipschitzBound::kFirstOrder;
    const Certificate c1 = cert.certify(y, p);
    p.bound = LipschitzBound::kThirdOrder;
    const Certificate c3 = cert.certify(y, p);
    p.bound = LipschitzBound::kCombined;
    const Certificate cc = cert.certify(y, p);
    p.bound = LipschitzBound::kSpectral;
    const Certificate cs = cert.certify(y, p);
    ASSERT_EQ(cc.leaves.size(), c1.leaves.size());
    ASSERT_EQ(cs.leaves.size(), c1.leaves.size());
    int smaller = 0;
    for (size_t i = 0; i < cc.leaves.size(); ++i) {
      ASSERT_LE(cc.leaves[i].L, std::min(c1.leaves[i].L, c3.leaves[i].L) * (1 + 1e-12));
      ASSERT_LE(cs.leaves[i].L, cc.leaves[i].L * (1 + 1e-12));
      smaller += cs.leaves[i].L < (1 - 1e-6) * cc.leaves[i].L;
    }
    EXPECT_GT(smaller, 0) << "the spectral term should decide on some leaves";
    for (LipschitzBound b : {LipschitzBound::kCombined, LipschitzBound::kSpectral}) {
      p.bound = b;
      p.max_depth = 2;
      const Certificate full = cert.certify(y, p);
      const VerificationResult v = verify_certificate(cert.basis(), y, full.leaves, 4, 3);
      EXPECT_EQ(v.violations, 0) << to_string(b);
      if (full.certified) {
        ++certified;
        EXPECT_EQ(v.nonpositive_in_certified, 0);
        EXPECT_LE(full.min_lower_bound, v.min_sigma3);
      }
      p.max_depth = 0;
    }
  }
  EXPECT_GT(certified, 0);
}

// The per-edge refinement and the previous per-face one take the same decisions (J and H agree to rounding,
// the bound sums are the same functions).
TEST(EdgeJet, RefinementAgreesWithPerFaceEvaluation) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  SamplingParams sp;
  sp.target_count = 800;
  sp.count_tolerance = 0.1;
  const OctreeCertifier cert(cage, sample_voxels(cage, sp));
  const MatX3d y = perturbed_map(cage, 0.012, 21);
  for (LipschitzBound b :
       {LipschitzBound::kFirstOrder, LipschitzBound::kThirdOrder, LipschitzBound::kCombined}) {
    CertifyParams p;
    p.bound = b;
    p.max_depth = 3;
    p.refinement =
        RefinementEval::kPerEdgeBatched;  // exact (the far field is compared in test_far_field.cpp)
    const Certificate a = cert.certify(y, p);
    p.refinement = RefinementEval::kPerFace;
    const Certificate o = cert.certify(y, p);
    EXPECT_GT(a.refined, 0) << to_string(b);
    EXPECT_EQ(a.certified, o.certified);
    ASSERT_EQ(a.leaves.size(), o.leaves.size()) << to_string(b);
    for (size_t i = 0; i < a.leaves.size(); ++i) {
      EXPECT_NEAR(a.leaves[i].sigma3, o.leaves[i].sigma3, 1e-12);
      EXPECT_NEAR(a.leaves[i].L, o.leaves[i].L, 1e-10 * o.leaves[i].L);
    }
  }
}

// Step 4f: with the third-order bound, a base voxel it leaves unproven takes the spectral bound where that
// proves it. Against three independent checks: the spectral certificate of the same map (the same loss, to
// the bit, at every voxel the fallback proved; the third-order one's at every other), dense sampling of σ3 in
// every leaf of the refined certificate, and the interval re-proof of its leaves.
TEST(CombinedBound, TheSpectralFallbackProvesBaseVoxelsWithTheSpectralBoundsLoss) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  const VoxelSampling samp = about_1500_voxels(cage);
  const OctreeCertifier cert(cage, samp);
  cert.factor_matrix(false);  // the first-order term of the spectral bound, as the solver builds it
  long fallback_total = 0, certified_full = 0;
  for (double amp : {0.02, 0.03}) {
    const MatX3d y = lidef::test::anisotropic_perturbed_map(cage, amp, 20);
    CertifyParams p;
    p.max_depth = 0;
    p.bound = LipschitzBound::kThirdOrder;
    const Certificate c3 = cert.certify(y, p);
    p.base_spectral_fallback = true;
    const Certificate cf = cert.certify(y, p);
    p.base_spectral_fallback = false;
    p.bound = LipschitzBound::kSpectral;
    const Certificate cs = cert.certify(y, p);
    ASSERT_EQ(cf.leaves.size(), c3.leaves.size());
    ASSERT_EQ(cs.leaves.size(), c3.leaves.size());
    long fell_back = 0;
    for (size_t i = 0; i < cf.leaves.size(); ++i) {
      const CertLeaf &f = cf.leaves[i], &t = c3.leaves[i], &s = cs.leaves[i];
      const bool by_fallback = !t.certified && f.certified;
      fell_back += by_fallback;
      const CertLeaf& expected = by_fallback ? s : t;
      ASSERT_EQ(f.margin, expected.margin) << "voxel " << i;
      ASSERT_EQ(f.L, expected.L) << "voxel " << i;
      ASSERT_EQ(f.certified, expected.certified) << "voxel " << i;
    }
    EXPECT_EQ(cf.fallback_voxels, fell_back);
    fallback_total += fell_back;

    p.bound = LipschitzBound::kThirdOrder;
    p.max_depth = 3;
    const Certificate third_full = cert.certify(y, p);
    p.base_spectral_fallback = true;
    const Certificate full = cert.certify(y, p);
    EXPECT_LE(full.refined, third_full.refined);
    EXPECT_TRUE(full.certified || !third_full.certified) << "the fallback never loses a verdict";
    const VerificationResult v = verify_certificate(cert.basis(), y, full.leaves, 4, 3);
    EXPECT_EQ(v.violations, 0);
    if (full.certified && ++certified_full == 1) {  // the re-proof once: it costs ~2 ms per leaf
      EXPECT_EQ(v.nonpositive_in_certified, 0);
      EXPECT_LE(full.min_lower_bound, v.min_sigma3);
      const IntervalVerification iv = verify_certificate_intervals(cage, y, full.leaves, p.bound);
      EXPECT_EQ(iv.not_proven, 0) << "the interval re-proof tries the spectral bound where (21) fails";
      EXPECT_EQ(iv.distortion_not_proven, 0) << "the fallback's σ1 and σ1/σ3 bounds, re-proven likewise";
    }
    std::printf(
        "[ amplitude %.2f ] base voxels %zu: third order proves %ld, the fallback %ld more; depth 3: "
        "%ld -> %ld refined\n",
        amp, c3.leaves.size(),
        static_cast<long>(
            std::count_if(c3.leaves.begin(), c3.leaves.end(), [](const CertLeaf& l) { return l.certified; })),
        fell_back, third_full.refined, full.refined);
  }
  EXPECT_GT(fallback_total, 0)
      << "maps where the third-order bound leaves base voxels the spectral one proves";
  EXPECT_GT(certified_full, 0);
}
