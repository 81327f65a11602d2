// Signed SVD (paper App. B) against truth: matrices built as R1 diag(σ) R2ᵀ from known signed singular
// values and random rotations, Eigen's unsigned singular values, the eigenvalues of JᵀJ, and the sign of det
// J.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <sstream>
#include <vector>

#include "lidef/internal/jacobi_singular_values.h"
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

TEST(SignedSvd, LanesGiveEachMatrixTheValuesOfTheSingleCall) {
  // The certificate computes its base centers' singular values kSvdLanes at a time: a matrix's values must
  // be bit-identical whatever its lane, its company (including matrices that converge later, singular ones,
  // NaN) and the number of lanes in use, so that a certificate does not depend on how its centers are
  // grouped; and they must be the known σ to within 1e-13 σ1 (an independent truth: J = R1 diag(σ) R2ᵀ).
  std::mt19937 rng(43);
  std::uniform_real_distribution<double> E(-14, 0), S(0, 1);
  std::vector<Mat3> J;
  std::vector<Vec3> known;
  for (int k = 0; k < 4000; ++k) {
    std::vector<double> v = {1.0, std::pow(10.0, E(rng)), std::pow(10.0, E(rng))};
    if (k % 5 == 0) v[2] = v[1] * (1 + 1e-9 * S(rng));  // nearly repeated
    if (k % 7 == 0) v = {1 + 1e-8 * S(rng), 1 + 1e-8 * S(rng), 1 + 1e-8 * S(rng)};
    std::sort(v.rbegin(), v.rend());
    Vec3 sigma(v[0], v[1], v[2]);
    const double scale = std::pow(10.0, 10 * E(rng) / 14 + 5);
    if (S(rng) < 0.5) sigma(2) = -sigma(2);
    J.push_back(scale * random_rotation(rng) * sigma.asDiagonal() * random_rotation(rng).transpose());
    known.push_back(scale * sigma);
  }
  Mat3 odd[3] = {Mat3::Zero(), Mat3::Identity(), Mat3::Constant(std::nan(""))};
  for (size_t k = 0; k < J.size(); ++k) {
    bool r1 = false;
    const Vec3 single = signed_singular_values(J[k], &r1);
    // Unsigned against the known values and Eigen's JacobiSVD (the sign of a σ3 below ~1e-11 σ1 may be
    // unresolved: σ3 is then reported as 0, SignedSvd.NearSingularMatrices).
    Vec3 unsigned_sv;
    jacobi_singular_values(&J[k], 1, &unsigned_sv);
    EXPECT_LE((unsigned_sv - known[k].cwiseAbs()).cwiseAbs().maxCoeff(), 1e-13 * known[k](0)) << show(J[k]);
    EXPECT_LE((unsigned_sv - Eigen::JacobiSVD<Mat3>(J[k]).singularValues()).cwiseAbs().maxCoeff(),
              1e-13 * known[k](0));
    if (r1 && single(2) != 0) {
      EXPECT_EQ(single(2) < 0, known[k](2) < 0) << show(J[k]);
    }
    // Every lane, with random company and a random number of lanes.
    const int n = 1 + static_cast<int>(k % kSvdLanes), lane = static_cast<int>((k / kSvdLanes) % n);
    Mat3 group[kSvdLanes];
    for (int l = 0; l < n; ++l)
      group[l] = l == lane ? J[k] : (l % 4 == 3 ? odd[(k + l) % 3] : J[(k * 7 + l) % J.size()]);
    Vec3 out[kSvdLanes];
    bool res[kSvdLanes];
    signed_singular_values_lanes(group, n, out, res);
    EXPECT_EQ(out[lane], single) << "lane " << lane << " of " << n << show(J[k]);
    EXPECT_EQ(res[lane], r1);
  }
}

// ---------------------------------------------------------------- the error-bounded sign of det J

