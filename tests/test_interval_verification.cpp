// The interval re-proof of a certificate (analysis/include/lidef/analysis/interval_verification.h, `lidef
// verify
// --interval`). Truths: the double-precision basis derivatives and central differences of the map (the
// enclosures must contain them and be tight); matrices built as U diag(s) Vᵀ with known singular values
// (the σ3 bound must stay below s3, and near it when well conditioned); the certifier's verdicts on small
// procedural models (every certified leaf must be proven); tampered leaves (must not be proven); the CLI's
// exit codes, a table cut short (its leaves proven, their coverage not) and a certificate that says "not
// certified" (never PROVEN). IntervalSlow.*: the certificates of every shared scenario's output (label
// "slow").
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "lidef/analysis/interval_verification.h"
#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/green_coordinates.h"
#include "lidef/hash.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"
#include "test_cages.h"
#include "test_support.h"

using namespace lidef;
using lidef::test::TempDir;

namespace {

Mat3 random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> N01;
  Mat3 A;
  for (int i = 0; i < 9; ++i) A(i / 3, i % 3) = N01(rng);
  Eigen::HouseholderQR<Mat3> qr(A);
  Mat3 Q = qr.householderQ();
  if (Q.determinant() < 0) Q.col(0) *= -1;
  return Q;
}

// A mildly bent map of the cage: identity plus a smooth displacement of the vertex coefficients.
MatX3d mild_bend(const Cage& cage, double amp) {
  MatX3d y = cage.identity_coefficients();
  const double size = (cage.bbox_max - cage.bbox_min).norm();
  for (int v = 0; v < cage.num_vertices(); ++v) {
    const Vec3 p = cage.V.row(v).transpose() / size;
    y.row(v) += amp * size * Vec3(std::sin(2 * p.y()), std::sin(2 * p.z()), std::cos(2 * p.x())).transpose();
  }
  return y;
}

std::string quote(const std::string& s) {
  return "'" + s + "'";
}
int run_lidef(const std::string& args, std::string* output) {
  return lidef::test::run_command(quote(lidef::test::cli()) + " " + args, output);
}
nlohmann::json read_json(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot open " << path;
  return nlohmann::json::parse(in);
}

}  // namespace

TEST(IntervalVerification, JetEnclosureContainsDoubleJetAndFiniteDifferences) {
  const Cage cage(lidef::test::icosphere(2, 0.2));
  const HarmonicBasis basis(cage);
  std::mt19937 rng(11);
  std::normal_distribution<double> N01;
  MatX3d y = cage.identity_coefficients();
  for (int i = 0; i < y.rows(); ++i) y.row(i) += 0.1 * Vec3(N01(rng), N01(rng), N01(rng)).transpose();
  const IntervalVerifier iv(cage, y, LipschitzBound::kThirdOrder);
  const MatX3d P = lidef::test::interior_points(cage, 20, 0.1);
  double max_width = 0;
  for (int i = 0; i < P.rows(); ++i) {
    const Vec3 p = P.row(i).transpose();
    const JetEnclosure e = iv.jet(p);
    const MapJet d = basis.map_jet(y, p, 2);
    const double sJ = d.J.cwiseAbs().maxCoeff(), sH = std::max(1.0, d.hessian_norm());
    // The double jet carries its own rounding (~1e-15 relative): containment up to that.
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        EXPECT_LE(e.J_lo(a, b), d.J(a, b) + 1e-13 * sJ);
        EXPECT_GE(e.J_hi(a, b), d.J(a, b) - 1e-13 * sJ);
        max_width = std::max(max_width, (e.J_hi(a, b) - e.J_lo(a, b)) / sJ);
        for (int c = 0; c < 3; ++c) {
          EXPECT_LE(e.H_lo[a](b, c), d.H[a](b, c) + 1e-12 * sH);
          EXPECT_GE(e.H_hi[a](b, c), d.H[a](b, c) - 1e-12 * sH);
        }
      }
    EXPECT_GE(e.hessian_norm_hi, d.hessian_norm() * (1 - 1e-12));
    EXPECT_LE(e.hessian_norm_hi, d.hessian_norm() * (1 + 1e-9) + 1e-12);
    // Central differences: of f for J, of the double J for H (both independent of the interval code).
    const double h = 1e-5;
    for (int b = 0; b < 3; ++b) {
      const Vec3 hp = p + h * Vec3::Unit(b), hm = p - h * Vec3::Unit(b);
      const Vec3 fd = (basis.map_jet(y, hp, 0).f - basis.map_jet(y, hm, 0).f) / (2 * h);
      const Mat3 fdJ = (basis.map_jet(y, hp, 1).J - basis.map_jet(y, hm, 1).J) / (2 * h);
      for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(0.5 * (e.J_lo(a, b) + e.J_hi(a, b)), fd(a), 1e-7 * sJ);
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(0.5 * (e.H_lo[a](c, b) + e.H_hi[a](c, b)), fdJ(a, c), 1e-6 * sH);
      }
    }
  }
  // Tight enough to prove anything: the enclosures are a few hundred ulps wide, not a loose box.
  EXPECT_LT(max_width, 1e-12);
  EXPECT_GT(max_width, 0.0);
}

