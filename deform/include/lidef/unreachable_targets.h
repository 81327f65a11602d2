// Targets that no certified map of the subspace reaches — a proof, or why there is none (docs/certificate.md,
// "Targets no certified map reaches"; docs/solver.md, "Continuation").
//
// When the handles pin the subspace (at least as many handles as reduced coefficients per coordinate, and
// the handle matrix D̃ of full column rank), the maps that reach the targets form a small ball around the
// least-squares map ỹ₀ = D̃⁺ Q: for any ỹ whose handles are all within τ of their targets,
//   ‖D̃ (ỹ − ỹ₀)‖_F ≤ √#h τ + ‖D̃ ỹ₀ − Q‖_F =: ε   and   ‖J_ỹ(x) − J_ỹ₀(x)‖₂ ≤ ‖G_x D̃⁺‖₂ ε
// at every point x (G_x: 3 by s reduced basis gradients). If ỹ₀ is orientation-reversing at a voxel center x
// by more than twice that radius (det J_ỹ₀(x) < 0 and σ_min(J_ỹ₀(x)) ≥ 2 ‖G_x D̃⁺‖₂ ε), every map that
// reaches the targets has det J(x) < 0 at x, inside the certified domain: no certificate can accept it.
// Likewise, if even the least-squares map misses a handle by more than √#h τ in total — proven on a lower bound
// of the exact least-squares residual, from which the rounding of its computation has been taken off, never on
// the computed residual itself (an upper bound, of order cond(D̃) u ‖Q‖ where the targets are reachable) — no
// map of the subspace reaches the targets at all. The factor 2 absorbs the double-precision rounding of
// the SVD, the least-squares map and the basis (relative ~cond(D̃) · 1e-16 ≤ ~1e-8 at the accepted
// conditioning, cond(D̃) ≤ 1e8).
//
// Otherwise nothing is proven and `reason` says why (too few handles, a handle matrix without full rank, or
// a least-squares map that is orientation-preserving everywhere within the margin). Not proven ≠ reachable.
#pragma once
#include <string>

#include "lidef/types.h"

namespace lidef {

class DeformationSolver;

struct UnreachabilityProof {
  bool proven = false;
  // "orientation": every reaching map folds at `point`; "residual": no map of the subspace reaches the
  // targets; "" when not proven.
  std::string kind;
  std::string reason;         // one sentence: the statement proven, or why nothing is
  int handles = 0;            // #h
  int reduced_size = 0;       // s
  double condition = 0;       // σ_max(D̃) / σ_min(D̃) (0 when not computed)
  double tolerance = 0;       // τ: handle_tolerance, normalized frame (= model units / frame scale)
  double residual = 0;        // ‖D̃ ỹ₀ − Q‖_F as computed, normalized frame
  // Bounds with every rounding accounted for (docs/certificate.md, step 3): residual_upper ≥ the exact
  // ‖D̃ ỹ₀ − Q‖_F of the computed ỹ₀; residual_lower ≤ the exact least-squares residual min ‖D̃ ỹ − Q‖_F
  // (0 when the rounding may account for all of it). "residual" is proven on residual_lower only.
  double residual_upper = 0;
  double residual_lower = 0;
  // Bound of the rounding in an evaluated ‖D̃ ỹ₀ − Q‖_F: below it reached and missed are not told apart, so
  // "residual" needs residual_lower ≥ 2 max(√#h τ, rounding_floor) — a tolerance of 0 proves nothing finer.
  double rounding_floor = 0;
  double radius = 0;          // ε = √#h τ + residual_upper
  Vec3 point = Vec3::Zero();  // "orientation": the voxel center x, model units
  double sigma_min = 0;       // "orientation": σ_min(J_ỹ₀(x)) (det J_ỹ₀(x) < 0)
  double jacobian_bound = 0;  // "orientation": ‖G_x D̃⁺‖₂ ε ≥ ‖J_ỹ(x) − J_ỹ₀(x)‖₂ for every reaching ỹ
  MatS3 least_squares;  // ỹ₀ (s by 3, normalized frame); empty when not computed
};

// For the solver's current handles and targets, the voxels of its sampling and params().handle_tolerance.
// Cost: an SVD of D̃ (#h by s) and one pass over the stored basis gradients (a few 0.1 s at s = 300), nothing
// when #h < s.
UnreachabilityProof prove_targets_unreachable(const DeformationSolver& solver);

}  // namespace lidef
