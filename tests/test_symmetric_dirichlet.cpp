// Symmetric Dirichlet energy, gradient and (projected) Hessian against independent truths: the singular
// values of Eigen's SVD, ‖J‖² + ‖J⁻¹‖², central finite differences of the energy and of the gradient (with
// the column-major vec index a + 3b written out explicitly), Eigen's numerical eigen-decomposition of the
// unprojected Hessian, and the closed-form Hessian at the identity.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <vector>

#include "lidef/internal/sd_lanes.h"
#include "lidef/signed_svd.h"
#include "lidef/symmetric_dirichlet.h"

using namespace lidef;

namespace {

std::string show(const Mat3& J) {
  std::ostringstream s;
  s.precision(17);
  s << "\nJ =\n" << J << "\nsigma = " << signed_singular_values(J).transpose();
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

Mat3 with_sigma(std::mt19937& rng, double s1, double s2, double s3) {
  return random_rotation(rng) * Vec3(s1, s2, s3).asDiagonal() * random_rotation(rng).transpose();
}

// Test matrices with det > 0: generic, near-singular (σ3 down to 1e-3), near-repeated and exactly repeated σ,
// strong stretch, and plain random Gaussian matrices (sign-fixed).
std::vector<Mat3> positive_jacobians() {
  std::mt19937 rng(20210801);
  std::uniform_real_distribution<double> U(0.3, 2.5);
  std::vector<Mat3> out;
  for (int k = 0; k < 12; ++k) {
    double s[3] = {U(rng), U(rng), U(rng)};
    std::sort(s, s + 3, [](double a, double b) { return a > b; });
    out.push_back(with_sigma(rng, s[0], s[1], s[2]));
  }
  for (double s3 : {1e-1, 1e-2, 1e-3}) out.push_back(with_sigma(rng, 1.7, 0.9, s3));
  out.push_back(with_sigma(rng, 1.3, 1.3 + 1e-9, 0.7));   // near-repeated σ1 ≈ σ2
  out.push_back(with_sigma(rng, 1.2, 0.8, 0.8 - 1e-10));  // near-repeated σ2 ≈ σ3
  out.push_back(with_sigma(rng, 2.0, 2.0, 0.5));          // exactly repeated (up to rounding of R Σ Rᵀ)
  out.push_back(with_sigma(rng, 0.6, 0.6, 0.6));          // compressed similarity: all twists negative
  out.push_back(with_sigma(rng, 5.0, 1.0, 0.2));          // strong anisotropy
  out.push_back(Vec3(2, 2, 0.5).asDiagonal().toDenseMatrix());
  std::normal_distribution<double> N01;
  for (int k = 0; k < 6; ++k) {
    Mat3 G;
    for (int e = 0; e < 9; ++e) G(e / 3, e % 3) = N01(rng);
    if (G.determinant() < 0) G.col(0) *= -1;
    out.push_back(G);
  }
  return out;
}

double smallest_sv(const Mat3& J) {
  return Eigen::JacobiSVD<Mat3>(J).singularValues()(2);
}

// Central differences of the energy, step h = t·σ3 (the energy varies on the scale of the smallest σ).
Mat3 fd_gradient(const Mat3& J) {
  const double h = 1e-5 * smallest_sv(J);
  Mat3 G;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      Mat3 Jp = J, Jm = J;
      Jp(a, b) += h;
      Jm(a, b) -= h;
      G(a, b) = (sd_energy(Jp) - sd_energy(Jm)) / (2 * h);
    }
  return G;
}

// Central differences of the gradient; column-major vec index a + 3b written out (not via Eigen's storage).
Mat9 fd_hessian(const Mat3& J) {
  const double h = 1e-5 * smallest_sv(J);
  Mat9 H;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      Mat3 Jp = J, Jm = J;
      Jp(a, b) += h;
      Jm(a, b) -= h;
      const Mat3 dG = (sd_gradient(Jp) - sd_gradient(Jm)) / (2 * h);
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d) H(c + 3 * d, a + 3 * b) = dG(c, d);
    }
  return H;
}

// Projection by brute force: numerical eigen-decomposition, eigenvalues clamped at 0, reassembled.
Mat9 numeric_psd(const Mat9& H) {
  const Eigen::SelfAdjointEigenSolver<Mat9> es(H);
  return es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).asDiagonal() * es.eigenvectors().transpose();
}

double rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / b.norm();
}

bool all_finite(const Eigen::MatrixXd& M) {
  return M.allFinite();
}

}  // namespace

TEST(SymmetricDirichlet, EnergyMatchesSingularValuesAndInverse) {
  for (const Mat3& J : positive_jacobians()) {
    SCOPED_TRACE(show(J));
    const double E = sd_energy(J);
    const Vec3 s = signed_svd(J).sigma;
    double Es = 0;
    for (int i = 0; i < 3; ++i) Es += s(i) * s(i) + 1.0 / (s(i) * s(i));
    // Eigen's unsigned SVD (independent of the signed one).
    const Vec3 u = Eigen::JacobiSVD<Mat3>(J).singularValues();
    const double Eu = u.squaredNorm() + u.cwiseInverse().squaredNorm();
    const double Ef = J.squaredNorm() + J.inverse().squaredNorm();
    const double kappa = u(0) / u(2);
    EXPECT_NEAR(E, Es, 1e-13 * kappa * E);
    EXPECT_NEAR(E, Eu, 1e-13 * kappa * E);
    EXPECT_NEAR(E, Ef, 1e-13 * kappa * E);  // J⁻¹ rounding grows with κ (FMA contraction may differ)
    EXPECT_GE(E, 6.0 - 1e-12);              // Σ σ² + σ⁻² ≥ 6, equality only at rotations
  }
}

TEST(SymmetricDirichlet, IdentityAndRotationsGiveSix) {
  EXPECT_DOUBLE_EQ(sd_energy(Mat3::Identity()), 6.0);
  std::mt19937 rng(7);
  for (int k = 0; k < 10; ++k) EXPECT_NEAR(sd_energy(random_rotation(rng)), 6.0, 1e-13);
  // Away from rotations it is strictly larger: E(s I) = 3 (s² + s⁻²).
  EXPECT_NEAR(sd_energy(2.0 * Mat3::Identity()), 3 * (4 + 0.25), 1e-13);
  EXPECT_NEAR(sd_energy(0.5 * Mat3::Identity()), 3 * (4 + 0.25), 1e-13);
}

TEST(SymmetricDirichlet, RotationInvariance) {
  std::mt19937 rng(11);
  for (const Mat3& J : positive_jacobians()) {
    SCOPED_TRACE(show(J));
    const double E = sd_energy(J);
    const double kappa = Eigen::JacobiSVD<Mat3>(J).singularValues()(0) / smallest_sv(J);
    for (int k = 0; k < 3; ++k) {
      const Mat3 R = random_rotation(rng);
      EXPECT_NEAR(sd_energy(R * J), E, 1e-13 * kappa * E);
      EXPECT_NEAR(sd_energy(J * R), E, 1e-13 * kappa * E);
    }
  }
}

TEST(SymmetricDirichlet, BarrierInfiniteForNonPositiveDeterminant) {
  const double inf = std::numeric_limits<double>::infinity();
  std::mt19937 rng(13);
  const Mat3 reflection = Vec3(1, 1, -1).asDiagonal();
  EXPECT_EQ(sd_energy(reflection), inf);
  EXPECT_EQ(sd_energy(-Mat3::Identity()), inf);
  EXPECT_EQ(sd_energy(Mat3::Zero()), inf);
  EXPECT_EQ(sd_energy(Vec3(1, 2, 0).asDiagonal().toDenseMatrix()), inf);  // det = 0 exactly
  for (int k = 0; k < 10; ++k) {
    const Mat3 J = with_sigma(rng, 1.5, 1.0, -0.1 * (k + 1));  // det < 0
    ASSERT_LT(J.determinant(), 0);
    EXPECT_EQ(sd_energy(J), inf) << show(J);
    // Derivatives are outside their domain: NaN, never a finite (wrong) value.
    EXPECT_TRUE(sd_gradient(J).array().isNaN().all());
    EXPECT_TRUE(sd_hessian(J).array().isNaN().all());
    EXPECT_TRUE(sd_hessian_psd(J).array().isNaN().all());
  }
  // Finite just on the positive side, and blowing up as det → 0⁺.
  EXPECT_TRUE(std::isfinite(sd_energy(Vec3(1, 1, 1e-8).asDiagonal().toDenseMatrix())));
  EXPECT_GT(sd_energy(Vec3(1, 1, 1e-8).asDiagonal().toDenseMatrix()), 1e15);
}

