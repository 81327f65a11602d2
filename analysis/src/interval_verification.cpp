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

// Step 3c of docs/certificate.md in intervals: a rigorous lower bound ℓ of σ3ˢ(J + H[v]) over |v| ≤ r, for
// every J and H in the enclosures (H[a][b][k] = ∂J_ab/∂p_k, not assumed symmetric); −∞ when none. The basis
// B = [x z1 z2] (the midpoint's eigenvectors of JᵀJ, any doubles) need not be orthonormal: in the coordinates
// c of y = B c the 2x2 reduction is exact linear algebra for unit c, and |y| = 1 gives |c|² ≥ 1/λmax(BᵀB).
double taylor_sigma3_lower_bound_i(const IM3& J, const std::array<IM3, 3>& H, double r, double hop_hi) {
  const I det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) +
                J[0][1] * (J[1][2] * J[2][0] - J[1][0] * J[2][2]) +
                J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
  if (!(lo(det) > 0) || !(r >= 0) || !std::isfinite(hop_hi)) return -kInf;
  Mat3 mid;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) mid(a, b) = 0.5 * lo(J[a][b]) + 0.5 * hi(J[a][b]);
  if (!mid.allFinite()) return -kInf;
  const Eigen::SelfAdjointEigenSolver<Mat3> es(mid.transpose() * mid);
  Mat3 B;
  B.col(0) = es.eigenvectors().col(0).normalized();
  B.col(1) = (es.eigenvectors().col(1) - B.col(0) * B.col(0).dot(es.eigenvectors().col(1))).normalized();
  B.col(2) = B.col(0).cross(B.col(1)).normalized();
  if (!B.allFinite()) return -kInf;
  // S = Bᵀ JᵀJ B = (JB)ᵀ(JB): μ1 = S00, ρ = |S_{Z0}|, μ2 = λmin(S_ZZ).
  IM3 JB = zero_m3(), S = zero_m3();
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 3; ++j)
      for (int b = 0; b < 3; ++b) JB[a][j] += J[a][b] * pt(B(b, j));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int a = 0; a < 3; ++a) S[i][j] += JB[a][i] * JB[a][j];
  const I mu1 = S[0][0];
  const I rho = isqrt(sq(S[1][0]) + sq(S[2][0]));
  const I mu2 = (S[1][1] + S[2][2]) / pt(2) - isqrt(sq((S[1][1] - S[2][2]) / pt(2)) + sq(S[1][2]));
  // Linear in v, with x = B e1: f(v) = 2 wᵀv, w = Σ_a (Jx)_a Hᵀ_a x ((Hᵀ_a x)_k = Σ_b H[a][b][k] x_b);
  // ZᵀF(v)x = ZᵀK v, K = JᵀK1 + K2, K1 rows (Hᵀ_a x)ᵀ, K2[b][k] = Σ_a (Jx)_a H[a][b][k].
  IV3 w;
  IM3 K1 = zero_m3(), K2 = zero_m3(), K = zero_m3();
  for (int a = 0; a < 3; ++a) {
    const I jx = JB[a][0];
    for (int k = 0; k < 3; ++k) {
      I hx = pt(0);
      for (int b = 0; b < 3; ++b) hx += H[a][b][k] * pt(B(b, 0));
      K1[a][k] = hx;
      w.v[k] += jx * hx;
      for (int b = 0; b < 3; ++b) K2[b][k] += jx * H[a][b][k];
    }
  }
  for (int b = 0; b < 3; ++b)
    for (int k = 0; k < 3; ++k) {
      K[b][k] = K2[b][k];
      for (int a = 0; a < 3; ++a) K[b][k] += J[a][b] * K1[a][k];
    }
  std::array<IV3, 2> ZK;  // rows of ZᵀK
  for (int i = 0; i < 2; ++i)
    for (int k = 0; k < 3; ++k) {
      ZK[i].v[k] = pt(0);
      for (int b = 0; b < 3; ++b) ZK[i].v[k] += pt(B(b, 1 + i)) * K[b][k];
    }
  const I g11 = dot(ZK[0], ZK[0]), g12 = dot(ZK[0], ZK[1]), g22 = dot(ZK[1], ZK[1]);
  const I zk = isqrt((g11 + g22) / pt(2) + isqrt(sq((g11 - g22) / pt(2)) + sq(g12)));
  // ‖J‖₂ and λmax(BᵀB) (the scale of |c|), both proven upper bounds.
  IM3 JtJ = zero_m3(), BtB = zero_m3();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int a = 0; a < 3; ++a) {
        JtJ[i][j] += J[a][i] * J[a][j];
        BtB[i][j] += pt(B(a, i)) * pt(B(a, j));
      }
  const double jtj = lambda_max_hi(JtJ), btb = lambda_max_hi(BtB);
  if (!std::isfinite(jtj) || !std::isfinite(btb)) return -kInf;
  // The worst case over the ball (each term at its monotone end), evaluated in intervals from those ends:
  // φ ≥ −λmax(BᵀB) ‖F‖₂ ≥ −λmax(BᵀB) 2 ‖J‖₂ r ‖H‖_op.
  const I f = pt(-2) * pt(r) * pt(hi(norm(w)));
  const I phi = pt(-2) * pt(btb) * isqrt(pt(jtj)) * pt(r) * pt(hop_hi);
  const I q = pt(hi(rho)) + pt(r) * pt(hi(zk));
  const I m1 = pt(lo(mu1)), m2 = pt(lo(mu2));
  const I D = m2 + pt(lo(phi)) - m1 - pt(lo(f));
  const I lam = m1 + pt(lo(f)) + (D - isqrt(sq(D) + pt(4) * sq(q))) / pt(2);
  if (!(lo(lam) > 0)) return -kInf;
  return lo(isqrt(pt(lo(lam)) / pt(btb)));
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