TEST(IntervalVerification, Sigma3LowerBoundIsBelowTrueSigma3) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(0.1, 3.0);
  int tight = 0, cases = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const Mat3 Uq = random_rotation(rng), Vq = random_rotation(rng);
    Vec3 s(U(rng), U(rng), U(rng));
    std::sort(s.data(), s.data() + 3, std::greater<double>());
    // Nearly singular ones too: s3 down to 1e-12 s1, and negative determinants.
    if (trial % 4 == 1) s(2) = s(0) * std::pow(10.0, -1 - (trial % 12));
    if (trial % 4 == 3) s(2) = -s(2);
    const Mat3 J = Uq * s.asDiagonal() * Vq.transpose();
    // The matrix as a box a few ulps wide (the true singular values of the rounded J differ from s by
    // ~1e-16 s1; `slack` covers that).
    const double eps = 1e-15 * s(0);
    const Mat3 lo = J.array() - eps, hi = J.array() + eps;
    const double bound = sigma3_lower_bound(lo, hi);
    const double slack = 5e-15 * s(0);
    ASSERT_LE(bound, s(2) + slack) << "trial " << trial << " s " << s.transpose();
    // Every matrix of the box has σ3 ≥ bound (corners and random points, σ3 by the signed SVD).
    std::uniform_real_distribution<double> W(-1, 1);
    for (int k = 0; k < 20; ++k) {
      Mat3 M = J;
      for (int i = 0; i < 9; ++i) M(i / 3, i % 3) += eps * W(rng);
      ASSERT_LE(bound, signed_singular_values(M)(2) + slack);
    }
    if (s(2) > 1e-3 * s(0)) {
      ++cases;
      tight += bound > s(2) * (1 - 1e-6);
    }
    if (s(2) < 0) {
      EXPECT_LT(bound, 0.0);
    }
  }
  // Well-conditioned matrices get (nearly) their σ3, not the |det|/‖cof‖ bound (up to √3 smaller).
  EXPECT_EQ(tight, cases);
  // A box containing a singular matrix cannot have a positive bound.
  Mat3 S = Mat3::Identity();
  S(2, 2) = 0;
  EXPECT_LE(sigma3_lower_bound(S.array() - 1e-12, S.array() + 1e-12), 0.0);
  // An unbounded or empty box has no bound.
  Mat3 inf_hi = Mat3::Identity();
  inf_hi(0, 1) = std::numeric_limits<double>::infinity();
  EXPECT_EQ(sigma3_lower_bound(Mat3::Identity(), inf_hi), -std::numeric_limits<double>::infinity());
  EXPECT_EQ(sigma3_lower_bound(Mat3::Identity(), Mat3::Zero()), -std::numeric_limits<double>::infinity());
}