TEST(SymmetricDirichlet, GradientMatchesFiniteDifferencesAndSvdForm) {
  for (const Mat3& J : positive_jacobians()) {
    SCOPED_TRACE(show(J));
    const Mat3 G = sd_gradient(J);
    ASSERT_TRUE(all_finite(G));
    EXPECT_LT(rel(G, fd_gradient(J)), 1e-6);
    // App. G (63): ∂E/∂J = U diag(2σ − 2σ⁻³) Vᵀ.
    const SignedSvd d = signed_svd(J);
    const Vec3 dE = 2 * d.sigma - 2 * d.sigma.cwiseInverse().array().cube().matrix();
    const Mat3 Gsvd = d.U * dE.asDiagonal() * d.V.transpose();
    EXPECT_LT(rel(G, Gsvd), 1e-10);
  }
  // Zero at rotations (the minimum).
  std::mt19937 rng(17);
  for (int k = 0; k < 5; ++k) EXPECT_LT(sd_gradient(random_rotation(rng)).norm(), 1e-13);
}

TEST(SymmetricDirichlet, HessianMatchesFiniteDifferencesAndIsSymmetric) {
  for (const Mat3& J : positive_jacobians()) {
    SCOPED_TRACE(show(J));
    const Mat9 H = sd_hessian(J);
    ASSERT_TRUE(all_finite(H));
    EXPECT_LT(rel(H, fd_hessian(J)), 1e-5);
    EXPECT_LE((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-14 * H.norm());
  }
}

// The closed-form Hessian-vector product (the solver's conjugate-gradient correction) against the
// eigensystem's matrix and against central differences of the gradient, for random directions at every test
// Jacobian (compressed, stretched, nearly singular, repeated σ); NaN where det J ≤ 0.
TEST(SymmetricDirichlet, HessianTimesMatchesTheMatrixAndGradientDifferences) {
  std::mt19937 rng(23);
  std::normal_distribution<double> nd;
  for (const Mat3& J : positive_jacobians()) {
    SCOPED_TRACE(show(J));
    const Mat9 H = sd_hessian(J);
    for (int k = 0; k < 4; ++k) {
      Mat3 D;
      for (int i = 0; i < 9; ++i) D(i) = nd(rng);
      const Mat3 HD = sd_hessian_times(J, D);
      const Vec9 ref = H * Eigen::Map<const Vec9>(D.data());
      EXPECT_LT((Eigen::Map<const Vec9>(HD.data()) - ref).norm(), 1e-10 * (ref.norm() + H.norm()));
      const double h = 1e-6 * J.norm() / D.norm();
      const Mat3 fd = (sd_gradient(J + h * D) - sd_gradient(J - h * D)) / (2 * h);
      EXPECT_LT(rel(HD, fd), 1e-5);
    }
  }
  Mat3 flipped = Mat3::Identity();
  flipped(2, 2) = -1;
  EXPECT_TRUE(sd_hessian_times(flipped, Mat3::Identity()).array().isNaN().all());
}

// The vec convention, stated without index arithmetic: d²/dt² E(J + tD) = vec(D)ᵀ H vec(D) with vec
// column-major, for a non-symmetric direction D (a row-major reading of H gives a different number).
TEST(SymmetricDirichlet, HessianUsesColumnMajorVec) {
  std::mt19937 rng(19);
  const Mat3 J = with_sigma(rng, 1.6, 0.9, 0.5);
  Mat3 D;
  D << 0.3, -1.2, 0.7, 0.1, 0.4, -0.9, 2.0, 0.05, -0.3;
  const double h = 1e-4;
  const double second = (sd_energy(J + h * D) - 2 * sd_energy(J) + sd_energy(J - h * D)) / (h * h);
  const Mat9 H = sd_hessian(J);
  Vec9 col, row;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      col(a + 3 * b) = D(a, b);
      row(3 * a + b) = D(a, b);
    }
  EXPECT_NEAR(col.dot(H * col), second, 1e-5 * std::abs(second));
  EXPECT_GT(std::abs(row.dot(H * row) - second), 1e-2 * std::abs(second));
}

