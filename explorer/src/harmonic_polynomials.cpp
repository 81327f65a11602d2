#include "lidef/explorer/harmonic_polynomials.h"

#include <algorithm>
#include <cmath>
#include <mutex>

#include "lidef/errors.h"

namespace lidef {
namespace {

struct MonomialTable {
  std::array<std::array<int, 3>, kNumMonomials> exps{};
  int index[5][5][5];
  MonomialTable() {
    for (auto& a : index)
      for (auto& b : a)
        for (int& c : b) c = -1;
    int n = 0;
    for (int d = 0; d <= kMaxHarmonicDegree; ++d)
      for (int a = d; a >= 0; --a)
        for (int b = d - a; b >= 0; --b) {
          const int c = d - a - b;
          exps[n] = {a, b, c};
          index[a][b][c] = n++;
        }
  }
};
const MonomialTable& table() {
  static const MonomialTable t;
  return t;
}

// All monomial values at p (storage order).
std::array<double, kNumMonomials> monomial_values(const Vec3& p) {
  double px[5], py[5], pz[5];
  px[0] = py[0] = pz[0] = 1;
  for (int i = 1; i < 5; ++i) {
    px[i] = px[i - 1] * p.x();
    py[i] = py[i - 1] * p.y();
    pz[i] = pz[i - 1] * p.z();
  }
  std::array<double, kNumMonomials> v;
  const auto& e = table().exps;
  for (int m = 0; m < kNumMonomials; ++m) v[m] = px[e[m][0]] * py[e[m][1]] * pz[e[m][2]];
  return v;
}

double dot(const Polynomial& q, const std::array<double, kNumMonomials>& mv) {
  double s = 0;
  for (int m = 0; m < kNumMonomials; ++m) s += q.c[m] * mv[m];
  return s;
}

// q times x_axis (or times 1 for axis < 0). Throws Error if the degree would exceed 4.
Polynomial times(const Polynomial& q, int axis) {
  Polynomial r;
  const auto& e = table().exps;
  for (int m = 0; m < kNumMonomials; ++m) {
    if (q.c[m] == 0) continue;
    std::array<int, 3> x = e[m];
    ++x[axis];
    const int i = monomial_index(x[0], x[1], x[2]);
    if (i < 0) throw Error("harmonic polynomials: degree above 4");
    r.c[i] += q.c[m];
  }
  return r;
}
Polynomial lin(double a, const Polynomial& p, double b, const Polynomial& q) {
  Polynomial r;
  for (int m = 0; m < kNumMonomials; ++m) r.c[m] = a * p.c[m] + b * q.c[m];
  return r;
}

double double_factorial(int n) {  // n!! for n ≥ -1
  double r = 1;
  for (int k = n; k > 1; k -= 2) r *= k;
  return r;
}
// (1/4π) ∫_{S²} x^a y^b z^c dA = (a−1)!!(b−1)!!(c−1)!! / (a+b+c+1)!! for even a, b, c; 0 otherwise.
double sphere_moment(int a, int b, int c) {
  if (a % 2 || b % 2 || c % 2) return 0;
  return double_factorial(a - 1) * double_factorial(b - 1) * double_factorial(c - 1) /
         double_factorial(a + b + c + 1);
}

HarmonicPolynomialBasis build_basis(int degree) {
  // Q_l^m = (x+iy)^m Π(z, r²) with Q_{l+1}^m = ((2l+1) z Q_l^m − (l+m) r² Q_{l−1}^m)/(l−m+1): r^l P_l^m
  // e^{imφ} up to a constant factor (the associated Legendre recurrence times r^{l+1}). Re → C_l^m, Im →
  // S_l^m.
  const int D = degree;
  std::vector<std::vector<Polynomial>> re(D + 1, std::vector<Polynomial>(D + 1)),
      im(D + 1, std::vector<Polynomial>(D + 1));
  Polynomial one;
  one.c[0] = 1;
  Polynomial xr = one, xi;  // (x+iy)^m
  for (int m = 0; m <= D; ++m) {
    if (m > 0) {
      const Polynomial nr = lin(1, times(xr, 0), -1, times(xi, 1));
      const Polynomial ni = lin(1, times(xr, 1), 1, times(xi, 0));
      xr = nr;
      xi = ni;
    }
    re[m][m] = xr;
    im[m][m] = xi;
    for (int l = m; l + 1 <= D; ++l) {
      Polynomial ar = times(re[l][m], 2), ai = times(im[l][m], 2);
      Polynomial br, bi;  // r² Q_{l−1}^m
      if (l - 1 >= m) {
        for (int a = 0; a < 3; ++a) {
          br = lin(1, br, 1, times(times(re[l - 1][m], a), a));
          bi = lin(1, bi, 1, times(times(im[l - 1][m], a), a));
        }
      }
      const double s = 1.0 / (l - m + 1);
      re[l + 1][m] = lin(s * (2 * l + 1), ar, -s * (l + m), br);
      im[l + 1][m] = lin(s * (2 * l + 1), ai, -s * (l + m), bi);
    }
  }
  HarmonicPolynomialBasis b;
  b.degree = D;
  auto add = [&](const Polynomial& p, const std::string& name, int l) {
    const double rms = std::sqrt(sphere_mean_product(p, p));
    b.q.push_back(lin(1.0 / rms, p, 0, p));
    b.names.push_back(name);
    b.degree_of.push_back(l);
  };
  for (int l = 0; l <= D; ++l) {
    add(re[l][0], "C" + std::to_string(l) + ",0", l);
    for (int m = 1; m <= l; ++m) {
      add(re[l][m], "C" + std::to_string(l) + "," + std::to_string(m), l);
      add(im[l][m], "S" + std::to_string(l) + "," + std::to_string(m), l);
    }
  }
  return b;
}

int sym2(int b, int c) {
  static const int t[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
  return t[b][c];
}
// Index (0..9) of the third derivative ∂_b∂_c∂_d among the degree-3 monomials' exponent order.
int sym3(int b, int c, int d) {
  int e[3] = {0, 0, 0};
  ++e[b];
  ++e[c];
  ++e[d];
  return monomial_index(e[0], e[1], e[2]) - 10;
}

}  // namespace

const std::array<std::array<int, 3>, kNumMonomials>& monomial_exponents() {
  return table().exps;
}

int monomial_index(int a, int b, int c) {
  if (a < 0 || b < 0 || c < 0 || a + b + c > kMaxHarmonicDegree) return -1;
  return table().index[a][b][c];
}

double Polynomial::eval(const Vec3& p) const {
  return dot(*this, monomial_values(p));
}

int Polynomial::degree() const {
  int d = -1;
  const auto& e = table().exps;
  for (int m = 0; m < kNumMonomials; ++m)
    if (c[m] != 0) d = std::max(d, e[m][0] + e[m][1] + e[m][2]);
  return d;
}

Polynomial differentiate(const Polynomial& q, int i, int j, int k) {
  Polynomial r;
  const auto& e = table().exps;
  auto falling = [](int n, int k) {
    double f = 1;
    for (int t = 0; t < k; ++t) f *= n - t;
    return f;
  };
  for (int m = 0; m < kNumMonomials; ++m) {
    const int a = e[m][0], b = e[m][1], c = e[m][2];
    if (q.c[m] == 0 || a < i || b < j || c < k) continue;
    r.c[monomial_index(a - i, b - j, c - k)] += q.c[m] * falling(a, i) * falling(b, j) * falling(c, k);
  }
  return r;
}

Polynomial laplacian(const Polynomial& q) {
  return lin(1, lin(1, differentiate(q, 2, 0, 0), 1, differentiate(q, 0, 2, 0)), 1,
             differentiate(q, 0, 0, 2));
}

double sphere_mean_product(const Polynomial& q, const Polynomial& r) {
  const auto& e = table().exps;
  double s = 0;
  for (int i = 0; i < kNumMonomials; ++i) {
    if (q.c[i] == 0) continue;
    for (int j = 0; j < kNumMonomials; ++j)
      if (r.c[j] != 0)
        s += q.c[i] * r.c[j] * sphere_moment(e[i][0] + e[j][0], e[i][1] + e[j][1], e[i][2] + e[j][2]);
  }
  return s;
}

const HarmonicPolynomialBasis& harmonic_polynomial_basis(int degree) {
  if (degree < 0 || degree > kMaxHarmonicDegree)
    throw Error("harmonic polynomial degree must be in 0.." + std::to_string(kMaxHarmonicDegree) + " (got " +
                std::to_string(degree) + ")");
  static std::once_flag once;
  static std::array<HarmonicPolynomialBasis, kMaxHarmonicDegree + 1> bases;
  std::call_once(once, [] {
    for (int d = 0; d <= kMaxHarmonicDegree; ++d) bases[d] = build_basis(d);
  });
  return bases[degree];
}

double PolyJet::hessian_norm() const {
  return std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
}
double PolyJet::third_norm() const {
  double s = 0;
  for (const auto& Ta : T)
    for (const Mat3& M : Ta) s += M.squaredNorm();
  return std::sqrt(s);
}

HarmonicPolynomialMap::HarmonicPolynomialMap(int degree,
                                             const Eigen::Matrix<double, 3, Eigen::Dynamic>& coeffs)
    : degree_(degree), coeffs_(coeffs) {
  if (degree < 0 || degree > kMaxHarmonicDegree)
    throw InputError("", "harmonic polynomial degree must be in 0.." + std::to_string(kMaxHarmonicDegree) +
                             " (got " + std::to_string(degree) + ")");
  if (coeffs.cols() != harmonic_basis_size(degree))
    throw InputError("", "a degree-" + std::to_string(degree) + " harmonic polynomial map needs " +
                             std::to_string(harmonic_basis_size(degree)) + " coefficient columns (got " +
                             std::to_string(coeffs.cols()) + ")");
  if (!coeffs.allFinite()) throw InputError("", "harmonic polynomial map: non-finite coefficient");
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  for (int a = 0; a < 3; ++a) {
    for (int j = 0; j < B.size(); ++j) comp_[a] = lin(1, comp_[a], coeffs(a, j), B.q[j]);
    for (int m = 0; m < kNumMonomials; ++m) abs_sum_ += std::abs(comp_[a].c[m]);
    for (int b = 0; b < 3; ++b) d1_[a][b] = differentiate(comp_[a], b == 0, b == 1, b == 2);
    for (int b = 0; b < 3; ++b)
      for (int c = b; c < 3; ++c) d2_[a][sym2(b, c)] = differentiate(d1_[a][b], c == 0, c == 1, c == 2);
    for (int b = 0; b < 3; ++b)
      for (int c = b; c < 3; ++c)
        for (int d = c; d < 3; ++d)
          d3_[a][sym3(b, c, d)] = differentiate(d2_[a][sym2(b, c)], d == 0, d == 1, d == 2);
    for (int b = 0; b < 3; ++b)
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d)
          for (int e = 0; e < 3; ++e)
            fourth_[a][b][c](d, e) = differentiate(d3_[a][sym3(b, c, d)], e == 0, e == 1, e == 2).c[0];
  }
  double s = 0;
  for (const auto& Fa : fourth_)
    for (const auto& Fab : Fa)
      for (const Mat3& M : Fab) s += M.squaredNorm();
  fourth_norm_ = std::sqrt(s);
}

Eigen::Matrix<double, 3, Eigen::Dynamic> HarmonicPolynomialMap::affine_coefficients(int degree, const Mat3& A,
                                                                                    const Vec3& b) {
  // Project onto the sphere-orthonormal basis: every harmonic polynomial of degree ≤ D lies in its span.
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  if (degree < 1) throw Error("an affine map needs degree ≥ 1");
  Eigen::Matrix<double, 3, Eigen::Dynamic> C = Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, B.size());
  for (int a = 0; a < 3; ++a) {
    Polynomial f;
    f.c[0] = b(a);
    f.c[monomial_index(1, 0, 0)] = A(a, 0);
    f.c[monomial_index(0, 1, 0)] = A(a, 1);
    f.c[monomial_index(0, 0, 1)] = A(a, 2);
    for (int j = 0; j < B.size(); ++j) C(a, j) = sphere_mean_product(f, B.q[j]);
  }
  return C;
}

