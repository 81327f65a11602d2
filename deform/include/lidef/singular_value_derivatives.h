// Spatial derivatives of the signed singular values σ1 ≥ σ2 ≥ |σ3| of a map's Jacobian J(x) (signed_svd.h),
// from the derivatives of J. With J = U diag(σ) Vᵀ and M_k = Uᵀ (∂J/∂x_k) V (perturbation theory of the
// symmetric matrix [[0, J], [Jᵀ, 0]], whose eigenpairs are ±σ_i, (u_i, ±v_i)/√2):
//   ∂σ_i/∂x_k      = M_k(i,i)
//   ∂²σ_i/∂x_k∂x_l = (Uᵀ ∂²J/∂x_k∂x_l V)(i,i)
//                    + ½ Σ_{j≠i} [ s^k_ij s^l_ij / (σ_i − σ_j) + a^k_ij a^l_ij / (σ_i + σ_j) ],
//   s^k_ij = M_k(j,i) + M_k(i,j),  a^k_ij = M_k(j,i) − M_k(i,j).
// Valid where σ_i is simple and σ_i + σ_j ≠ 0 (gap() reports how far from that a point is). The Laplacian is
// the trace of the Hessian; for a harmonic map the first term's trace vanishes (paper App. D, eq. (47)).
#pragma once
#include <array>

#include "lidef/types.h"

namespace lidef {

struct SigmaDerivatives {
  Vec3 sigma = Vec3::Zero();      // signed σ1, σ2, σ3
  Mat3 grad = Mat3::Zero();       // row i: ∇σ_i
  std::array<Mat3, 3> hess{};     // hess[i]: Hessian of σ_i (only when second derivatives of J were given)
  Vec3 laplacian = Vec3::Zero();  // trace of hess[i]
  // The two parts of the perturbation term's trace, ½ Σ_k Σ_{j≠i} (s^k_ij)²/(σ_i − σ_j) and (a^k_ij)²/(σ_i +
  // σ_j): for σ3 the first is ≤ 0 and the second ≥ 0 (for σ1 both are ≥ 0). For a harmonic map their sum is
  // the Laplacian.
  Vec3 laplacian_symmetric = Vec3::Zero(), laplacian_antisymmetric = Vec3::Zero();
  // min over j ≠ i of |σ_i − σ_j| and |σ_i + σ_j|, per i: the formulas lose accuracy as this nears 0.
  Vec3 gap = Vec3::Zero();
};

// J: the Jacobian. dJ[k] = ∂J/∂x_k, i.e. dJ[k](a,b) = ∂²f_a/∂x_b∂x_k. d2J (optional): d2J[k][l] =
// ∂²J/∂x_k∂x_l. Without d2J only sigma, grad and gap are filled.
SigmaDerivatives sigma_derivatives(const Mat3& J, const std::array<Mat3, 3>& dJ,
                                   const std::array<std::array<Mat3, 3>, 3>* d2J = nullptr);

}  // namespace lidef
