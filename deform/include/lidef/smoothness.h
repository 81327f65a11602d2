// The smoothness operator K of Liao et al. 2021, Sec. 6.1: per cage edge, the jump of the per-face
// affine matrices A_t (Lemma 5.1) across the edge. E_smooth = ‖K y‖² vanishes exactly on affine maps, and
// ‖δ_A^e‖ bounds ‖H‖ (Theorem 5.2), so the certificate and the subspace reduction both start from K.
//
// Coefficients y are #V+#F by 3: vertex rows y_v first, then face rows y_t (see cage.h).
#pragma once
#include <Eigen/SparseCore>

#include "lidef/cage.h"
#include "lidef/types.h"

namespace lidef {

// A_t of Lemma 5.1 for face t: the unique linear map with A_t n_t = y_t and A_t (x_b − x_a) = y_b − y_a on
// the edges of t. Written with the gradients of t's barycentric coordinates,
//   A_t = y_t n_tᵀ + Σ_{v∈t} y_v ∇λ_vᵀ,   ∇λ_a = n_t × (c − b) / (2 s_t)  (cyclically for b, c),
// which is the printed −1/(2s_t) Σ y_v (n_t × d_v)ᵀ with d_v = w − u for (u,v,w) in cage order.
// For the coefficients of an affine map p -> A p + b, A_t = A for every t.
//   y: #V+#F by 3. Throws InputError on a bad face index or a y of the wrong shape.
Mat3 face_affine_matrix(const Cage& cage, const MatX3d& y, int t);

// Sparse K, 3#E by #V+#F: rows 3e..3e+2 of K y (K y is 3#E by 3) hold (δ_A^e)ᵀ = (A_{f0} − A_{f1})ᵀ for the
// undirected edge e = cage.edges[e] (f0, f1 as stored there). K y = 0 exactly (up to rounding) iff y is the
// coefficient matrix of an affine map — per column, the null space of K is the 4-dim space {a·v + b on
// vertex rows, a·n_t on face rows} (for a connected cage, of any genus).
Eigen::SparseMatrix<double> smoothness_matrix(const Cage& cage);

// ‖δ_A^e‖_F for every edge, #E. K: smoothness_matrix(cage); y: #V+#F by 3.
// Invariant under adding any affine map's coefficients to y, and under composing f with a rigid motion
// (y ↦ y Rᵀ on all rows, + t on vertex rows); a general linear B scales δ to B δ.
VecXd edge_delta_norms(const Cage& cage, const Eigen::SparseMatrix<double>& K, const MatX3d& y);

// E_smooth = ‖K y‖_F² (paper eq. 27, unscaled). K: 3#E by #V+#F, y: #V+#F by 3.
double smoothness_energy(const Eigen::SparseMatrix<double>& K, const MatX3d& y);

}  // namespace lidef
