#include "lidef/explorer/sigma_minima.h"

#include <omp.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

#include "explorer_rng.h"
#include "lidef/errors.h"
#include "lidef/procedural_models.h"
#include "lidef/signed_svd.h"

namespace lidef {
namespace {

// Fibonacci points on the unit sphere.
std::vector<Vec3> fibonacci_sphere(int n) {
  std::vector<Vec3> p(n);
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1 - (2 * i + 1.0) / n, r = std::sqrt(std::max(0.0, 1 - z * z));
    p[i] = Vec3(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return p;
}

struct DescentResult {
  Vec3 x;
  double sigma3;
  double grad_norm;
  double sigma1;
};

// Projected trust-region Newton descent of σ3 from x0 (see find_sigma3_minima).
DescentResult descend(const ExplorerMap& map, const Ball& ball, Vec3 x, int max_iterations, double tol) {
  SigmaDerivatives d = map_sigma_derivatives(map, x, true);
  double delta = 0.1 * ball.radius;
  for (int it = 0; it < max_iterations; ++it) {
    const Vec3 g = d.grad.row(2).transpose();
    const bool interior = (x - ball.center).norm() < ball.radius * (1 - 1e-9);
    if (g.norm() <= tol * (1 + std::abs(d.sigma(0))) && interior) break;
    Eigen::SelfAdjointEigenSolver<Mat3> es(d.hess[2]);
    Vec3 p;
    if (es.info() == Eigen::Success && es.eigenvalues()(0) > 0)
      p = -(es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() *
            es.eigenvectors().transpose()) *
          g;
    else
      p = -g.normalized() * delta;
    if (!p.allFinite()) break;
    if (p.norm() > delta) p *= delta / p.norm();
    Vec3 xn = x + p;
    if ((xn - ball.center).norm() > ball.radius)
      xn = ball.center + ball.radius * (xn - ball.center).normalized();
    const SigmaDerivatives dn = map_sigma_derivatives(map, xn, true);
    if (dn.sigma(2) <= d.sigma(2) + 4e-16 * std::abs(d.sigma(2))) {
      const bool full = p.norm() >= 0.99 * delta;
      x = xn;
      d = dn;
      if (full) delta = std::min(2 * delta, ball.radius);
    } else {
      delta *= 0.25;
      if (delta < 1e-13 * ball.radius) break;
    }
  }
  return {x, d.sigma(2), d.grad.row(2).norm(), d.sigma(0)};
}

}  // namespace

std::vector<Sigma3Minimum> find_sigma3_minima(const ExplorerMap& map, const Ball& ball,
                                              const MinimaSearchParams& params) {
  if (params.starts < 1) throw InputError("", "the minima search needs at least one start");
  explorer_detail::Rng rng(params.seed);
  std::vector<Vec3> starts{ball.center};
  while (static_cast<int>(starts.size()) < params.starts) starts.push_back(rng.in_ball(ball));
  std::vector<DescentResult> res(starts.size());
#pragma omp parallel for schedule(dynamic) if (!omp_in_parallel())
  for (int s = 0; s < static_cast<int>(starts.size()); ++s)
    res[s] = descend(map, ball, starts[s], params.max_iterations, params.gradient_tolerance);

  // Converged interior points, merged when closer than 1e-6 R (keeping the lowest σ3).
  std::vector<DescentResult> good;
  for (const DescentResult& r : res)
    if ((r.x - ball.center).norm() < ball.radius * (1 - params.interior_margin) &&
        r.grad_norm <= params.gradient_tolerance * (1 + std::abs(r.sigma1)))
      good.push_back(r);
  std::stable_sort(good.begin(), good.end(),
                   [](const DescentResult& a, const DescentResult& b) { return a.sigma3 < b.sigma3; });
  std::vector<Sigma3Minimum> out;
  const std::vector<Vec3> sphere = fibonacci_sphere(params.sphere_points);
  for (const DescentResult& r : good) {
    bool merged = false;
    for (Sigma3Minimum& m : out)
      if ((m.position - r.x).norm() < 1e-6 * ball.radius) {
        ++m.starts;
        merged = true;
        break;
      }
    if (merged) continue;
    Sigma3Minimum m;
    m.position = r.x;
    m.starts = 1;
    const SigmaDerivatives d = map_sigma_derivatives(map, r.x, true);
    m.sigma3 = d.sigma(2);
    m.gradient_norm = d.grad.row(2).norm();
    m.gap = d.gap(2);
    Eigen::SelfAdjointEigenSolver<Mat3> es(d.hess[2], Eigen::EigenvaluesOnly);
    m.hessian_eigenvalues = es.eigenvalues();
    m.sphere_radius = std::min(0.01 * ball.radius, 0.5 * (ball.radius - (r.x - ball.center).norm()));
    m.sphere_min_sigma3 = std::numeric_limits<double>::infinity();
    for (const Vec3& u : sphere) {
      const Vec3 s = signed_singular_values(map.jacobian(r.x + m.sphere_radius * u));
      m.sphere_min_sigma3 = std::min(m.sphere_min_sigma3, s(2));
    }
    // Flat directions (a constant σ3, e.g. an affine map) are not strict minima: demand curvature and a rise
    // that clearly exceed rounding.
    const double scale = 1 + std::abs(d.sigma(0));
    m.strict = m.hessian_eigenvalues(0) > 1e-8 * scale && m.sphere_min_sigma3 > m.sigma3 + 1e-12 * scale;
    out.push_back(m);
  }
  return out;
}

std::pair<double, Vec3> sampled_sphere_min_sigma3(const ExplorerMap& map, const Ball& ball,
                                                  int subdivisions) {
  const TriMesh s = icosphere(ball.radius, subdivisions);
  double best = std::numeric_limits<double>::infinity();
  Vec3 where = ball.center;
  for (int i = 0; i < s.V.rows(); ++i) {
    const Vec3 p = ball.center + s.V.row(i).transpose();
    const double v = signed_singular_values(map.jacobian(p))(2);
    if (v < best) {
      best = v;
      where = p;
    }
  }
  return {best, where};
}

const Sigma3Minimum* lowest_strict_minimum(const std::vector<Sigma3Minimum>& minima) {
  for (const Sigma3Minimum& m : minima)
    if (m.strict) return &m;
  return nullptr;
}

}  // namespace lidef
