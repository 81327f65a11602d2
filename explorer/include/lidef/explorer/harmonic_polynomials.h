// Closed-form harmonic maps on a ball (the σ3 explorer's polynomial family, docs/explorer.md):
//   f(x) = Σ_j c_j q_j(x),   c_j ∈ R³,  q_j the real solid harmonics of degree 0..D (D ≤ 4),
// i.e. f(x) = b + A x + Σ_k c_k h_k(x) with the vector-valued harmonic polynomials h_k = e_a q_j (deg q_j ≥
// 2). Every component of f is harmonic. Values and all derivatives up to order 4 are exact (polynomial
// differentiation), so J, H, the third derivatives T and the (constant) fourth derivatives F are exact.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "lidef/types.h"

namespace lidef {

// Largest supported degree (the fourth derivatives of a degree ≤ 4 map are constant, which keeps the
// certificate's Lipschitz bound of σ3 exact; see ball_certificate.h).
constexpr int kMaxHarmonicDegree = 4;
// Monomials x^a y^b z^c with a+b+c ≤ 4.
constexpr int kNumMonomials = 35;

// A scalar polynomial of degree ≤ 4 in monomial form.
struct Polynomial {
  std::array<double, kNumMonomials> c{};  // coefficient of each monomial (order: monomial_exponents())
  double eval(const Vec3& p) const;
  // Degree of the highest monomial with a nonzero coefficient (-1 for the zero polynomial).
  int degree() const;
};

// Exponents (a, b, c) of the monomials, in the storage order: by total degree, then lexicographic (a desc).
const std::array<std::array<int, 3>, kNumMonomials>& monomial_exponents();
// Index of the monomial x^a y^b z^c (a+b+c ≤ 4), -1 otherwise.
int monomial_index(int a, int b, int c);

// Exact partial derivative ∂^(i,j,k) of a polynomial.
Polynomial differentiate(const Polynomial& q, int i, int j, int k);
// Exact Laplacian.
Polynomial laplacian(const Polynomial& q);
// (1/4π) ∫_{S²} q r dA for polynomials q, r with deg q + deg r ≤ 8 (exact monomial moments of the unit
// sphere).
double sphere_mean_product(const Polynomial& q, const Polynomial& r);

// The scalar basis q_0 … q_{N−1}, N = (D+1)²: for each degree l = 0..D the 2l+1 real solid harmonics
// C_l^0, C_l^1, S_l^1, …, C_l^l, S_l^l (real and imaginary parts of the regular solid harmonics
// r^l P_l^m(cos θ) e^{imφ}, built by the standard recurrence), each scaled to unit RMS on the unit sphere.
// They are orthonormal for the sphere mean: (1/4π) ∫ q_i q_j dA = δ_ij.
struct HarmonicPolynomialBasis {
  int degree = 0;
  std::vector<Polynomial> q;       // N polynomials
  std::vector<std::string> names;  // "C2,1", "S3,2", … (C_l^m / S_l^m)
  std::vector<int> degree_of;      // N: l of each q_j
  int size() const { return static_cast<int>(q.size()); }
};
// Throws Error unless 0 ≤ degree ≤ kMaxHarmonicDegree.
const HarmonicPolynomialBasis& harmonic_polynomial_basis(int degree);
// N = (D+1)² basis functions of degree ≤ D.
inline int harmonic_basis_size(int degree) {
  return (degree + 1) * (degree + 1);
}

// f, J, H, third and fourth derivatives of a map at one point:
//   J(a,b) = ∂_b f_a,  H[a](b,c) = ∂_b∂_c f_a,  T[a][b](c,d) = ∂_b∂_c∂_d f_a,  F[a][b][c](d,e) = ∂⁴ f_a.
struct PolyJet {
  Vec3 f = Vec3::Zero();
  Mat3 J = Mat3::Zero();
  std::array<Mat3, 3> H{};
  std::array<std::array<Mat3, 3>, 3> T{};
  // Full Frobenius norms of the tensors (every entry, permutations counted separately): 27, 81 and 243
  // entries.
  double hessian_norm() const;
  double third_norm() const;
};

// A harmonic polynomial map R³ → R³ of degree ≤ D: f(x) = Σ_j coeffs.col(j) q_j(x).
class HarmonicPolynomialMap {
 public:
  HarmonicPolynomialMap() : HarmonicPolynomialMap(1, identity_coefficients(1)) {}
  // coeffs: 3 by (D+1)², columns in basis order. Throws InputError on a wrong shape or non-finite value.
  HarmonicPolynomialMap(int degree, const Eigen::Matrix<double, 3, Eigen::Dynamic>& coeffs);

  // Coefficients of the identity f(x) = x in the basis of degree D (3 by (D+1)²).
  static Eigen::Matrix<double, 3, Eigen::Dynamic> identity_coefficients(int degree);
  // Coefficients of the affine map A x + b (exact: C_1^1 = −x/2, S_1^1 = −y/2, C_1^0 = z before scaling).
  static Eigen::Matrix<double, 3, Eigen::Dynamic> affine_coefficients(int degree, const Mat3& A,
                                                                      const Vec3& b);

  // The map with the given components (monomial form) in the basis of degree D. Throws InputError when a
  // component is not harmonic or has degree above D (it is then not reproduced by its projection).
  static HarmonicPolynomialMap from_components(int degree, const std::array<Polynomial, 3>& components);

  int degree() const { return degree_; }
  const Eigen::Matrix<double, 3, Eigen::Dynamic>& coefficients() const { return coeffs_; }
  // The components f_a in monomial form.
  const std::array<Polynomial, 3>& components() const { return comp_; }

  Vec3 value(const Vec3& p) const;
  // order 1: f, J; 2: + H; 3: + T.
  PolyJet jet(const Vec3& p, int order = 3) const;
  // The fourth derivative tensor (constant in p for degree ≤ 4), as 3×3×3 of Mat3, and its Frobenius norm.
  const std::array<std::array<std::array<Mat3, 3>, 3>, 3>& fourth() const { return fourth_; }
  double fourth_norm() const { return fourth_norm_; }
  // Σ of |monomial coefficients| (a scale for rounding allowances).
  double abs_coefficient_sum() const { return abs_sum_; }

 private:
  int degree_;
  Eigen::Matrix<double, 3, Eigen::Dynamic> coeffs_;
  std::array<Polynomial, 3> comp_;
  // Derivative polynomials, so jet() is a plain evaluation: d1[a][b], d2[a][sym bc], d3[a][sym bcd].
  std::array<std::array<Polynomial, 3>, 3> d1_;
  std::array<std::array<Polynomial, 6>, 3> d2_;
  std::array<std::array<Polynomial, 10>, 3> d3_;
  std::array<std::array<std::array<Mat3, 3>, 3>, 3> fourth_{};
  double fourth_norm_ = 0, abs_sum_ = 0;
};

}  // namespace lidef
