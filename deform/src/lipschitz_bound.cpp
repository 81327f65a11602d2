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
template <bool Third>
inline double edge_factor(double ux, double uy, double uz, double wx, double wy, double wz, double ex,
                          double ey, double ez, double d, double px, double py, double pz, double r) {
  const BallBounds bb = ball_bounds(ux, uy, uz, wx, wy, wz, ex, ey, ez, d, px, py, pz, r);
  const bool ok = (bb.h > d) & (bb.a > 0) & (bb.b > 0);
  const double f = Third ? third_order_factor(bb.h, d, bb.a, bb.b) : first_order_factor(bb.h, d);
  return ok ? f : kInf;
}

template <bool Third>
double edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const Vec3 e = w - u;
  return edge_factor<Third>(u.x(), u.y(), u.z(), w.x(), w.y(), w.z(), e.x(), e.y(), e.z(), e.norm(), p.x(),
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

template <bool Third>
bool factor_row_impl(const EdgeArrays& E, const Vec3& p, double r, float* out) {
  const long n = E.size();
  const double px = p.x(), py = p.y(), pz = p.z();
  int infinite = 0;
#pragma omp simd reduction(| : infinite)
  for (long e = 0; e < n; ++e) {
    const float f = round_up_nonneg(edge_factor<Third>(E.ux[e], E.uy[e], E.uz[e], E.wx[e], E.wy[e], E.wz[e],
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
  return edge_factor<false>(u, w, p, r);
}

double third_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  return edge_factor<true>(u, w, p, r);
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

bool factor_row(const EdgeArrays& edges, bool third, const Vec3& p, double r, float* out) {
  return third ? factor_row_impl<true>(edges, p, r, out) : factor_row_impl<false>(edges, p, r, out);
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

// Step 3c of docs/certificate.md, in its notation: x the unit eigenvector of M = JᵀJ for its smallest
// eigenvalue, Z an orthonormal basis of x⊥; every unit y is a x + Z b with a² + |b|² = 1 and
//   yᵀ(M + F)y ≥ a²(μ1 + f11) − 2|a||b|(ρ + p) + |b|²(μ2 + φ)
// with μ1 = xᵀMx, ρ = |ZᵀMx|, μ2 = λmin(ZᵀMZ), f11 = xᵀF x = 2 wᵀv, p = |ZᵀF x| = |ZᵀK v|, φ ≥ −‖F‖₂ ≥
// −2‖J‖₂ r ‖H‖_op; the right side is ≥ (μ1 + f11) + λmin([[0, −q], [−q, D]]), q = ρ + p, D = μ2 + φ − μ1 −
// f11, increasing in f11 and φ and decreasing in p, so their worst values over |v| ≤ r give the bound.
double taylor_sigma3_lower_bound(const Mat3& J, const std::array<Mat3, 3>& H, double r) {
  constexpr double kNone = -std::numeric_limits<double>::infinity();
  if (!(r >= 0) || !J.allFinite() || !H[0].allFinite() || !H[1].allFinite() || !H[2].allFinite())
    return kNone;
  if (!(J.determinant() > 0)) return kNone;
  const Mat3 M = J.transpose() * J;
  const double nJ2 = M.trace();  // ‖J‖_F²
  if (!(nJ2 > 0)) return kNone;
  // Rounding allowance of the quadratic forms of M and F: ~10⁴ times their double-precision rounding (the
  // eigensolver is backward stable, the products are short sums; docs/certificate.md Step 3c).
  const double hF = std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
  const double epsM = 1e-12 * nJ2, epsF = 1e-12 * std::sqrt(nJ2) * hF;
  // x and Z only need to be a unit vector and an orthonormal basis of x⊥ (their accuracy only makes the bound
  // tighter): the closed-form eigenvectors (computeDirect) do, and cost less than the iterative solver (the
  // spectral term's overhead per certification went from ~13-16 to ~10 ms, CHANGELOG.md, 2026-11-24).
  Eigen::SelfAdjointEigenSolver<Mat3> es;
  es.computeDirect(M);
  Vec3 x = es.eigenvectors().col(0).normalized();
  if (!x.allFinite()) x = Vec3::UnitX();
  Vec3 z1 = es.eigenvectors().col(1);
  z1 = (z1 - x * x.dot(z1)).normalized();
  if (!z1.allFinite() || std::abs(z1.dot(x)) > 1e-6) z1 = x.unitOrthogonal();
  const Vec3 z2 = x.cross(z1).normalized();
  const Vec3 Mx = M * x;
  const double xMx = x.dot(Mx);
  const double mu1 = xMx - epsM;
  const double rho = std::hypot(z1.dot(Mx), z2.dot(Mx)) + epsM;
  const double m11 = z1.dot(M * z1), m12 = z1.dot(M * z2), m22 = z2.dot(M * z2);
  const double mu2 = 0.5 * (m11 + m22) - std::hypot(0.5 * (m11 - m22), m12) - epsM;
  // ‖J‖₂² = λmax(M) ≤ λmax([[xᵀMx, ρ], [ρ, λmax(ZᵀMZ)]]) (the same reduction, from above).
  const double zz_max = 0.5 * (m11 + m22) + std::hypot(0.5 * (m11 - m22), m12) + epsM;
  const double j2 = std::sqrt(std::max(lambda_max_2x2(xMx + epsM, rho, zz_max), 0.0) + epsM);  // ≥ ‖J‖₂
  // Linear in v: f11(v) = 2 wᵀv with w = Σ_a (Jx)_a H[a]ᵀ x; F(v)x = K v with K = Jᵀ K1 + K2,
  // K1 = rows (H[a]ᵀ x)ᵀ, K2 = Σ_a (Jx)_a H[a].
  const Vec3 Jx = J * x;
  Vec3 w = Vec3::Zero();
  Mat3 K1, K2 = Mat3::Zero();
  for (int a = 0; a < 3; ++a) {
    const Vec3 Hx = H[a].transpose() * x;  // (E(v)x)_a = vᵀ H[a]ᵀ x (H[a] symmetric up to rounding)
    w += Jx(a) * Hx;
    K1.row(a) = Hx.transpose();
    K2 += Jx(a) * H[a];
  }
  const Mat3 K = J.transpose() * K1 + K2;
  const Vec3 k1 = K.transpose() * z1, k2 = K.transpose() * z2;  // rows of ZᵀK
  const double zk2 = lambda_max_2x2(k1.squaredNorm(), k1.dot(k2), k2.squaredNorm());
  const double zk = std::sqrt(std::max(zk2, 0.0) + 1e-12 * (k1.squaredNorm() + k2.squaredNorm())) + epsF;
  const double f11 = -2 * r * (w.norm() + epsF);
  const double phi = -2 * j2 * r * hessian_operator_norm(H) - 2 * r * epsF;
  const double q = rho + r * zk;
  const double D = mu2 + phi - mu1 - f11;
  const double lam = mu1 + f11 + 0.5 * (D - std::hypot(D, 2 * q));
  if (!(lam > 0) || !std::isfinite(lam)) return kNone;
  return std::sqrt(lam) * (1 - 1e-14);
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