// A certified small procedural model: every certified leaf is proven, for both bounds, for the identity and
// for a mild non-affine deformation that needs refinement.
TEST(IntervalVerification, CertifiedLeavesOfProceduralModelsAreProven) {
  BallParams bp;
  bp.cage_subdivisions = 1;
  bp.mesh_subdivisions = 2;
  const Model model = make_ball(bp);
  SamplingParams sp;
  sp.target_count = 300;
  sp.count_tolerance = 0.2;
  const VoxelSampling samp = sample_voxels(model.cage, sp);
  const HarmonicBasis basis(model.cage);
  long refined = 0;
  for (const MatX3d& y : {model.cage.identity_coefficients(), mild_bend(model.cage, 0.15)}) {
    for (LipschitzBound b : {LipschitzBound::kThirdOrder, LipschitzBound::kFirstOrder,
                             LipschitzBound::kCombined, LipschitzBound::kSpectral}) {
      CertifyParams cp;
      cp.bound = b;
      const Certificate cert = certify_map(model.cage, samp, y, cp);
      ASSERT_TRUE(cert.certified) << cert.reason;
      std::cout << to_string(b) << ": " << cert.num_leaves << " leaves, " << cert.refined << " refined\n";
      refined += cert.refined;
      const IntervalVerification v = verify_certificate_intervals(model.cage, y, cert.leaves, b);
      EXPECT_EQ(v.proven, cert.num_leaves) << to_string(b);
      EXPECT_EQ(v.not_proven, 0);
      EXPECT_GT(v.worst_slack, 0.0);
      for (size_t q = 0; q < v.results.size(); ++q) {
        const CertLeaf& l = cert.leaves[v.leaf_index[q]];
        const IntervalLeaf& r = v.results[q];
        // σ3 from below, and tightly: against σ3 of the double-precision jet at the center (the certificate's
        // own σ3 may come from float-stored derivatives, ~1e-7 off). L from above the certificate's (whose
        // factors are rounded up to floats, ~1e-7 larger).
        const double s3 = signed_singular_values(basis.map_jet(y, l.center, 1).J)(2);
        EXPECT_LE(r.sigma3_lo, s3 + 1e-13 * (1 + std::abs(s3)));
        EXPECT_GE(r.sigma3_lo, s3 - 1e-11 * (1 + std::abs(s3)));
        if (b == LipschitzBound::kThirdOrder) {
          EXPECT_GE(r.L_hi, basis.map_jet(y, l.center, 2).hessian_norm());
        }
        // Both terms of the combined L are ≥ ‖H(c)‖_op (first order: max over the ball of ‖H‖_F).
        if (b == LipschitzBound::kCombined) {
          EXPECT_GE(r.L_hi, hessian_operator_norm(basis.map_jet(y, l.center, 2).H) * (1 - 1e-12));
        }
        EXPECT_LE(r.L_hi, l.L * (1 + 1e-6) + 1e-6);
        EXPECT_GE(r.radius_hi, 0.5 * std::sqrt(3.0) * l.side);
      }
    }
  }
  EXPECT_GT(refined, 0) << "the bent map should need refinement somewhere, or half the test proves little";
}

// The Taylor σ3 bound in intervals (Step 3c) does work: on a map with spread singular values (as in
// CombinedBound.CertificatesAreNoWeakerThan...), the interval re-proof of a spectral certificate proves a
// larger margin than the combined L alone on some leaves, never a smaller one, and never above the
// certificate's σ3 − rL.
TEST(IntervalVerification, SpectralTermRaisesTheProvenMargin) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  SamplingParams sp;
  sp.target_count = 600;
  sp.count_tolerance = 0.2;
  const VoxelSampling samp = sample_voxels(cage, sp);
  const MatX3d y = lidef::test::anisotropic_perturbed_map(cage, 0.02, 20);
  CertifyParams cp;
  cp.bound = LipschitzBound::kSpectral;
  cp.max_depth = 0;
  const Certificate cert = certify_map(cage, samp, y, cp);
  const IntervalVerification vs =
      verify_certificate_intervals(cage, y, cert.leaves, LipschitzBound::kSpectral);
  const IntervalVerification vc =
      verify_certificate_intervals(cage, y, cert.leaves, LipschitzBound::kCombined);
  ASSERT_EQ(vs.results.size(), vc.results.size());
  ASSERT_GT(vs.results.size(), 100u);
  const HarmonicBasis basis(cage);
  std::mt19937 rng(5);
  std::normal_distribution<double> N01;
  int raised = 0;
  for (size_t q = 0; q < vs.results.size(); ++q) {
    const double ms = vs.results[q].margin_lo, mc = vc.results[q].margin_lo;
    // The proven margin is a lower bound of σ3 on the whole ball: sampled points (half on its sphere).
    for (int k = 0; k < 16; ++k) {
      const Vec3 d = Vec3(N01(rng), N01(rng), N01(rng)).normalized();
      const Vec3 p = cert.leaves[vs.leaf_index[q]].center + vs.results[q].radius_hi * (k % 2 ? 1.0 : 0.5) * d;
      ASSERT_GE(signed_singular_values(basis.map_jet(y, p, 1).J)(2), ms) << "leaf " << q;
    }
    EXPECT_GE(ms, mc);
    const CertLeaf& l = cert.leaves[vs.leaf_index[q]];
    // The certificate's σ3 − rL (before τ), whose factors are rounded up to floats (~1e-7 larger).
    EXPECT_LE(ms, l.sigma3 - 0.5 * std::sqrt(3.0) * l.side * l.L * (1 - 1e-6) + 1e-9);
    raised += ms > mc + 1e-12;
  }
  EXPECT_EQ(vs.proven, static_cast<long>(vs.results.size()));
  std::cout << raised << " of " << vs.results.size()
            << " leaves: the spectral term raised the proven margin\n";
  EXPECT_GT(raised, 0);
}

