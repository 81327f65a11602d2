// Signed SVD (paper App. B) against truth: matrices built as R1 diag(σ) R2ᵀ from known signed singular
// values and random rotations, Eigen's unsigned singular values, the eigenvalues of JᵀJ, and the sign of det
// J.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <random>
#include <sstream>
#include <vector>

#include "lidef/signed_svd.h"

using namespace lidef;

namespace {

std::string show(const Mat3& J) {
  std::ostringstream s;
  s.precision(17);
  s << "\nJ =\n" << J;
  return s.str();
}

// A uniformly random rotation (QR of a Gaussian matrix, sign-fixed so that det = +1).
Mat3 random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> N01;
  Mat3 G;
  for (int k = 0; k < 9; ++k) G(k / 3, k % 3) = N01(rng);
  Eigen::HouseholderQR<Mat3> qr(G);
  Mat3 Q = qr.householderQ();
  const Mat3 R = qr.matrixQR().triangularView<Eigen::Upper>();
  for (int k = 0; k < 3; ++k)
    if (R(k, k) < 0) Q.col(k) *= -1;
  if (Q.determinant() < 0) Q.col(2) *= -1;
  return Q;
}

// Every property the header promises, for one matrix. `tol` is relative to σ1 (the spectral norm).
void check_signed_svd(const Mat3& J, double tol = 1e-13) {
  SCOPED_TRACE(show(J));
  const SignedSvd s = signed_svd(J);
  const Eigen::JacobiSVD<Mat3> ref(J);
  const Vec3 unsigned_sv = ref.singularValues();
  const double scale = unsigned_sv(0);

  // U, V are rotations.
  for (const Mat3* R : {&s.U, &s.V}) {
    EXPECT_LT((R->transpose() * *R - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_NEAR(R->determinant(), 1.0, 1e-12);
  }
  // Reconstruction.
  const Mat3 back = s.U * s.sigma.asDiagonal() * s.V.transpose();
  EXPECT_LE((back - J).cwiseAbs().maxCoeff(), tol * scale + 1e-300);
  // Ordering σ1 ≥ σ2 ≥ |σ3| (exact: the sort is of the computed values).
  EXPECT_GE(s.sigma(0), s.sigma(1));
  EXPECT_GE(s.sigma(1), std::abs(s.sigma(2)));
  // |σ| are Eigen's unsigned singular values.
  EXPECT_LE((s.sigma.cwiseAbs() - unsigned_sv).cwiseAbs().maxCoeff(), tol * scale);
  // ... and, independently of any SVD code, σ_i² are the eigenvalues of JᵀJ (absolute error ~ ε σ1²).
  const Vec3 ev = Eigen::SelfAdjointEigenSolver<Mat3>(J.transpose() * J).eigenvalues();  // ascending
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s.sigma(i) * s.sigma(i), ev(2 - i), 1e-13 * scale * scale);
  // sign(σ3) = sign(det J) wherever det J is distinguishable from rounding of a σ1³-sized product.
  const double det = J.determinant();
  if (std::abs(det) > 1e-12 * scale * scale * scale) {
    EXPECT_EQ(s.sigma(2) < 0, det < 0) << "det = " << det << ", sigma = " << s.sigma.transpose();
    EXPECT_NEAR(s.sigma.prod(), det, 1e-12 * scale * scale * scale);
  }
  // The cheap entry point agrees with the full decomposition.
  const Vec3 sv = signed_singular_values(J);
  EXPECT_LE((sv - s.sigma).cwiseAbs().maxCoeff(), tol * scale)
      << sv.transpose() << " vs " << s.sigma.transpose();
  if (std::abs(det) > 1e-12 * scale * scale * scale) {
    EXPECT_EQ(sv(2) < 0, det < 0);
  }
}

// J = R1 diag(σ) R2ᵀ with σ given (σ1 ≥ σ2 ≥ |σ3|, σ3 may be negative): the signed singular values must come
// back as σ itself, a truth that does not come from any SVD routine.
void check_known(const Vec3& sigma, std::mt19937& rng, double tol = 1e-13) {
  const Mat3 R1 = random_rotation(rng), R2 = random_rotation(rng);
  const Mat3 J = R1 * sigma.asDiagonal() * R2.transpose();
  check_signed_svd(J, tol);
  SCOPED_TRACE("expected sigma = " + [&] {
    std::ostringstream o;
    o.precision(17);
    o << sigma.transpose();
    return o.str();
  }());
  const double scale = sigma(0);
  EXPECT_LE((signed_svd(J).sigma - sigma).cwiseAbs().maxCoeff(), tol * scale);
  EXPECT_LE((signed_singular_values(J) - sigma).cwiseAbs().maxCoeff(), tol * scale);
}

}  // namespace

TEST(SignedSvd, RandomGaussianMatricesOfBothOrientations) {
  std::mt19937 rng(17);
  std::normal_distribution<double> N01;
  int negative = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    Mat3 J;
    for (int k = 0; k < 9; ++k) J(k / 3, k % 3) = N01(rng);
    negative += J.determinant() < 0;
    check_signed_svd(J);
    check_signed_svd(-J);  // 3x3: det(−J) = −det J, so both orientations are covered for every draw
    EXPECT_NEAR(signed_svd(-J).sigma(2), -signed_svd(J).sigma(2), 1e-13 * signed_svd(J).sigma(0));
  }
  EXPECT_GT(negative, 500);
}

