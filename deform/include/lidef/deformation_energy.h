// The deformation energy of Liao et al. 2021 (Sec. 3, 6, 7.1) in the reduced space y = Ξ ỹ:
//
//   E(ỹ) = E_dis + λ1 E_P2P + λ2 E_smooth
//   E_dis    = (1/|I|) Σ_{i∈I} (E_iso(J_i) − 6)        mean symmetric Dirichlet excess over the voxel samples
//   E_P2P    = Σ_h ‖D̃_h ỹ − q_h‖²                       soft handles (paper (29))
//   E_smooth = (1/|E|) ‖K Ξ ỹ‖² = (1/|E|) Σ_j μ_j ‖ỹ_j‖²  (Ξ's columns are eigenvectors of KᵀK, eigenvalues
//   μ)
//
// Weighting (MATH-NOTES leaves it open): on the paper's grid all voxels have the same volume, so the mean
// over samples is the paper's volume-weighted integral divided by the sampled volume — independent of the
// sampling density, and 0 at rigid maps. The mesh domain's refined leaves are smaller: set_sample_weights
// gives each its volume (see there). Like the reference code, E_smooth is divided by the number of cage edges
// |E| so that λ2 means the same on coarse and fine cages. E_P2P is a plain sum (paper) so λ1 keeps the
// paper's meaning.
//
// Layouts. ỹ: s by 3 (column a = coordinate a). vec(ỹ) is column-major: index j + s·a. Jacobians at the
// samples are stored as one 3|I| by 3 matrix JT with JT(3i+b, a) = J_i(a,b) = ∂f_a/∂p_b (J_iᵀ in rows
// 3i..3i+2), which is exactly G ỹ for the reduced gradient matrix G (3|I| by s, row 3i+b = ∂/∂p_b of the
// reduced basis).
//
// Hessian: ∇²E_dis is approximated on the subset H ⊂ I (weight 1/|H|) with every per-sample 9x9 block
// projected to PSD by the analytic eigensystem (symmetric_dirichlet.h). The block structure is Kronecker:
// vec(J_i) = (I_3 ⊗ G_i) vec(ỹ) up to a permutation, so the (a, a') s-by-s block of the reduced Hessian is
// G_Hᵀ diag_i(H̃_i^{aa'}) G_H with H̃_i^{aa'}(b,b') = H_i(a+3b, a'+3b'): six products of shape s × 3|H| × s
// instead of one 3s × 9|H| × 3s SYRK. They run in single precision (BLAS sgemm): the Hessian only shapes the
// search direction, never a certificate or an accepted energy.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "lidef/symmetric_dirichlet.h"
#include "lidef/types.h"

namespace lidef {

struct EnergyWeights {
  double p2p = 1e5;     // λ1
  double smooth = 0.1;  // λ2
};

struct EnergyTerms {
  double dis = 0, p2p = 0, smooth = 0;  // unweighted terms
  double total = 0;                     // dis + λ1 p2p + λ2 smooth; +∞ when some det J_i ≤ 0
};

// Storage: G is kept rounded to single precision (half the memory traffic of the two passes over it per
// iteration, which are memory-bound); all arithmetic with it is double. The energy is then exactly that of
// the map whose basis gradients are the rounded ones — a fixed smooth function of ỹ, so the line search and
// the derivative checks are consistent; it differs from the true E_dis by ~1e-7 relative. Certificates never
// use it (the certifier has its own bounds on its own storage).
class DeformationEnergy {
 public:
  // G: 3|I| by s reduced gradient matrix (see above). hessian_subset: indices into I (the set H; empty =
  // all). smooth_eigenvalues: s eigenvalues μ_j of KᵀK for the basis columns. num_edges: |E| of the cage.
  DeformationEnergy(MatXdR G, std::vector<int> hessian_subset, VecXd smooth_eigenvalues, int num_edges);

  // D: #h by s reduced basis values at the handle sources (f(p_h) = D_h ỹ); Q: #h by 3 targets.
  void set_handles(const MatXd& D, const MatX3d& Q);
  void set_targets(const MatX3d& Q);
  // Per-sample volume weights (#I, > 0; empty = all 1): the mesh domain's leaves of level k weigh 8^-k
  // (VoxelSampling::weight_of). They are rescaled to mean 1, so E_dis = (1/|I|) Σ w_i (E_iso(J_i) − 6) stays
  // the volume-weighted mean; the Hessian subset's blocks weigh w_i / Σ_H w.
  void set_sample_weights(const VecXd& w);
  bool weighted() const { return w_.size() > 0; }

