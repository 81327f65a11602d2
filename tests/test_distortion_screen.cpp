// The line search's distortion screen (lidef/internal/distortion_screen.h): the sample of largest σ1/σ3 of
// J0 + t dJ against an SVD of every sample, inverted and singular samples skipped, ties to the smaller index,
// and the same answer with 1 and 2 threads; with σ1 and σ3 targets, the sample farthest beyond them.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/SVD>
#include <cmath>
#include <random>

#include "lidef/internal/distortion_screen.h"

using namespace lidef;

namespace {

// With only max_distortion = 1 the excess is σ1/σ3 itself.
const DistortionTargets kRatio{1, 0, 0};

// n random Jacobians near rotations times stretches (JT layout), det > 0.
MatJT random_jacobians(long n, unsigned seed, double spread) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  MatJT J(3 * n, 3);
  for (long i = 0; i < n; ++i) {
    Mat3 A = Mat3::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) A(r, c) += spread * u(rng);
    if (A.determinant() < 0) A.row(0) *= -1;
    J.middleRows<3>(3 * i) = A;
  }
  return J;
}

double svd_ratio(const Mat3& J) {
  const Vec3 s = Eigen::JacobiSVD<Mat3>(J).singularValues();
  return s(0) / s(2);
}

}  // namespace

TEST(DistortionScreen, FindsTheSampleOfLargestRatioLikeAnSvd) {
  const long n = 2000;
  const MatJT J0 = random_jacobians(n, 7, 0.3),
              dJ = random_jacobians(n, 11, 0.3) - random_jacobians(n, 11, 0);
  for (const double t : {0.0, 0.25, 1.0}) {
    long best = -1;
    double best_k = 0;
    for (long i = 0; i < n; ++i) {
      const Mat3 J = J0.middleRows<3>(3 * i) + t * dJ.middleRows<3>(3 * i);
      if (!(J.determinant() > 0)) continue;
      const double k = svd_ratio(J);
      if (k > best_k) best_k = k, best = i;
    }
    double k = 0;
    const long i = largest_excess_sample(J0, dJ, t, kRatio, &k);
    ASSERT_GE(best, 0);
    EXPECT_NEAR(k, best_k, 1e-9 * best_k) << "t = " << t;
    // The closed-form eigenvalues may pick another sample only where two ratios agree to rounding.
    if (i != best) {
      const Mat3 Ji = J0.middleRows<3>(3 * i) + t * dJ.middleRows<3>(3 * i);
      EXPECT_NEAR(svd_ratio(Ji), best_k, 1e-9 * best_k) << "t = " << t;
    }
  }
}

TEST(DistortionScreen, SkipsInvertedAndFlatSamplesAndBreaksTiesByIndex) {
  MatJT J0(12, 3), dJ = MatJT::Zero(12, 3);
  J0.middleRows<3>(0) = Vec3(1, 1, 1).asDiagonal();   // K = 1
  J0.middleRows<3>(3) = Vec3(-8, 1, 1).asDiagonal();  // det < 0: skipped although K = 8
  J0.middleRows<3>(6) = Vec3(2, 1, 1).asDiagonal();   // K = 2
  J0.middleRows<3>(9) = Vec3(1, 2, 1).asDiagonal();   // K = 2 too: the tie goes to sample 2
  double k = 0;
  EXPECT_EQ(largest_excess_sample(J0, dJ, 1.0, kRatio, &k), 2);
  EXPECT_DOUBLE_EQ(k, 2.0);
  // Moving along dJ: sample 0 becomes diag(4, 1, 1) at t = 1.5.
  dJ.middleRows<3>(0) = Vec3(2, 0, 0).asDiagonal();
  EXPECT_EQ(largest_excess_sample(J0, dJ, 1.5, kRatio, &k), 0);
  EXPECT_NEAR(k, 4.0, 1e-12);
  // Nothing with det > 0: none.
  MatJT flat = MatJT::Zero(6, 3);
  EXPECT_EQ(largest_excess_sample(flat, flat, 1.0, kRatio, &k), -1);
  EXPECT_EQ(k, 0.0);
}

TEST(DistortionScreen, SameSampleWithOneAndTwoThreads) {
  const long n = 5000;
  const MatJT J0 = random_jacobians(n, 3, 0.1);
  // Equal ratios in both halves of the range: a thread count that split the tie differently would show.
  MatJT Jt = J0;
  Jt.middleRows<3>(3 * 10) = Vec3(9, 1, 1).asDiagonal();
  Jt.middleRows<3>(3 * (n - 10)) = Vec3(1, 9, 1).asDiagonal();
  const int saved = omp_get_max_threads();
  long idx[2];
  double k[2];
  for (int threads = 1; threads <= 2; ++threads) {
    omp_set_num_threads(threads);
    idx[threads - 1] = largest_excess_sample(Jt, MatJT::Zero(3 * n, 3), 0.5, kRatio, &k[threads - 1]);
  }
  omp_set_num_threads(saved);
  EXPECT_EQ(idx[0], 10);
  EXPECT_EQ(idx[1], 10);
  EXPECT_EQ(k[0], k[1]);
}

