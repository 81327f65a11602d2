// Bounded distortion (docs/certificate.md, "Bounded distortion"): the per-leaf upper bounds of σ1 and of
// K = σ1/σ3 against dense sampling of the exact map (random maps, every bound, on the fly and from stored
// float derivatives, chains of certificates by perturbation), the interval re-proof of the same bounds, the
// target K (refined until proven, or not certified with its reason), voxels.csv's new columns, and a
// constrained solve of beam_bend through the CLI checked by `lidef verify`.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <utility>

#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/certificate_verification.h"
#include "lidef/analysis/interval_verification.h"
#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"
#include "lidef/subspace.h"
#include "test_cages.h"
#include "test_support.h"

using namespace lidef;
using lidef::test::TempDir;

namespace {

using MatR = Eigen::Matrix<double, Eigen::Dynamic, 3>;
constexpr double kInf = std::numeric_limits<double>::infinity();

// The subdivided bumpy icosphere's ~1,500 voxels and a 40-function subspace.
struct Sphere {
  Cage cage{lidef::test::icosphere(2, 0.15, 8)};
  VoxelSampling sampling;
  SpectralSubspace sub;
  Sphere() {
    SamplingParams sp;
    sp.target_count = 1500;
    sp.count_tolerance = 0.1;
    sampling = sample_voxels(cage, sp);
    sub = compute_subspace(cage, 40);
  }
};
const Sphere& sphere() {
  static const Sphere s;
  return s;
}

// Dense sampling of a certificate's leaves: no sample above its leaf's σ1 or K bound, and for a certified map
// the certificate-wide bounds at or above every sampled value (and finite). Returns the sampled max of K.
double check_against_sampling(const HarmonicBasis& basis, const MatX3d& y, const Certificate& c,
                              int samples = 8) {
  const VerificationResult v = verify_certificate(basis, y, c.leaves, samples, 3);
  EXPECT_EQ(v.distortion_violations, 0) << "a sampled sigma1 or sigma1/sigma3 is above its leaf's bound";
  if (c.certified) {
    EXPECT_TRUE(std::isfinite(c.max_sigma1_upper_bound));
    EXPECT_TRUE(std::isfinite(c.max_distortion_upper_bound));
    EXPECT_GE(c.max_sigma1_upper_bound, v.max_sigma1);
    EXPECT_GE(c.max_distortion_upper_bound, v.max_distortion);
    EXPECT_GE(v.max_distortion, 1.0);
  }
  return v.max_distortion;
}

// The leaves of largest and of smallest center σ1/σ3 (null when no leaf has σ3 > 0 and a finite σ1).
std::pair<const CertLeaf*, const CertLeaf*> extreme_leaves(const Certificate& c) {
  const CertLeaf* hi = nullptr;
  const CertLeaf* lo = nullptr;
  for (const CertLeaf& l : c.leaves) {
    if (!(l.sigma3 > 0) || !std::isfinite(l.sigma1)) continue;
    if (!hi || l.sigma1 / l.sigma3 > hi->sigma1 / hi->sigma3) hi = &l;
    if (!lo || l.sigma1 / l.sigma3 < lo->sigma1 / lo->sigma3) lo = &l;
  }
  return {hi, lo};
}

// The bent map of the target tests (a smooth map of the icosphere's cage), certified at depth 3 without a
// target: once for all of them.
struct BentMap {
  OctreeCertifier cert{sphere().cage, sphere().sampling};
  MatX3d y = lidef::test::smooth_map(sphere().cage, sphere().sub, 0.9, 12);
  CertifyParams p = [] {
    CertifyParams q;
    q.max_depth = 3;
    return q;
  }();
  Certificate c0 = cert.certify(y, p);
};
const BentMap& bent_map() {
  static const BentMap b;
  return b;
}

}  // namespace

TEST(DistortionBound, NeverBelowDenseSamplingOnRandomMapsAndEveryBound) {
  const Sphere& s = sphere();
  OctreeCertifier cert(s.cage, s.sampling);
  std::vector<MatX3d> maps = {
      lidef::test::perturbed_map(s.cage, 0.01, 3), lidef::test::anisotropic_perturbed_map(s.cage, 0.01, 4),
      lidef::test::smooth_map(s.cage, s.sub, 0.45, 11), lidef::test::smooth_map(s.cage, s.sub, 0.9, 12)};
  {  // an orientation-preserving affine map composed with a bend: K well above 1 everywhere
    Mat3 A;
    A << 1.6, 0.3, 0, -0.2, 0.8, 0.1, 0.05, 0, 0.5;
    MatX3d y = maps[2];
    for (int i = 0; i < y.rows(); ++i) y.row(i) = (A * y.row(i).transpose()).transpose();
    maps.push_back(y);
  }
  int certified = 0;
  for (size_t mi = 0; mi < maps.size(); ++mi)
    for (LipschitzBound b : {LipschitzBound::kFirstOrder, LipschitzBound::kThirdOrder,
                             LipschitzBound::kCombined, LipschitzBound::kSpectral}) {
      if (b == LipschitzBound::kFirstOrder && mi >= 2) continue;  // very many leaves on bent maps
      SCOPED_TRACE("map " + std::to_string(mi) + ", bound " + to_string(b));
      CertifyParams p;
      p.bound = b;
      p.max_depth = 2;
      const Certificate c = cert.certify(maps[mi], p);
      check_against_sampling(cert.basis(), maps[mi], c, 4);
      certified += c.certified;
      // Every certified leaf has a finite bound at least σ1(c) (the center is in the leaf).
      for (const CertLeaf& l : c.leaves)
        if (l.certified) {
          ASSERT_TRUE(std::isfinite(l.distortion_upper));
          EXPECT_GE(l.sigma1_upper, l.sigma1);
        } else {
          EXPECT_EQ(l.distortion_upper, kInf);
        }
    }
  EXPECT_GT(certified, 8);
}

