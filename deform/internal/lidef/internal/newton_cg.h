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

// Solves A x = b (A symmetric positive definite, given through products) by conjugate gradients
// preconditioned with M (symmetric positive definite), from x = 0 (so the first iterate is M⁻¹b scaled to the
// minimum of ½xᵀAx − bᵀx along it), until the residual r = b − A x in the preconditioner's norm,
// ‖r‖_{M⁻¹} = sqrt(rᵀM⁻¹r), is at most tolerance ‖b‖_{M⁻¹} (converged), or max_steps products — or earlier,
// from the fourth step on, when that relative residual's mean rate of decrease so far predicts more than 4 ×
// tolerance after max_steps (not converged). With M ≈ A the M⁻¹-norm of r is about the A-norm of the error,
// so the tolerance bounds the error where the quadratic model measures it; the Euclidean residual would be
// dominated by the stiffest terms (the handles' λ1 = 1e5) and leave the soft directions loose. The solver's
// direction with a kept factor (DeformParams::kept_factor_cg_steps; docs/solver.md, "The kept factor").
struct PcgResult {
  VecXd x;
  int steps = 0;                 // products of A taken
  double relative_residual = 1;  // ‖b − A x‖_{M⁻¹} / ‖b‖_{M⁻¹} of the last iterate
  bool converged = false;        // relative_residual ≤ tolerance
};
PcgResult preconditioned_cg(const VecXd& b, const std::function<VecXd(const VecXd&)>& A,
                            const std::function<bool(VecXd&)>& M, int max_steps, double tolerance);

}  // namespace lidef
