#include "lidef/internal/newton_cg.h"

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

}  // namespace lidef