TEST(DistortionBound, StoredDerivativesFarFieldAndPerturbationChainsStaySound) {
  const Sphere& s = sphere();
  const OctreeCertifier cert(s.cage, s.sampling, &s.sub.basis);
  const MatR y0 = s.sub.basis.transpose() * lidef::test::smooth_map(s.cage, s.sub, 0.6, 14);
  CertifyParams p;
  p.max_depth = 4;  // third order, far-field refinement, float-stored base derivatives
  const Certificate c0 = cert.certify_reduced(y0, p);
  ASSERT_TRUE(c0.certified) << c0.reason;
  ASSERT_EQ(static_cast<long>(c0.base_upper.size()), s.sampling.size());
  EXPECT_GT(c0.refined, 0);
  check_against_sampling(cert.basis(), s.sub.basis * y0, c0);

  // A chain of two small steps certified by perturbation: the voxels taken over carry σ1 bounds.
  std::mt19937 rng(5);
  std::normal_distribution<double> N01;
  MatR prev = y0;
  Certificate cp = c0;
  for (int step = 0; step < 2; ++step) {
    MatR d(prev.rows(), 3);
    for (long k = 0; k < d.rows(); ++k) d.row(k) << N01(rng), N01(rng), N01(rng);
    const MatR y1 = prev + 1e-4 * y0.norm() / d.norm() * d;
    CertifyParams q = p;
    q.previous_y = &prev;
    q.previous_lower = &cp.base_lower;
    q.previous_upper = &cp.base_upper;
    const Certificate c1 = cert.certify_reduced(y1, q);
    ASSERT_TRUE(c1.certified) << c1.reason;
    EXPECT_GT(c1.perturbed_voxels, s.sampling.size() / 2);
    std::vector<CertLeaf> taken;
    for (const CertLeaf& l : c1.leaves)
      if (std::isnan(l.sigma3) && l.certified) {
        EXPECT_TRUE(std::isfinite(l.sigma1_upper));
        EXPECT_TRUE(std::isfinite(l.distortion_upper));
        taken.push_back(l);
      }
    ASSERT_FALSE(taken.empty());
    const VerificationResult v = verify_certificate(cert.basis(), s.sub.basis * y1, taken, 16, 7);
    EXPECT_EQ(v.distortion_violations, 0);
    EXPECT_GE(c1.max_distortion_upper_bound, v.max_distortion);
    prev = y1;
    cp = c1;
  }

  // With a target the previous bounds do not prove, nothing is taken over without proof: the verdict and the
  // bound stay sound either way.
  CertifyParams q = p;
  q.previous_y = &y0;
  q.previous_lower = &c0.base_lower;
  q.max_distortion = 1.0 + 1e-9;  // not provable for a bent map
  const Certificate c2 = cert.certify_reduced(y0, q);
  EXPECT_FALSE(c2.certified);
  EXPECT_TRUE(c2.distortion_failed);
  EXPECT_EQ(c2.perturbed_voxels, 0) << "taken over without an upper bound of sigma1";
}

TEST(DistortionBound, TargetIsProvenByRefinementOrReportedNotCertified) {
  const BentMap& b = bent_map();
  const OctreeCertifier& cert = b.cert;
  const MatX3d& y = b.y;
  const CertifyParams& p = b.p;
  const Certificate& c0 = b.c0;
  ASSERT_TRUE(c0.certified) << c0.reason;
  const double sampled = check_against_sampling(cert.basis(), y, c0);
  const double bound0 = c0.max_distortion_upper_bound;
  ASSERT_GT(bound0, sampled);

  // A target between the sampled maximum and the bound: refinement proves it.
  CertifyParams q = p;
  q.max_distortion = sampled + 0.6 * (bound0 - sampled);
  const Certificate c1 = cert.certify(y, q);
  ASSERT_TRUE(c1.certified) << c1.reason;
  EXPECT_TRUE(c1.distortion_met);
  EXPECT_LE(c1.max_distortion_upper_bound, q.max_distortion);
  EXPECT_GT(c1.num_leaves, c0.num_leaves);
  check_against_sampling(cert.basis(), y, c1);
  // The leaves still tile the base voxels: their volume is the base voxels'.
  double vol0 = 0, vol1 = 0;
  for (const CertLeaf& l : c0.leaves) vol0 += l.side * l.side * l.side;
  for (const CertLeaf& l : c1.leaves) vol1 += l.side * l.side * l.side;
  EXPECT_NEAR(vol1, vol0, 1e-12 * vol0);

  // A target below the sampled maximum can never be proven: not certified, with the reason.
  q.max_distortion = std::max(1.0, 0.98 * sampled);
  const Certificate c2 = cert.certify(y, q);
  EXPECT_FALSE(c2.certified);
  EXPECT_TRUE(c2.distortion_failed);
  EXPECT_NE(c2.reason.find("distortion bound"), std::string::npos) << c2.reason;
  EXPECT_NE(c2.reason.find("not proven at ("), std::string::npos) << c2.reason;
  EXPECT_FALSE(c2.failing.empty());
  EXPECT_TRUE(c2.base_lower.empty());
  // It fails where a leaf cannot be split further, not at the budget: the reason does not blame the budget.
  EXPECT_EQ(c2.distortion_budget, 0);
  EXPECT_EQ(c2.reason.find("budget"), std::string::npos) << c2.reason;

  // A target 3% above the sampled maximum with budgets from 4,096 nodes up: where σ3 is proven and the
  // distortion stage's next split would pass the budget, the map is not certified and the reason says that
  // the budget ran out (a larger one may prove it).
  q.max_distortion = 1.03 * sampled;
  bool budget_failure_seen = false;
  for (long budget = 4096; budget <= (1L << 20) && !budget_failure_seen; budget = budget * 5 / 4 + 8) {
    q.max_refined_voxels = budget;
    const Certificate c3 = cert.certify(y, q);
    if (c3.certified) break;
    if (!c3.distortion_failed) continue;  // the σ3 stage's budget
    budget_failure_seen = true;
    EXPECT_EQ(c3.distortion_budget, budget);
    EXPECT_NE(c3.reason.find("not proven at ("), std::string::npos) << c3.reason;
    EXPECT_NE(c3.reason.find("refinement budget of " + std::to_string(budget) + " nodes used up"),
              std::string::npos)
        << c3.reason;
    EXPECT_EQ(c3.distortion_reason(), c3.reason);
  }
  EXPECT_TRUE(budget_failure_seen);

  // A target below 1 is refused as a parameter.
  DeformParams dp;
  dp.max_distortion = 0.5;
  EXPECT_THROW(validate_params(dp, "test"), InputError);
  dp.max_distortion = 1.5;
  EXPECT_NO_THROW(validate_params(dp, "test"));
}

