#include "lidef/analysis/interval_verification.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <boost/numeric/interval.hpp>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/signed_svd.h"

namespace lidef {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// The next double above x (what std::nextafter(x, +∞) returns, without its call and errno handling): the
// bit pattern of a finite double moves by one ulp per unit, up for positive and down for negative values.
inline double step_up(double x) {
  if (!(x < kInf)) return x;  // +∞ or NaN
  if (x == 0) return std::numeric_limits<double>::denorm_min();
  std::uint64_t b;
  std::memcpy(&b, &x, sizeof b);
  b = x > 0 ? b + 1 : b - 1;
  std::memcpy(&x, &b, sizeof b);
  return x;
}
inline double step_down(double x) {
  return -step_up(-x);
}
inline double steps_up(double x, int n) {
  for (int i = 0; i < n; ++i) x = step_up(x);
  return x;
}
inline double steps_down(double x, int n) {
  for (int i = 0; i < n; ++i) x = step_down(x);
  return x;
}

// Boost.Interval rounding policy without any change of the FPU rounding mode: every operation is computed
// rounded to nearest (the default mode, which nothing here changes) and the result is moved one ulp outward.
// The exact result of +, −, ×, ÷ and sqrt lies within half an ulp of the rounded-to-nearest one (IEEE 754:
// these are correctly rounded), so one ulp outward encloses it; results that overflow to ±∞ stay valid
// bounds (a lower bound DBL_MAX of +∞, an upper bound +∞). This avoids Boost's rounded_arith_std, whose
// mode switches need -frounding-math to be safe from compiler reordering, and is independent of fused
// multiply-adds (this file is compiled with -ffp-contract=off, and each operation is rounded on its own
// anyway: the result passes through nextafter). log and atan are not correctly rounded by the C library:
// their results are widened by kTranscendentalUlps ulps (see the header). Both are increasing, so the
// interval functions of Boost (transc.hpp) call them at the endpoints only.
struct OutwardRounding {
  void init() {}
  template <class U>
  double conv_down(U const& v) {
    const double d = static_cast<double>(v);
    return static_cast<U>(d) == v ? d : step_down(d);
  }
  template <class U>
  double conv_up(U const& v) {
    const double d = static_cast<double>(v);
    return static_cast<U>(d) == v ? d : step_up(d);
  }
  double add_down(double x, double y) { return step_down(x + y); }
  double add_up(double x, double y) { return step_up(x + y); }
  double sub_down(double x, double y) { return step_down(x - y); }
  double sub_up(double x, double y) { return step_up(x - y); }
  double mul_down(double x, double y) { return step_down(x * y); }
  double mul_up(double x, double y) { return step_up(x * y); }
  double div_down(double x, double y) { return step_down(x / y); }
  double div_up(double x, double y) { return step_up(x / y); }
  double median(double x, double y) { return 0.5 * (x + y); }
  double sqrt_down(double x) { return x <= 0 ? 0.0 : step_down(std::sqrt(x)); }
  double sqrt_up(double x) { return step_up(std::sqrt(x)); }
  double int_down(double x) { return std::floor(x); }
  double int_up(double x) { return std::ceil(x); }
  double log_down(double x) { return steps_down(std::log(x), kTranscendentalUlps); }
  double log_up(double x) { return steps_up(std::log(x), kTranscendentalUlps); }
  double atan_down(double x) { return steps_down(std::atan(x), kTranscendentalUlps); }
  double atan_up(double x) { return steps_up(std::atan(x), kTranscendentalUlps); }
};

namespace bi = boost::numeric::interval_lib;
using I = boost::numeric::interval<double, bi::policies<OutwardRounding, bi::checking_base<double>>>;

inline I pt(double x) {
  return I(x, x);
}
inline I sq(const I& x) {
  return boost::numeric::square(x);
}
inline I isqrt(const I& x) {
  return boost::numeric::sqrt(x);
}
inline double lo(const I& x) {
  return x.lower();
}
inline double hi(const I& x) {
  return x.upper();
}
// Upper bound of |x| (NaN-safe: NaN gives +∞).
inline double abs_hi(const I& x) {
  const double m = std::max(std::abs(x.lower()), std::abs(x.upper()));
  return std::isnan(x.lower()) || std::isnan(x.upper()) ? kInf : m;
}

const I& pi_i() {
  static const I p = bi::pi<I>();
  return p;
}

// A 3-vector of intervals.
struct IV3 {
  I v[3];
  IV3() : v{pt(0), pt(0), pt(0)} {}
  IV3(const I& a, const I& b, const I& c) : v{a, b, c} {}
  static IV3 point(const Vec3& p) { return {pt(p.x()), pt(p.y()), pt(p.z())}; }
  const I& operator[](int i) const { return v[i]; }
  I& operator[](int i) { return v[i]; }
};
inline IV3 operator-(const IV3& a, const IV3& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
inline IV3 operator+(const IV3& a, const IV3& b) {
  return {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
}
inline IV3 operator*(const I& s, const IV3& a) {
  return {s * a[0], s * a[1], s * a[2]};
}
inline IV3 operator/(const IV3& a, const I& s) {
  return {a[0] / s, a[1] / s, a[2] / s};
}
inline I dot(const IV3& a, const IV3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline IV3 cross(const IV3& a, const IV3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline I norm(const IV3& a) {
  return isqrt(sq(a[0]) + sq(a[1]) + sq(a[2]));
}

using IM3 = std::array<std::array<I, 3>, 3>;

IM3 zero_m3() {
  IM3 m;
  for (auto& r : m)
    for (auto& e : r) e = pt(0);
  return m;
}

// atan2(y, x) for intervals, as an enclosure of {atan2(y', x') : y' ∈ y, x' ∈ x} away from the branch cut;
// where the boxes meet the cut (x ≤ 0 with y of either sign) or the origin, the enclosure is [−π, π].
I atan2_i(const I& y, const I& x) {
  const I& pi = pi_i();
  if (lo(x) > 0) return boost::numeric::atan(y / x);
  if (lo(y) > 0) return pi / pt(2) - boost::numeric::atan(x / y);
  if (hi(y) < 0) return -pi / pt(2) - boost::numeric::atan(x / y);
  return I(-hi(pi), hi(pi));
}

// Frobenius-norm upper bound of a set of intervals.
template <class It>
double frobenius_hi(It begin, It end) {
  I s = pt(0);
  for (It it = begin; it != end; ++it) s += sq(*it);
  return hi(isqrt(s));
}

// Upper bound of λmax(G) for every symmetric G in the enclosure (G[k][l] and G[l][k] the same interval): a
// candidate μ from the midpoint's eigenvalue plus slack, proven ≥ λmax by Sylvester's criterion on μI − G
// (all three leading principal minors > 0 in interval arithmetic); +∞ when no candidate is proven.
double lambda_max_hi(const IM3& G) {
  Mat3 mid;
  for (int k = 0; k < 3; ++k)
    for (int l = 0; l < 3; ++l) mid(k, l) = 0.5 * (lo(G[k][l]) + hi(G[k][l]));
  if (!mid.allFinite()) return kInf;
  const double lmax = Eigen::SelfAdjointEigenSolver<Mat3>(mid, Eigen::EigenvaluesOnly).eigenvalues()(2);
  const double tr = std::max(0.0, mid.trace());
  // Candidates from tight to generous: the first one proven is used.
  for (const double slack : {1e-12, 1e-9, 1e-6, 1e-3}) {
    const I mu = pt(std::max(lmax, 0.0) + slack * tr + 1e-300);
    // M = μI − G (symmetric, off-diagonal entries −G_kl): leading principal minors.
    const I m00 = mu - G[0][0], m11 = mu - G[1][1], m22 = mu - G[2][2];
    const I d2 = m00 * m11 - sq(G[0][1]);
    const I d3 = m00 * (m11 * m22 - sq(G[1][2])) - G[0][1] * (G[0][1] * m22 + G[1][2] * G[0][2]) -
                 G[0][2] * (G[0][1] * G[1][2] + m11 * G[0][2]);
    if (lo(m00) > 0 && lo(d2) > 0 && lo(d3) > 0) return hi(mu);
  }
  return kInf;
}

// Upper bound of the operator norm of the Hessian tensor v ↦ Σ_k v_k H_k (H_k)_ab = H[a][b][k], as a map into
// (R³ˣ³, ‖·‖_F): sqrt(λmax(G)), G_kl = Σ_ab H[a][b][k] H[a][b][l] (docs/certificate.md, Step 3b), λmax proven
// by lambda_max_hi; when that fails, the Frobenius norm (sqrt(trace G)) is returned.
double hessian_operator_norm_hi(const std::array<IM3, 3>& H, double frobenius) {
  IM3 G = zero_m3();
  for (int k = 0; k < 3; ++k)
    for (int l = 0; l < 3; ++l)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) G[k][l] += H[a][b][k] * H[a][b][l];
  const double mu = lambda_max_hi(G);
  return std::isfinite(mu) ? std::min(frobenius, hi(isqrt(pt(mu)))) : frobenius;
}

// One basis' reduction in intervals: μ = (BᵀMB)_00, ρ = |(BᵀMB)_Z0|, the 2x2 block's eigenvalue bounds,
// w = Σ_a (JBe0)_a H[a]ᵀ x (f(v) = 2 w·v), zk ≥ ‖B_ZᵀK‖₂ (B_ZᵀF(v)x = B_ZᵀK v).
struct ReductionI {
  I mu, rho, zz_min, zz_max, zk;
  IV3 w;
};
ReductionI reduce_i(const IM3& J, const std::array<IM3, 3>& H, const Mat3& B) {
  ReductionI R;
  IM3 JB = zero_m3(), S = zero_m3();
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 3; ++j)
      for (int b = 0; b < 3; ++b) JB[a][j] += J[a][b] * pt(B(b, j));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int a = 0; a < 3; ++a) S[i][j] += JB[a][i] * JB[a][j];
  R.mu = S[0][0];
  R.rho = isqrt(sq(S[1][0]) + sq(S[2][0]));
  const I half = (S[1][1] + S[2][2]) / pt(2), rad = isqrt(sq((S[1][1] - S[2][2]) / pt(2)) + sq(S[1][2]));
  R.zz_min = half - rad;
  R.zz_max = half + rad;
  IM3 K1 = zero_m3(), K2 = zero_m3(), K = zero_m3();
  for (int a = 0; a < 3; ++a) {
    const I jx = JB[a][0];
    for (int k = 0; k < 3; ++k) {
      I hx = pt(0);
      for (int b = 0; b < 3; ++b) hx += H[a][b][k] * pt(B(b, 0));
      K1[a][k] = hx;
      R.w.v[k] += jx * hx;
      for (int b = 0; b < 3; ++b) K2[b][k] += jx * H[a][b][k];
    }
  }
  for (int b = 0; b < 3; ++b)
    for (int k = 0; k < 3; ++k) {
      K[b][k] = K2[b][k];
      for (int a = 0; a < 3; ++a) K[b][k] += J[a][b] * K1[a][k];
    }
  std::array<IV3, 2> ZK;
  for (int i = 0; i < 2; ++i)
    for (int k = 0; k < 3; ++k) {
      ZK[i].v[k] = pt(0);
      for (int b = 0; b < 3; ++b) ZK[i].v[k] += pt(B(b, 1 + i)) * K[b][k];
    }
  const I g11 = dot(ZK[0], ZK[0]), g12 = dot(ZK[0], ZK[1]), g22 = dot(ZK[1], ZK[1]);
  R.zk = isqrt((g11 + g22) / pt(2) + isqrt(sq((g11 - g22) / pt(2)) + sq(g12)));
  return R;
}
// AᵀA in intervals, of an interval matrix or of a matrix of doubles.
IM3 gram_i(const IM3& A) {
  IM3 G = zero_m3();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int a = 0; a < 3; ++a) G[i][j] += A[a][i] * A[a][j];
  return G;
}
IM3 gram_i(const Mat3& B) {
  IM3 P;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) P[a][b] = pt(B(a, b));
  return gram_i(P);
}
// A basis from the midpoint's eigenvectors: x = column `col`, z1 from column 1, z2 = x × z1.
Mat3 basis_around(const Eigen::SelfAdjointEigenSolver<Mat3>& es, int col) {
  Mat3 B;
  B.col(0) = es.eigenvectors().col(col).normalized();
  B.col(1) = (es.eigenvectors().col(1) - B.col(0) * B.col(0).dot(es.eigenvectors().col(1))).normalized();
  B.col(2) = B.col(0).cross(B.col(1)).normalized();
  return B;
}
// Proven bounds λmax(BᵀB) ≤ hi and 1/λmin(BᵀB) ≤ inv_lo_hi (λmin ≥ 1 − ‖BᵀB − I‖_F).
bool gram_bounds(const Mat3& B, double& lmax_hi, double& inv_lmin_hi) {
  const IM3 G = gram_i(B);
  std::array<I, 9> dev;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dev[3 * i + j] = G[i][j] - pt(i == j ? 1 : 0);
  lmax_hi = lambda_max_hi(G);
  const I lmin = pt(1) - pt(frobenius_hi(dev.begin(), dev.end()));
  if (!(lo(lmin) > 0) || !std::isfinite(lmax_hi)) return false;
  inv_lmin_hi = hi(pt(1) / lmin);
  return true;
}