TEST(SignedSvd, KnownSignedSingularValues) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> U(0.05, 3.0), S(0, 1);
  for (int trial = 0; trial < 1000; ++trial) {
    std::vector<double> v = {U(rng), U(rng), U(rng)};
    std::sort(v.rbegin(), v.rend());
    Vec3 sigma(v[0], v[1], v[2]);
    if (S(rng) < 0.5) sigma(2) = -sigma(2);
    check_known(sigma, rng);
  }
}

TEST(SignedSvd, NearSingularMatrices) {
  std::mt19937 rng(29);
  for (const double eps : {1e-3, 1e-6, 1e-9, 1e-12, 1e-15})
    for (const double sgn : {1.0, -1.0}) check_known(Vec3(2.0, 0.7, sgn * eps), rng);
  // Rank 2 and rank 1: σ3 = 0 (no sign to get right, but ordering and reconstruction must hold).
  check_known(Vec3(1.5, 0.4, 0.0), rng);
  check_known(Vec3(1.5, 0.0, 0.0), rng);
  check_signed_svd(Mat3::Zero());
  Mat3 rank2;
  rank2 << 1, 2, 3, 4, 5, 6, 7, 8, 9;  // exactly singular in exact arithmetic
  check_signed_svd(rank2);
  EXPECT_LT(std::abs(signed_svd(rank2).sigma(2)), 1e-14 * signed_svd(rank2).sigma(0));
}

TEST(SignedSvd, RepeatedSingularValues) {
  std::mt19937 rng(31);
  const std::vector<Vec3> cases = {{2, 2, 1},  {2, 2, -1}, {3, 1, 1},    {3, 1, -1},   {2, 2, 2},
                                   {2, 2, -2}, {1, 1, 0},  {5, 5, 5e-9}, {5, 5, -5e-9}};
  for (const Vec3& sigma : cases)
    for (int rep = 0; rep < 20; ++rep) check_known(sigma, rng);
}

TEST(SignedSvd, RotationsAndReflections) {
  std::mt19937 rng(37);
  for (int trial = 0; trial < 200; ++trial) {
    const Mat3 R = random_rotation(rng);
    const SignedSvd s = signed_svd(R);
    check_signed_svd(R);
    EXPECT_LT((s.sigma - Vec3(1, 1, 1)).cwiseAbs().maxCoeff(), 1e-13);
    EXPECT_LT((s.U * s.V.transpose() - R).cwiseAbs().maxCoeff(), 1e-13);  // the rotation factor is R itself
    // A reflection (orthogonal, det −1): σ = (1, 1, −1).
    const Mat3 M = R * Vec3(1, 1, -1).asDiagonal();
    check_signed_svd(M);
    EXPECT_LT((signed_svd(M).sigma - Vec3(1, 1, -1)).cwiseAbs().maxCoeff(), 1e-13);
    EXPECT_LT((signed_singular_values(M) - Vec3(1, 1, -1)).cwiseAbs().maxCoeff(), 1e-13);
  }
  check_signed_svd(Mat3::Identity());
  EXPECT_EQ(signed_svd(Mat3::Identity()).sigma, Vec3(1, 1, 1));
  EXPECT_EQ(signed_singular_values(-Mat3::Identity()), Vec3(1, 1, -1));
}

TEST(SignedSvd, DiagonalMatricesWithNegativeEntries) {
  // diag(d): |σ| are the |d_i| sorted decreasingly; σ3 carries the sign of Π d_i.
  const std::vector<Vec3> diags = {{-3, 2, 1}, {3, -2, 1},   {3, 2, -1}, {-1, -2, -3}, {-1, -2, 3},
                                   {1, -1, 1}, {-4, 0.5, 2}, {0, 1, 2},  {0, -1, -2},  {-2, -2, -2}};
  for (const Vec3& d : diags) {
    const Mat3 J = d.asDiagonal();
    check_signed_svd(J);
    std::vector<double> a = {std::abs(d(0)), std::abs(d(1)), std::abs(d(2))};
    std::sort(a.rbegin(), a.rend());
    const double prod = d.prod();
    const Vec3 expected(a[0], a[1], prod < 0 ? -a[2] : a[2]);
    EXPECT_LT((signed_svd(J).sigma - expected).cwiseAbs().maxCoeff(), 1e-14) << "diag " << d.transpose();
    EXPECT_LT((signed_singular_values(J) - expected).cwiseAbs().maxCoeff(), 1e-14)
        << "diag " << d.transpose();
  }
}

TEST(SignedSvd, ExtremeScales) {
  // Scale invariance: the properties are relative, so tiny and huge Jacobians must behave the same.
  std::mt19937 rng(41);
  for (const double scale : {1e-80, 1e-20, 1e20, 1e80})
    for (const double s3 : {0.3, -0.3}) check_known(scale * Vec3(1.7, 0.9, s3), rng);
}
