// Per-sample symmetric Dirichlet energy E_iso (paper Sec. 3 / 7.1, App. G): value, gradient with respect to
// the Jacobian, and its 9x9 Hessian with the analytic PSD projection of projected Newton.
//
// Energy. With the signed SVD J = U diag(σ) Vᵀ (U, V rotations, σ1 ≥ σ2 ≥ |σ3|, see signed_svd.h):
//     E(J) = Σ_i σ_i² + σ_i⁻² = ‖J‖_F² + ‖J⁻¹‖_F²        (= 6 at every rotation, its minimum).
//   E is a *barrier*: it is returned as +∞ whenever det J ≤ 0 (also when J⁻¹ overflows). The formula
//   ‖J‖² + ‖J⁻¹‖² would be finite for det J < 0; reporting +∞ there is what lets the solver's line search
//   reject every step that inverts a sample without an explicit constraint (paper Sec. 3, condition (1b)).
//
// Gradient (same layout as J: G(a,b) = ∂E/∂J(a,b), J(a,b) = ∂f_a/∂p_b):
//     ∂E/∂J = U diag(∂E/∂σ_i) Vᵀ = 2J − 2 J⁻ᵀ J⁻¹ J⁻ᵀ,      ∂E/∂σ_i = 2σ_i − 2σ_i⁻³      (App. G (63)).
//   The closed form on the right is what is computed (no SVD).
//
// vec convention: COLUMN-MAJOR, vec(J)(a + 3b) = J(a,b) — the layout of Eigen's default Mat3 storage
//   (Eigen::Map<const Vec9>(J.data())) and the one under which vec(U M Vᵀ) = (V ⊗ U) vec(M) as in (63).
//   Every 9-vector and 9x9 matrix here uses it: d²E = vec(dJ)ᵀ H vec(dJ).
//
// Hessian eigensystem (Smith, De Goes, Kim 2019, "Analytic Eigensystems for Isotropic Distortion Energies",
// ACM TOG 38(1); Stomakhin et al. 2012; paper App. G (63), whose Q Λ Qᵀ is exactly this decomposition). For
// an isotropic E(σ), H = ∂²E/∂vec(J)² = Σ_k λ_k q_k q_kᵀ with 9 orthonormal eigenvectors q_k = vec(U M_k Vᵀ):
//   scaling (3): eigenpairs (μ, v) of the 3x3 matrix A_ij = ∂²E/∂σ_i∂σ_j, lifted as M = diag(v).
//                For SD A is diagonal, A_ii = 2 + 6σ_i⁻⁴, so v = e_i and M = e_i e_iᵀ.
//   per pair (i, j) ∈ {(0,1), (1,2), (0,2)}, M in the plane of e_i, e_j:
//     twist  M = (e_i e_jᵀ − e_j e_iᵀ)/√2,  λ = (∂E/∂σ_i + ∂E/∂σ_j)/(σ_i + σ_j)
//     flip   M = (e_i e_jᵀ + e_j e_iᵀ)/√2,  λ = (∂E/∂σ_i − ∂E/∂σ_j)/(σ_i − σ_j)
//   (the eigenvalues of the 2x2 block Λ of (63): both factors of Λ share the eigenvectors (1, ∓1)). For SD
//   the quotients simplify, with no division by σ_i ∓ σ_j and hence no special case for repeated σ:
//     λ_twist = 2 − 2 (σ_i² − σ_iσ_j + σ_j²)/(σ_i³σ_j³)    (negative when the pair is compressed: the only
//                                                           source of indefiniteness; 0 at a rotation)
//     λ_flip  = 2 + 2 (σ_i² + σ_iσ_j + σ_j²)/(σ_i³σ_j³)    (> 0 for σ > 0)
//   With repeated σ the eigenvectors are not unique but the sums Σ λ q qᵀ are, so H is well defined.
//   Note SD is not convex even near the identity: at J = s·R with s < 1 the three twist eigenvalues are
//   2 − 2/s⁴ < 0; the projection clamps them.
// PSD projection: H⁺ = Σ_k max(λ_k, 0) q_k q_kᵀ, the Frobenius-closest PSD matrix (paper Sec. 7.1).
//
// Domain of the derivatives: det J > 0 (where E is finite). For det J ≤ 0 the gradient and both Hessians are
// returned filled with quiet NaN: the solver must never evaluate them there (its line search keeps every
// sample at det J > 0), and NaN makes a violation loud instead of silently wrong.
#pragma once
#include <Eigen/Core>

#include "lidef/types.h"

namespace lidef {

using Vec9 = Eigen::Matrix<double, 9, 1>;
using Mat9 = Eigen::Matrix<double, 9, 9>;

// E(J) = ‖J‖_F² + ‖J⁻¹‖_F²; +∞ when det J ≤ 0 (barrier).
double sd_energy(const Mat3& J);

// ∂E/∂J, same layout as J. NaN-filled when det J ≤ 0.
Mat3 sd_gradient(const Mat3& J);

// ∂²E/∂J² applied to dJ (same layout as J; = sd_hessian(J) vec(dJ) reshaped), without projection, from the
// closed form: with B = J⁻ᵀ, X = dJᵀ, it is 2 dJ + 2 (B X B Bᵀ B + B Bᵀ dJ Bᵀ B + B Bᵀ B X B) — a few 3x3
// products, no eigensystem (the solver's Hessian-vector products, docs/solver.md "Correcting the subset
// Hessian"). NaN-filled when det J ≤ 0.
Mat3 sd_hessian_times(const Mat3& J, const Mat3& dJ);

// ∂²E/∂vec(J)² (column-major vec), from the analytic eigensystem, without clamping. Symmetric. NaN-filled
// when det J ≤ 0.
Mat9 sd_hessian(const Mat3& J);

// PSD projection of sd_hessian: the same eigensystem with negative eigenvalues clamped to 0. NaN-filled when
// det J ≤ 0.
Mat9 sd_hessian_psd(const Mat3& J);

}  // namespace lidef