  int reduced_size() const { return static_cast<int>(G_.cols()); }
  int num_samples() const { return static_cast<int>(G_.rows() / 3); }
  int num_handles() const { return static_cast<int>(D_.rows()); }
  const MatXfR& gradient_matrix() const { return G_; }  // rounded to float (see above)
  const std::vector<int>& hessian_subset() const { return subset_; }
  const MatXd& handle_matrix() const { return D_; }        // D: #h by s
  const MatX3d& targets() const { return Q_; }             // Q: #h by 3 (normalized frame)
  const VecXd& smooth_eigenvalues() const { return mu_; }  // μ: s
  int num_edges() const { return num_edges_; }             // |E|
  const VecXd& sample_weights() const { return w_; }       // #I with mean 1, or empty (uniform)
  // The Hessian subset's block weights (#H, summing to 1): 1/|H| each, weighted or not (the subset is
  // stratified by volume, so each pick stands for the same volume; see the .cpp).
  VecXd subset_block_weights() const;

  // JT = G ỹ (3|I| by 3).
  MatJT jacobians(const MatS3& y) const;
  // Handle images D ỹ (#h by 3) and their distances to the targets (#h).
  MatX3d handle_positions(const MatS3& y) const;
  VecXd handle_errors(const MatS3& y) const;

  // Terms at ỹ given its Jacobians JT (= jacobians(y)). Deterministic: the sample sum runs in fixed chunks
  // whose partial sums are added in order, whatever the thread count.
  EnergyTerms evaluate(const MatJT& JT, const MatS3& y, const EnergyWeights& w) const;
  EnergyTerms evaluate(const MatS3& y, const EnergyWeights& w) const { return evaluate(jacobians(y), y, w); }
  // ∇E (s by 3). Requires det J_i > 0 at every sample.
  MatS3 gradient(const MatJT& JT, const MatS3& y, const EnergyWeights& w) const;
  // ∇²E as 3s by 3s (vec(ỹ) column-major), single-precision products on the subset. projected = PSD-projected
  // blocks (the solver's matrix); all_samples = use every sample with weight 1/|I| in double precision (the
  // exact Hessian when not projected; for tests) instead of the subset H in single precision.
  MatXd hessian(const MatJT& JT, const EnergyWeights& w, bool projected = true,
                bool all_samples = false) const;
  // Only the E_dis part of hessian(), for benchmarks.
  MatXd distortion_hessian(const MatJT& JT, bool projected, bool all_samples) const;

