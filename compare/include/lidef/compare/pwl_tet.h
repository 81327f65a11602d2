// PWL(Tet): the piecewise-linear tetrahedral deformation the paper compares with (Smith, De Goes, Kim 2019;
// Liao et al. 2021 Sec. 8, Table 1). Unknowns are the tet-mesh vertex positions X (#V by 3, 3#V DOF); the
// mesh to deform and the handles are embedded barycentrically (tet_mesh.h).
//
// Energy (the same terms and weights as lidef's, so the two minimise the same thing on different spaces):
//   E(X) = Σ_t w_t (E_iso(J_t) − 6) + λ1 Σ_h ‖W_h X − q_h‖²,    w_t = vol_t / Σ vol  (rest volumes),
// J_t = D_s(X) D_m⁻¹ the constant Jacobian of tet t (D = [x1−x0, x2−x0, x3−x0]), E_iso the symmetric
// Dirichlet energy (symmetric_dirichlet.h: +∞ when det J_t ≤ 0) and W_h the barycentric weights of handle h
// (soft handles). The volume-weighted mean is lidef's mean over equal voxels.
//
// Solver: projected Newton. Per tet the 9x9 Hessian in vec(J) is projected to PSD with the analytic
// eigensystem (sd_hessian_psd) and mapped to the 12 vertex coordinates by the constant 9x12 matrix
// ∂vec(J)/∂x; the sparse 3#V system (plus 2λ1 WᵀW and a relative diagonal shift) is factored with CHOLMOD
// (supernodal LLᵀ through Eigen's CholmodSupport; symbolic analysis once). Line search from t = 1, halving,
// Armijo on E: since E = +∞ when any tet has det J ≤ 0 and the map is affine per tet, an accepted step never
// inverts a tet (exactly, not only at samples). Converged when the predicted decrease −∇Eᵀδ/2 (Newton
// decrement) is below energy_tolerance · |E| or the Newton direction ‖δ‖ is below step_tolerance · max(1,
// ‖X‖) — judged on δ, not on the accepted t δ, since a line search shortened to keep the tets positive makes
// t δ small far from a minimum; stops otherwise after max_iterations or when no step decreases E.
#pragma once
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lidef/compare/tet_mesh.h"
#include "lidef/types.h"

namespace lidef {

struct PwlTetParams {
  double lambda_p2p = 1e5;
  int max_iterations = 200;
  double energy_tolerance = 1e-5;
  double step_tolerance = 1e-6;
  double armijo = 1e-4;
  int max_halvings = 60;
  double diagonal_shift = 1e-8;  // relative to the mean diagonal of the Hessian
};

struct PwlTetIteration {
  int iteration = 0;                        // 1-based
  double energy = 0, e_dis = 0, e_p2p = 0;  // after the step
  double step = 0;                          // accepted t (0: none)
  double step_norm = 0;                     // t‖δ‖
  double direction_norm = 0;                // ‖δ‖ (the Newton direction before the line search)
  double newton_decrement = 0;  // −∇Eᵀδ (half of it: the decrease the quadratic model predicts)
  int halvings = 0;
  double max_handle_error = 0;
  double ms = 0;
};

struct PwlTetResult {
  bool converged = false;
  std::string message;
  int iterations = 0;
  double seconds = 0;
};

class PwlTetSolver {
 public:
  // Throws InputError(mesh.source, ...) for an empty mesh or a tet with non-positive rest volume.
  PwlTetSolver(const TetMesh& mesh, const PwlTetParams& params = {});
  ~PwlTetSolver();

  // Handles: sources/targets #h by 3 (h ≥ 1). Throws InputError(where, ...) when a source lies outside
  // every tet. Keeps the current positions.
  void set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where = "handles");

  PwlTetResult solve(const std::function<bool(const PwlTetIteration&)>& on_iteration = {});
  // One projected Newton iteration from the current positions.
  PwlTetIteration step();

  // E at positions X (#V by 3); dis/p2p (optional) receive the terms. +∞ when a tet is inverted.
  double energy(const MatX3d& X, double* dis = nullptr, double* p2p = nullptr) const;
  // Gradient of E with respect to X (#V by 3), and the projected Hessian (3#V square, index 3i + a).
  MatX3d gradient(const MatX3d& X) const;
  Eigen::SparseMatrix<double> projected_hessian(const MatX3d& X) const;

  const MatX3d& positions() const { return X_; }
  void set_positions(const MatX3d& X);  // for tests; throws InputError when a tet is inverted
  const TetMesh& mesh() const { return mesh_; }
  Mat3 jacobian(const MatX3d& X, int t) const;  // J_t = D_s(X) D_m⁻¹
  int inverted_count(const MatX3d& X) const;    // tets with det J_t ≤ 0
  VecXd handle_errors() const;                  // #h: ‖W_h X − q_h‖
  const std::vector<PwlTetIteration>& history() const { return history_; }
  int dof() const { return 3 * mesh_.num_vertices(); }

  // The 9x12 matrix ∂vec(J)/∂x for a tet with rest-shape inverse Bm = D_m⁻¹ (vec column-major as in
  // symmetric_dirichlet.h; x = [x0; x1; x2; x3], 3 coordinates each).
  static Eigen::Matrix<double, 9, 12> jacobian_derivative(const Mat3& Bm);

 private:
  struct Impl;
  void analyze();  // sparsity pattern, value slots and CHOLMOD's symbolic factorization
  TetMesh mesh_;
  PwlTetParams params_;
  std::vector<Mat3> Bm_;                            // #T rest-shape inverses
  VecXd w_;                                         // #T volume weights, Σ = 1
  Eigen::SparseMatrix<double, Eigen::RowMajor> W_;  // #h by #V handle weights
  MatX3d targets_;
  MatX3d X_;
  std::vector<PwlTetIteration> history_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lidef
