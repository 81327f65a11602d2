// Truncated preconditioned conjugate gradients for the Newton system ∇²E d = −∇E, the correction of the
// subset Hessian's direction (DeformParams::newton_cg_steps; docs/solver.md, "Correcting the subset
// Hessian").
//
// The preconditioner is the factored subset Hessian M (positive definite); the operator is the exact Hessian,
// given only through products. Started at d = 0, the first iterate is p0 = −M⁻¹∇E scaled to the minimum of
// the exact quadratic model along it; every further iterate costs one Hessian-vector product. The iteration
// stops early at non-positive curvature (Steihaug): the exact Hessian of E_iso is indefinite where samples
// are compressed, and every iterate before such a direction is a descent direction.
#pragma once
#include <functional>

#include "lidef/types.h"

namespace lidef {

struct NewtonCgOperators {
  // Makes p the current direction (the solver computes its Jacobians G p here) and returns pᵀ ∇²E p.
  std::function<double(const VecXd& p)> curvature;
  // ∇²E p for the current direction p (called after curvature(p)).
  std::function<VecXd(const VecXd& p)> hessian_times;
  // r ← M⁻¹ r; false if the solve failed.
  std::function<bool(VecXd& r)> precondition;
  // Called with α after each accepted iterate d += α p (the solver accumulates the Jacobians of d).
  std::function<void(double alpha, int k)> accepted;
};

struct NewtonCgResult {
  VecXd d;           // the last iterate (p0 itself when no iterate was taken)
  int steps = 0;     // iterates taken (0: the first curvature was not positive)
  double scale = 0;  // α of the first iterate (the exact model's scale of p0)
};

// g: ∇E (n); p0: −M⁻¹ g (n); steps ≥ 1: iterates at most.
NewtonCgResult truncated_newton_cg(const VecXd& g, const VecXd& p0, int steps, const NewtonCgOperators& ops);

}  // namespace lidef
