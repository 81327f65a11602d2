// Compute backends: the per-sample stages of the solver and of the certificate behind one interface, so that
// they run on the CPU (the reference, this library) or on an OpenCL device (opencl/, docs/opencl.md).
//
// The solver keeps its state on the backend: the Jacobians at the current map J_cur and along the current
// Newton direction dJ stay where they were computed (device memory for OpenCL); per step only the reduced
// coefficients (s by 3) travel there and only scalars, the gradient (s by 3) and the Hessian blocks come
// back. Decisions (Armijo, the certificate's condition (6) with its rounding allowance, refinement, budgets)
// are taken on the host from the values the backend returns, with the same code for every backend.
#pragma once
#include <array>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/deformation_energy.h"
#include "lidef/errors.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/types.h"

namespace lidef {

// The distortion stages of one DeformationEnergy (E_dis = (1/|I|) Σ_i E_iso(J_i) − 6).
class EnergyKernels {
 public:
  virtual ~EnergyKernels() = default;
  // J_cur = G y (y: s by 3).
  virtual void set_current(const MatS3& y) = 0;
  // dJ = G d (d: s by 3).
  virtual void set_direction(const MatS3& d) = 0;
  // Σ_i (E_iso(J_cur,i + t dJ_i) − 6), +∞ when some det ≤ 0. t = 0 reads J_cur only.
  virtual double distortion_sum(double t) = 0;
  // J_cur ← J_cur + t dJ (the accepted step).
  virtual void accept(double t) = 0;
  // Σ_i G_iᵀ ∂E_iso/∂J_i at J_cur, s by 3 (not divided by |I|). Requires det J_i > 0 everywhere.
  virtual MatS3 distortion_gradient_sum() = 0;
  // The six pair blocks G_Hᵀ diag(H̃^{aa'}) G_H of the PSD-projected distortion Hessian at J_cur, side by side
  // (s by 6s, pairs 00, 01, 02, 11, 12, 22), weighted by 1/|H|; single or double precision products.
  virtual MatXd distortion_pair_blocks(bool double_precision) = 0;
  // Exact second derivatives along dJ at J_cur (DeformationEnergy::distortion_hessian_times_sum /
  // distortion_curvature), for the conjugate-gradient correction of the subset Hessian. A backend that
  // does not provide them says so with has_hessian_products() (the solver then computes them on the host from
  // current_jacobians()). The direction sum D = Σ α_k dJ_k of the CG iterates is kept beside dJ so that the
  // final direction needs no further pass over G: accumulate_direction(α, start) adds α dJ to it (start:
  // D = α dJ), use_accumulated_direction() makes D the direction dJ.
  virtual bool has_hessian_products() const { return false; }
  virtual MatS3 distortion_hessian_direction_sum() { throw Error("this backend has no Hessian products"); }
  virtual double distortion_curvature() { throw Error("this backend has no Hessian products"); }
  virtual void accumulate_direction(double, bool) { throw Error("this backend has no Hessian products"); }
  virtual void use_accumulated_direction() { throw Error("this backend has no Hessian products"); }
  // J_cur in the JT layout (3|I| by 3), for reports and tests.
  virtual MatJT current_jacobians() = 0;
  // dJ on the host (JT layout, double sums of the stored float rows: DeformationEnergy::jacobians), for the
  // certificate's perturbation test (CertifyParams::direction_jacobians); nullptr where it stays on a device.
  virtual const MatJT* direction_jacobians() const { return nullptr; }
};

// The data a certifier backend needs, all owned by the OctreeCertifier that creates it.
struct CertifierData {
  const Cage* cage = nullptr;
  long voxels = 0;                   // N
  const MatX3d* centers = nullptr;   // N by 3
  long m = 0;                        // coefficient rows of the stored derivatives (0: none stored)
  const float* GH = nullptr;         // N blocks of 9 rows by m floats (octree_certifier.cpp)
  std::vector<Vec3> edge_u, edge_w;  // endpoints of each undirected cage edge (#E)
};

// One octree node evaluated: signed σ3 and ‖H‖ at its center, its own bound Σ_e δ_e factor_e(center, radius)
// and the rounding scales of the differential representation (HarmonicBasis::differential_jet).
// sign_unresolved: det J's sign at the center is not resolved in double precision (σ3 is then 0).
struct NodeValues {
  double sigma3 = 0, hnorm = 0, own_bound = 0, scale_J = 0, scale_H = 0;
  double hnorm_op = 0, own_first = 0;  // bound "combined" only (CPU): ‖H‖_op bound and Σ_e δ_e Γ_e
  bool sign_unresolved = false;
  // Far-field refinement (CPU): sigma3 and hnorm are those of an approximate J̃ and H̃ with |J − J̃|₂ ≤ eps_J
  // and ‖H − H̃‖_F ≤ eps_H at the center (docs/certificate.md, Step 4d); 0 for an exact evaluation.
  double eps_J = 0, eps_H = 0;
  // Bounded distortion: σ1 at the center (NaN: not computed, no σ1 bound) and, for the spectral bound (CPU),
  // the operator-norm bound of H(c) before the σ3-specific Taylor term replaced it (a bound on J's change).
  double sigma1 = std::numeric_limits<double>::quiet_NaN();
  double hnorm_op_j = 0;
  // Step 3d (CPU, exact evaluations, when the certifier asks for it): the Taylor bounds of σ1 and σ3.
  TaylorSingularBounds taylor;
};

class CertifierKernels {
 public:
  virtual ~CertifierKernels() = default;
  // Edge factor matrix of one bound (N by #E, row-major, rounded up to float), given once per bound.
  virtual void set_factors(bool third, const float* factors, long edges) = 0;
  // Base voxels: σ3, σ1 (the bounded-distortion stage's), ‖H‖ (stored Hessian rows) and T_i = Σ_e δ_e F(i, e)
  // (δ_e = 0 skipped), for the stored derivatives times Y (m by 3, column-major). Outputs are N-vectors;
  // `unresolved` (1: det J's sign at the center is not resolved in double precision, σ3 = 0 there) as well.
  virtual void base_stage(const double* Y, bool third, const VecXd& delta, VecXd& sigma3, VecXd& sigma1,
                          VecXd& hnorm, VecXd& T, std::vector<char>& unresolved) = 0;
  // Octree nodes (centers #nodes by 3, radii #nodes) through the differential representation of the map
  // whose face matrices are `fm`.
  virtual void evaluate_nodes(const std::vector<Mat3>& A, const std::vector<std::array<Mat3, 3>>& AD,
                              const std::vector<double>& A_abs, const VecXd& delta, bool third,
                              const MatX3d& centers, const VecXd& radii, std::vector<NodeValues>& out) = 0;
};

class ComputeBackend {
 public:
  virtual ~ComputeBackend() = default;
  // "cpu", or "opencl (<device>, <platform>)".
  virtual std::string name() const = 0;
  virtual bool is_cpu() const { return false; }
  virtual std::unique_ptr<EnergyKernels> energy_kernels(const DeformationEnergy& energy) const = 0;
  // nullptr: the certifier uses its own CPU code (the reference).
  virtual std::unique_ptr<CertifierKernels> certifier_kernels(const CertifierData& data) const = 0;
};

// The CPU backend (Eigen, OpenMP, OpenBLAS).
std::shared_ptr<const ComputeBackend> cpu_backend();

struct DeformParams;  // deform_params.h

// Makes the backend that the parameters name (backend, opencl_device, ...) and says which it chose in
// *message. Code that must not link a device library (lidef_analysis, the studio's engine) takes one of these
// from its caller; opencl_backend.h provides the OpenCL-aware one.
using BackendFactory =
    std::function<std::shared_ptr<const ComputeBackend>(const DeformParams& params, std::string* message)>;
// The factory of a build without OpenCL: "cpu" and "auto" give cpu_backend(); "opencl" throws Error.
BackendFactory cpu_backend_factory();

}  // namespace lidef
