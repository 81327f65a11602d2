#include "lidef/lipschitz_bound.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/enum_names.h"

namespace lidef {
namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

// The lower bounds over the ball B(p, r) of |q−u|, |q−w| (a, b) and of |q−u| + |q−w| (h): the larger of
// (|p−u| − r) + (|p−w| − r) and 2 sqrt(ρ² + d²/4), ρ = max(0, dist(p, line uw) − r) — points at distance ρ
// from the line have |q−u| + |q−w| ≥ 2 sqrt(ρ² + d²/4) (minimum on the bisector plane). e = w − u, d = |e|.
// Branch-free (std::max, selects), so that factor_row's loop over the edges vectorizes.
struct BallBounds {
  double h, a, b;
};
inline BallBounds ball_bounds(double ux, double uy, double uz, double wx, double wy, double wz, double ex,
                              double ey, double ez, double d, double px, double py, double pz, double r) {
  const double lux = ux - px, luy = uy - py, luz = uz - pz;  // u − p
  const double lwx = wx - px, lwy = wy - py, lwz = wz - pz;  // w − p
  const double a = std::sqrt(lux * lux + luy * luy + luz * luz) - r;
  const double b = std::sqrt(lwx * lwx + lwy * lwy + lwz * lwz) - r;
  const double cx = luy * ez - luz * ey, cy = luz * ex - lux * ez, cz = lux * ey - luy * ex;  // (u−p) × e
  const double line_dist = std::sqrt(cx * cx + cy * cy + cz * cz) / d;
  const double rho = std::max(0.0, line_dist - r);
  const double h = std::max(std::max(a, 0.0) + std::max(b, 0.0), 2.0 * std::sqrt(rho * rho + 0.25 * d * d));
  return {h, a, b};
}

// The factor of one edge; +∞ when the ball nears the edge (h ≤ d, or it contains u or w). Both factors are
// computed and the result selected, so that the loop over the edges has no branch.
template <EdgeFactor Kind>
inline double edge_factor(double ux, double uy, double uz, double wx, double wy, double wz, double ex,
                          double ey, double ez, double d, double px, double py, double pz, double r) {
  const BallBounds bb = ball_bounds(ux, uy, uz, wx, wy, wz, ex, ey, ez, d, px, py, pz, r);
  const bool ok = (bb.h > d) & (bb.a > 0) & (bb.b > 0);
  double f;
  if constexpr (Kind == EdgeFactor::kThirdOrder)
    f = third_order_factor(bb.h, d, bb.a, bb.b);
  else if constexpr (Kind == EdgeFactor::kSharpFirstOrder)
    f = sharp_first_order_factor(bb.h, d, bb.a, bb.b);
  else
    f = first_order_factor(bb.h, d);
  return ok ? f : kInf;
}

template <EdgeFactor Kind>
double edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const Vec3 e = w - u;
  return edge_factor<Kind>(u.x(), u.y(), u.z(), w.x(), w.y(), w.z(), e.x(), e.y(), e.z(), e.norm(), p.x(),
                           p.y(), p.z(), r);
}

// The smallest float ≥ x for x ≥ 0 (+∞ stays +∞): the next float up is the next bit pattern.
inline float round_up_nonneg(double x) {
  float f = static_cast<float>(x);
  std::uint32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  bits += static_cast<double>(f) < x ? 1u : 0u;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

template <EdgeFactor Kind>
bool factor_row_impl(const EdgeArrays& E, const Vec3& p, double r, float* out) {
  const long n = E.size();
  const double px = p.x(), py = p.y(), pz = p.z();
  int infinite = 0;
#pragma omp simd reduction(| : infinite)
  for (long e = 0; e < n; ++e) {
    const float f = round_up_nonneg(edge_factor<Kind>(E.ux[e], E.uy[e], E.uz[e], E.wx[e], E.wy[e], E.wz[e],
                                                      E.ex[e], E.ey[e], E.ez[e], E.d[e], px, py, pz, r));
    out[e] = f;
    infinite |= f < std::numeric_limits<float>::infinity() ? 0 : 1;
  }
  return infinite == 0;
}
}  // namespace

