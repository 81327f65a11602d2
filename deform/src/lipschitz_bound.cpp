#include "lidef/lipschitz_bound.h"

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>

#include "lidef/errors.h"
#include "lidef/green_coordinates.h"

namespace lidef {
namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}

double edge_sum_lower_bound(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const Vec3 e = w - u;
  const double d = e.norm();
  const double a = (u - p).norm() - r, b = (w - p).norm() - r;
  const double line_dist = (p - u).cross(e).norm() / d;
  const double rho = std::max(0.0, line_dist - r);
  // |q−u| + |q−w| ≥ |q−u| ... triangle inequality per endpoint; and the ellipse bound: points at distance
  // ρ from the line have |q−u| + |q−w| ≥ 2 sqrt(ρ² + d²/4) (minimum on the bisector plane).
  return std::max(std::max(a, 0.0) + std::max(b, 0.0), 2.0 * std::sqrt(rho * rho + 0.25 * d * d));
}

double first_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const double d = (w - u).norm();
  const double h = edge_sum_lower_bound(u, w, p, r);
  if (!(h > d) || (u - p).norm() <= r || (w - p).norm() <= r) return kInf;
  // |α| ≤ m / (2π(m²−d²)),  |β| ≤ 2d / (2π(m²−d²)), both decreasing in m.
  return first_order_factor(h, d);
}

double third_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const double d = (w - u).norm();
  const double h = edge_sum_lower_bound(u, w, p, r);
  const double a = (u - p).norm() - r, b = (w - p).norm() - r;  // lower bounds of |l_u|, |l_w| on the ball
  if (!(h > d) || !(a > 0) || !(b > 0)) return kInf;
  return third_order_factor(h, d, a, b);
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