// What both interval Taylor bounds (Steps 3c, 3d) start from: det J > 0 proven, r ≥ 0, a finite ‖H‖_op bound,
// and the eigenvectors of the midpoint's JᵀJ (any doubles: the bases built from them need not be exact).
bool taylor_setup_i(const IM3& J, double r, double hop_hi, Eigen::SelfAdjointEigenSolver<Mat3>& es) {
  const I det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) +
                J[0][1] * (J[1][2] * J[2][0] - J[1][0] * J[2][2]) +
                J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
  if (!(lo(det) > 0) || !(r >= 0) || !std::isfinite(hop_hi)) return false;
  Mat3 mid;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) mid(a, b) = 0.5 * lo(J[a][b]) + 0.5 * hi(J[a][b]);
  if (!mid.allFinite()) return false;
  es.compute(mid.transpose() * mid);
  return true;
}

// Step 3c of docs/certificate.md in intervals: a rigorous lower bound ℓ of σ3ˢ(J + H[v]) over |v| ≤ r, for
// every J and H in the enclosures (H[a][b][k] = ∂J_ab/∂p_k, not assumed symmetric); −∞ when none. The basis
// B = [x z1 z2] (the midpoint's eigenvectors of JᵀJ, any doubles) need not be orthonormal: in the coordinates
// c of y = B c the 2x2 reduction is exact linear algebra for unit c, and |y| = 1 gives |c|² ≥ 1/λmax(BᵀB).
double taylor_sigma3_lower_bound_i(const IM3& J, const std::array<IM3, 3>& H, double r, double hop_hi) {
  Eigen::SelfAdjointEigenSolver<Mat3> es;
  if (!taylor_setup_i(J, r, hop_hi, es)) return -kInf;
  const Mat3 B = basis_around(es, 0);
  if (!B.allFinite()) return -kInf;
  // S = Bᵀ JᵀJ B = (JB)ᵀ(JB): μ1 = S00, ρ = |S_{Z0}|, μ2 = λmin(S_ZZ); f(v) = 2 wᵀv, ‖ZᵀF(v)x‖ ≤ r zk.
  const ReductionI R = reduce_i(J, H, B);
  // ‖J‖₂ and λmax(BᵀB) (the scale of |c|), both proven upper bounds.
  const double jtj = lambda_max_hi(gram_i(J)), btb = lambda_max_hi(gram_i(B));
  if (!std::isfinite(jtj) || !std::isfinite(btb)) return -kInf;
  // The worst case over the ball (each term at its monotone end), evaluated in intervals from those ends:
  // φ ≥ −λmax(BᵀB) ‖F‖₂ ≥ −λmax(BᵀB) 2 ‖J‖₂ r ‖H‖_op.
  const I f = pt(-2) * pt(r) * pt(hi(norm(R.w)));
  const I phi = pt(-2) * pt(btb) * isqrt(pt(jtj)) * pt(r) * pt(hop_hi);
  const I q = pt(hi(R.rho)) + pt(r) * pt(hi(R.zk));
  const I m1 = pt(lo(R.mu)), m2 = pt(lo(R.zz_min));
  const I D = m2 + pt(lo(phi)) - m1 - pt(lo(f));
  const I lam = m1 + pt(lo(f)) + (D - isqrt(sq(D) + pt(4) * sq(q))) / pt(2);
  if (!(lo(lam) > 0)) return -kInf;
  return lo(isqrt(pt(lo(lam)) / pt(btb)));
}