// σ1 and σ3 targets: the sample farthest beyond them, measured as σ1 / max_sigma1 and min_sigma3 / σ3, the
// largest of the targets that are on.
TEST(DistortionScreen, IsometricTargetsPickTheSampleFarthestBeyondThem) {
  MatJT J0(12, 3);
  const MatJT dJ = MatJT::Zero(12, 3);
  J0.middleRows<3>(0) = Vec3(1.5, 1, 1).asDiagonal();    // σ1 1.5, σ3 1
  J0.middleRows<3>(3) = Vec3(1, 1, 0.5).asDiagonal();    // σ1 1, σ3 0.5
  J0.middleRows<3>(6) = Vec3(1.2, 1, 0.9).asDiagonal();  // σ1 1.2, σ3 0.9
  J0.middleRows<3>(9) = Vec3(1, 1, 1).asDiagonal();
  double e = 0;
  EXPECT_EQ(largest_excess_sample(J0, dJ, 1.0, DistortionTargets{0, 1.2, 0}, &e), 0);
  EXPECT_NEAR(e, 1.5 / 1.2, 1e-12);
  EXPECT_EQ(largest_excess_sample(J0, dJ, 1.0, DistortionTargets{0, 0, 0.8}, &e), 1);
  EXPECT_NEAR(e, 0.8 / 0.5, 1e-12);
  // Both: 1.5 / 1.2 = 1.25 against 0.8 / 0.5 = 1.6.
  EXPECT_EQ(largest_excess_sample(J0, dJ, 1.0, DistortionTargets{0, 1.2, 0.8}, &e), 1);
  // All within the targets: the largest excess is at most 1 (no probe).
  EXPECT_GE(largest_excess_sample(J0, dJ, 1.0, DistortionTargets{0, 2, 0.4}, &e), 0);
  EXPECT_LE(e, 1.0);
}

TEST(DistortionTargets, UnprovenViolatedAndReasonNameTheTarget) {
  const DistortionTargets t{1.5, 1.2, 0.8};
  EXPECT_EQ(t.unproven(1.1, 0.9, 1.4), DistortionTarget::kNone);
  EXPECT_EQ(t.unproven(1.1, 0.9, 1.6), DistortionTarget::kDistortion);
  EXPECT_EQ(t.unproven(1.3, 0.9, 1.4), DistortionTarget::kSigma1);
  EXPECT_EQ(t.unproven(1.1, 0.7, 1.4), DistortionTarget::kSigma3);
  // A NaN or missing bound proves nothing.
  EXPECT_EQ(t.unproven(std::nan(""), 0.9, 1.4), DistortionTarget::kSigma1);
  EXPECT_EQ(DistortionTargets{}.unproven(std::nan(""), -1, 1e9), DistortionTarget::kNone);
  // Values at a point contradict a target only beyond the slack.
  EXPECT_EQ(t.violated(1.25, 0.9, 1e-9), DistortionTarget::kSigma1);
  EXPECT_EQ(t.violated(1.2 * (1 + 1e-12), 0.9, 1e-9), DistortionTarget::kNone);
  EXPECT_EQ(t.violated(1.0, 0.75, 1e-9), DistortionTarget::kSigma3);
  EXPECT_EQ(t.violated(1.1, 0.78, 1e-9), DistortionTarget::kSigma3);
  EXPECT_EQ(DistortionTargets({1.4, 0, 0}).violated(1.19, 0.8, 1e-9), DistortionTarget::kDistortion);
  EXPECT_EQ(t.reason(DistortionTarget::kSigma1, Vec3(1, 2, 3)),
            "distortion bound sigma1 <= 1.2 not proven at (1, 2, 3)");
  EXPECT_EQ(t.reason(DistortionTarget::kSigma3, Vec3(1, 2, 3)),
            "distortion bound sigma3 >= 0.8 not proven at (1, 2, 3)");
  EXPECT_EQ(t.reason(DistortionTarget::kDistortion, Vec3(1, 2, 3)),
            "distortion bound 1.5 not proven at (1, 2, 3)");
  EXPECT_EQ(t.describe(), "max_distortion 1.5, max_sigma1 1.2, min_sigma3 0.8");
  EXPECT_EQ(DistortionTargets({0, 0, 0.5}).describe(), "min_sigma3 0.5");
  EXPECT_FALSE(DistortionTargets{}.any());
}

// The screen kept for one line search (DistortionScreen) against the function: the same sample and excess at
// every step where that excess is above 1, for ratio, σ1 and σ3 targets, and at most 1 where the function's
// is; with 1 and 2 threads.
TEST(DistortionScreen, KeptScreenFindsTheSameSampleAtEveryStep) {
  const long n = 4000;
  const MatJT J0 = random_jacobians(n, 21, 0.15),
              dJ = 0.8 * (random_jacobians(n, 23, 0.3) - random_jacobians(n, 23, 0));
  const int saved = omp_get_max_threads();
  int above = 0, below = 0;
  for (int threads = 1; threads <= 2; ++threads) {
    omp_set_num_threads(threads);
    const DistortionScreen screen(J0, dJ);
    for (const DistortionTargets& targets :
         {DistortionTargets{1.6, 0, 0}, DistortionTargets{2.5, 0, 0}, DistortionTargets{0, 1.3, 0},
          DistortionTargets{0, 0, 0.75}, DistortionTargets{1.8, 1.35, 0.7}})
      for (double t = 1; t > 1e-4; t *= 0.5) {
        double e_full = 0, e_kept = 0;
        const long i_full = largest_excess_sample(J0, dJ, t, targets, &e_full);
        const long i_kept = screen.largest_excess_sample(t, targets, &e_kept);
        if (e_full > 1) {
          ++above;
          EXPECT_EQ(i_kept, i_full) << "t = " << t;
          EXPECT_EQ(e_kept, e_full) << "t = " << t;
        } else {
          ++below;
          EXPECT_LE(e_kept, 1.0) << "t = " << t;
        }
      }
  }
  omp_set_num_threads(saved);
  // Both cases occur: steps beyond the targets and steps within them.
  EXPECT_GT(above, 10);
  EXPECT_GT(below, 10);
}
