// The blocked Cholesky factorization of the reduced Newton system (lidef/internal/cholesky.h): against
// Eigen's LLT on sizes around the panel and tile widths, bit-identical for any thread count, the upper
// triangle untouched, and an indefinite matrix refused.
#include <gtest/gtest.h>
#include <omp.h>

#include <random>

#include "lidef/internal/cholesky.h"

namespace {

using lidef::MatXd;
using lidef::VecXd;

// A random symmetric positive definite n x n matrix with condition number about 1e4 (a spread diagonal).
MatXd random_spd(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N(0, 1);
  MatXd B(n, n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) B(i, j) = N(rng);
  MatXd H = B * B.transpose() / n;
  for (int i = 0; i < n; ++i) H(i, i) += std::pow(10.0, -4.0 * i / std::max(1, n - 1)) + 1e-3;
  return H;
}

TEST(Cholesky, MatchesEigensFactorAndSolves) {
  for (const int n : {1, 2, 5, 95, 96, 97, 128, 129, 250, 300, 601, 900}) {
    const MatXd H = random_spd(n, 7u + n);
    MatXd F = H;
    ASSERT_TRUE(lidef::cholesky_factor(F)) << n;
    const MatXd L = F.triangularView<Eigen::Lower>();
    const MatXd Le = H.llt().matrixL();
    EXPECT_LT((L - Le).cwiseAbs().maxCoeff(), 1e-10 * Le.cwiseAbs().maxCoeff()) << n;
    // The strict upper triangle is the input's.
    EXPECT_EQ(MatXd(F.triangularView<Eigen::StrictlyUpper>()),
              MatXd(H.triangularView<Eigen::StrictlyUpper>()))
        << n;
    const VecXd x = VecXd::LinSpaced(n, -1.0, 2.0);
    VecXd b = H * x;
    ASSERT_TRUE(lidef::cholesky_solve_factored(F, b)) << n;
    EXPECT_LT((b - x).norm(), 1e-8 * x.norm()) << n;
  }
}

TEST(Cholesky, TheFactorIsTheSameForAnyThreadCount) {
  const MatXd H = random_spd(900, 11u);
  const int saved = omp_get_max_threads();
  MatXd F1 = H, F4 = H;
  omp_set_num_threads(1);
  ASSERT_TRUE(lidef::cholesky_factor(F1));
  omp_set_num_threads(4);
  ASSERT_TRUE(lidef::cholesky_factor(F4));
  omp_set_num_threads(saved);
  EXPECT_EQ(F1, F4);
}

TEST(Cholesky, AnIndefiniteMatrixIsRefused) {
  for (const int n : {3, 200, 900}) {
    MatXd H = random_spd(n, 3u + n);
    // A negative eigenvalue in the last panel (the first panels factor, the last one fails) and in the first.
    for (const int at : {n - 1, 0}) {
      MatXd G = H;
      G(at, at) = -1.0;
      VecXd b = VecXd::Ones(n);
      EXPECT_FALSE(lidef::cholesky_solve(G, b)) << n << " " << at;
    }
    VecXd b = VecXd::Ones(n);
    EXPECT_TRUE(lidef::cholesky_solve(H, b)) << n;
  }
}

TEST(Cholesky, ShapeMismatchesAreRefused) {
  MatXd H = MatXd::Identity(4, 3);
  EXPECT_FALSE(lidef::cholesky_factor(H));
  MatXd I = MatXd::Identity(4, 4);
  VecXd b = VecXd::Ones(3);
  EXPECT_FALSE(lidef::cholesky_solve(I, b));
}

}  // namespace