// The isometric targets (max_sigma1, min_sigma3): between the sampled extreme and the unconstrained bound,
// refinement proves them (the certificate's σ1 upper bound and σ3 lower bound move to the target, sampling
// agrees); beyond the sampled extreme the map is not certified, naming the target; together with a K target
// the one that fails is named.
TEST(DistortionBound, IsometricTargetsAreProvenByRefinementOrReportedNotCertified) {
  const BentMap& b = bent_map();
  const OctreeCertifier& cert = b.cert;
  const MatX3d& y = b.y;
  const CertifyParams& p = b.p;
  const Certificate& c0 = b.c0;
  ASSERT_TRUE(c0.certified) << c0.reason;
  const VerificationResult v0 = verify_certificate(cert.basis(), y, c0.leaves, 8, 3);
  ASSERT_GT(c0.max_sigma1_upper_bound, v0.max_sigma1);
  ASSERT_LT(c0.min_lower_bound, v0.min_sigma3);
  ASSERT_GT(v0.max_sigma1, 1.05) << "the map should stretch";
  ASSERT_LT(v0.min_sigma3, 0.95) << "the map should compress";

  // σ1: a target between the sampled maximum and the bound.
  CertifyParams q = p;
  q.max_sigma1 = v0.max_sigma1 + 0.6 * (c0.max_sigma1_upper_bound - v0.max_sigma1);
  const Certificate c1 = cert.certify(y, q);
  ASSERT_TRUE(c1.certified) << c1.reason;
  EXPECT_TRUE(c1.distortion_met);
  EXPECT_LE(c1.max_sigma1_upper_bound, q.max_sigma1);
  EXPECT_GT(c1.num_leaves, c0.num_leaves);
  for (const CertLeaf& l : c1.leaves) EXPECT_LE(l.sigma1_upper, q.max_sigma1);
  const VerificationResult v1 = verify_certificate(cert.basis(), y, c1.leaves, 8, 5);
  EXPECT_EQ(v1.distortion_violations, 0);
  EXPECT_LE(v1.max_sigma1, q.max_sigma1);

  // σ3: a target between the unconstrained lower bound and the sampled minimum.
  q = p;
  q.min_sigma3 = v0.min_sigma3 - 0.4 * (v0.min_sigma3 - c0.min_lower_bound);
  const Certificate c2 = cert.certify(y, q);
  ASSERT_TRUE(c2.certified) << c2.reason;
  EXPECT_TRUE(c2.distortion_met);
  EXPECT_GE(c2.min_lower_bound, q.min_sigma3);
  const VerificationResult v2 = verify_certificate(cert.basis(), y, c2.leaves, 8, 6);
  EXPECT_EQ(v2.violations, 0);
  EXPECT_GE(v2.min_sigma3, q.min_sigma3);

  // Beyond the sampled extremes: never proven; the reason names the target.
  q = p;
  q.max_sigma1 = std::max(1.0, 0.98 * v0.max_sigma1);
  const Certificate c3 = cert.certify(y, q);
  EXPECT_FALSE(c3.certified);
  EXPECT_TRUE(c3.distortion_failed);
  EXPECT_EQ(c3.distortion_failed_on, DistortionTarget::kSigma1);
  EXPECT_NE(c3.reason.find("distortion bound sigma1 <= "), std::string::npos) << c3.reason;
  ASSERT_FALSE(c3.failing.empty());
  EXPECT_GT(c3.failing.front().sigma1_upper, q.max_sigma1);
  q = p;
  q.min_sigma3 = std::min(1.0, 1.02 * v0.min_sigma3);
  const Certificate c4 = cert.certify(y, q);
  EXPECT_FALSE(c4.certified);
  EXPECT_EQ(c4.distortion_failed_on, DistortionTarget::kSigma3);
  EXPECT_NE(c4.reason.find("distortion bound sigma3 >= "), std::string::npos) << c4.reason;
  // A K target that holds with a σ3 target that cannot: the σ3 target is named.
  q.max_distortion = 2 * c0.max_distortion_upper_bound;
  const Certificate c5 = cert.certify(y, q);
  EXPECT_FALSE(c5.certified);
  EXPECT_EQ(c5.distortion_failed_on, DistortionTarget::kSigma3);

  // In the line search (stop_on_failure) a probe where σ1 is certainly above the target refuses at once.
  const CertLeaf* hi = nullptr;
  for (const CertLeaf& l : c0.leaves)
    if (std::isfinite(l.sigma1) && (!hi || l.sigma1 > hi->sigma1)) hi = &l;
  ASSERT_TRUE(hi);
  q = p;
  q.stop_on_failure = true;
  q.max_sigma1 = std::max(1.0, 0.99 * hi->sigma1);
  q.distortion_probes = {hi->center};
  const Certificate quick = cert.certify(y, q);
  EXPECT_FALSE(quick.certified);
  EXPECT_EQ(quick.distortion_failed_on, DistortionTarget::kSigma1);
  EXPECT_EQ(quick.reason, q.targets().reason(DistortionTarget::kSigma1, hi->center));
  EXPECT_EQ(quick.num_leaves, 0) << "the probe refused before evaluating the voxels";
  q.distortion_probes.clear();
  EXPECT_FALSE(cert.certify(y, q).certified) << "the full certificate refuses it too";

  // Targets the rest state cannot meet are refused as parameters.
  DeformParams dp;
  dp.max_sigma1 = 0.9;
  EXPECT_THROW(validate_params(dp, "test"), InputError);
  dp.max_sigma1 = 1.2;
  dp.min_sigma3 = 1.1;
  EXPECT_THROW(validate_params(dp, "test"), InputError);
  dp.min_sigma3 = 0.8;
  EXPECT_NO_THROW(validate_params(dp, "test"));
}