double edge_sum_lower_bound(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const Vec3 e = w - u;
  return ball_bounds(u.x(), u.y(), u.z(), w.x(), w.y(), w.z(), e.x(), e.y(), e.z(), e.norm(), p.x(), p.y(),
                     p.z(), r)
      .h;
}

double first_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  // |α| ≤ m / (2π(m²−d²)),  |β| ≤ 2d / (2π(m²−d²)), both decreasing in m.
  return edge_factor<EdgeFactor::kFirstOrder>(u, w, p, r);
}

double sharp_first_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  return edge_factor<EdgeFactor::kSharpFirstOrder>(u, w, p, r);
}

double third_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  return edge_factor<EdgeFactor::kThirdOrder>(u, w, p, r);
}

EdgeArrays::EdgeArrays(const std::vector<Vec3>& u, const std::vector<Vec3>& w) {
  for (size_t k = 0; k < u.size(); ++k) {
    const Vec3 e = w[k] - u[k];
    ux.push_back(u[k].x());
    uy.push_back(u[k].y());
    uz.push_back(u[k].z());
    wx.push_back(w[k].x());
    wy.push_back(w[k].y());
    wz.push_back(w[k].z());
    ex.push_back(e.x());
    ey.push_back(e.y());
    ez.push_back(e.z());
    d.push_back(e.norm());
  }
}

bool factor_row(const EdgeArrays& edges, EdgeFactor kind, const Vec3& p, double r, float* out) {
  switch (kind) {
    case EdgeFactor::kThirdOrder:
      return factor_row_impl<EdgeFactor::kThirdOrder>(edges, p, r, out);
    case EdgeFactor::kSharpFirstOrder:
      return factor_row_impl<EdgeFactor::kSharpFirstOrder>(edges, p, r, out);
    case EdgeFactor::kFirstOrder:
      break;
  }
  return factor_row_impl<EdgeFactor::kFirstOrder>(edges, p, r, out);
}

// sup_{|v|=1} ‖Σ_k v_k H_k‖_F² = sup vᵀ G v = λmax(G), G_kl = Σ_ab H[a](b,k) H[a](b,l) = Σ_a (H[a]ᵀ H[a])_kl.
// The symmetric eigensolver is backward stable (the computed eigenvalues are exact for G + ΔG with
// ‖ΔG‖₂ ≤ c·u·‖G‖₂, c a small constant for n = 3), and ‖G‖₂ ≤ trace G = ‖H‖_F², so adding 10⁻¹²·trace G
// (≈ 4500 u) makes it an upper bound. λmax ≤ trace G also caps it at the Frobenius norm.
double hessian_operator_norm(const std::array<Mat3, 3>& H) {
  Mat3 G = Mat3::Zero();
  for (int a = 0; a < 3; ++a) G.noalias() += H[a].transpose() * H[a];
  const double tr = G.trace();
  if (!std::isfinite(tr)) return kInf;
  if (tr == 0) return 0;
  const double lmax = Eigen::SelfAdjointEigenSolver<Mat3>(G, Eigen::EigenvaluesOnly).eigenvalues()(2);
  return std::sqrt(std::min(tr, std::max(lmax, 0.0) + 1e-12 * tr));
}

namespace {
// λmax of the symmetric 2x2 [[a, b], [b, c]] (closed form).
double lambda_max_2x2(double a, double b, double c) {
  return 0.5 * (a + c) + std::hypot(0.5 * (a - c), b);
}
}  // namespace

