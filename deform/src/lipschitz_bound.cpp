#include "lidef/lipschitz_bound.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "lidef/errors.h"
#include "lidef/green_coordinates.h"

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
  switch (b) {
    case LipschitzBound::kFirstOrder:
      return "first";
    case LipschitzBound::kThirdOrder:
      return "third";
    case LipschitzBound::kCombined:
      return "combined";
  }
  return "third";
}

LipschitzBound lipschitz_bound_from_string(const std::string& s) {
  if (s == "first") return LipschitzBound::kFirstOrder;
  if (s == "third") return LipschitzBound::kThirdOrder;
  if (s == "combined") return LipschitzBound::kCombined;
  throw InputError("", "unknown bound '" + s + "' (expected 'first', 'third' or 'combined')");
}

}  // namespace lidef