// The line search's probes: a probe where σ1/σ3 is above the target refuses the map at once, with the verdict
// of the full certificate (which fails too); probes below the target, or outside the voxels, change nothing.
TEST(DistortionBound, ProbesRefuseOnlyWhatTheFullCertificateRefuses) {
  const Sphere& s = sphere();
  OctreeCertifier cert(s.cage, s.sampling);
  const MatX3d y = lidef::test::smooth_map(s.cage, s.sub, 0.9, 12);
  CertifyParams p;
  p.max_depth = 3;
  p.stop_on_failure = true;
  const Certificate c0 = cert.certify(y, p);
  ASSERT_TRUE(c0.certified) << c0.reason;
  // The leaf center of largest σ1/σ3, and one of the smallest.
  const auto [hi, lo] = extreme_leaves(c0);
  ASSERT_TRUE(hi && lo);
  const double k_hi = hi->sigma1 / hi->sigma3, k_lo = lo->sigma1 / lo->sigma3;
  ASSERT_GT(k_hi, 1.01 * k_lo);

  // Target below the value at `hi`: the probe there refuses at once; the full certificate refuses too.
  CertifyParams q = p;
  q.max_distortion = std::max(1.0, 0.99 * k_hi);
  const Certificate full = cert.certify(y, q);
  EXPECT_FALSE(full.certified);
  EXPECT_TRUE(full.distortion_failed);
  q.distortion_probes = {lo->center, hi->center};
  const Certificate quick = cert.certify(y, q);
  EXPECT_FALSE(quick.certified);
  EXPECT_TRUE(quick.distortion_failed);
  EXPECT_EQ(quick.distortion_failed_on, DistortionTarget::kDistortion);
  EXPECT_EQ(quick.reason, q.targets().reason(DistortionTarget::kDistortion, hi->center));
  ASSERT_EQ(quick.failing.size(), 1u);
  EXPECT_EQ(quick.failing.front().center, hi->center);
  EXPECT_EQ(quick.num_leaves, 0) << "the probe refused before evaluating the voxels";
  // The probes after the first are evaluated together: the refusal still names the first in order that
  // proves a violation (a point next to `hi` before `hi` itself), and skips the one outside every voxel.
  const Vec3 near_hi = hi->center + Vec3(1e-7, -1e-7, 1e-7);
  q.distortion_probes = {lo->center, Vec3(100, 100, 100), near_hi, hi->center, lo->center};
  const Certificate ordered = cert.certify(y, q);
  EXPECT_FALSE(ordered.certified);
  ASSERT_EQ(ordered.failing.size(), 1u);
  EXPECT_EQ(ordered.failing.front().center, near_hi);
  EXPECT_EQ(ordered.reason, q.targets().reason(DistortionTarget::kDistortion, near_hi));
  EXPECT_EQ(ordered.num_leaves, 0);

  // Target above every leaf's bound: certified with or without probes, identical bounds.
  q.max_distortion = 2 * c0.max_distortion_upper_bound;
  q.distortion_probes.clear();
  const Certificate plain = cert.certify(y, q);
  q.distortion_probes = {hi->center, lo->center, Vec3(100, 100, 100)};  // the last outside every voxel
  const Certificate probed = cert.certify(y, q);
  ASSERT_TRUE(plain.certified) << plain.reason;
  ASSERT_TRUE(probed.certified) << probed.reason;
  EXPECT_EQ(probed.max_distortion_upper_bound, plain.max_distortion_upper_bound);
  EXPECT_EQ(probed.min_lower_bound, plain.min_lower_bound);
  EXPECT_EQ(probed.num_leaves, plain.num_leaves);

  // Without stop_on_failure (a report, not a line search) probes are not used: the full verdict with leaves.
  q.max_distortion = std::max(1.0, 0.99 * k_hi);
  q.stop_on_failure = false;
  q.distortion_probes = {hi->center};
  const Certificate report = cert.certify(y, q);
  EXPECT_FALSE(report.certified);
  EXPECT_GT(report.num_leaves, 0);
}