namespace {
// The 2x2 reduction of Step 3c around a unit vector x with an orthonormal basis z1, z2 of x⊥, for M = JᵀJ and
// F(v) = JᵀH[v] + H[v]ᵀJ, without rounding allowances (the callers add them): μ = xᵀMx, ρ = |ZᵀMx|, the
// eigenvalues of ZᵀMZ, f(v) = xᵀF(v)x = 2 w·v with w = Σ_a (Jx)_a H[a]ᵀ x, and ‖ZᵀF(v)x‖ ≤ |v|·zk:
// F(v)x = K v with K = JᵀK1 + K2, K1 = rows (H[a]ᵀ x)ᵀ, K2 = Σ_a (Jx)_a H[a].
struct Reduction {
  double mu, rho, zz_min, zz_max, zk;
  Vec3 w;
};
Reduction reduce(const Mat3& J, const std::array<Mat3, 3>& H, const Mat3& M, const Vec3& x, const Vec3& z1,
                 const Vec3& z2) {
  Reduction R;
  const Vec3 Mx = M * x;
  R.mu = x.dot(Mx);
  R.rho = std::hypot(z1.dot(Mx), z2.dot(Mx));
  const double m11 = z1.dot(M * z1), m12 = z1.dot(M * z2), m22 = z2.dot(M * z2);
  R.zz_min = 0.5 * (m11 + m22) - std::hypot(0.5 * (m11 - m22), m12);
  R.zz_max = 0.5 * (m11 + m22) + std::hypot(0.5 * (m11 - m22), m12);
  const Vec3 Jx = J * x;
  R.w = Vec3::Zero();
  Mat3 K1, K2 = Mat3::Zero();
  for (int a = 0; a < 3; ++a) {
    const Vec3 Hx = H[a].transpose() * x;  // (E(v)x)_a = vᵀ H[a]ᵀ x
    R.w += Jx(a) * Hx;
    K1.row(a) = Hx.transpose();
    K2 += Jx(a) * H[a];
  }
  const Mat3 K = J.transpose() * K1 + K2;
  const Vec3 k1 = K.transpose() * z1, k2 = K.transpose() * z2;  // rows of ZᵀK
  const double zk2 = lambda_max_2x2(k1.squaredNorm(), k1.dot(k2), k2.squaredNorm());
  R.zk = std::sqrt(std::max(zk2, 0.0) + 1e-12 * (k1.squaredNorm() + k2.squaredNorm()));
  return R;
}
// x = the eigenvector of M's column `col` (0: smallest eigenvalue, 2: largest), z1 from its column 1, z2 =
// x × z1: a unit vector and an orthonormal basis of x⊥ whatever the eigenvectors' accuracy.
void reduction_basis(const Eigen::SelfAdjointEigenSolver<Mat3>& es, int col, Vec3& x, Vec3& z1, Vec3& z2) {
  x = es.eigenvectors().col(col).normalized();
  if (!x.allFinite()) x = Vec3::UnitX();
  z1 = es.eigenvectors().col(1);
  z1 = (z1 - x * x.dot(z1)).normalized();
  if (!z1.allFinite() || std::abs(z1.dot(x)) > 1e-6) z1 = x.unitOrthogonal();
  z2 = x.cross(z1).normalized();
}
// The rounding allowances of the quadratic forms of M and F: ~10⁴ times their double-precision rounding (the
// eigensolver is backward stable, the products are short sums; docs/certificate.md Step 3c).
struct Allowances {
  double epsM, epsF;
};
Allowances allowances(const std::array<Mat3, 3>& H, double nJ2) {
  const double hF = std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
  return {1e-12 * nJ2, 1e-12 * std::sqrt(nJ2) * hF};
}
bool finite_jet(const Mat3& J, const std::array<Mat3, 3>& H, double r) {
  return r >= 0 && J.allFinite() && H[0].allFinite() && H[1].allFinite() && H[2].allFinite();
}
// An upper bound of ‖J‖₂ = sqrt(λmax(M)) from the σ3 reduction: λmax(M) ≤ λmax([[xᵀMx, ρ], [ρ, λmax(ZᵀMZ)]]).
double spectral_norm_upper(const Reduction& R, double epsM) {
  return std::sqrt(std::max(lambda_max_2x2(R.mu + epsM, R.rho + epsM, R.zz_max + epsM), 0.0) + epsM);
}
// What both Taylor bounds start from: M = JᵀJ, the allowances and M's closed-form eigenvectors
// (computeDirect: x and Z only need to be a unit vector and an orthonormal basis of x⊥, their accuracy only
// makes the bounds tighter, and it costs less than the iterative solver — the spectral term's overhead per
// certification went from ~13-16 to ~10 ms, CHANGELOG.md, 2026-11-24). ok = false: J or H not finite, det J ≤
// 0, or J = 0.
struct JetSetup {
  bool ok = false;
  Mat3 M;
  Allowances eps{0, 0};
  Eigen::SelfAdjointEigenSolver<Mat3> es;
  JetSetup(const Mat3& J, const std::array<Mat3, 3>& H, double r) {
    if (!finite_jet(J, H, r) || !(J.determinant() > 0)) return;
    M = J.transpose() * J;
    const double nJ2 = M.trace();  // ‖J‖_F²
    if (!(nJ2 > 0)) return;
    eps = allowances(H, nJ2);
    es.computeDirect(M);
    ok = true;
  }
  // The reduction around M's eigenvector of column `col` (0: σ3, 2: σ1).
  Reduction reduction(const Mat3& J, const std::array<Mat3, 3>& H, int col) const {
    Vec3 x, z1, z2;
    reduction_basis(es, col, x, z1, z2);
    return reduce(J, H, M, x, z1, z2);
  }
};
}  // namespace

