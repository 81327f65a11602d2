// A local/global (ARAP-like, as VHM) solve in the solver's reduced harmonic space: the rotation-aware warm
// start / fallback of the continuation (continuation.h; docs/solver.md, "Continuation").
//
//   E_LG(ỹ, R) = (c/|I|) Σ_i w_i ‖G_i ỹ − R_iᵀ‖²  +  λ1 Σ_h ‖D_h ỹ − q_h‖²  +  (λ2/|E|) Σ_j μ_j ‖ỹ_j‖²
//
// with the solver's energy pieces (deformation_energy.h): G_i the 3 rows of the reduced gradient matrix at
// sample i (JT layout: G_i ỹ = J_iᵀ), w_i its volume weight (mean 1), D the handle rows, μ the smoothness
// eigenvalues, |E| the cage's edges; λ1, λ2 the user's weights. c = 4 (`rigidity`) makes the first term the
// second-order expansion of E_dis = mean(E_iso − 6) about a rotation (E_iso − 6 ≈ 4‖J − R‖²), so that the
// three terms are balanced as in the solver's energy. Local step: R_i = closest rotation to J_i. Global step:
// the s-by-s normal matrix A = (c/|I|) Gᵀ W G + λ1 DᵀD + (λ2/|E|) diag μ, the same for the three columns, is
// factored once per handle set (Cholesky); each iteration is one product with G and one back-substitution.
// The iterations are Anderson-accelerated (the last five image/residual differences; an iterate that does not
// lower E_LG is replaced by the plain one, at the cost of one more local step), so E_LG does not increase from
// one iterate to the next (up to the plain step's rounding).
// Nothing here is certified: the continuation accepts a local/global map only through the solver's
// certificate (DeformationSolver::set_reduced_map).
#pragma once
#include <Eigen/Cholesky>
#include <atomic>
#include <vector>

#include "lidef/deformation_energy.h"
#include "lidef/types.h"

namespace lidef {

// The rotation closest to M in the Frobenius norm (polar decomposition; a reflection is turned into a
// rotation by flipping the smallest singular direction).
Mat3 closest_rotation(const Mat3& M);

struct LocalGlobalResult {
  MatS3 y;                   // s by 3 reduced coefficients (normalized frame)
  int iterations = 0;        // local/global iterations run
  double energy = 0;         // E_LG at y with its best rotations
  bool converged = false;    // relative energy decrease below the tolerance
  bool interrupted = false;  // `stop` was set: y is the last iterate (E_LG no higher than at y0)
};

class LocalGlobalSolver {
 public:
  // Factors A for `energy`'s samples, weights and handles (set_handles must have been called) with the
  // weights `w`. rigidity = c above (0: no rotation term, a plain smoothed least-squares fit of the handles).
  // Throws NumericalError when A is not positive definite.
  LocalGlobalSolver(const DeformationEnergy& energy, const EnergyWeights& w, double rigidity = 4.0);

  // Local/global iterations from y0 (s by 3) toward the handle targets Q (#h by 3, normalized frame), until
  // the relative decrease of E_LG is below `tolerance` or after `max_iterations`; `stop` (optional) is
  // checked before every iteration (a solve of hundreds of iterations takes seconds on the shared models).
  LocalGlobalResult solve(const MatS3& y0, const MatX3d& Q, int max_iterations = 200, double tolerance = 1e-8,
                          const std::atomic<bool>* stop = nullptr) const;
  // E_LG(y, R) with the rotations closest to y's Jacobians.
  double energy(const MatS3& y, const MatX3d& Q) const;
  // The best rotations of y's Jacobians, stacked as the targets of G y: 3|I| by 3, rows 3i..3i+2 = R_iᵀ.
  // `rigid` (optional): the first term of E_LG at y with these rotations.
  MatJT rotation_targets(const MatS3& y, double* rigid = nullptr) const;
  // One global step: argmin over ỹ of E_LG(ỹ, R) for the stacked targets T (3|I| by 3, as above).
  MatS3 global_step(const MatJT& T, const MatX3d& Q) const;

 private:
  double rest_energy(const MatS3& y, const MatX3d& Q) const;  // the handle and smoothness terms
  const DeformationEnergy& energy_;
  EnergyWeights w_;
  double rigidity_;
  Eigen::LLT<MatXd> llt_;
};

}  // namespace lidef
