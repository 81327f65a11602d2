// VHM: Variational Harmonic Maps (Ben-Chen, Weber, Gotsman 2009), the harmonic-subspace method the paper
// compares with (Liao et al. 2021 Sec. 8, Table 1, Fig. 11). Same cage-based harmonic basis as lidef
// (green_coordinates.h), all #V+#F coefficients per coordinate (3(#V+#F) DOF, no spectral reduction), no
// injectivity guarantee.
//
// Energy over coefficients y (#V+#F by 3) and one rotation R_i per interior anchor a_i (n_a anchors):
//   E(y, R) = (1/n_a) Σ_i ‖J(a_i) − R_i‖_F²                       (as-rigid-as-possible at the anchors)
//           + w_s ℓ² (1/n_b) Σ_k ‖H(b_k)‖²                          (VHM smoothness: full Hessian tensor
//           norm)
//           + λ1 Σ_h ‖f(p_h) − q_h‖²                               (soft handles, lidef's λ1)
// with ℓ the cage bounding-box diagonal (makes w_s scale-free) and b_k boundary samples: Ben-Chen et al.
// integrate ‖H‖² over the boundary of the domain (Liao et al. Sec. 6.1); we sum it over points of the
// deformed surface. Local/global (block coordinate descent): R_i = the rotation closest to J(a_i) (polar
// decomposition with the reflection removed), then y = the minimiser of the quadratic in y — one dense
// (#V+#F)² system shared by the three coordinates, factored once (LLᵀ) with a proximal term ρ‖y − y_prev‖² (ρ
// = `proximal` · trace/(#V+#F)) that keeps it definite when the anchors do not determine every coefficient;
// it does not move the fixed points. Both steps decrease E. Stops when the relative decrease of E in one
// iteration is below energy_tolerance (or E below 1e-14), or after max_iterations.
#pragma once
#include <Eigen/Cholesky>
#include <functional>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/green_coordinates.h"
#include "lidef/types.h"

namespace lidef {

struct VhmParams {
  double lambda_p2p = 1e5;
  double smooth_weight = 1e-4;  // w_s
  int max_iterations = 1000;
  double energy_tolerance = 1e-5;
  double proximal = 1e-9;
};

struct VhmIteration {
  int iteration = 0;
  double energy = 0, e_rigid = 0, e_smooth = 0, e_p2p = 0;
  double max_handle_error = 0;
  double ms = 0;
};

struct VhmResult {
  bool converged = false;
  std::string message;
  int iterations = 0;
  double seconds = 0;
};

class VhmSolver {
 public:
  // anchors: #A by 3 interior points (e.g. the shared models' vhm_anchors.xyz); boundary: #B by 3 points of
  // the shape's surface for the smoothness term (e.g. mesh vertices). Throws InputError(where, ...) for no
  // anchors or a point outside the cage (winding number < 1/2).
  VhmSolver(const Cage& cage, const HarmonicBasis& basis, const MatX3d& anchors, const MatX3d& boundary,
            const VhmParams& params = {}, const std::string& where = "anchors");
  // sources/targets: #h by 3; throws InputError for a source outside the cage. Starts from the identity.
  void set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where = "handles");
  VhmResult solve(const std::function<bool(const VhmIteration&)>& on_iteration = {});
  VhmIteration step();  // one local + global iteration

  double energy(const MatX3d& y, const std::vector<Mat3>& R, VhmIteration* terms = nullptr) const;
  // Rotations closest to the Jacobians at the anchors of y.
  std::vector<Mat3> best_rotations(const MatX3d& y) const;
  const MatX3d& coefficients() const { return y_; }  // #V+#F by 3
  VecXd handle_errors() const;
  int dof() const { return 3 * static_cast<int>(y_.rows()); }
  int num_anchors() const { return static_cast<int>(G_.rows() / 3); }
  const std::vector<VhmIteration>& history() const { return history_; }

 private:
  void factor();
  const Cage& cage_;
  const HarmonicBasis& basis_;  // must outlive the solver
  VhmParams params_;
  MatXd G_;   // 3#A by #V+#F basis gradients at the anchors (row 3i+b: ∂/∂p_b)
  MatXd Hs_;  // 6#B by #V+#F basis Hessians at the boundary samples, rows scaled by √(multiplicity) so that
              // ‖Hs y‖² = Σ‖H‖² (full tensor)
  MatXd D_;   // #h by #V+#F basis values at the handles
  MatX3d targets_;
  MatXd A_;  // the system matrix (without the proximal term)
  Eigen::LLT<MatXd> llt_;
  double rho_ = 0, ws_ = 0;
  MatX3d y_;
  std::vector<Mat3> R_;
  std::vector<VhmIteration> history_;
};

}  // namespace lidef