// Leaves the certificate claims but that are false or unprovable are not proven.
TEST(IntervalVerification, TamperedLeavesAreNotProven) {
  BallParams bp;
  bp.cage_subdivisions = 1;
  bp.mesh_subdivisions = 2;
  const Model model = make_ball(bp);
  SamplingParams sp;
  sp.target_count = 200;
  sp.count_tolerance = 0.3;
  const VoxelSampling samp = sample_voxels(model.cage, sp);
  const MatX3d y = mild_bend(model.cage, 0.03);
  const Certificate cert = certify_map(model.cage, samp, y);
  ASSERT_TRUE(cert.certified) << cert.reason;
  std::vector<CertLeaf> leaves = cert.leaves;
  // 1. An enlarged side: the ball reaches the cage, or r·L outgrows σ3.
  leaves[0].side *= 8;
  // 2. A mirrored map (det J < 0 everywhere) with a leaf claimed certified: σ3 ≤ 0 at its center.
  const MatX3d mirror = model.cage.affine_coefficients(Vec3(-1, 1, 1).asDiagonal(), Vec3::Zero());
  const IntervalVerification v = verify_certificate_intervals(model.cage, y, leaves, cert.bound);
  EXPECT_EQ(v.not_proven, 1);
  ASSERT_FALSE(v.results[0].proven);
  EXPECT_EQ(v.leaf_index[0], 0);
  const IntervalVerification m = verify_certificate_intervals(model.cage, mirror, cert.leaves, cert.bound);
  EXPECT_EQ(m.proven, 0);
  for (const IntervalLeaf& r : m.results) {
    EXPECT_LT(r.sigma3_lo, 0.0);
    EXPECT_FALSE(r.proven);
  }
  // 3. A rank-deficient affine map: σ3 = 0 exactly, never proven.
  Mat3 flat = Mat3::Identity();
  flat(2, 2) = 0;
  const MatX3d squash = model.cage.affine_coefficients(flat, Vec3::Zero());
  const IntervalVerification s = verify_certificate_intervals(model.cage, squash, cert.leaves, cert.bound);
  EXPECT_EQ(s.proven, 0);
}