// Step 3d of docs/certificate.md in intervals (the double version: taylor_singular_bounds): for every J and H
// in the enclosures and |v| ≤ r,  σ1(J + H[v]) ≤ C1 + g1·v  and  σ3ˢ(J + H[v]) ≥ C3 + g3·v,  with g1, g3 in
// the returned interval vectors. The bases B = [x z1 z2] (x the midpoint's eigenvector of JᵀJ for its largest
// (σ1) or smallest (σ3) eigenvalue, any doubles) need not be orthonormal: with y = B c for unit y,
// 1/λmax(BᵀB) ≤ |c|² ≤ 1/λmin(BᵀB), and in the coordinates c the 2x2 reductions are exact linear algebra.
struct TaylorBoundsI {
  bool valid = false;
  double C1 = kInf, C3 = -kInf;
  IV3 g1, g3;
};

TaylorBoundsI taylor_singular_bounds_i(const IM3& J, const std::array<IM3, 3>& H, double r, double hop_hi) {
  TaylorBoundsI out;
  Eigen::SelfAdjointEigenSolver<Mat3> es;
  if (!taylor_setup_i(J, r, hop_hi, es)) return out;
  const Mat3 B1 = basis_around(es, 2), B3 = basis_around(es, 0);
  double l1, inv1, l3, inv3;
  if (!B1.allFinite() || !B3.allFinite() || !gram_bounds(B1, l1, inv1) || !gram_bounds(B3, l3, inv3))
    return out;
  const double jtj = lambda_max_hi(gram_i(J));
  if (!std::isfinite(jtj)) return out;
  const I R_ = pt(r), hop = pt(hop_hi), E2 = sq(R_ * hop);  // ‖H[v]‖₂² ≤ r² hop²
  const I normF = pt(2) * isqrt(pt(jtj)) * R_ * hop;        // ‖F(v)‖₂ ≤ 2‖J‖₂ r hop

  // σ1: for unit y = B1 c, yᵀ(M + F)y ≤ |c|² λmax([[μ + f, q], [q, zz_max + λmax(B_ZᵀB_Z)‖F‖]]) when that is
  // ≥ 0; λmax = μ + f + h1(D), h1 increasing in D, at D's largest value over the ball.
  const ReductionI R1 = reduce_i(J, H, B1);
  const I w1 = norm(R1.w);
  const I D1 = pt(hi(R1.zz_max + pt(l1) * normF - R1.mu + pt(2) * R_ * w1));
  const I q1 = pt(hi(R1.rho + R_ * R1.zk));
  const I s1 = isqrt(sq(D1) + pt(4) * sq(q1));
  const I h1 = lo(D1) < 0 ? pt(2) * sq(q1) / (s1 - D1) : (D1 + s1) / pt(2);
  const I base1 = R1.mu + pt(hi(h1));  // μ + h1; with f(v) = 2 w·v ≥ −2r|w| it stays ≥ 0 (checked)
  if (!(lo(base1 - pt(2) * R_ * w1) >= 0)) return out;
  // σ1² ≤ β(μ + h1 + 2 w·v) + r² hop² (β ≥ 1/λmin(BᵀB)); σ1 ≤ (a² + X)/(2a) for any a > 0.
  const double a1 = std::sqrt(0.5 * lo(R1.mu) + 0.5 * hi(R1.mu));
  if (!(a1 > 0)) return out;
  const I A1 = pt(a1), beta = pt(inv1);
  out.C1 = hi((sq(A1) + beta * base1 + E2) / (pt(2) * A1));
  out.g1 = (beta / A1) * R1.w;

  // σ3: yᵀ(M + F)y ≥ |c|² (μ + f − h3(D)) ≥ (μ + f − h3)/λmax(BᵀB) when μ + f − h3 ≥ 0, h3 decreasing in D,
  // at D's smallest value.
  const ReductionI R3 = reduce_i(J, H, B3);
  const I w3 = norm(R3.w);
  const I D3 = pt(lo(R3.zz_min - pt(l3) * normF - R3.mu - pt(2) * R_ * w3));
  const I q3 = pt(hi(R3.rho + R_ * R3.zk));
  const I s3 = isqrt(sq(D3) + pt(4) * sq(q3));
  const I h3 = hi(D3) > 0 ? pt(2) * sq(q3) / (s3 + D3) : (s3 - D3) / pt(2);
  const I L3 = pt(l3);
  if (!(lo(R3.mu - pt(hi(h3)) - pt(2) * R_ * w3) > 0)) return out;
  // σ3² ≥ a² + t(v), t(v) = (μ − h3)/λ − a² + (2w/λ)·v ≥ −c0 + (2w/λ)·v, |t| ≤ T < a²:
  // σ3 ≥ a − c0/(2a) − T²/(2a³) + (w/(λa))·v.
  const double a3 = std::sqrt((0.5 * lo(R3.mu) + 0.5 * hi(R3.mu)) / l3);
  if (!(a3 > 0)) return out;
  const I A3 = pt(a3);
  const I t0 = (R3.mu - pt(hi(h3))) / L3 - sq(A3);
  const double c0 = std::max(0.0, -lo(t0));
  const double T = hi(pt(std::max(c0, abs_hi(t0))) + pt(2) * R_ * w3 / L3);
  if (!(T < lo(sq(A3)))) return out;
  out.C3 = lo(A3 - pt(c0) / (pt(2) * A3) - sq(pt(T)) / (pt(2) * A3 * A3 * A3));
  out.g3 = R3.w / (L3 * A3);
  out.valid = std::isfinite(out.C1) && out.C3 > 0;
  return out;
}