namespace {

// Exact arithmetic on doubles (Shewchuk's expansions): a·b = p + e exactly (fma), a + b = s + e exactly.
void two_prod(double a, double b, double& p, double& e) {
  p = a * b;
  e = std::fma(a, b, -p);
}
void two_sum(double a, double b, double& s, double& e) {
  s = a + b;
  const double bb = s - a;
  e = (a - (s - bb)) + (b - bb);
}
// Adds x to a nonoverlapping expansion kept in increasing magnitude order (GROW-EXPANSION).
void grow(std::vector<double>& h, double x) {
  double q = x;
  for (double& hi : h) {
    double s, e;
    two_sum(q, hi, s, e);
    hi = e;
    q = s;
  }
  h.push_back(q);
}

// The exact det J as an expansion (no overflow or underflow for the magnitudes used here): the sign is the
// sign of its largest nonzero component; `approx` its value to ~1e-15 relative.
int exact_det_sign(const Mat3& J, double* approx = nullptr) {
  std::vector<double> h;
  const int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {1, 0, 2}, {2, 1, 0}};
  for (int k = 0; k < 6; ++k) {
    const double sgn = k < 3 ? 1.0 : -1.0;
    double p, e;
    two_prod(J(0, perm[k][0]), J(1, perm[k][1]), p, e);
    for (double t : {p, e}) {
      double q, f;
      two_prod(t, J(2, perm[k][2]), q, f);
      grow(h, sgn * q);
      grow(h, sgn * f);
    }
  }
  if (approx) {
    double s = 0;
    for (double x : h) s += x;  // increasing magnitude, nonoverlapping: accurate to ~u
    *approx = s;
  }
  for (auto it = h.rbegin(); it != h.rend(); ++it)
    if (*it != 0) return *it > 0 ? 1 : -1;
  return 0;
}

// det_sign is never wrong; 0 only when the exact |det J| is within twice the bound (|fl(det)| ≤ bound and
// |fl(det) − det| ≤ bound; gcc -O1's fused multiply-adds under ASan reach 1.01 × bound) or det J = 0; σ3's
// sign from signed_singular_values and signed_svd is the exact sign when resolved, and σ3 = 0 when not.
int check_det_sign(const Mat3& J) {
  SCOPED_TRACE(show(J));
  double exact = 0;
  const int truth = exact_det_sign(J, &exact);
  const DetSign d = det_sign_bounded(J);
  EXPECT_EQ(d.sign, det_sign(J));
  // Eigen's determinant is another evaluation of the same Leibniz sum (expanded along a column), so it obeys
  // the same bound; bit equality is not promised: whether a*b - c*d becomes an FMA depends on the compiler
  // and the optimization level (gcc -O1 under ASan, clang's -ffp-contract=on), and the bound holds either
  // way.
  EXPECT_LE(std::abs(d.det - J.determinant()), 2 * d.bound) << "our determinant and Eigen's disagree";
  EXPECT_LE(std::abs(d.det - exact), d.bound * (1 + 1e-12)) << "the bound does not hold";
  if (d.sign != 0) {
    EXPECT_EQ(d.sign, truth) << "det_sign is wrong: exact det " << exact;
    EXPECT_TRUE(d.resolved);
  } else {
    EXPECT_LE(std::abs(exact), 2 * d.bound * (1 + 1e-12)) << "left unresolved although |det| > 2 bound";
    if (d.resolved) {
      EXPECT_EQ(truth, 0);
    }
  }
  bool resolved = false;
  const Vec3 s = signed_singular_values(J, &resolved);
  EXPECT_EQ(resolved, d.resolved);
  const double s3_svd = signed_svd(J).sigma(2);
  if (d.sign == 0) {
    EXPECT_EQ(s(2), 0.0);
    EXPECT_EQ(s3_svd, 0.0);
  } else {
    if (s(2) != 0) {
      EXPECT_EQ(s(2) < 0, truth < 0) << "sigma3 " << s(2);
    }
    if (s3_svd != 0) {
      EXPECT_EQ(s3_svd < 0, truth < 0) << "sigma3 (signed_svd) " << s3_svd;
    }
  }
  return d.sign;
}

// A few ulps in a random direction on every nonzero entry (zeros stay zero: an ulp of 0 is subnormal, and the
// exact reference above assumes no underflow).
Mat3 perturb_ulps(Mat3 J, std::mt19937& rng, int max_ulps) {
  std::uniform_int_distribution<int> k(-max_ulps, max_ulps);
  for (int q = 0; q < 9; ++q) {
    const int n = k(rng);
    double& x = J.data()[q];
    if (x == 0) continue;
    for (int i = 0; i < std::abs(n); ++i) x = std::nextafter(x, n > 0 ? HUGE_VAL : -HUGE_VAL);
  }
  return J;
}

Mat3 random_integer_matrix(std::mt19937& rng, int rank) {
  std::uniform_int_distribution<int> I(-9, 9);
  auto vec = [&] { return Vec3(I(rng), I(rng), I(rng)); };
  const Vec3 a = vec(), b = vec(), c = vec();
  if (rank == 1) return a * b.transpose();
  if (rank == 2) return a * b.transpose() + c * vec().transpose();
  return (Mat3() << a.transpose(), b.transpose(), c.transpose()).finished();
}

}  // namespace