TEST(SymmetricDirichlet, ProjectionMatchesNumericalEigenDecomposition) {
  int indefinite = 0;
  for (const Mat3& J : positive_jacobians()) {
    SCOPED_TRACE(show(J));
    const Mat9 H = sd_hessian(J);
    const Mat9 P = sd_hessian_psd(J);
    ASSERT_TRUE(all_finite(P));
    EXPECT_LT(rel(P, numeric_psd(H)), 1e-8);
    EXPECT_LE((P - P.transpose()).cwiseAbs().maxCoeff(), 1e-14 * P.norm());
    const Eigen::SelfAdjointEigenSolver<Mat9> es(P);
    EXPECT_GE(es.eigenvalues().minCoeff(), -1e-10 * P.norm());
    // The analytic eigenvalues are the numerical ones: compare the spectra of H.
    const Vec9 ev = Eigen::SelfAdjointEigenSolver<Mat9>(H).eigenvalues();
    if (ev(0) < -1e-8 * H.norm()) {
      ++indefinite;
      EXPECT_GT((P - H).norm(), 1e-8 * H.norm());  // the projection did something
    }
  }
  EXPECT_GT(indefinite, 3);  // the set of test matrices exercises the clamping
}

// Where every twist eigenvalue 2 − 2(σi² − σiσj + σj²)/(σi³σj³) is ≥ 0 (e.g. all σ ≥ 1, pure stretch near the
// identity), H is PSD and the projection must change nothing. Compression (σ < 1) is not convex even near
// the identity: there the twist modes are clamped.
TEST(SymmetricDirichlet, ProjectionIsIdentityWhereConvex) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> U(1.0, 1.2);
  for (int k = 0; k < 20; ++k) {
    double s[3] = {U(rng), U(rng), U(rng)};
    std::sort(s, s + 3, [](double a, double b) { return a > b; });
    const Mat3 J = with_sigma(rng, s[0], s[1], s[2]);
    SCOPED_TRACE(show(J));
    const Mat9 H = sd_hessian(J);
    EXPECT_LE((sd_hessian_psd(J) - H).norm(), 1e-14 * H.norm());
    EXPECT_GE(Eigen::SelfAdjointEigenSolver<Mat9>(H).eigenvalues().minCoeff(), -1e-12 * H.norm());
  }
  for (double s : {1.0, 1.05}) {
    const Mat3 J = s * Mat3::Identity();
    EXPECT_LE((sd_hessian_psd(J) - sd_hessian(J)).norm(), 1e-14 * sd_hessian(J).norm()) << s;
  }
  // J = 0.9 I: three twist eigenvalues 2 − 2/0.9⁴ < 0; the projection removes exactly them.
  const Mat3 J = 0.9 * Mat3::Identity();
  const Vec9 ev = Eigen::SelfAdjointEigenSolver<Mat9>(sd_hessian(J)).eigenvalues();
  const double twist = 2 - 2 / std::pow(0.9, 4);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(ev(k), twist, 1e-12);
  EXPECT_GT(ev(3), 0);
  const Vec9 evp = Eigen::SelfAdjointEigenSolver<Mat9>(sd_hessian_psd(J)).eigenvalues();
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(evp(k), 0.0, 1e-12);
  for (int k = 3; k < 9; ++k) EXPECT_NEAR(evp(k), ev(k), 1e-12);
}