// φ(K) = C1 + ρ + r|g1 − K g3| − K(C3 − ρ) ≤ 0 proven for every g1, g3 in the enclosures.
bool taylor_distortion_holds_i(const TaylorBoundsI& t, double r, double rho, double K) {
  const IV3 d = t.g1 - pt(K) * t.g3;
  return hi(pt(t.C1) + pt(rho) + pt(r) * norm(d) - pt(K) * (pt(t.C3) - pt(rho))) <= 0;
}

// The Taylor bounds of σ1, σ3 and σ1/σ3 (Step 3d) on the ball, with ρ = ½ r² T3 the remainder of the exact
// Taylor polynomial. For σ1/σ3 the certifier's claim when it is re-proven, else the smallest K found (the
// root of φ computed from the midpoints and moved up until φ(K) ≤ 0 is proven); +∞ (−∞) when none.
void taylor_distortion_bound_i(const TaylorBoundsI& t, double r, double rho, double claim_k,
                               double& sigma1_hi, double& sigma3_lo, double& k_hi) {
  sigma1_hi = k_hi = kInf;
  sigma3_lo = -kInf;
  if (!t.valid || !std::isfinite(rho)) return;
  sigma1_hi = hi(pt(t.C1) + pt(rho) + pt(r) * norm(t.g1));
  sigma3_lo = lo(pt(t.C3) - pt(rho) - pt(r) * norm(t.g3));
  if (std::isfinite(claim_k) && taylor_distortion_holds_i(t, r, rho, claim_k)) {
    k_hi = claim_k;
    return;
  }
  Vec3 g1, g3;
  for (int k = 0; k < 3; ++k) {
    g1(k) = 0.5 * lo(t.g1[k]) + 0.5 * hi(t.g1[k]);
    g3(k) = 0.5 * lo(t.g3[k]) + 0.5 * hi(t.g3[k]);
  }
  const double A = t.C1 + rho, B = t.C3 - rho;
  const double alpha = B * B - r * r * g3.squaredNorm();
  if (!(B > 0) || !(alpha > 0)) return;
  const double beta = A * B - r * r * g1.dot(g3), gamma = A * A - r * r * g1.squaredNorm();
  const double K0 = std::max((beta + std::sqrt(std::max(0.0, beta * beta - alpha * gamma))) / alpha, A / B);
  for (const double bump : {1e-12, 1e-9, 1e-6, 1e-3})
    if (taylor_distortion_holds_i(t, r, rho, K0 * (1 + bump))) {
      k_hi = K0 * (1 + bump);
      return;
    }
}