// Step 3c of docs/certificate.md, in its notation: x the unit eigenvector of M = JᵀJ for its smallest
// eigenvalue, Z an orthonormal basis of x⊥; every unit y is a x + Z b with a² + |b|² = 1 and
//   yᵀ(M + F)y ≥ a²(μ1 + f11) − 2|a||b|(ρ + p) + |b|²(μ2 + φ)
// with μ1 = xᵀMx, ρ = |ZᵀMx|, μ2 = λmin(ZᵀMZ), f11 = xᵀF x = 2 wᵀv, p = |ZᵀF x| = |ZᵀK v|, φ ≥ −‖F‖₂ ≥
// −2‖J‖₂ r ‖H‖_op; the right side is ≥ (μ1 + f11) + λmin([[0, −q], [−q, D]]), q = ρ + p, D = μ2 + φ − μ1 −
// f11, increasing in f11 and φ and decreasing in p, so their worst values over |v| ≤ r give the bound.
double taylor_sigma3_lower_bound(const Mat3& J, const std::array<Mat3, 3>& H, double r) {
  constexpr double kNone = -std::numeric_limits<double>::infinity();
  const JetSetup js(J, H, r);
  if (!js.ok) return kNone;
  const auto [epsM, epsF] = js.eps;
  const Reduction R = js.reduction(J, H, 0);
  const double mu1 = R.mu - epsM;
  const double rho = R.rho + epsM;
  const double mu2 = R.zz_min - epsM;
  const double j2 = spectral_norm_upper(R, epsM);  // ≥ ‖J‖₂
  const double zk = R.zk + epsF;
  const double f11 = -2 * r * (R.w.norm() + epsF);
  const double phi = -2 * j2 * r * hessian_operator_norm(H) - 2 * r * epsF;
  const double q = rho + r * zk;
  const double D = mu2 + phi - mu1 - f11;
  const double lam = mu1 + f11 + 0.5 * (D - std::hypot(D, 2 * q));
  if (!(lam > 0) || !std::isfinite(lam)) return kNone;
  return std::sqrt(lam) * (1 - 1e-14);
}