// `lidef verify --interval` end to end: proven (0), tampered (1), bad input (2).
TEST(IntervalVerification, CliExitCodes) {
  TempDir tmp;
  const std::string ball = lidef::test::project_data() + "/models/ball";
  const Cage cage(read_mesh(ball + "/cage.obj"));
  {
    std::ofstream out(tmp / "y.txt");
    write_coefficients(out, mild_bend(cage, 0.02));
  }
  std::string output;
  ASSERT_EQ(run_lidef("certify " + quote(ball) + " --coeffs " + quote(tmp / "y.txt") + " --out " +
                          quote(tmp / "cert") + " --samples 400 --grid 0",
                      &output),
            0)
      << output;
  const std::string verify = "verify " + quote(ball) + " --coeffs " + quote(tmp / "y.txt") +
                             " --certificate " + quote(tmp / "cert/certificate.json") + " --interval";
  ASSERT_EQ(run_lidef(verify, &output), 0) << output;
  EXPECT_NE(output.find("PROVEN"), std::string::npos) << output;
  const nlohmann::json cj = read_json(tmp / "cert/certificate.json");
  const nlohmann::json ij = read_json(tmp / "cert/interval.json");
  EXPECT_EQ(ij["proven"].get<long>(), cj["leaves"].get<long>());
  EXPECT_EQ(ij["not_proven"].get<long>(), 0);
  EXPECT_GT(ij["worst_slack"].get<double>(), 0.0);
  EXPECT_EQ(ij["bound"], cj["bound"]);
  {
    std::istringstream csv(lidef::test::read_text(tmp / "cert/interval.csv"));
    std::string line;
    std::getline(csv, line);
    EXPECT_EQ(line,
              "leaf,proven,sigma3_lo,L_hi,margin_lo,certificate_margin,sigma1_hi,distortion_hi,"
              "certificate_distortion");
    long rows = 0;
    while (std::getline(csv, line)) {
      ++rows;
      EXPECT_EQ(line.substr(line.find(',') + 1, 2), "1,") << line;
    }
    EXPECT_EQ(rows, cj["leaves"].get<long>());
  }
  // Deterministic: a second run with one thread writes the same interval.csv.
  const std::string first = lidef::test::read_text(tmp / "cert/interval.csv");
  ASSERT_EQ(lidef::test::run_command("OMP_NUM_THREADS=1 " + quote(lidef::test::cli()) + " " + verify +
                                         " --out " + quote(tmp / "one"),
                                     &output),
            0)
      << output;
  EXPECT_EQ(lidef::test::read_text(tmp / "one/interval.csv"), first);

  // Tampered: a certified leaf's side enlarged 8 times, the voxels.csv hash in certificate.json updated so
  // the reader accepts it. The re-proof must fail on that leaf (exit 1) and name it.
  std::string vox = lidef::test::read_text(tmp / "cert/voxels.csv");
  const size_t row1 = vox.find('\n') + 1;
  const size_t end1 = vox.find('\n', row1);
  std::vector<std::string> f;
  {
    std::istringstream r(vox.substr(row1, end1 - row1));
    for (std::string x; std::getline(r, x, ',');) f.push_back(x);
  }
  ASSERT_EQ(f.size(), 13u);
  ASSERT_EQ(f[8], "1");
  f[3] = format_double(8 * std::stod(f[3]));
  std::string row;
  for (size_t i = 0; i < f.size(); ++i) row += (i ? "," : "") + f[i];
  const std::string old_hash = hex64(fnv1a64(vox));
  vox = vox.substr(0, row1) + row + vox.substr(end1);
  std::string json = lidef::test::read_text(tmp / "cert/certificate.json");
  const size_t at = json.find(old_hash);
  ASSERT_NE(at, std::string::npos);
  json.replace(at, old_hash.size(), hex64(fnv1a64(vox)));
  lidef::test::write_text(tmp / "cert/voxels.csv", vox);
  lidef::test::write_text(tmp / "cert/certificate.json", json);
  EXPECT_EQ(run_lidef(verify, &output), 1) << output;
  EXPECT_NE(output.find("NOT PROVEN"), std::string::npos) << output;
  EXPECT_NE(output.find("not proven: leaf 0 "), std::string::npos) << output;
  EXPECT_EQ(read_json(tmp / "cert/interval.json")["not_proven"].get<long>(), 1);

  // A certificate cut to its first 10 leaves, its leaf count and hash rewritten (FNV is no signature): every
  // leaf left is proven, but they no longer cover the domain the certificate claims (exit 1, the gap named).
  ASSERT_EQ(run_lidef("certify " + quote(ball) + " --coeffs " + quote(tmp / "y.txt") + " --out " +
                          quote(tmp / "cut") + " --samples 400 --grid 0",
                      &output),
            0)
      << output;
  {
    const std::string full = lidef::test::read_text(tmp / "cut/voxels.csv");
    size_t end = 0;
    for (int row = 0; row < 11; ++row) end = full.find('\n', end) + 1;
    const std::string cut = full.substr(0, end);
    std::string cj_text = lidef::test::read_text(tmp / "cut/certificate.json");
    nlohmann::json cut_json = nlohmann::json::parse(cj_text);
    const std::string leaves_line = "\"leaves\": " + std::to_string(cut_json["leaves"].get<long>()) + ",";
    const size_t at_leaves = cj_text.find(leaves_line);
    ASSERT_NE(at_leaves, std::string::npos);
    cj_text.replace(at_leaves, leaves_line.size(), "\"leaves\": 10,");
    const std::string old_cut_hash = hex64(fnv1a64(full));
    cj_text.replace(cj_text.find(old_cut_hash), old_cut_hash.size(), hex64(fnv1a64(cut)));
    lidef::test::write_text(tmp / "cut/voxels.csv", cut);
    lidef::test::write_text(tmp / "cut/certificate.json", cj_text);
  }
  EXPECT_EQ(run_lidef("verify " + quote(ball) + " --coeffs " + quote(tmp / "y.txt") + " --certificate " +
                          quote(tmp / "cut/certificate.json") + " --interval",
                      &output),
            1)
      << output;
  EXPECT_NE(output.find("NOT PROVEN: 10 of 10"), std::string::npos) << output;
  EXPECT_NE(output.find("do not provably cover the certified domain"), std::string::npos) << output;
  EXPECT_FALSE(read_json(tmp / "cut/interval.json")["coverage_proven"].get<bool>());

  // A certificate that says "not certified" (a mirrored map) is never PROVEN, whatever its leaves.
  {
    std::ofstream out(tmp / "mirror.txt");
    write_coefficients(out, cage.affine_coefficients(Vec3(-1, 1, 1).asDiagonal(), Vec3::Zero()));
  }
  ASSERT_EQ(run_lidef("certify " + quote(ball) + " --coeffs " + quote(tmp / "mirror.txt") + " --out " +
                          quote(tmp / "folded") + " --samples 400 --grid 0",
                      &output),
            1)
      << output;
  EXPECT_EQ(run_lidef("verify " + quote(ball) + " --coeffs " + quote(tmp / "mirror.txt") + " --certificate " +
                          quote(tmp / "folded/certificate.json") + " --interval",
                      &output),
            1)
      << output;
  EXPECT_NE(output.find("NOT PROVEN"), std::string::npos) << output;
  EXPECT_NE(output.find("the certificate itself says 'not certified'"), std::string::npos) << output;

  // Bad input: a missing certificate, other coefficients (exit 2, nothing written).
  EXPECT_EQ(run_lidef("verify " + quote(ball) + " --coeffs identity --certificate " +
                          quote(tmp / "none.json") + " --interval --out " + quote(tmp / "bad"),
                      &output),
            2)
      << output;
  EXPECT_EQ(run_lidef("verify " + quote(ball) + " --coeffs identity --certificate " +
                          quote(tmp / "cert/certificate.json") + " --interval --out " + quote(tmp / "bad"),
                      &output),
            2)
      << output;
  EXPECT_FALSE(std::filesystem::exists(tmp / "bad"));
}