double sigma3_lower_bound_i(const IM3& J) {
  // det J by cofactors along the first row, and the cofactor matrix.
  const I c00 = J[1][1] * J[2][2] - J[1][2] * J[2][1];
  const I c01 = J[1][2] * J[2][0] - J[1][0] * J[2][2];
  const I c02 = J[1][0] * J[2][1] - J[1][1] * J[2][0];
  const I c10 = J[0][2] * J[2][1] - J[0][1] * J[2][2];
  const I c11 = J[0][0] * J[2][2] - J[0][2] * J[2][0];
  const I c12 = J[0][1] * J[2][0] - J[0][0] * J[2][1];
  const I c20 = J[0][1] * J[1][2] - J[0][2] * J[1][1];
  const I c21 = J[0][2] * J[1][0] - J[0][0] * J[1][2];
  const I c22 = J[0][0] * J[1][1] - J[0][1] * J[1][0];
  const I det = J[0][0] * c00 + J[0][1] * c01 + J[0][2] * c02;
  const I cof2 = sq(c00) + sq(c01) + sq(c02) + sq(c10) + sq(c11) + sq(c12) + sq(c20) + sq(c21) + sq(c22);
  const I cofn = isqrt(cof2);
  if (std::isnan(lo(det)) || std::isnan(hi(det)) || !std::isfinite(hi(cofn))) return -kInf;
  if (!(lo(det) > 0)) {
    // Sign not proven positive: σ3 ≥ det/(σ1σ2) ≥ √3 det_lo / ‖cof J‖_F (‖cof J‖_F ≤ √3 σ1σ2).
    if (!(lo(cofn) > 0)) return -kInf;
    return lo(isqrt(pt(3)) * pt(lo(det)) / pt(lo(cofn)));
  }
  // det J > 0: σ3 = det / (σ1σ2) ≥ det / ‖cof J‖_F (‖cof J‖_F² = σ1²σ2² + σ1²σ3² + σ2²σ3²).
  double best = lo(pt(lo(det)) / pt(hi(cofn)));
  // Tighter, and tight also when singular values cluster (J ≈ I): with U, V from the double SVD of the box's
  // midpoint (any matrices; only their near-orthogonality matters), B = Uᵀ J V is nearly diagonal and
  //   σ_min(J) ≥ σ_min(B) / (‖U‖₂ ‖V‖₂)            (σ_min(Uᵀ J V) ≤ ‖U‖₂ σ_min(J) ‖V‖₂),
  //   σ_min(B) ≥ min_i |B_ii| − ‖B − diag(B)‖_F      (Weyl: σ_min(D + E) ≥ σ_min(D) − ‖E‖₂),
  //   ‖U‖₂² = λ_max(UᵀU) ≤ 1 + ‖UᵀU − I‖_F,
  // all evaluated in intervals. det J > 0 makes the signed σ3 equal to σ_min.
  Mat3 mid;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) mid(a, b) = 0.5 * lo(J[a][b]) + 0.5 * hi(J[a][b]);
  if (!mid.allFinite()) return best;
  const SignedSvd sv = signed_svd(mid);
  IM3 T = zero_m3(), B = zero_m3();
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 3; ++j)
      for (int b = 0; b < 3; ++b) T[a][j] += J[a][b] * pt(sv.V(b, j));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int a = 0; a < 3; ++a) B[i][j] += pt(sv.U(a, i)) * T[a][j];
  double dmin = kInf;
  I off2 = pt(0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      if (i != j) {
        off2 += sq(B[i][j]);
        continue;
      }
      const double m = lo(B[i][i]) > 0 ? lo(B[i][i]) : hi(B[i][i]) < 0 ? -hi(B[i][i]) : 0.0;
      dmin = std::min(dmin, m);
    }
  auto gram_excess = [](const Mat3& Q) {  // upper bound of ‖QᵀQ − I‖_F
    std::array<I, 9> e;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        I g = pt(i == j ? -1.0 : 0.0);
        for (int a = 0; a < 3; ++a) g += pt(Q(a, i)) * pt(Q(a, j));
        e[3 * i + j] = g;
      }
    return frobenius_hi(e.begin(), e.end());
  };
  const I num = pt(dmin) - isqrt(off2);
  if (!(lo(num) > 0)) return best;
  const I den = isqrt((pt(1) + pt(gram_excess(sv.U))) * (pt(1) + pt(gram_excess(sv.V))));
  const double svd_bound = lo(num / den);
  if (svd_bound > best) best = svd_bound;
  return best;
}

}  // namespace

double sigma3_lower_bound(const Mat3& lo_m, const Mat3& hi_m) {
  IM3 J;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      if (!(lo_m(a, b) <= hi_m(a, b))) return -kInf;  // NaN or an empty interval: no bound
      J[a][b] = I(lo_m(a, b), hi_m(a, b));
    }
  return sigma3_lower_bound_i(J);
}

struct IntervalVerifier::Impl {
  struct Face {
    Vec3 x[3];    // vertices (exact doubles of the cage)
    IV3 n;        // unit outward normal
    IV3 dhat[3];  // unit edge vectors d_k / |d_k|, d_k = x_{k+1} − x_{k−1}
    IV3 nxd[3];   // n × d̂_k
    I dlen[3];    // |d_k|
    I yt[3];      // face coefficient y_t
    IV3 g[3];     // g_a = Σ_k y_{v_k}(a) d_k / (2 s_t), one per output component a
  };
  struct Edge {
    Vec3 u, w;
    double delta_hi;  // upper bound of ‖A_{f0} − A_{f1}‖_F
  };
  std::vector<Face> faces;
  std::vector<Edge> edges;
  LipschitzBound bound;

