// PWL(Tri): surface ARAP with the smooth-rotation term, SR-ARAP (Levi and Gotsman 2015), the surface method
// the paper compares with (Liao et al. 2021 Sec. 8, Table 1). Unknowns: the full-resolution mesh vertices X
// (#V by 3, 3#V DOF) and one rotation R_i per vertex; no interior, so no volumetric distortion and no
// injectivity notion.
//
//   E(X, R) = (1/A) Σ_i Σ_{j∈N(i)} w_ij ‖(x_i − x_j) − R_i (p_i − p_j)‖²      (ARAP, cotangent weights)
//           + α Σ_i Σ_{j∈N(i)} w_ij ‖R_i − R_j‖_F²                              (smooth rotations)
//           + λ1 Σ_h ‖W_h X − q_h‖²                                              (soft handles, lidef's λ1)
// A = total rest area (Levi and Gotsman's αA weighting, divided through by A so λ1 keeps lidef's meaning),
// w_ij = ½(cot α_ij + cot β_ij) clamped at 0 (negative weights would make the global step indefinite),
// handles embedded barycentrically at the closest surface point. Local step: Gauss–Seidel over vertices, R_i
// = argmax tr(R S_i) with S_i = Σ_j w_ij e_ij e'_ijᵀ + 2αA Σ_j w_ij R_jᵀ (each update is exact given the
// others, so E never increases; a simultaneous update could). Global step: the sparse Laplacian system
// (constant; CHOLMOD LLᵀ factored once) with a tiny proximal term ρ‖X − X_prev‖² that keeps it definite (e.g.
// for a component without handles) without moving fixed points. Stops when the relative decrease of E in an
// iteration is below energy_tolerance, or after max_iterations.
#pragma once
#include <Eigen/SparseCore>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

struct PwlTriParams {
  double lambda_p2p = 1e5;
  double alpha = 1e-3;  // smooth-rotation weight (Levi and Gotsman's α; docs/compare.md on the choice)
  int max_iterations = 1000;
  double energy_tolerance = 1e-5;
  double proximal = 1e-10;  // relative to the mean diagonal
};

struct PwlTriIteration {
  int iteration = 0;
  double energy_after_local = 0, energy = 0;  // E after the rotation step and after the position step
  double max_handle_error = 0;
  double ms = 0;
};

struct PwlTriResult {
  bool converged = false;
  std::string message;
  int iterations = 0;
  double seconds = 0;
};

class SrArapSolver {
 public:
  // Throws InputError(mesh.source, ...) for an empty mesh or a face with a bad index.
  explicit SrArapSolver(const TriMesh& mesh, const PwlTriParams& params = {});
  ~SrArapSolver();
  // Handles at the closest points of the surface (#h by 3). Throws InputError(where, ...) when a source is
  // farther than 1e-6 of the bounding-box diagonal from the surface. Starts from the rest shape.
  void set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where = "handles");
  PwlTriResult solve(const std::function<bool(const PwlTriIteration&)>& on_iteration = {});
  PwlTriIteration step();  // one local (rotations) + global (positions) iteration

  double energy(const MatX3d& X, const std::vector<Mat3>& R) const;
  const MatX3d& positions() const { return X_; }
  const std::vector<Mat3>& rotations() const { return R_; }
  VecXd handle_errors() const;
  int dof() const { return 3 * static_cast<int>(X_.rows()); }
  const std::vector<PwlTriIteration>& history() const { return history_; }

 private:
  struct Impl;
  void local_step();
  void global_step();
  TriMesh mesh_;
  PwlTriParams params_;
  double area_ = 0;
  std::vector<std::vector<std::pair<int, double>>> nbr_;  // per vertex: (j, w_ij)
  Eigen::SparseMatrix<double, Eigen::RowMajor> W_;        // #h by #V handle weights
  MatX3d targets_;
  MatX3d X_;
  std::vector<Mat3> R_;
  std::vector<PwlTriIteration> history_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lidef
