// The batched evaluation of octree children (EdgeJet::evaluate_lanes, lane_math.h; docs/certificate.md,
// Step 4c) against independent truths: long-double references for its log and atan2, the one-point
// evaluation (EdgeJet::evaluate) at random points near and far from the cage, the per-face and per-edge
// refinements (same leaves), and dense sampling of refined certified maps.
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <random>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/internal/edge_jet.h"
#include "lidef/internal/lane_math.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "test_cages.h"

using namespace lidef;
using lidef::test::perturbed_map;

namespace {

constexpr double kU = 0x1p-53;  // unit roundoff

double frob(const std::array<Mat3, 3>& H) {
  return std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
}

}  // namespace

// lane_log_ratio against log1p in long double (exact n − d when n/d is near 1, so the reference keeps its
// relative accuracy there), over ratios from 1 + 2⁻⁵² to 2⁶⁰⁰ and back, and the certificate's arguments.
TEST(LaneMath, LogRatioWithinSixRoundingUnits) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> U(0, 1);
  double worst = 0;
  long n_checked = 0;
  for (int i = 0; i < 400000; ++i) {
    double n, d;
    const int kind = i % 4;
    d = std::ldexp(1 + U(rng), static_cast<int>(U(rng) * 200) - 100);
    if (kind == 0) {
      n = d * std::exp2((U(rng) - 0.5) * 1200);  // anything
    } else if (kind == 1) {
      n = d * (1 + std::ldexp(U(rng), -static_cast<int>(U(rng) * 52)));  // just above 1
    } else if (kind == 2) {
      n = std::nextafter(d, i % 8 < 4 ? 0.0 : 1e300);  // neighbours
    } else {
      // The certificate's argument ((m + d)², m² − d²) for an edge of length e and a point at distance t.
      const double e = std::exp2((U(rng) - 0.5) * 8), m = e * (1 + std::exp2((U(rng) - 0.2) * 30));
      n = (m + e) * (m + e);
      d = (m - e) * (m + e);
    }
    if (!(n > 0) || !std::isfinite(n) || n < 0x1p-1022 || !lane_math::log_ratio_in_domain(n, d)) continue;
    // log1p keeps the relative accuracy near n/d = 1 (n − d exact there); elsewhere logl(n) − logl(d).
    const long double q = static_cast<long double>(n) / d;
    const long double ref = std::fabs(q - 1) < 0.5L ? std::log1p((static_cast<long double>(n) - d) / d)
                                                    : std::log(static_cast<long double>(n)) -
                                                          std::log(static_cast<long double>(d));
    const double got = lane_math::lane_log_ratio(n, d);
    const double err = static_cast<double>(std::fabs(static_cast<long double>(got) - ref));
    const double rel = err / (kU * static_cast<double>(std::fabs(ref)));
    if (ref == 0) {
      EXPECT_EQ(got, 0.0);
      continue;
    }
    ++n_checked;
    worst = std::max(worst, rel);
    ASSERT_LE(rel, 6.0) << "n " << n << " d " << d << " got " << got << " ref " << static_cast<double>(ref);
  }
  std::cout << n_checked << " ratios; largest error " << worst << " u relative\n";
  EXPECT_GT(n_checked, 300000);
  EXPECT_FALSE(lane_math::log_ratio_in_domain(0.0, 1.0));
  EXPECT_FALSE(lane_math::log_ratio_in_domain(1.0, std::numeric_limits<double>::infinity()));
  EXPECT_FALSE(lane_math::log_ratio_in_domain(std::nan(""), 1.0));
  EXPECT_FALSE(lane_math::log_ratio_in_domain(1.0, 0x1p-1030));
}