  // Enclosures of J and the (unsymmetrized but exact in sum) Hessian at the exact point p.
  void jet(const Vec3& p_in, IM3& J, std::array<IM3, 3>& H, bool with_hessian) const {
    J = zero_m3();
    for (auto& h : H) h = zero_m3();
    const I inv2pi = pt(1) / (pt(2) * pi_i());
    const I inv4pi = pt(1) / (pt(4) * pi_i());
    const IV3 p = IV3::point(p_in);
    for (const Face& fc : faces) {
      IV3 l[3];
      I L[3];
      for (int k = 0; k < 3; ++k) {
        l[k] = IV3::point(fc.x[k]) - p;
        L[k] = norm(l[k]);
      }
      // Solid angle / 4π (van Oosterom & Strackee): ω = atan2(triple, den) / (2π).
      const I triple = dot(l[0], cross(l[1], l[2]));
      const I den =
          L[0] * L[1] * L[2] + dot(l[0], l[1]) * L[2] + dot(l[1], l[2]) * L[0] + dot(l[2], l[0]) * L[1];
      const I omega = atan2_i(triple, den) * inv2pi;
      IV3 csum;
      IV3 alpha[3], beta[3];
      for (int k = 0; k < 3; ++k) {
        const int u = (k + 2) % 3, w = (k + 1) % 3;
        const I m = L[u] + L[w];
        const I md = pt(2) * (L[u] * L[w] + dot(l[u], l[w]));  // m² − d², cancellation-free
        const I& d = fc.dlen[k];
        const I C = inv4pi * boost::numeric::log(sq(m + d) / md);
        csum = csum + C * fc.dhat[k];
        if (with_hessian) {
          alpha[k] = (m * inv2pi / (md * L[u] * L[w])) * cross(l[u], l[w]);
          beta[k] = (d * inv2pi / md) * (l[u] / L[u] + l[w] / L[w]);
        }
      }
      // P_t = n × Σ_k C_k d̂_k − ω n;  row a of J gets −y_t(a) P + P × g_a.
      const IV3 P = cross(fc.n, csum) - omega * fc.n;
      for (int a = 0; a < 3; ++a) {
        const IV3 row = cross(P, fc.g[a]) - fc.yt[a] * P;
        for (int b = 0; b < 3; ++b) J[a][b] += row[b];
      }
      if (!with_hessian) continue;
      // J(P_t) = Σ_k (n × d̂_k) β_kᵀ + n α_kᵀ (= −Hess ψ_t);  H[a] gets −y_t(a) J(P) − [g_a]× J(P).
      IM3 JP = zero_m3();
      for (int k = 0; k < 3; ++k)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) JP[i][j] += fc.nxd[k][i] * beta[k][j] + fc.n[i] * alpha[k][j];
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < 3; ++j) {
          const IV3 col(JP[0][j], JP[1][j], JP[2][j]);
          const IV3 gx = cross(fc.g[a], col);
          for (int i = 0; i < 3; ++i) H[a][i][j] -= fc.yt[a] * col[i] + gx[i];
        }
    }
  }

  // Upper bound of the edge factor Γ_e (first order) or Θ_e (third order) over the ball B(c, r) (r is an
  // upper bound of the radius), following lipschitz_bound.cpp with every step rounded outward: lower
  // bounds of m = |q−u| + |q−w| and of |q−u|, |q−w| on the ball, then the decreasing closed forms.
  double edge_factor_hi(const Edge& e, const Vec3& c, double r, bool third) const {
    const IV3 u = IV3::point(e.u), w = IV3::point(e.w), cc = IV3::point(c);
    const IV3 ev = w - u;
    const I d = norm(ev);
    const double a = lo(norm(u - cc) - pt(r)), b = lo(norm(w - cc) - pt(r));
    const double line = lo(norm(cross(cc - u, ev)) / d);
    const double rho = std::max(0.0, lo(pt(line) - pt(r)));
    const double sum_lo = lo(pt(std::max(a, 0.0)) + pt(std::max(b, 0.0)));
    const double ell_lo = lo(pt(2) * isqrt(sq(pt(rho)) + sq(d) / pt(4)));
    const double h = std::max(sum_lo, ell_lo);
    if (!(h > hi(d)) || !(a > 0) || !(b > 0)) return kInf;
    const I H = pt(h);
    const I md = sq(H) - sq(d);
    const I& pi = pi_i();
    if (!third) return hi(isqrt(sq(H) + pt(4) * sq(d)) / (pt(2) * pi * md));
    const I n = pt(lo(pt(a) * pt(b)));
    const I nn = sq(n), md2 = sq(md), h2d2 = sq(H) * sq(d), pi2 = sq(pi);
    const I b66 = (pt(1) + h2d2 / nn) / (pi2 * md2);
    const I b67 = pt(3) * h2d2 / (pt(2) * pi2 * md2 * nn);
    return hi(isqrt(b66 + b67));
  }
};

// ---- Bounded distortion (docs/certificate.md, "Bounded distortion", interval re-proof) ----
namespace {

// Upper bound of σ1 for every matrix in the enclosure: sqrt(λmax(JᵀJ)) with λmax proven by lambda_max_hi
// (Sylvester's criterion), else the Frobenius norm.
double sigma1_upper_bound_i(const IM3& J) {
  IM3 G = zero_m3();
  for (int k = 0; k < 3; ++k)
    for (int l = 0; l < 3; ++l)
      for (int a = 0; a < 3; ++a) G[k][l] += J[a][k] * J[a][l];
  std::array<I, 9> entries;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) entries[3 * a + b] = pt(abs_hi(J[a][b]));
  const double frob = frobenius_hi(entries.begin(), entries.end());
  const double mu = lambda_max_hi(G);
  return std::isfinite(mu) ? std::min(frob, hi(isqrt(pt(mu)))) : frob;
}

// σ1(q) ≤ σ1(J(c)) + ‖J(q) − J(c)‖₂ ≤ sigma1_upper_bound_i(J) + r·L on the ball (Weyl; r·L bounds J's change,
// L the first, third-order or combined constant), and σ1/σ3 ≤ that / margin_lo where margin_lo > 0.
void add_distortion_bound_i(IntervalLeaf& res, const IM3& J, double r, double L_jacobian_hi) {
  const I s1 = pt(sigma1_upper_bound_i(J)) + pt(r) * pt(L_jacobian_hi);
  res.sigma1_hi = std::isnan(hi(s1)) ? kInf : hi(s1);
  res.distortion_hi = kInf;
  if (res.margin_lo > 0 && std::isfinite(res.sigma1_hi)) {
    const double k = hi(pt(res.sigma1_hi) / pt(res.margin_lo));
    if (!std::isnan(k)) res.distortion_hi = k;
  }
}