// Step 3d of docs/certificate.md, in its notation (items 2-5 there). Both reductions of Step 3c, one around
// the smallest eigenvector of M (σ3), one around the largest (σ1); each second-order term h is taken at its
// worst over the ball, the linear terms f(v) = 2 w·v are kept, and the square roots are linearized:
//   σ1: sqrt(X) ≤ (a² + X)/(2a) for any a > 0 (AM-GM);
//   σ3: sqrt(a² + t) ≥ a + t/(2a) − t²/(2a³) for t ≥ −a².
TaylorSingularBounds taylor_singular_bounds(const Mat3& J, const std::array<Mat3, 3>& H, double r) {
  TaylorSingularBounds out;
  const JetSetup js(J, H, r);
  if (!js.ok) return out;
  const auto [epsM, epsF] = js.eps;
  const Reduction R3 = js.reduction(J, H, 0), R1 = js.reduction(J, H, 2);
  const double hop = hessian_operator_norm(H);  // ‖H[v]‖₂ ≤ r·hop
  // ‖F(v)‖₂ ≤ 2‖J‖₂‖H[v]‖₂ bounds ZᵀF(v)Z from both sides (items 2 and 3).
  const double psi = 2 * spectral_norm_upper(R3, epsM) * r * hop + 2 * r * epsF;
  const double lin = 2 * r * epsF;  // |2 (w − w̃)·v| for the computed w̃ (|w − w̃| ≤ epsF)

  // σ1 (item 2): λmax(M + F(v)) ≤ μ + f(v) + h1 with h1 = (D + sqrt(D² + 4q²))/2, increasing in D and q, at
  // D's largest value over the ball (f at −2r|w|, μ at its low end); σ1(J + H[v])² ≤ λmax(M + F) + ‖H[v]‖₂².
  const double w1 = R1.w.norm() + epsF;
  const double D1 = (R1.zz_max + epsM) + psi - (R1.mu - epsM) + 2 * r * w1;
  const double q1 = R1.rho + epsM + r * (R1.zk + epsF);
  const double s1 = std::hypot(D1, 2 * q1);
  const double h1 = D1 < 0 ? 2 * q1 * q1 / (s1 - D1) : 0.5 * (D1 + s1);  // cancellation-free for D1 < 0
  const double mu1 = R1.mu + epsM;
  const double a1 = std::sqrt(mu1);
  if (!(a1 > 0)) return out;
  // X = σ1² ≤ mu1 + 2 w̃·v + (h1 + r² hop² + lin): σ1 ≤ (a² + X)/(2a).
  out.upper1 = (a1 * a1 + mu1 + h1 + r * r * hop * hop + lin) / (2 * a1) * (1 + 1e-12);
  out.g1 = R1.w / a1;

  // σ3 (item 3): λmin(M + F(v)) ≥ μ + f(v) − h3, h3 = (sqrt(D² + 4q²) − D)/2 decreasing in D, at D's smallest
  // value (f at +2r|w|, μ at its high end, φ = −psi).
  const double w3 = R3.w.norm() + epsF;
  const double D3 = (R3.zz_min - epsM) - psi - (R3.mu + epsM) - 2 * r * w3;
  const double q3 = R3.rho + epsM + r * (R3.zk + epsF);
  const double s3 = std::hypot(D3, 2 * q3);
  const double h3 = D3 > 0 ? 2 * q3 * q3 / (s3 + D3) : 0.5 * (s3 - D3);
  const double mu3 = R3.mu - epsM;
  const double a3 = std::sqrt(mu3);
  if (!(a3 > 0)) return out;
  // σ3² ≥ a3² + t(v), t(v) ≥ −c0 + 2 w̃·v with c0 = h3 + lin + |mu3 − a3²| (the last: the square root's
  // rounding, 4 ulps), |t| ≤ T; T < a3² keeps J + H[v] nonsingular on the ball (det keeps det J's sign).
  const double c0 = h3 + lin + std::abs(mu3 - a3 * a3) + 4e-16 * mu3;
  const double T = c0 + 2 * r * R3.w.norm();
  if (!(T < a3 * a3)) return out;
  out.lower3 = (a3 - c0 / (2 * a3) - T * T / (2 * a3 * a3 * a3)) - 1e-12 * a3;
  out.g3 = R3.w / a3;
  out.valid = std::isfinite(out.upper1) && out.lower3 > 0 && out.g1.allFinite() && out.g3.allFinite();
  return out;
}