// Every shared scenario: `lidef deform` (default parameters but 8000 samples, to keep the slow label within
// CI's time; docs/benchmarks.md has the full-size runs, all leaves proven), then `lidef verify --interval` on
// the certificate of the written map (deform certifies it with `lidef certify`'s code). All leaves proven,
// and the written map globally injective.
class IntervalSlow : public ::testing::TestWithParam<std::string> {};

TEST_P(IntervalSlow, SharedScenarioOutputCertificateIsProven) {
  LIDEF_REQUIRE_SHARED();
  TempDir tmp;
  const std::string scenario = lidef::test::shared_data() + "/scenarios/" + GetParam() + ".json";
  const nlohmann::json sc = read_json(scenario);
  const std::string model = lidef::test::shared_data() + "/models/" + sc["model"].get<std::string>();
  std::string output;
  const auto t0 = Clock::now();
  const int rc =
      run_lidef("deform " + quote(scenario) + " --samples 8000 --out " + quote(tmp / "out"), &output);
  ASSERT_TRUE(rc == 0 || rc == 1) << output;  // 1: stopped short of the handles, still certified
  const double t_deform = seconds_since(t0);
  const nlohmann::json cj = read_json(tmp / "out/certificate.json");
  ASSERT_TRUE(cj["certified"].get<bool>()) << "the written map's certificate is not certified";
  // The shared scenarios are benign: every written map is decided globally injective (the bar's rest mesh
  // intersects itself, and the verdict is about the solid whose boundary the check computes exactly).
  EXPECT_EQ(cj["globally_injective"], nlohmann::json(true)) << cj["global_reason"];
  const auto t1 = Clock::now();
  ASSERT_EQ(run_lidef("verify " + quote(model) + " --coeffs " + quote(tmp / "out/coefficients.txt") +
                          " --certificate " + quote(tmp / "out/certificate.json") + " --interval",
                      &output),
            0)
      << output;
  const double t_verify = seconds_since(t1);
  const nlohmann::json ij = read_json(tmp / "out/interval.json");
  EXPECT_EQ(ij["proven"].get<long>(), cj["leaves"].get<long>());
  std::cout << GetParam() << ": deform " << t_deform << " s; verify --interval " << t_verify << " s wall, "
            << ij["proven"] << " leaves proven, worst slack " << ij["worst_slack"] << ", "
            << ij["leaves_per_s"] << " leaves/s\n";
}

INSTANTIATE_TEST_SUITE_P(Shared, IntervalSlow,
                         ::testing::Values("bar_bend", "bar_twist90", "bar_twist180", "horse_leg_lift",
                                           "spot_head_turn", "animal_tail_lift"));