// The distortion summary of a re-proof: each checked leaf's interval bounds against voxels.csv's.
void summarize_distortion_i(IntervalVerification& out, const std::vector<CertLeaf>& leaves) {
  for (size_t q = 0; q < out.results.size(); ++q) {
    const IntervalLeaf& r = out.results[q];
    const CertLeaf& l = leaves[out.leaf_index[q]];
    const bool ok = (!std::isfinite(l.sigma1_upper) || r.sigma1_hi <= l.sigma1_upper) &&
                    (!std::isfinite(l.distortion_upper) || r.distortion_hi <= l.distortion_upper);
    (ok ? out.distortion_proven : out.distortion_not_proven) += 1;
    out.max_sigma1_hi = std::max(out.max_sigma1_hi, r.sigma1_hi);
    out.max_distortion_hi = std::max(out.max_distortion_hi, r.distortion_hi);
  }
}

}  // namespace
// ---- end of bounded distortion ----

IntervalVerifier::IntervalVerifier(const Cage& cage, const MatX3d& y, LipschitzBound bound)
    : impl_(std::make_unique<Impl>()) {
  Impl& im = *impl_;
  im.bound = bound;
  const int nv = cage.num_vertices(), nf = cage.num_faces();
  if (y.rows() != nv + nf) throw InputError("", "coefficient rows do not match the cage (#V+#F)");
  im.faces.resize(nf);
  std::vector<IM3> A(nf);
  for (int t = 0; t < nf; ++t) {
    Impl::Face& fc = im.faces[t];
    int vid[3];
    for (int k = 0; k < 3; ++k) {
      vid[k] = cage.F(t, k);
      fc.x[k] = cage.V.row(vid[k]).transpose();
    }
    // The exact geometry of the face from its vertices: the basis is defined by it, not by the rounded
    // normals and areas the double-precision code stores.
    const IV3 x0 = IV3::point(fc.x[0]), x1 = IV3::point(fc.x[1]), x2 = IV3::point(fc.x[2]);
    const IV3 e = cross(x1 - x0, x2 - x0);
    const I two_area = norm(e);
    fc.n = e / two_area;
    const IV3 X[3] = {x0, x1, x2};
    IV3 d[3];
    for (int k = 0; k < 3; ++k) {
      d[k] = X[(k + 1) % 3] - X[(k + 2) % 3];
      fc.dlen[k] = norm(d[k]);
      fc.dhat[k] = d[k] / fc.dlen[k];
      fc.nxd[k] = cross(fc.n, fc.dhat[k]);
    }
    for (int a = 0; a < 3; ++a) {
      fc.yt[a] = pt(y(nv + t, a));
      IV3 g;
      for (int k = 0; k < 3; ++k) g = g + pt(y(vid[k], a)) * d[k];
      fc.g[a] = g / two_area;
      // Lemma 5.1: row a of A_t = y_t(a) nᵀ − (n × g_a)ᵀ.
      const IV3 row = fc.yt[a] * fc.n - cross(fc.n, fc.g[a]);
      for (int b = 0; b < 3; ++b) A[t][a][b] = row[b];
    }
  }
  im.edges.reserve(cage.edges.size());
  for (const CageEdge& ce : cage.edges) {
    Impl::Edge e;
    e.u = cage.V.row(ce.v0).transpose();
    e.w = cage.V.row(ce.v1).transpose();
    std::array<I, 9> dl;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) dl[3 * a + b] = A[ce.f0][a][b] - A[ce.f1][a][b];
    e.delta_hi = frobenius_hi(dl.begin(), dl.end());
    im.edges.push_back(e);
  }
}

IntervalVerifier::~IntervalVerifier() = default;

JetEnclosure IntervalVerifier::jet(const Vec3& p) const {
  IM3 J;
  std::array<IM3, 3> H;
  impl_->jet(p, J, H, true);
  JetEnclosure out;
  std::vector<I> all;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      out.J_lo(a, b) = lo(J[a][b]);
      out.J_hi(a, b) = hi(J[a][b]);
      for (int c = 0; c < 3; ++c) {
        out.H_lo[a](b, c) = lo(H[a][b][c]);
        out.H_hi[a](b, c) = hi(H[a][b][c]);
        all.push_back(pt(abs_hi(H[a][b][c])));
      }
    }
  out.hessian_norm_hi = frobenius_hi(all.begin(), all.end());
  return out;
}