// When no probe proves a violation but one comes within 2% of the target, a short pattern search around it
// looks for a point that does: a proven violation there refuses the map before any voxel is evaluated, and
// the full certificate refuses it too; sampled independently, σ1/σ3 at that point is above the target.
// distortion_refuted searches only when asked.
TEST(DistortionBound, SearchNearAProbeRefusesOnlyProvenViolations) {
  const Sphere& s = sphere();
  const BentMap& b = bent_map();
  ASSERT_TRUE(b.c0.certified) << b.c0.reason;
  const CertLeaf* hi = extreme_leaves(b.c0).first;
  ASSERT_TRUE(hi);
  auto K = [&](const Vec3& x) {
    const Vec3 sv = signed_singular_values(b.cert.basis().map_jet(b.y, x, 1).J);
    return sv(0) / sv(2);
  };
  const double k_hi = K(hi->center);
  // A probe a quarter of a voxel side from `hi` along an axis (the search's first step from it reaches
  // `hi`), inside the voxels, with σ1/σ3 below k_hi: the largest such.
  const VoxelLocator locate(s.sampling);
  const VecXi vhi = locate.find(hi->center.transpose());
  ASSERT_GE(vhi(0), 0);
  const double h = s.sampling.side_of(vhi(0)) / 4;
  Vec3 probe = hi->center;
  double k_probe = 0;
  for (int j = 0; j < 6; ++j) {
    Vec3 x = hi->center;
    x(j / 2) += j % 2 ? -h : h;
    const VecXi vx = locate.find(x.transpose());
    if (vx(0) >= 0 && s.sampling.side_of(vx(0)) == 4 * h && K(x) < k_hi && K(x) > k_probe)
      probe = x, k_probe = K(x);
  }
  ASSERT_GT(k_probe, 0) << "no probe position next to the largest distortion";
  CertifyParams q = b.p;
  q.stop_on_failure = true;
  q.max_distortion = std::max(1.0, 0.5 * (k_probe + k_hi));
  ASSERT_GT(k_probe, 0.98 * q.max_distortion) << "the probe is not within 2% of the target";
  q.distortion_probes = {probe};
  const Certificate quick = b.cert.certify(b.y, q);
  EXPECT_FALSE(quick.certified);
  EXPECT_EQ(quick.distortion_failed_on, DistortionTarget::kDistortion);
  EXPECT_EQ(quick.num_leaves, 0) << "the search refused before evaluating the voxels";
  ASSERT_EQ(quick.failing.size(), 1u);
  const Vec3 at = quick.failing.front().center;
  EXPECT_NE(at, probe) << "the probe itself proves nothing";
  EXPECT_LE((at - probe).norm(), 4 * h) << "found near the probe";
  EXPECT_GT(K(at), q.max_distortion) << "the refusal names a point beyond the target";
  EXPECT_GE(locate.find(at.transpose())(0), 0) << "a point of the domain";
  EXPECT_EQ(quick.reason, q.targets().reason(DistortionTarget::kDistortion, at));
  // distortion_refuted (the same map in the subspace, through the reduced certifier): the probe alone proves
  // nothing; asked to search, the same refusal before any voxel.
  {
    const OctreeCertifier red(s.cage, s.sampling, &s.sub.basis);
    const MatR yr = s.sub.basis.transpose() * b.y;
    ASSERT_LT((s.sub.basis * yr - b.y).norm(), 1e-9 * b.y.norm()) << "the bent map lies in the subspace";
    Certificate alone, searched;
    EXPECT_FALSE(red.distortion_refuted(yr, q, alone));
    ASSERT_TRUE(red.distortion_refuted(yr, q, searched, /*search=*/true));
    EXPECT_FALSE(searched.certified);
    ASSERT_EQ(searched.failing.size(), 1u);
    EXPECT_GT(K(searched.failing.front().center), q.max_distortion);
    EXPECT_LE((searched.failing.front().center - probe).norm(), 4 * h);
    EXPECT_EQ(searched.num_leaves, 0);
  }
  q.distortion_probes.clear();
  const Certificate full = b.cert.certify(b.y, q);
  EXPECT_FALSE(full.certified) << "the full certificate refuses it too";
  EXPECT_TRUE(full.distortion_failed);

  // A target above the sampled maximum (leaves up to depth 6), with a probe at the largest σ1/σ3 sampled on a
  // grid in the cells of the leaves near it: the search runs, finds nothing, and the verdict and leaves are
  // those of the certificate without probes.
  const double sampled = check_against_sampling(b.cert.basis(), b.y, b.c0);
  Vec3 top = hi->center;
  double k_top = k_hi;
  for (const CertLeaf& l : b.c0.leaves) {
    if (!(l.sigma3 > 0) || l.sigma1 / l.sigma3 < 0.9 * k_hi) continue;
    for (int g = 0; g < 64; ++g) {
      const Vec3 x = l.center + l.side * (Vec3(g % 4, g / 4 % 4, g / 16) / 3 - Vec3::Constant(0.5));
      if (K(x) > k_top && locate.find(x.transpose())(0) >= 0) top = x, k_top = K(x);
    }
  }
  q.max_distortion = std::max(1.015 * k_top, 1.005 * sampled);
  q.max_depth = 6;
  ASSERT_GT(k_top, 0.98 * q.max_distortion) << "the probe is within 2% of the target: the search runs";
  const Certificate plain = b.cert.certify(b.y, q);
  q.distortion_probes = {top};
  const Certificate searched = b.cert.certify(b.y, q);
  ASSERT_TRUE(plain.certified) << plain.reason;
  ASSERT_TRUE(searched.certified) << searched.reason;
  EXPECT_EQ(searched.max_distortion_upper_bound, plain.max_distortion_upper_bound);
  EXPECT_EQ(searched.num_leaves, plain.num_leaves);
}

// distortion_refuted: the probes alone, as certify_reduced judges them, and nothing else — a refusal only
// with a proof (the same refusal as certify_reduced's), no search near the probes, no voxel, no answer
// otherwise.
TEST(DistortionBound, ProbesAloneRefuteOnlyWithAProof) {
  const Sphere& s = sphere();
  const OctreeCertifier red(s.cage, s.sampling, &s.sub.basis);
  const Eigen::Matrix<double, Eigen::Dynamic, 3> yr =
      s.sub.basis.transpose() * lidef::test::smooth_map(s.cage, s.sub, 0.9, 12);
  CertifyParams p;
  p.max_depth = 3;
  const Certificate c0 = red.certify_reduced(yr, p);
  ASSERT_TRUE(c0.certified) << c0.reason;
  const auto [hi, lo] = extreme_leaves(c0);
  ASSERT_TRUE(hi && lo);
  CertifyParams q = p;
  q.stop_on_failure = true;
  q.max_distortion = std::max(1.0, 0.99 * hi->sigma1 / hi->sigma3);
  ASSERT_LT(lo->sigma1 / lo->sigma3, 0.9 * q.max_distortion);
  q.distortion_probes = {lo->center, hi->center};
  Certificate refusal;
  ASSERT_TRUE(red.distortion_refuted(yr, q, refusal));
  const Certificate full = red.certify_reduced(yr, q);
  EXPECT_FALSE(refusal.certified);
  EXPECT_EQ(refusal.reason, full.reason);
  EXPECT_EQ(refusal.reason, q.targets().reason(DistortionTarget::kDistortion, hi->center));
  EXPECT_EQ(refusal.distortion_failed_on, full.distortion_failed_on);
  ASSERT_EQ(refusal.failing.size(), 1u);
  EXPECT_EQ(refusal.failing.front().center, hi->center);
  EXPECT_EQ(refusal.failed_voxels, full.failed_voxels);
  EXPECT_EQ(refusal.num_leaves, 0);

  // A probe below the target decides nothing, although the map is refused (the full certificate fails).
  q.distortion_probes = {lo->center};
  Certificate untouched;
  untouched.reason = "unchanged";
  EXPECT_FALSE(red.distortion_refuted(yr, q, untouched));
  EXPECT_EQ(untouched.reason, "unchanged");
  EXPECT_FALSE(red.certify_reduced(yr, q).certified);
  // Outside a line search, without probes or without a target: nothing to judge.
  q.distortion_probes = {hi->center};
  q.stop_on_failure = false;
  EXPECT_FALSE(red.distortion_refuted(yr, q, untouched));
  q.stop_on_failure = true;
  q.max_distortion = 0;
  EXPECT_FALSE(red.distortion_refuted(yr, q, untouched));
  q.max_distortion = 1.01;
  q.distortion_probes.clear();
  EXPECT_FALSE(red.distortion_refuted(yr, q, untouched));
  // Reduced coefficients of another size are refused with a clear error.
  q.distortion_probes = {hi->center};
  EXPECT_THROW(red.distortion_refuted(yr.topRows(yr.rows() - 1), q, untouched), InputError);
}

