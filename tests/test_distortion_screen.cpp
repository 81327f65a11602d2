// The line search's distortion screen (lidef/internal/distortion_screen.h): the sample of largest σ1/σ3 of
// J0 + t dJ against an SVD of every sample, inverted and singular samples skipped, ties to the smaller index,
// and the same answer with 1 and 2 threads.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/SVD>
#include <random>

#include "lidef/internal/distortion_screen.h"

using namespace lidef;

namespace {

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
    const long i = largest_distortion_sample(J0, dJ, t, &k);
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
  EXPECT_EQ(largest_distortion_sample(J0, dJ, 1.0, &k), 2);
  EXPECT_DOUBLE_EQ(k, 2.0);
  // Moving along dJ: sample 0 becomes diag(4, 1, 1) at t = 1.5.
  dJ.middleRows<3>(0) = Vec3(2, 0, 0).asDiagonal();
  EXPECT_EQ(largest_distortion_sample(J0, dJ, 1.5, &k), 0);
  EXPECT_NEAR(k, 4.0, 1e-12);
  // Nothing with det > 0: none.
  MatJT flat = MatJT::Zero(6, 3);
  EXPECT_EQ(largest_distortion_sample(flat, flat, 1.0, &k), -1);
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
    idx[threads - 1] = largest_distortion_sample(Jt, MatJT::Zero(3 * n, 3), 0.5, &k[threads - 1]);
  }
  omp_set_num_threads(saved);
  EXPECT_EQ(idx[0], 10);
  EXPECT_EQ(idx[1], 10);
  EXPECT_EQ(k[0], k[1]);
}