double taylor_distortion_bound(const TaylorSingularBounds& t, double r, double rho) {
  if (!t.valid || !(rho >= 0) || !(r >= 0)) return kInf;
  const double A = (t.upper1 + rho) * (1 + 1e-15), B = (t.lower3 - rho) * (1 - 1e-15);
  if (!(B > 0) || !std::isfinite(A)) return kInf;
  // φ(K) = A + r|g1 − K g3| − K B is convex in K and positive at K = A/B; its zero beyond A/B is the larger
  // root of (KB − A)² = r²|g1 − K g3|² when B > r|g3| (else φ never becomes ≤ 0).
  const double G11 = t.g1.squaredNorm(), G13 = t.g1.dot(t.g3), G33 = t.g3.squaredNorm();
  const double alpha = B * B - r * r * G33;
  if (!(alpha > 0)) return kInf;
  const double beta = A * B - r * r * G13, gamma = A * A - r * r * G11;
  const double K0 = std::max((beta + std::sqrt(std::max(0.0, beta * beta - alpha * gamma))) / alpha, A / B);
  // The root is computed in floating point: the returned K is one at which φ(K) ≤ 0 is checked with the
  // rounding of that check allowed for (the norm's cancellation, relative to its terms' sizes).
  const double n1 = std::sqrt(G11), n3 = std::sqrt(G33);
  for (const double bump : {1e-12, 1e-9, 1e-6, 1e-3}) {
    const double K = K0 * (1 + bump);
    const double lhs = (A + r * ((t.g1 - K * t.g3).norm() + 1e-14 * (n1 + K * n3))) * (1 + 1e-13);
    if (lhs <= K * B * (1 - 1e-13)) return K;
  }
  return kInf;
}

double taylor_sigma1_upper_bound(const TaylorSingularBounds& t, double r, double rho) {
  if (!t.valid || !(rho >= 0) || !(r >= 0)) return kInf;
  return (t.upper1 + rho + r * t.g1.norm()) * (1 + 1e-13);
}

double taylor_sigma3_lower_bound(const TaylorSingularBounds& t, double r, double rho) {
  if (!t.valid || !(rho >= 0) || !(r >= 0)) return -kInf;
  const double b = t.lower3 - rho - r * t.g3.norm();
  return b > 0 ? b * (1 - 1e-13) : b * (1 + 1e-13);
}

double alpha_beta_norm2(const Vec3& u, const Vec3& w, const Vec3& q) {
  const EdgeAlphaBeta ab = edge_alpha_beta(u, w, q);
  return ab.alpha.squaredNorm() + ab.beta.squaredNorm();
}

double grad_alpha_norm2_closed_form(const Vec3& u, const Vec3& w, const Vec3& q) {
  const Vec3 lu = u - q, lw = w - q;
  const double Lu = lu.norm(), Lw = lw.norm(), d = (w - u).norm();
  const double m = Lu + Lw, n = Lu * Lw;
  const double c = lu.dot(lw) / n, s2 = 1 - c * c;
  const double md = m * m - d * d;
  return (s2 * (2 * n * n * (1 + c) + m * m * (Lu * Lu + Lw * Lw)) + 2 * m * m * d * d) /
         (4 * M_PI * M_PI * n * n * md * md);
}

double grad_beta_norm2_closed_form(const Vec3& u, const Vec3& w, const Vec3& q) {
  const Vec3 lu = u - q, lw = w - q;
  const double Lu = lu.norm(), Lw = lw.norm(), d = (w - u).norm();
  const double m = Lu + Lw, n = Lu * Lw;
  const double c = lu.dot(lw) / n, s2 = 1 - c * c;
  const double md = m * m - d * d;
  return (2 * m * m * d * d * c + 4 * m * m * d * d - 2 * n * d * d * s2) /
         (4 * M_PI * M_PI * n * n * md * md);
}

const char* to_string(LipschitzBound b) {
  return enum_name(b);
}

LipschitzBound lipschitz_bound_from_string(const std::string& s) {
  if (const auto b = enum_from_name<LipschitzBound>(s)) return *b;
  throw InputError("", "unknown bound '" + s + "' (expected " + enum_name_list<LipschitzBound>() + ")");
}

}  // namespace lidef