// Repeated singular values make the SVD (and the eigenvectors) non-unique; the derivatives must be finite and
// right regardless.
TEST(SymmetricDirichlet, RepeatedSingularValues) {
  std::mt19937 rng(29);
  std::vector<Mat3> cases = {Mat3::Identity(), Vec3(2, 2, 0.5).asDiagonal().toDenseMatrix(),
                             Vec3(0.7, 0.7, 0.7).asDiagonal().toDenseMatrix()};
  for (int k = 0; k < 5; ++k) cases.push_back(random_rotation(rng));
  for (const Mat3& J : cases) {
    SCOPED_TRACE(show(J));
    const Mat3 G = sd_gradient(J);
    const Mat9 H = sd_hessian(J), P = sd_hessian_psd(J);
    ASSERT_TRUE(all_finite(G));
    ASSERT_TRUE(all_finite(H));
    ASSERT_TRUE(all_finite(P));
    EXPECT_LT(rel(H, fd_hessian(J)), 1e-5);
    EXPECT_LT(rel(P, numeric_psd(H)), 1e-8);
  }
  // Closed form at the identity: scaling 8, flip 2 + 6 = 8, twist 0, so H = 8 (I₉ − P_skew) with P_skew the
  // projector onto vec of skew-symmetric matrices: P_skew vec(D) = vec((D − Dᵀ)/2).
  Mat9 Pskew = Mat9::Zero();
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      Pskew(a + 3 * b, a + 3 * b) += 0.5;
      Pskew(a + 3 * b, b + 3 * a) -= 0.5;
    }
  const Mat9 H_identity = 8.0 * (Mat9::Identity() - Pskew);
  EXPECT_LE((sd_hessian(Mat3::Identity()) - H_identity).cwiseAbs().maxCoeff(), 1e-13);
  EXPECT_LE((sd_hessian_psd(Mat3::Identity()) - H_identity).cwiseAbs().maxCoeff(), 1e-13);
  // ... and at any rotation R: H(R) = (I ⊗ R) H(I) (I ⊗ R)ᵀ, i.e. the same quadratic form in Rᵀ dJ.
  const Mat3 R = random_rotation(rng);
  const Mat9 HR = sd_hessian(R);
  Mat3 D;
  D << 0.3, -1.2, 0.7, 0.1, 0.4, -0.9, 2.0, 0.05, -0.3;
  const Mat3 RtD = R.transpose() * D;
  const Vec9 vD = Eigen::Map<const Vec9>(D.data()), vRtD = Eigen::Map<const Vec9>(RtD.data());
  EXPECT_NEAR(vD.dot(HR * vD), vRtD.dot(H_identity * vRtD), 1e-12 * vD.squaredNorm());
}

// The four-sample lanes of the energy passes (sd_lanes.h) against the scalar functions above, with the
// samples in the JT layout the passes read (J_i(a, b) = JT(3i + b, a)): every test Jacobian in every lane
// position, a direction per sample, a group cut short by `last` (its extra lanes repeat the last sample), and
// +∞ / NaN where det J ≤ 0 exactly as sd_energy, sd_gradient and sd_hessian_times give them.
TEST(SymmetricDirichlet, LanesMatchTheScalarFunctions) {
  std::vector<Mat3> Js = positive_jacobians();
  Mat3 flipped = Mat3::Identity();
  flipped(2, 2) = -1;
  Js.push_back(flipped);
  Js.push_back(Mat3::Zero());
  const long n = static_cast<long>(Js.size());
  std::mt19937 rng(29);
  std::normal_distribution<double> nd;
  MatJT JT(3 * n, 3), DT(3 * n, 3);
  std::vector<Mat3> Ds(n);
  for (long i = 0; i < n; ++i) {
    for (int k = 0; k < 9; ++k) Ds[i](k) = nd(rng);
    JT.middleRows<3>(3 * i) = Js[i].transpose();
    DT.middleRows<3>(3 * i) = Ds[i].transpose();
  }
  const auto close = [](double got, double want, double scale) {
    if (std::isnan(want)) return std::isnan(got);
    if (std::isinf(want)) return got == want;
    return std::abs(got - want) <= 1e-12 * scale;
  };
  for (long first = 0; first < n; ++first) {
    sd_lanes::Mat3Lanes J, D, g;
    const long last = std::min(n - 1, first + 2);  // three samples, then the last one again
    sd_lanes::load(JT.data(), JT.rows(), first, last, J);
    sd_lanes::load(DT.data(), DT.rows(), first, last, D);
    const sd_lanes::Lanes e = sd_lanes::energy(J), c = sd_lanes::curvature(J, D);
    sd_lanes::gradient(J, g);
    for (int k = 0; k < 4; ++k) {
      const long i = std::min(first + k, last);
      SCOPED_TRACE(show(Js[i]));
      const double inv_scale = Js[i].determinant() > 0 ? Js[i].inverse().squaredNorm() : 0.0;
      EXPECT_TRUE(close(e[k], sd_energy(Js[i]), Js[i].squaredNorm() + inv_scale)) << e[k];
      const Mat3 G = sd_gradient(Js[i]);
      const double gscale = G.allFinite() ? G.norm() + Js[i].norm() : 0.0;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) EXPECT_TRUE(close(g[a][b][k], G(a, b), gscale)) << a << b;
      const Mat3 HD = sd_hessian_times(Js[i], Ds[i]);
      const double want = Ds[i].cwiseProduct(HD).sum();
      const double cscale = HD.allFinite() ? Ds[i].norm() * HD.norm() : 0.0;
      EXPECT_TRUE(close(c[k], want, cscale)) << c[k] << " against " << want;
    }
  }
}