IntervalLeaf IntervalVerifier::verify_leaf(const Vec3& c, double side, double radius_slack,
                                           double claim_distortion, double claim_sigma1) const {
  const Impl& im = *impl_;
  IntervalLeaf base;
  // The ball: the voxel of side h around c has circumradius (√3/2) h. voxels.csv holds shortest round-trip
  // decimals, so c and h are the certifier's doubles; should a decimal not be exactly that double, the
  // voxel it describes still lies in the ball widened by one ulp of h and of each coordinate of c.
  auto ulp = [](double x) { return step_up(std::abs(x)) - std::abs(x); };
  const I h = pt(side) + pt(ulp(side));
  const I shift = isqrt(sq(pt(ulp(c.x()))) + sq(pt(ulp(c.y()))) + sq(pt(ulp(c.z()))));
  const double r = hi(isqrt(pt(3)) / pt(2) * h + shift + pt(radius_slack));
  base.radius_hi = r;

  const bool third = im.bound != LipschitzBound::kFirstOrder;  // ‖H(c)‖ and Σ δ Θ (third, combined)
  // Spectral: the combined L, and the Taylor σ3 bound of Step 3c in intervals (taylor_sigma3_lower_bound_i).
  const bool own_combined = im.bound == LipschitzBound::kCombined || im.bound == LipschitzBound::kSpectral;
  IM3 J;
  std::array<IM3, 3> H;
  im.jet(c, J, H, third);
  base.sigma3_lo = sigma3_lower_bound_i(J);
  I sum = pt(0);  // Σ δ Θ (third, combined) or Σ δ Γ (first)
  for (const Impl::Edge& e : im.edges) sum += pt(e.delta_hi) * pt(im.edge_factor_hi(e, c, r, third));
  // The leaf's bounds with the certificate's bound, or (`spectral_terms`) with the spectral bound's; J, H and
  // the sum above are the same for both.
  auto bounds = [&](bool spectral_terms) {
    IntervalLeaf res = base;
    const bool combined = own_combined || spectral_terms;
    const bool spectral = im.bound == LipschitzBound::kSpectral || spectral_terms;
    double hop = kInf;
    I sum1 = pt(0);  // Σ δ Γ (combined)
    if (combined)
      for (const Impl::Edge& e : im.edges) sum1 += pt(e.delta_hi) * pt(im.edge_factor_hi(e, c, r, false));
    I L = sum;
    if (third) {
      std::array<I, 27> hs;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          for (int k = 0; k < 3; ++k) hs[9 * a + 3 * b + k] = pt(abs_hi(H[a][b][k]));
      const double frob = frobenius_hi(hs.begin(), hs.end());
      L = pt(frob) + pt(r) * sum;
      // Combined: min(first order, Taylor form ‖H(c)‖_op + ½ r Σ δ Θ); both are upper bounds, so is the min.
      if (combined) {
        hop = hessian_operator_norm_hi(H, frob);
        const I taylor = pt(hop) + pt(r) * sum / pt(2);
        L = pt(std::min(hi(sum1), hi(taylor)));
      }
    }
    res.L_hi = std::isnan(hi(L)) ? kInf : hi(L);
    const I margin = pt(res.sigma3_lo) - pt(r) * pt(res.L_hi);
    res.margin_lo = std::isnan(lo(margin)) ? -kInf : lo(margin);
    const double L_jacobian_hi = res.L_hi;  // bounds J's change too (the spectral term below is σ3's only)
    // Spectral (Step 3c): σ3 ≥ ℓ − ½ r² Σ δ Θ on the ball; where that is the better margin, L_hi is the loss
    // over r that gives it from sigma3_lo.
    if (spectral) {
      const double ell = taylor_sigma3_lower_bound_i(J, H, r, hop);
      const I m2 = pt(ell) - pt(r) * pt(r) * pt(hi(sum)) / pt(2);
      if (ell > -kInf && !std::isnan(lo(m2)) && lo(m2) > res.margin_lo) {
        res.margin_lo = lo(m2);
        res.L_hi = hi((pt(res.sigma3_lo) - pt(res.margin_lo)) / pt(r));
      }
    }
    res.proven = res.margin_lo > 0;
    add_distortion_bound_i(res, J, r, L_jacobian_hi);
    // Step 3d: the Taylor bounds of σ1, σ3 and σ1/σ3 (third-order sums only: ½ r² Σ δ Θ bounds the
    // remainder), where the Lipschitz bounds do not re-prove the certifier's claims; the better of each pair
    // holds; σ3's and σ1/σ3's only where σ3 is proven positive, as the certifier's (which leaves are proven
    // stays the Lipschitz bound's decision).
    if (third && (res.distortion_hi > claim_distortion || res.sigma1_hi > claim_sigma1)) {
      if (!std::isfinite(hop)) {
        std::array<I, 27> hs;
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b)
            for (int k = 0; k < 3; ++k) hs[9 * a + 3 * b + k] = H[a][b][k];
        hop = hessian_operator_norm_hi(H, frobenius_hi(hs.begin(), hs.end()));
      }
      const double rho = hi(pt(r) * pt(r) * sum / pt(2));
      double s1 = kInf, s3 = -kInf, k = kInf;
      taylor_distortion_bound_i(taylor_singular_bounds_i(J, H, r, hop), r, rho, claim_distortion, s1, s3, k);
      res.sigma1_hi = std::min(res.sigma1_hi, s1);
      if (res.margin_lo > 0) {
        res.margin_lo = std::max(res.margin_lo, s3);
        const double kq = hi(pt(res.sigma1_hi) / pt(res.margin_lo));
        res.distortion_hi = std::min({res.distortion_hi, std::isnan(kq) ? kInf : kq, k});
      }
    }
    return res;
  };
  IntervalLeaf res = bounds(false);
  // Step 4f: a third-order certificate's base voxel may have been proven, or given its σ1 and σ1/σ3 bounds,
  // by the spectral bound (the certifier's fallback). Where the third-order bound does not re-prove the leaf
  // or its claims, the spectral bound's are computed too; each is a rigorous bound, so the better of each
  // holds.
  if (third && !own_combined &&
      (!res.proven || res.distortion_hi > claim_distortion || res.sigma1_hi > claim_sigma1)) {
    const IntervalLeaf s = bounds(true);
    res.margin_lo = std::max(res.margin_lo, s.margin_lo);
    res.L_hi = std::min(res.L_hi, s.L_hi);
    res.sigma1_hi = std::min(res.sigma1_hi, s.sigma1_hi);
    res.distortion_hi = std::min(res.distortion_hi, s.distortion_hi);
    res.proven = res.margin_lo > 0;
  }
  return res;
}

IntervalVerification verify_certificate_intervals(const Cage& cage, const MatX3d& y,
                                                  const std::vector<CertLeaf>& leaves, LipschitzBound bound,
                                                  double radius_slack) {
  const auto t0 = Clock::now();
  IntervalVerification out;
  const IntervalVerifier verifier(cage, y, bound);
  for (size_t i = 0; i < leaves.size(); ++i)
    if (leaves[i].certified) out.leaf_index.push_back(static_cast<long>(i));
  const long n = static_cast<long>(out.leaf_index.size());
  out.results.resize(n);
#pragma omp parallel for schedule(dynamic, 8)
  for (long q = 0; q < n; ++q) {
    const CertLeaf& l = leaves[out.leaf_index[q]];
    out.results[q] = verifier.verify_leaf(l.center, l.side, radius_slack, l.distortion_upper, l.sigma1_upper);
  }
  out.worst_slack = kInf;
  for (const IntervalLeaf& r : out.results) {
    (r.proven ? out.proven : out.not_proven) += 1;
    out.worst_slack = std::min(out.worst_slack, r.margin_lo);
  }
  summarize_distortion_i(out, leaves);
  out.seconds = seconds_since(t0);
  return out;
}

}  // namespace lidef