TEST(SignedSvd, DetSignOfExactlySingularIntegerMatrices) {
  std::mt19937 rng(43);
  int unresolved = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const int rank = 1 + trial % 2;
    std::uniform_int_distribution<int> E(-60, 60);
    const Mat3 J = std::ldexp(1.0, E(rng)) * random_integer_matrix(rng, rank);  // exact in binary
    ASSERT_EQ(exact_det_sign(J), 0);
    EXPECT_EQ(check_det_sign(J), 0) << "rank " << rank;  // det J = 0: no sign may be claimed
    unresolved += !det_sign_bounded(J).resolved;
  }
  EXPECT_GT(unresolved, 1000);  // most are not structurally zero
  // The matrices the header names: rank 2 and rank 1 without zero entries, unresolved; zero rows or
  // columns: det J = 0 exactly, resolved.
  const Mat3 rank2 = (Mat3() << 1, 2, 3, 4, 5, 6, 7, 8, 9).finished();
  EXPECT_FALSE(det_sign_bounded(rank2).resolved);
  EXPECT_EQ(signed_singular_values(rank2)(2), 0.0);
  EXPECT_FALSE(det_sign_bounded(Vec3(1, 2, 3) * Vec3(-1, 1, 2).transpose()).resolved);
  for (const Mat3& Z : {Mat3(Mat3::Zero()), Mat3((Mat3() << 1, 2, 3, 0, 0, 0, 7, 8, 9).finished()),
                        Mat3((Mat3() << 1, 0, 3, 4, 0, 6, 7, 0, 9).finished())}) {
    const DetSign d = det_sign_bounded(Z);
    EXPECT_TRUE(d.resolved);
    EXPECT_EQ(d.sign, 0);
    EXPECT_EQ(signed_singular_values(Z)(2), 0.0);
  }
}

TEST(SignedSvd, DetSignOfSingularMatricesPerturbedByUlps) {
  std::mt19937 rng(47);
  int resolved = 0, total = 0;
  for (int trial = 0; trial < 6000; ++trial) {
    const int rank = 1 + trial % 3;
    std::uniform_int_distribution<int> E(-30, 30);
    const Mat3 base = std::ldexp(1.0, E(rng)) * random_integer_matrix(rng, rank);
    const Mat3 J = perturb_ulps(base, rng, 1 + trial % 4);
    resolved += check_det_sign(J) != 0;
    ++total;
  }
  std::cout << resolved << " of " << total << " perturbed matrices resolved\n";
  EXPECT_GT(resolved, 0);
}

TEST(SignedSvd, DetSignOfRotatedNearlyDoublySingularMatrices) {
  // U diag(s) Vᵀ with s3 = ±1e-17 s1 (and s2 small too): the rounded matrix's exact sign is whatever it is;
  // det_sign must never contradict it.
  std::mt19937 rng(53);
  std::uniform_real_distribution<double> S(0.0, 1.0);
  for (int trial = 0; trial < 4000; ++trial) {
    const double s1 = std::ldexp(1.0 + S(rng), trial % 40 - 20);
    const double s2 = s1 * (trial % 2 ? S(rng) : 1e-9 * S(rng));
    const double s3 = (trial % 4 < 2 ? 1e-17 : -1e-17) * s1;
    const Mat3 J = random_rotation(rng) * Vec3(s1, s2, s3).asDiagonal() * random_rotation(rng).transpose();
    check_det_sign(J);
  }
}

TEST(SignedSvd, DetSignResolvesWellConditionedMatrices) {
  // σ3 > 1e-6 σ1 (either sign): |det J| = σ1 σ2 |σ3| ≥ 1e-12 σ1³ is far above the bound (≤ 2⁻⁵⁰ · 6 ‖J‖³).
  std::mt19937 rng(59);
  std::uniform_real_distribution<double> S(0.0, 1.0);
  for (int trial = 0; trial < 20000; ++trial) {
    const double s1 = std::ldexp(1.0 + S(rng), trial % 200 - 100);
    const double s3 = s1 * std::pow(10.0, -6.0 * S(rng)) * (1 + 1e-3);
    const double s2 = s3 + (s1 - s3) * S(rng);
    const double sg = trial % 2 ? 1.0 : -1.0;
    const Mat3 J =
        random_rotation(rng) * Vec3(s1, s2, sg * s3).asDiagonal() * random_rotation(rng).transpose();
    const int s = check_det_sign(J);
    ASSERT_EQ(s, sg > 0 ? 1 : -1) << show(J);
  }
  // Random Gaussian matrices with σ3 > 1e-6 σ1.
  std::normal_distribution<double> N01;
  for (int trial = 0; trial < 20000; ++trial) {
    Mat3 J;
    for (int q = 0; q < 9; ++q) J.data()[q] = N01(rng);
    const Vec3 sv = Eigen::JacobiSVD<Mat3>(J).singularValues();
    if (!(sv(2) > 1e-6 * sv(0))) continue;
    ASSERT_NE(check_det_sign(J), 0) << show(J);
  }
}