HarmonicPolynomialMap HarmonicPolynomialMap::from_components(int degree,
                                                             const std::array<Polynomial, 3>& components) {
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  Eigen::Matrix<double, 3, Eigen::Dynamic> C(3, B.size());
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < B.size(); ++j) C(a, j) = sphere_mean_product(components[a], B.q[j]);
  // Projection round-off (~1e-17) on coefficients that are exactly zero is set to zero, for readable files.
  const double cmax = C.cwiseAbs().maxCoeff();
  C = C.unaryExpr([cmax](double v) { return std::abs(v) < 1e-14 * cmax ? 0.0 : v; });
  HarmonicPolynomialMap m(degree, C);
  for (int a = 0; a < 3; ++a) {
    double err = 0, scale = 0;
    for (int k = 0; k < kNumMonomials; ++k) {
      err = std::max(err, std::abs(m.comp_[a].c[k] - components[a].c[k]));
      scale = std::max(scale, std::abs(components[a].c[k]));
    }
    if (err > 1e-12 * std::max(1.0, scale))
      throw InputError("", "component " + std::to_string(a + 1) +
                               " is not a harmonic polynomial of degree <= " + std::to_string(degree));
  }
  return m;
}

Eigen::Matrix<double, 3, Eigen::Dynamic> HarmonicPolynomialMap::identity_coefficients(int degree) {
  return affine_coefficients(degree, Mat3::Identity(), Vec3::Zero());
}

Vec3 HarmonicPolynomialMap::value(const Vec3& p) const {
  const auto mv = monomial_values(p);
  return Vec3(dot(comp_[0], mv), dot(comp_[1], mv), dot(comp_[2], mv));
}

PolyJet HarmonicPolynomialMap::jet(const Vec3& p, int order) const {
  const auto mv = monomial_values(p);
  PolyJet j;
  for (int a = 0; a < 3; ++a) {
    j.f(a) = dot(comp_[a], mv);
    for (int b = 0; b < 3; ++b) j.J(a, b) = dot(d1_[a][b], mv);
    if (order >= 2)
      for (int b = 0; b < 3; ++b)
        for (int c = b; c < 3; ++c) j.H[a](b, c) = j.H[a](c, b) = dot(d2_[a][sym2(b, c)], mv);
    if (order >= 3) {
      std::array<double, 10> t;
      for (int k = 0; k < 10; ++k) t[k] = dot(d3_[a][k], mv);
      for (int b = 0; b < 3; ++b)
        for (int c = 0; c < 3; ++c)
          for (int d = 0; d < 3; ++d) j.T[a][b](c, d) = t[sym3(b, c, d)];
    }
  }
  return j;
}

}  // namespace lidef