// The line search's distortion stage refines the voxels most likely to fail first (priority voxels, probes,
// leaves within 0.5% of a target): a provable target gives the same leaves, in the same order, as one pass
// over all leaves (a report, stop_on_failure off); an unprovable one is refused with no more refinement than
// the full pass, naming a leaf of the first phase.
TEST(DistortionBound, CriticalVoxelsFirstChangeNeitherLeavesNorVerdict) {
  const BentMap& b = bent_map();
  ASSERT_TRUE(b.c0.certified) << b.c0.reason;
  const double sampled = check_against_sampling(b.cert.basis(), b.y, b.c0);
  const double bound0 = b.c0.max_distortion_upper_bound;
  CertifyParams report = b.p;
  report.max_distortion = sampled + 0.3 * (bound0 - sampled);
  CertifyParams search = report;
  search.stop_on_failure = true;
  search.priority_voxels = {0, 7, static_cast<long>(b.c0.leaves.back().base)};
  search.distortion_probes = {b.c0.leaves[b.c0.leaves.size() / 2].center};
  const Certificate full = b.cert.certify(b.y, report);
  const Certificate phased = b.cert.certify(b.y, search);
  ASSERT_TRUE(full.certified) << full.reason;
  ASSERT_TRUE(phased.certified) << phased.reason;
  ASSERT_EQ(phased.leaves.size(), full.leaves.size());
  for (size_t i = 0; i < full.leaves.size(); ++i) {
    EXPECT_EQ(phased.leaves[i].center, full.leaves[i].center) << i;
    EXPECT_EQ(phased.leaves[i].side, full.leaves[i].side) << i;
    EXPECT_EQ(phased.leaves[i].distortion_upper, full.leaves[i].distortion_upper) << i;
    EXPECT_EQ(phased.leaves[i].margin, full.leaves[i].margin) << i;
  }
  EXPECT_EQ(phased.max_distortion_upper_bound, full.max_distortion_upper_bound);
  EXPECT_EQ(phased.refined, full.refined);

  // Just above the largest value at a leaf center: the proof near that center would need leaves far below
  // the depth limit, so the map is refused either way; the phased stage refines that voxel in its first
  // phase, refines less than the full pass and names a voxel of the first phase.
  double kmax = 0;
  for (const CertLeaf& l : b.c0.leaves)
    if (l.sigma3 > 0) kmax = std::max(kmax, l.sigma1 / l.sigma3);
  report.max_distortion = search.max_distortion = std::max(1.0, 1.0005 * kmax);
  search.distortion_probes.clear();
  search.priority_voxels.clear();
  const Certificate full_no = b.cert.certify(b.y, report);
  const Certificate phased_no = b.cert.certify(b.y, search);
  EXPECT_FALSE(full_no.certified);
  EXPECT_FALSE(phased_no.certified);
  EXPECT_TRUE(phased_no.distortion_failed);
  EXPECT_LT(phased_no.refined, full_no.refined);
  ASSERT_FALSE(phased_no.failing.empty());
  bool critical = false;
  for (const CertLeaf& l : b.c0.leaves)
    if (l.base == phased_no.failing.front().base && l.sigma3 > 0 &&
        l.sigma1 / l.sigma3 > 0.995 * search.max_distortion)
      critical = true;
  EXPECT_TRUE(critical) << "the refused trial names a voxel outside its first phase";
  std::printf("refused: %ld nodes refined in phases, %ld in one pass\n", phased_no.refined, full_no.refined);
}