// lane_atan2 against atan2 in long double in all quadrants, near the axes and the diagonals, with signed
// zeros: within 12u |atan2| (docs/certificate.md, Step 4c).
TEST(LaneMath, Atan2WithinStatedBound) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> U(-1, 1);
  double worst = 0;
  for (int i = 0; i < 400000; ++i) {
    double x = U(rng), y = U(rng);
    switch (i % 5) {
      case 1:
        y *= std::exp2(-60 * std::fabs(U(rng)));  // near the x axis
        break;
      case 2:
        x *= std::exp2(-60 * std::fabs(U(rng)));  // near the y axis
        break;
      case 3:
        y = std::copysign(std::fabs(x) * (1 + 1e-3 * U(rng)), y);  // near the diagonals
        break;
      case 4:
        y = std::copysign(std::fabs(x) * (0.41421356237309503 + 1e-9 * U(rng)),
                          y);  // near the reduction switch
        break;
    }
    const double s = std::exp2(std::round(300 * U(rng)));
    x *= s;
    y *= s;
    ASSERT_TRUE(lane_math::atan2_in_domain(y, x));
    const long double ref = std::atan2(static_cast<long double>(y), static_cast<long double>(x));
    const double got = lane_math::lane_atan2(y, x);
    const double err = static_cast<double>(std::fabs(static_cast<long double>(got) - ref));
    const double bound = 12 * kU * static_cast<double>(std::fabs(ref));
    worst = std::max(worst, err / bound);
    ASSERT_LE(err, bound) << "y " << y << " x " << x;
  }
  std::cout << "largest error / bound " << worst << "\n";
  for (double y : {0.0, -0.0, 1.0, -1.0})
    for (double x : {0.0, -0.0, 2.0, -2.0}) {
      if (y == 0 && x == 0) {
        EXPECT_FALSE(lane_math::atan2_in_domain(y, x));
        continue;
      }
      const double got = lane_math::lane_atan2(y, x), ref = std::atan2(y, x);
      EXPECT_NEAR(got, ref, 12 * kU * std::fabs(ref)) << y << " " << x;
      EXPECT_EQ(std::signbit(got), std::signbit(ref)) << y << " " << x;
    }
  EXPECT_FALSE(lane_math::atan2_in_domain(std::nan(""), 1.0));
  EXPECT_FALSE(lane_math::atan2_in_domain(1.0, std::numeric_limits<double>::infinity()));
}

// Per point, the batched values equal the one-point evaluation to rounding: J and H within 10⁻¹³ of their
// rounding scales, the scales and both factor sums within 10⁻¹² relative (+∞ where the one-point sum is
// +∞); points near the cage (down to 0.002) and far from it, radii up to the clearance, every n = 1..8. Each
// lane's values do not depend on the other lanes (bit for bit).
TEST(EdgeJet, LanesMatchOnePointEvaluation) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  const HarmonicBasis B(cage);
  const EdgeJet ej(cage);
  const EdgeJet::MapData md = ej.prepare(B.face_matrices(perturbed_map(cage, 0.05, 6)));
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> U(0, 1);
  int infinite = 0, compared = 0;
  for (double margin : {0.002, 0.02, 0.1}) {
    const MatX3d P =
        lidef::test::interior_points(cage, 48, margin, 13 + static_cast<unsigned>(1000 * margin));
    std::vector<Vec3> pts;
    std::vector<double> rad;
    std::vector<char> near_touch;  // radius 0.999 of the clearance
    for (int i = 0; i < P.rows(); ++i) {
      pts.push_back(P.row(i).transpose());
      near_touch.push_back(i % 3 == 0);
      rad.push_back(cage.distance(pts.back()) * (i % 3 == 0 ? 0.999 : 0.9 * U(rng)));
    }
    for (int combo = 0; combo < 8; ++combo) {
      const bool h = combo & 4, f = combo & 2, t = combo & 1;
      for (size_t i0 = 0, n = 1; i0 < pts.size(); i0 += n, n = n % 8 + 1) {
        const int cnt = static_cast<int>(std::min(n, pts.size() - i0));
        EdgeJet::Values lanes[EdgeJet::kLanes];
        ej.evaluate_lanes(md, &pts[i0], &rad[i0], cnt, h, f, t, lanes);
        for (int k = 0; k < cnt; ++k) {
          EdgeJet::Values one, alone;
          ej.evaluate(md, pts[i0 + k], rad[i0 + k], h, f, t, one);
          ej.evaluate_lanes(md, &pts[i0 + k], &rad[i0 + k], 1, h, f, t, &alone);
          const EdgeJet::Values& v = lanes[k];
          ++compared;
          EXPECT_LT((v.J - one.J).norm(), 1e-13 * one.scale_J);
          EXPECT_NEAR(v.scale_J, one.scale_J, 1e-12 * one.scale_J);
          if (h) {
            std::array<Mat3, 3> d;
            for (int a = 0; a < 3; ++a) d[a] = v.H[a] - one.H[a];
            EXPECT_LT(frob(d), 1e-13 * one.scale_H);
            EXPECT_NEAR(v.scale_H, one.scale_H, 1e-12 * one.scale_H);
          } else {
            EXPECT_EQ(frob(v.H), 0.0);
          }
          for (auto [got, ref, want] : {std::tuple<double, double, bool>{v.T_first, one.T_first, f},
                                        std::tuple<double, double, bool>{v.T_third, one.T_third, t}}) {
            if (!want) {
              EXPECT_EQ(got, 0.0);
            } else if (std::isinf(ref)) {
              ++infinite;
              EXPECT_TRUE(std::isinf(got));
            } else {
              // A ball that nearly touches an edge has h² − d² ≪ h²: both codes' rounding of h is amplified
              // by h²/(h² − d²) in that edge's factor (Step 4c), so those are compared to 10⁻⁷ only.
              EXPECT_NEAR(got, ref, (near_touch[i0 + k] ? 1e-7 : 1e-12) * ref);
            }
          }
          // Lane independence: the same bits alone as among other points.
          EXPECT_EQ(v.J, alone.J);
          for (int a = 0; a < 3; ++a) EXPECT_EQ(v.H[a], alone.H[a]);
          EXPECT_EQ(v.scale_J, alone.scale_J);
          EXPECT_EQ(v.scale_H, alone.scale_H);
          EXPECT_EQ(v.T_first, alone.T_first);
          EXPECT_EQ(v.T_third, alone.T_third);
        }
      }
    }
  }
  EXPECT_GT(compared, 1000);
  EXPECT_GT(infinite, 0);  // balls reaching an edge's neighbourhood are exercised too
}