  // --- The pieces the solver combines with a compute backend (compute_backend.h).
  // Σ_i (E_iso(J_i) − 6), +∞ when some det J_i ≤ 0 (fixed chunk order: deterministic).
  double distortion_sum(const MatJT& JT) const;
  // Σ_i G_iᵀ ∂E_iso/∂J_i (s by 3, not divided by |I|).
  MatS3 distortion_gradient_sum(const MatJT& JT) const;
  // Σ_i w_i G_iᵀ T_i (s by 3) for T stacked like JT (3|I| by 3, rows 3i..3i+2 = T_i), w the sample weights:
  // the adjoint of jacobians() (the local/global solve's right side), in the same fixed chunk order.
  MatS3 weighted_transpose_times(const MatJT& T) const;
  // Exact (all samples, unprojected) second derivatives along a direction whose Jacobians are dJ (= G d,
  // 3|I| by 3), for the conjugate-gradient correction of the subset Hessian (docs/solver.md): Σ_i w_i G_iᵀ
  // ∇²E_iso(J_i)[dJ_i] (s by 3) and Σ_i w_i ⟨dJ_i, ∇²E_iso(J_i)[dJ_i]⟩, neither divided by |I|. Deterministic
  // like the sums above; require det J_i > 0 everywhere.
  MatS3 distortion_hessian_times_sum(const MatJT& JT, const MatJT& dJ) const;
  double distortion_curvature(const MatJT& JT, const MatJT& dJ) const;
  // The exact Hessian of the handle and smoothness terms times d (s by 3).
  MatS3 quadratic_hessian_times(const MatS3& d, const EnergyWeights& w) const;
  // The six pair blocks (s by 6s) of the PSD-projected distortion Hessian on the subset H, weighted by 1/|H|,
  // products in single (OpenBLAS sgemm) or double precision (dgemm).
  MatXd distortion_pair_blocks(const MatJT& JT, bool double_precision) const;
  // The same from given per-subset-sample 9x9 blocks (PSD-projected, weighted by 1/|H|): the host product for
  // backends whose device is the CPU itself (docs/opencl.md).
  MatXd distortion_pair_blocks_from(const std::vector<Mat9>& blocks, bool double_precision) const;
  // The PSD-projected distortion Hessians at the subset's samples (#H 9x9 blocks, vec(J) order a + 3b),
  // weighted by 1/|H|: the blocks whose products distortion_pair_blocks assembles.
  std::vector<Mat9> subset_hessian_blocks(const MatJT& JT) const;
  // That assembled distortion part (hessian_from without the quadratic terms) times d (s by 3), from the
  // blocks and the subset's rows of G without assembling it: one pass over the 3|H| by s stored rows, the
  // arithmetic in double (linear to working precision, as conjugate gradients need).
  MatS3 subset_hessian_times(const std::vector<Mat9>& blocks, const MatS3& d) const;
  // All terms from Σ_i (E_iso − 6) and ỹ.
  EnergyTerms terms(double distortion_sum, const MatS3& y, const EnergyWeights& w) const;
  // ∇E from Σ_i G_iᵀ ∂E_iso/∂J_i (adds the handle and smoothness terms).
  MatS3 gradient_from(const MatS3& distortion_gradient_sum, const MatS3& y, const EnergyWeights& w) const;
  // ∇²E (3s by 3s) from the pair blocks (symmetrized, plus the exact quadratic terms).
  MatXd hessian_from(const MatXd& pair_blocks, const EnergyWeights& w) const;
  const MatXfR& subset_gradient_matrix() const { return GH_; }  // 3|H| by s

 private:
  MatXd pair_blocks(const MatJT& JT, bool projected, bool all_samples, bool double_precision) const;
  // weight(k) times the (projected) 9x9 Hessian of E_iso at sample idx[k].
  std::vector<Mat9> sample_blocks(const MatJT& JT, const std::vector<int>& idx, const VecXd& weight,
                                  bool projected) const;
  MatXd products(const std::vector<Mat9>& blocks, bool all_samples, bool double_precision) const;
  void add_quadratic_hessian(MatXd& H, const EnergyWeights& w) const;
  double sample_weight(int i) const;  // w_i (1 without weights)
  // Σ_i w_i v_i in fixed chunks added in order (the same bits for every thread count), the values v_i four
  // samples at a time: per_lanes(first, last) returns those of samples first, …, first + 3 (sd_lanes.h;
  // lanes past last are ignored).
  template <class PerLanes>
  double weighted_lane_sum(const PerLanes& per_lanes) const;
  // Σ_i G_iᵀ P_i (s by 3) in fixed chunks: fill(b, e, P) writes the weighted per-sample 3x3 matrices of
  // samples [b, e) into P in J's transposed layout (rows 3(i − b) + r, column a: entry (a, r)).
  template <class Fill>
  MatS3 transpose_sum(const Fill& fill) const;
  // transpose_sum of w_i per_sample(i), one 3x3 per sample.
  template <class PerSample>
  MatS3 weighted_transpose_sum(const PerSample& per_sample) const;
  // transpose_sum of w_i M_i, the matrices four samples at a time: per_lanes(first, last, M) as above.
  template <class PerLanes>
  MatS3 weighted_transpose_lanes(const PerLanes& per_lanes) const;
  VecXd all_block_weights() const;  // #samples: w_i / Σ w (1/n without weights)
  MatXfR G_;
  std::vector<int> subset_;
  MatXfR GH_;  // 3|H| by s, the rows of G at the subset, single precision
  VecXd mu_;
  int num_edges_;
  MatXd D_;    // #h by s
  MatX3d Q_;   // #h by 3
  MatXd DtD_;  // s by s
  VecXd w_;    // #I sample weights with mean 1, or empty (uniform)
};

}  // namespace lidef
