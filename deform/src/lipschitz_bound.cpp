#include "lidef/lipschitz_bound.h"

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
  return std::sqrt(h * h + 4 * d * d) / (2 * M_PI * (h * h - d * d));
}

double third_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r) {
  const double d = (w - u).norm();
  const double h = edge_sum_lower_bound(u, w, p, r);
  const double a = (u - p).norm() - r, b = (w - p).norm() - r;  // lower bounds of |l_u|, |l_w| on the ball
  if (!(h > d) || !(a > 0) || !(b > 0)) return kInf;
  const double md2 = (h * h - d * d) * (h * h - d * d);
  const double nn = (a * b) * (a * b);
  const double b66 = (1.0 + h * h * d * d / nn) / (M_PI * M_PI * md2);
  const double b67 = 3.0 * h * h * d * d / (2.0 * M_PI * M_PI * md2 * nn);
  return std::sqrt(b66 + b67);
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
  return b == LipschitzBound::kFirstOrder ? "first" : "third";
}

LipschitzBound lipschitz_bound_from_string(const std::string& s) {
  if (s == "first") return LipschitzBound::kFirstOrder;
  if (s == "third") return LipschitzBound::kThirdOrder;
  throw InputError("", "unknown bound '" + s + "' (expected 'first' or 'third')");
}

}  // namespace lidef
