#include "lidef/internal/newton_cg.h"

#include <cmath>

namespace lidef {

NewtonCgResult truncated_newton_cg(const VecXd& g, const VecXd& p0, int steps, const NewtonCgOperators& ops) {
  NewtonCgResult out;
  out.d = VecXd::Zero(g.size());
  VecXd r = -g, p = p0;
  double rz = r.dot(p0);  // z0 = M⁻¹ r0 = p0
  for (int k = 0; k < steps; ++k) {
    const double kappa = ops.curvature(p);
    if (!(kappa > 0) || !(rz > 0)) break;
    const double alpha = rz / kappa;
    out.d += alpha * p;
    if (ops.accepted) ops.accepted(alpha, k);
    if (k == 0) out.scale = alpha;
    ++out.steps;
    if (k + 1 == steps) break;
    r -= alpha * ops.hessian_times(p);
    VecXd z = r;
    if (!ops.precondition(z)) break;
    const double rz_next = r.dot(z);
    p = z + (rz_next / rz) * p;
    rz = rz_next;
  }
  if (out.steps == 0) out.d = p0;
  return out;
}

PcgResult preconditioned_cg(const VecXd& b, const std::function<VecXd(const VecXd&)>& A,
                            const std::function<bool(VecXd&)>& M, int max_steps, double tolerance) {
  PcgResult out;
  out.x = VecXd::Zero(b.size());
  VecXd r = b, z = b;
  if (!M(z)) return out;
  double rz = r.dot(z);
  const double rz0 = rz;  // ‖b‖²_{M⁻¹}
  if (!(rz0 > 0)) {       // b = 0 (M is positive definite): x = 0 solves it
    out.relative_residual = 0;
    out.converged = b.isZero(0);
    return out;
  }
  VecXd p = z;
  double first = 1;
  constexpr double kGiveUp = 4;  // the residual is not monotone: a margin before predicting failure
  for (int k = 0; k < max_steps; ++k) {
    const VecXd Ap = A(p);
    ++out.steps;
    const double curvature = p.dot(Ap);
    if (!(curvature > 0)) break;  // not positive definite in rounding: give up
    const double alpha = rz / curvature;
    out.x += alpha * p;
    r -= alpha * Ap;
    z = r;
    if (!M(z)) break;
    const double rz_next = r.dot(z);
    if (!(rz_next >= 0)) break;
    out.relative_residual = std::sqrt(rz_next / rz0);
    if (out.relative_residual <= tolerance) {
      out.converged = true;
      break;
    }
    if (k == 0) first = out.relative_residual;
    // From the fourth step on, give up when the mean rate so far would leave the residual well above the
    // tolerance after max_steps: the caller's other way is cheaper than the remaining steps.
    if (k >= 3) {
      const double rate = std::pow(out.relative_residual / first, 1.0 / k);
      if (!(rate < 1) || out.relative_residual * std::pow(rate, max_steps - 1 - k) > kGiveUp * tolerance)
        break;
    }
    p = z + (rz_next / rz) * p;
    rz = rz_next;
  }
  return out;
}

}  // namespace lidef
