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

#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/certificate_verification.h"
#include "lidef/analysis/interval_verification.h"
#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"
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
  const Sphere& s = sphere();
  OctreeCertifier cert(s.cage, s.sampling);
  const MatX3d y = lidef::test::smooth_map(s.cage, s.sub, 0.9, 12);
  CertifyParams p;
  p.max_depth = 3;
  const Certificate c0 = cert.certify(y, p);
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

  // A target below 1 is refused as a parameter.
  DeformParams dp;
  dp.max_distortion = 0.5;
  EXPECT_THROW(validate_params(dp, "test"), InputError);
  dp.max_distortion = 1.5;
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
  const CertLeaf* hi = nullptr;
  const CertLeaf* lo = nullptr;
  for (const CertLeaf& l : c0.leaves) {
    if (!(l.sigma3 > 0) || !std::isfinite(l.sigma1)) continue;
    if (!hi || l.sigma1 / l.sigma3 > hi->sigma1 / hi->sigma3) hi = &l;
    if (!lo || l.sigma1 / l.sigma3 < lo->sigma1 / lo->sigma3) lo = &l;
  }
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
  EXPECT_EQ(quick.reason, distortion_reason(q.max_distortion, hi->center));
  ASSERT_EQ(quick.failing.size(), 1u);
  EXPECT_EQ(quick.failing.front().center, hi->center);
  EXPECT_EQ(quick.num_leaves, 0) << "the probe refused before evaluating the voxels";

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
    // A leaf claiming a smaller K than the intervals prove is refused.
    std::vector<CertLeaf> tampered = cert.leaves;
    tampered[0].distortion_upper = 0.999 * v.results[0].distortion_hi;
    const IntervalVerification t = verify_certificate_intervals(model.cage, y, tampered, b);
    EXPECT_EQ(t.distortion_not_proven, 1);
  }
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

// beam_bend, unconstrained and at a K below the unconstrained map's sampled maximum: the constrained map is
// certified with max_distortion_upper_bound <= K, and `lidef verify` samples it without a violation.
TEST(DistortionCli, ConstrainedBeamBendIsCertifiedBelowTheTargetAndSamplingAgrees) {
  std::srand(static_cast<unsigned>(::getpid()) * 2654435761u);
  TempDir tmp;
  const std::string scenario = lidef::test::project_data() + "/scenarios/beam_bend.json";
  const std::string model = lidef::test::project_data() + "/models/beam";
  auto q = [](const std::string& x) { return "'" + x + "'"; };
  auto deform = [&](const std::string& out, const std::string& extra, std::string* output) {
    return lidef::test::run_command(q(lidef::test::cli()) + " deform " + q(scenario) + " --out " + q(out) +
                                        " --quiet --cache-dir " + q(tmp / "cache") +
                                        " --samples 4000 --reduced-dof 60 " + extra,
                                    output);
  };
  auto read_json = [](const std::string& path) {
    std::ifstream in(path);
    return nlohmann::json::parse(in);
  };
  std::string output;
  ASSERT_EQ(deform(tmp / "free", "", &output), 0) << output;
  const nlohmann::json free = read_json(tmp / "free/summary.json");
  const double k_free = free["max_distortion_vertices"].get<double>();
  const double k_free_bound = free["max_distortion_upper_bound"].get<double>();
  EXPECT_GE(k_free_bound, k_free);
  ASSERT_GT(k_free, 1.05) << "beam_bend should distort the beam";
  const std::string k_text = format_double(1 + 0.8 * (k_free - 1));  // shortest round trip: K is exact
  const double K = std::stod(k_text);

  output.clear();
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

  output.clear();
  ASSERT_EQ(lidef::test::run_command(q(lidef::test::cli()) + " verify " + q(model) + " --coeffs " +
                                         q(tmp / "k/coefficients.txt") + " --certificate " +
                                         q(tmp / "k/certificate.json") + " --samples-per-voxel 8 --out " +
                                         q(tmp / "verify"),
                                     &output),
            0)
      << output;
  EXPECT_NE(output.find("samples above their leaf's bounds 0"), std::string::npos) << output;
}