TEST(DistortionBound, IntervalReproofConfirmsEveryCertifiedLeafAndRefusesATamperedOne) {
  BallParams bp;
  bp.cage_subdivisions = 1;
  bp.mesh_subdivisions = 2;
  const Model model = make_ball(bp);
  SamplingParams sp;
  sp.target_count = 300;
  sp.count_tolerance = 0.2;
  const VoxelSampling samp = sample_voxels(model.cage, sp);
  MatX3d y = lidef::test::perturbed_map(model.cage, 0.01, 9);
  y.col(1) *= 0.7;
  for (LipschitzBound b : {LipschitzBound::kThirdOrder, LipschitzBound::kSpectral}) {
    CertifyParams cp;
    cp.bound = b;
    const Certificate cert = certify_map(model.cage, samp, y, cp);
    ASSERT_TRUE(cert.certified) << cert.reason;
    const IntervalVerification v = verify_certificate_intervals(model.cage, y, cert.leaves, b);
    EXPECT_EQ(v.distortion_not_proven, 0) << to_string(b);
    EXPECT_EQ(v.distortion_proven, cert.num_leaves);
    EXPECT_LE(v.max_distortion_hi, cert.max_distortion_upper_bound);
    EXPECT_GE(v.max_distortion_hi, 1 / 0.7 * 0.9);  // the map's K is about 1/0.7
    // A leaf claiming a K below the one at its own center (false) is refused.
    std::vector<CertLeaf> tampered = cert.leaves;
    tampered[0].distortion_upper = 0.999 * tampered[0].sigma1 / tampered[0].sigma3;
    const IntervalVerification t = verify_certificate_intervals(model.cage, y, tampered, b);
    EXPECT_EQ(t.distortion_not_proven, 1);
  }
  // Under a target the leaves whose Lipschitz bounds do not prove it carry the Taylor bounds of Step 3d
  // (third-order sums): the intervals re-prove them too, and they are tighter than the quotient's.
  CertifyParams cp;
  const Certificate free = certify_map(model.cage, samp, y, cp);
  cp.max_distortion = 0.6 * free.max_distortion_upper_bound;
  const Certificate cert = certify_map(model.cage, samp, y, cp);
  ASSERT_TRUE(cert.certified) << cert.reason;
  EXPECT_LT(cert.max_distortion_upper_bound, free.max_distortion_upper_bound);
  // The same target with the Lipschitz bounds alone needs more refinement (or is not proven at all).
  CertifyParams lipschitz_only = cp;
  lipschitz_only.taylor_bounds = false;
  const Certificate quotient = certify_map(model.cage, samp, y, lipschitz_only);
  EXPECT_TRUE(!quotient.certified || quotient.refined > cert.refined)
      << quotient.refined << " vs " << cert.refined;
  const IntervalVerification v = verify_certificate_intervals(model.cage, y, cert.leaves, cp.bound);
  EXPECT_EQ(v.not_proven, 0);
  EXPECT_EQ(v.distortion_not_proven, 0);
  EXPECT_EQ(v.distortion_proven, cert.num_leaves);
  const HarmonicBasis basis(model.cage);
  const VerificationResult dense = verify_certificate(basis, y, cert.leaves, 16, 3);
  EXPECT_EQ(dense.distortion_violations, 0);
  std::printf(
      "K bound without / with the Taylor bounds %.6g / %.6g, sampled %.6g; refined %ld (Lipschitz "
      "bounds alone: %ld, %s)\n",
      free.max_distortion_upper_bound, cert.max_distortion_upper_bound, dense.max_distortion, cert.refined,
      quotient.refined, quotient.certified ? "certified" : "not certified");
}

TEST(DistortionBound, VoxelsCsvCarriesTheBoundsAndOlderFilesAreRead) {
  const Sphere& s = sphere();
  const MatX3d y = lidef::test::smooth_map(s.cage, s.sub, 0.45, 11);
  CertifyParams p;
  p.max_depth = 2;
  const Certificate c = certify_map(s.cage, s.sampling, y, p);
  TempDir tmp;
  const std::string path = tmp / "voxels.csv";
  { std::ofstream(path) << voxels_csv(c.leaves); }
  const std::vector<CertLeaf> back = read_voxels_csv(path);
  ASSERT_EQ(back.size(), c.leaves.size());
  for (size_t i = 0; i < back.size(); ++i) {
    EXPECT_EQ(back[i].sigma1_upper, c.leaves[i].sigma1_upper);
    EXPECT_EQ(back[i].distortion_upper, c.leaves[i].distortion_upper);
  }
  // The previous layout (10 columns): read, with no distortion bound (+∞).
  {
    std::ofstream(path) << "cx,cy,cz,side,depth,sigma3,L,margin,certified,sigma3_error\n"
                        << "0,0,0,0.1,0,1,0.5,0.9,1,0\n";
  }
  const std::vector<CertLeaf> old = read_voxels_csv(path);
  ASSERT_EQ(old.size(), 1u);
  EXPECT_EQ(old[0].distortion_upper, kInf);
  // A negative bound is refused, naming the file.
  {
    std::ofstream(path) << voxels_csv_header() << "\n"
                        << "0,0,0,0.1,0,1,0.5,0.9,1,0,1,-1,2\n";
  }
  EXPECT_THROW(read_voxels_csv(path), InputError);
}

namespace {

// `lidef deform` of beam_bend at the tests' small sampling (4000 voxels, 60 coefficients), `lidef verify`,
// and the JSON files they write, in a temporary folder.
class DistortionCli : public ::testing::Test {
 protected:
  // Before any fixture's TempDir draws its name: processes running side by side draw different names.
  static void SetUpTestSuite() { std::srand(static_cast<unsigned>(::getpid()) * 2654435761u); }
  static std::string q(const std::string& x) { return "'" + x + "'"; }
  static int run(const std::string& args, std::string* output) {
    output->clear();
    return lidef::test::run_command(q(lidef::test::cli()) + " " + args, output);
  }
  int deform(const std::string& out, const std::string& extra, std::string* output) const {
    return run("deform " + q(scenario) + " --out " + q(out) + " --quiet --cache-dir " + q(tmp / "cache") +
                   " --samples 4000 --reduced-dof 60 " + extra,
               output);
  }
  // `lidef verify` of the map written into `dir` (coefficients.txt, certificate.json), with `extra` options.
  int verify(const std::string& dir, const std::string& extra, std::string* output) const {
    return run("verify " + q(model) + " --coeffs " + q(dir + "/coefficients.txt") + " --certificate " +
                   q(dir + "/certificate.json") + " " + extra,
               output);
  }
  static nlohmann::json read_json(const std::string& path) {
    std::ifstream in(path);
    return nlohmann::json::parse(in);
  }
  TempDir tmp;
  const std::string scenario = lidef::test::project_data() + "/scenarios/beam_bend.json";
  const std::string model = lidef::test::project_data() + "/models/beam";
};

}  // namespace