IntervalLeaf IntervalVerifier::verify_leaf(const Vec3& c, double side, double radius_slack) const {
  const Impl& im = *impl_;
  IntervalLeaf res;
  // The ball: the voxel of side h around c has circumradius (√3/2) h. voxels.csv holds shortest round-trip
  // decimals, so c and h are the certifier's doubles; should a decimal not be exactly that double, the
  // voxel it describes still lies in the ball widened by one ulp of h and of each coordinate of c.
  auto ulp = [](double x) { return step_up(std::abs(x)) - std::abs(x); };
  const I h = pt(side) + pt(ulp(side));
  const I shift = isqrt(sq(pt(ulp(c.x()))) + sq(pt(ulp(c.y()))) + sq(pt(ulp(c.z()))));
  const double r = hi(isqrt(pt(3)) / pt(2) * h + shift + pt(radius_slack));
  res.radius_hi = r;

  const bool third = im.bound != LipschitzBound::kFirstOrder;  // ‖H(c)‖ and Σ δ Θ (third, combined)
  // Spectral: the combined L, and the Taylor σ3 bound of Step 3c in intervals (taylor_sigma3_lower_bound_i).
  const bool combined = im.bound == LipschitzBound::kCombined || im.bound == LipschitzBound::kSpectral;
  const bool spectral = im.bound == LipschitzBound::kSpectral;
  double hop = kInf;
  IM3 J;
  std::array<IM3, 3> H;
  im.jet(c, J, H, third);
  res.sigma3_lo = sigma3_lower_bound_i(J);

  I sum = pt(0), sum1 = pt(0);  // Σ δ Θ (third, combined) or Σ δ Γ (first); Σ δ Γ (combined)
  for (const Impl::Edge& e : im.edges) {
    sum += pt(e.delta_hi) * pt(im.edge_factor_hi(e, c, r, third));
    if (combined) sum1 += pt(e.delta_hi) * pt(im.edge_factor_hi(e, c, r, false));
  }
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
  const double L_jacobian_hi = res.L_hi;  // bounds J's change too (the spectral term below is σ3's only)
  const I margin = pt(res.sigma3_lo) - pt(r) * pt(res.L_hi);
  res.margin_lo = std::isnan(lo(margin)) ? -kInf : lo(margin);
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
    out.results[q] = verifier.verify_leaf(l.center, l.side, radius_slack);
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