// The three evaluations of children take the same decisions: the same leaves, σ3 to 10⁻¹², L to 10⁻¹⁰
// relative, for every bound; and the batched one gives bit-identical leaves at 1 and 2 threads.
TEST(EdgeJet, BatchedRefinementAgreesWithPerEdgeAndPerFace) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  SamplingParams sp;
  sp.target_count = 800;
  sp.count_tolerance = 0.1;
  const OctreeCertifier cert(cage, sample_voxels(cage, sp));
  const MatX3d y = perturbed_map(cage, 0.012, 21);
  for (LipschitzBound b : {LipschitzBound::kFirstOrder, LipschitzBound::kThirdOrder,
                           LipschitzBound::kCombined, LipschitzBound::kSpectral}) {
    CertifyParams p;
    p.bound = b;
    p.max_depth = 3;
    p.refinement = RefinementEval::kPerEdgeBatched;
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const Certificate a1 = cert.certify(y, p);
    omp_set_num_threads(2);
    const Certificate a = cert.certify(y, p);
    omp_set_num_threads(threads);
    EXPECT_GT(a.refined, 0) << to_string(b);
    ASSERT_EQ(a1.leaves.size(), a.leaves.size());
    for (size_t i = 0; i < a.leaves.size(); ++i) {
      EXPECT_EQ(a1.leaves[i].sigma3, a.leaves[i].sigma3);
      EXPECT_EQ(a1.leaves[i].L, a.leaves[i].L);
      EXPECT_EQ(a1.leaves[i].margin, a.leaves[i].margin);
    }
    for (RefinementEval r : {RefinementEval::kPerEdge, RefinementEval::kPerFace}) {
      p.refinement = r;
      const Certificate o = cert.certify(y, p);
      SCOPED_TRACE(std::string(to_string(b)) + " vs " + to_string(r));
      EXPECT_EQ(a.certified, o.certified);
      EXPECT_EQ(a.refined, o.refined);
      ASSERT_EQ(a.leaves.size(), o.leaves.size());
      for (size_t i = 0; i < a.leaves.size(); ++i) {
        EXPECT_EQ(a.leaves[i].depth, o.leaves[i].depth);
        EXPECT_EQ(a.leaves[i].certified, o.leaves[i].certified);
        EXPECT_NEAR(a.leaves[i].sigma3, o.leaves[i].sigma3, 1e-12);
        EXPECT_NEAR(a.leaves[i].L, o.leaves[i].L, 1e-10 * o.leaves[i].L);
      }
    }
  }
}

// Refined certified maps (batched children) under dense sampling: no sample of a certified leaf has σ3 ≤ 0
// or below that leaf's certified lower bound σ3(c) − rL − τ, and no sample breaks the leaf's Lipschitz
// bound; both bounds, and a map certified only after refinement.
TEST(EdgeJet, BatchedRefinedCertificatesHoldUnderDenseSampling) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  SamplingParams sp;
  sp.target_count = 800;
  sp.count_tolerance = 0.1;
  const OctreeCertifier cert(cage, sample_voxels(cage, sp));
  int refined_certified = 0;
  for (double amp : {0.008, 0.012})
    for (LipschitzBound b :
         {LipschitzBound::kThirdOrder, LipschitzBound::kCombined, LipschitzBound::kSpectral}) {
      const MatX3d y = perturbed_map(cage, amp, 21);
      CertifyParams p;
      p.bound = b;
      p.max_depth = 4;
      const Certificate c = cert.certify(y, p);
      if (!c.certified || c.refined == 0) continue;
      ++refined_certified;
      std::vector<CertLeaf> refined;
      for (const CertLeaf& l : c.leaves)
        if (l.depth > 0) refined.push_back(l);
      ASSERT_FALSE(refined.empty());
      const VerificationResult v = verify_certificate(cert.basis(), y, refined, 64, 5);
      EXPECT_EQ(v.violations, 0);
      EXPECT_EQ(v.nonpositive_in_certified, 0);
      for (size_t i = 0; i < refined.size(); ++i)
        EXPECT_GE(v.voxels[i].min_sigma3, refined[i].margin) << "leaf " << i;
    }
  EXPECT_GE(refined_certified, 2);
}