// beam_bend, unconstrained and at a K below the unconstrained map's sampled maximum: the constrained map is
// certified with max_distortion_upper_bound <= K, and `lidef verify` samples it without a violation.
TEST_F(DistortionCli, ConstrainedBeamBendIsCertifiedBelowTheTargetAndSamplingAgrees) {
  std::string output;
  ASSERT_EQ(deform(tmp / "free", "", &output), 0) << output;
  const nlohmann::json free = read_json(tmp / "free/summary.json");
  const double k_free = free["max_distortion_vertices"].get<double>();
  const double k_free_bound = free["max_distortion_upper_bound"].get<double>();
  EXPECT_GE(k_free_bound, k_free);
  ASSERT_GT(k_free, 1.05) << "beam_bend should distort the beam";
  const std::string k_text = format_double(1 + 0.8 * (k_free - 1));  // shortest round trip: K is exact
  const double K = std::stod(k_text);

  // A few iterations of the direct solve suffice for the claim (every accepted map satisfies the bound): the
  // whole run, blocked after the continuation's strategies, takes minutes (docs/benchmarks.md, "Bounded
  // distortion").
  const int rc =
      deform(tmp / "k", "--max-distortion " + k_text + " --max-iterations 3 --continuation false", &output);
  EXPECT_TRUE(rc == 0 || rc == 1) << output;  // reached (0) or stopped short by the bound (1)
  const nlohmann::json s = read_json(tmp / "k/summary.json");
  EXPECT_EQ(s["certified"], true) << output;
  EXPECT_LE(s["max_distortion_upper_bound"].get<double>(), K);
  EXPECT_LE(s["max_distortion_vertices"].get<double>(), K);
  EXPECT_EQ(s["parameters"]["max_distortion"].get<double>(), K);
  const nlohmann::json c = read_json(tmp / "k/certificate.json");
  EXPECT_EQ(c["distortion_met"], true);
  EXPECT_LE(c["max_distortion_upper_bound"].get<double>(), K);
  if (s["stop_reason"] == "blocked_by_certificate" || s["stop_reason"] == "no_certified_step") {
    EXPECT_NE(s["message"].get<std::string>().find("distortion bound"), std::string::npos) << s["message"];
  }

  ASSERT_EQ(verify(tmp / "k", "--samples-per-voxel 8 --out " + q(tmp / "verify"), &output), 0) << output;
  EXPECT_NE(output.find("samples above their leaf's bounds 0"), std::string::npos) << output;
}

// beam_bend under the isometric targets: max_sigma1 and min_sigma3 between the rest state and the
// unconstrained map's sampled extremes. The written map is certified with σ1 ≤ S and σ3 ≥ s on every leaf,
// the mesh vertices agree, `lidef verify` finds every sample within the targets and `--interval` re-proves
// them on every leaf.
TEST_F(DistortionCli, IsometricTargetsHoldOnTheWrittenMapAndVerifyAgrees) {
  std::string output;
  ASSERT_EQ(deform(tmp / "free", "", &output), 0) << output;
  const nlohmann::json free = read_json(tmp / "free/summary.json");
  const double s1_free = free["max_sigma1_vertices"].get<double>();
  const double s3_free = free["min_sigma3_vertices"].get<double>();
  ASSERT_GT(s1_free, 1.05) << "beam_bend should stretch the beam";
  ASSERT_LT(s3_free, 0.95) << "beam_bend should compress the beam";
  const std::string s1_text = format_double(1 + 0.8 * (s1_free - 1));
  const std::string s3_text = format_double(1 - 0.8 * (1 - s3_free));
  const double S = std::stod(s1_text), s = std::stod(s3_text);

  const int rc = deform(
      tmp / "iso",
      "--max-sigma1 " + s1_text + " --min-sigma3 " + s3_text + " --max-iterations 3 --continuation false",
      &output);
  EXPECT_TRUE(rc == 0 || rc == 1) << output;
  const nlohmann::json sum = read_json(tmp / "iso/summary.json");
  EXPECT_EQ(sum["certified"], true) << output;
  EXPECT_NE(output.find("distortion targets (max_sigma1 " + format_g(S) + ", min_sigma3 " + format_g(s) +
                        ") proven: sigma1 <= "),
            std::string::npos)
      << output;
  EXPECT_EQ(sum["max_sigma1"].get<double>(), S);
  EXPECT_EQ(sum["min_sigma3"].get<double>(), s);
  EXPECT_LE(sum["max_sigma1_upper_bound"].get<double>(), S);
  EXPECT_GE(sum["min_sigma3_lower_bound"].get<double>(), s);
  EXPECT_LE(sum["max_sigma1_vertices"].get<double>(), S);
  EXPECT_GE(sum["min_sigma3_vertices"].get<double>(), s);
  const nlohmann::json c = read_json(tmp / "iso/certificate.json");
  EXPECT_EQ(c["distortion_met"], true);
  EXPECT_EQ(c["max_sigma1"].get<double>(), S);
  EXPECT_EQ(c["min_sigma3"].get<double>(), s);
  EXPECT_GE(c["min_lower_bound"].get<double>(), s);
  if (sum["stop_reason"] == "blocked_by_certificate" || sum["stop_reason"] == "no_certified_step") {
    EXPECT_NE(sum["message"].get<std::string>().find("distortion bound"), std::string::npos)
        << sum["message"];
  }

  ASSERT_EQ(verify(tmp / "iso", "--samples-per-voxel 8 --out " + q(tmp / "verify"), &output), 0) << output;
  EXPECT_NE(output.find("proven by the certificate; every sample within them"), std::string::npos) << output;
  ASSERT_EQ(verify(tmp / "iso", "--interval --out " + q(tmp / "interval"), &output), 0) << output;
  const nlohmann::json iv = read_json(tmp / "interval/interval.json");
  EXPECT_EQ(iv["distortion_targets_not_proven"], 0);
  EXPECT_EQ(iv["distortion_targets"], "max_sigma1 " + format_g(S) + ", min_sigma3 " + format_g(s));

  // A certificate that claims a σ1 target its map does not meet: both checks refuse it.
  nlohmann::json tampered = c;
  tampered["max_sigma1"] = 1.0;
  { std::ofstream(tmp / "iso/certificate.json") << tampered.dump(2); }
  EXPECT_EQ(verify(tmp / "iso", "--samples-per-voxel 2 --out " + q(tmp / "verify2"), &output), 1) << output;
  EXPECT_NE(output.find("a sample beyond them: the claim is WRONG"), std::string::npos) << output;
  EXPECT_EQ(verify(tmp / "iso", "--interval --out " + q(tmp / "interval2"), &output), 1) << output;
  EXPECT_GT(read_json(tmp / "interval2/interval.json")["distortion_targets_not_proven"].get<long>(), 0);
}
