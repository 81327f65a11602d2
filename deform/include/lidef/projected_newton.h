// The deformation solver of Liao et al. 2021 (Algorithm 1, Sec. 7): projected Newton on the reduced
// coefficients with a line search that accepts a step only when it (1) decreases the energy enough (Armijo)
// and (2) is certified locally injective by the octree certificate (octree_certifier.h). Every accepted
// iterate is certified; the solver's current map is always the last certified one.
//
// Dynamic weighting (Sec. 7.3, absent from the published code; docs/solver.md): after each accepted step,
//   if E_P2P >= E0:  λ2 ← κ2 λ2, and if the certificate's min over leaves of σ3 − r L is < ε (condition
//   (36)):
//                    λ1 ← κ1 λ1;
//   else if the full Newton step failed condition (6) (the certificate shortened the step): λ2 ← κ2 λ2;
//   else (nothing needed a change): λ2 ← max(default, λ2/κ2), λ1 ← min(default, λ1/κ1)   (our addition).
// When no certified decreasing step exists at all, λ1 ← κ1 λ1 and λ2 ← κ2 λ2 and the iteration goes on.
// λ2 ≤ max_smooth_factor · default, λ1 ≥ min_p2p_factor · default. When the iteration converges with changed
// weights they are reset to the defaults and the iteration goes on (at most max_weight_resets times), so the
// final map minimises the energy with the user's weights whenever it can.
//
// Units (normalization.h): the solver works in the cage's normalized frame — its subspace, sampling, basis,
// energy, certifier and reduced coefficients are those of the normalized cage — and speaks model units at its
// interface: handles, coefficients(), set_initial_map(), handle_errors()/handle_positions(), sampling(),
// basis(), certificate() and certify_current() are in the units of the cage it was given. E_P2P is the sum
// of squared handle errors measured in the normalized frame (model distance / frame().scale), so λ1 and the
// energies recorded per iteration do not depend on the model's units.
//
// Usage: DeformationSolver precomputes once per cage (subspace, sampling, reduced gradient matrix,
// certifier); set_handles() / set_targets() and solve() or step() many times (the studio calls step() while a
// handle is dragged, starting from the last solution).
#pragma once
#include <atomic>
#include <functional>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/compute_backend.h"
#include "lidef/deform_params.h"
#include "lidef/deformation_energy.h"
#include "lidef/errors.h"
#include "lidef/global_injectivity.h"
#include "lidef/green_coordinates.h"
#include "lidef/normalization.h"
#include "lidef/octree_certifier.h"
#include "lidef/precompute_cache.h"
#include "lidef/sampling.h"
#include "lidef/subspace.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

class DistortionScreen;  // lidef/internal/distortion_screen.h

// The precomputation stopped because its caller asked (PrecomputeSetup::cancel; the studio's Cancel):
// nothing it would have produced exists.
class Cancelled : public Error {
 public:
  Cancelled() : Error("cancelled") {}
};

// How the solver's precomputation runs: where it caches (precompute_cache.h), what it reports, and when it
// stops early.
struct PrecomputeSetup {
  std::string cache_dir = default_cache_dir();  // "" = no cache (the subspace's and the precomputation's)
  std::uint64_t cache_max_bytes = default_cache_max_bytes();
  std::function<void(const std::string&)> log;  // one line per stage (and the cache's outcome)
  // The stage running and the fraction of the whole precomputation done (0..1), at every chunk of work.
  std::function<void(const std::string& stage, double fraction)> progress;
  // Polled at every chunk of work; once set the constructor throws Cancelled.
  const std::atomic<bool>* cancel = nullptr;
  // The model's mesh (#V by 3, #F by 3), read during construction only: with params.domain "mesh" the voxels
  // cover its triangles and solid (domain_sampling.h); nullptr = the paper's grid.
  const TriMesh* mesh = nullptr;
  // Write a computed entry on a thread of its own once the constructor is done (the studio: the session can
  // rest while it is written), instead of as the constructor's last stage. The entry's arrays do not change
  // after construction; cache_store() says when it is done, the destructor waits for it. `log` is not called
  // for it.
  bool background_store = false;
};

// One Newton iteration, as iterations.csv records it.
struct IterationRecord {
  int iteration = 0;                         // 1-based
  double lambda_p2p = 0, lambda_smooth = 0;  // weights used in this iteration
  double energy_before = 0;                  // E at the start (these weights)
  EnergyTerms terms;                         // at the accepted point (these weights)
  double gradient_norm = 0;                  // ‖∇E‖ at the start
  double newton_decrement = 0;               // −∇Eᵀδ
  double step = 0;                           // accepted t (0: no step accepted)
  double step_norm = 0;                      // t ‖δ‖
  int armijo_rejections = 0;       // halvings because the energy did not decrease enough (or became +∞)
  int certificate_rejections = 0;  // halvings because the certificate failed
  // halvings because the locally certified trial was not proven globally injective (injectivity "global")
  int global_rejections = 0;
  bool accepted = false;
  bool certified = false;  // the current map (accepted point, or the previous one) is certified
  // The line search's certificate of the current map: min σ3 at the evaluated voxel centers, and min over
  // leaves of σ3 − r L − τ (voxels certified by perturbation carry their bound, docs/certificate.md Step 4e).
  double min_sigma3 = 0;
  double min_lower_bound = 0;
  long refined = 0;             // voxels the certificate subdivided
  double max_handle_error = 0;  // max ‖f(p_h) − q_h‖ at the current map
  std::string weight_action;    // what dynamic weighting did after this step ("", "smooth*", "p2p*", "reset")
  // The direction came from an earlier step's factor: as it is (set_dragging) or as the preconditioner of
  // kept_factor_steps conjugate-gradient steps on this iteration's subset Hessian (kept_factor_cg_steps).
  bool hessian_reused = false;
  int kept_factor_steps = 0;  // CG steps with the kept factor (also those of a try that then assembled)
  int cg_steps = 0;           // conjugate-gradient iterates taken (newton_cg_steps; 0: the plain direction)
  double cg_scale = 0;        // the first iterate's scale of the plain direction (1: the subset Hessian's)
  // ms_solve: the Cholesky solve and the direction (its Jacobians G δ and the CG iterates, newton_cg_steps);
  // before 2026-11-24 the Jacobian pass was counted in ms_line_search.
  double ms_gradient = 0, ms_hessian = 0, ms_solve = 0, ms_line_search = 0, ms_certificate = 0, ms_total = 0;
  double ms_global = 0;  // the global injectivity checks of the line search (part of ms_line_search)
};

enum class StopReason {
  kConverged,  // step below step_tolerance or energy decrease below energy_tolerance, at the user's weights —
               // or at adjusted ones once max_weight_resets is used up (SolveResult::message says so)
  kMaxIterations,
  kBlocked,          // the certificate shortened the step to below the tolerance: at the injectivity boundary
                     // (injectivity "global": also where the shape would pass through itself)
  kNoCertifiedStep,  // no step length in max_halvings halvings was both decreasing and certified
  kInterrupted,      // the callback or the stop flag asked to stop
  kReached,  // solve_to_targets only: every handle within handle_tolerance of its target with a certified
             // map, but Newton stopped before its convergence test (blocked, no certified step, or an
             // internal polish limit — not the user's max_iterations): the targets are met, the energy is not
             // stationary (the message says why)
  kUnreachable,  // solve_to_targets only: proven that no map of the subspace reaches the targets (the least-
                 // squares residual of the handles alone exceeds the tolerance; unreachable_targets.h). The
                 // map is the last certified one of a direct solve toward them.
};
const char* to_string(StopReason r);

struct SolveResult {
  StopReason reason = StopReason::kMaxIterations;
  std::string message;
  int iterations = 0;  // accepted or attempted Newton iterations run by this solve()
  bool converged() const { return reason == StopReason::kConverged; }
  // The handles are at their targets: converged, or kReached. What the CLI's exit status reports.
  bool targets_met() const { return reason == StopReason::kConverged || reason == StopReason::kReached; }
  double seconds = 0;
};

// Why `p` cannot be a handle source of `cage`, or "" when it can: the winding number must exceed 1/2 (inside)
// and p must not lie on the cage (distance < 1e-9 of the bounding-box diagonal), where the harmonic map is
// undefined. The text continues "source (x, y, z) ...". DeformationSolver::set_handles and the studio check
// with it.
std::string handle_source_problem(const Cage& cage, const Vec3& p);

class DeformationSolver {
 public:
  // Precomputes everything that depends only on the cage and the parameters that shape it (reduced_dof,
  // samples/voxel_side, safety, hessian_fraction, threads). `log` receives one line per preprocessing stage.
  // `backend` runs the per-sample stages (compute_backend.h); nullptr = the CPU backend. The front end turns
  // params.backend ("cpu", "opencl", "auto") into one (opencl/include/lidef/opencl/opencl_backend.h).
  //
  // The voxels (energy samples and certificate) cover params.domain: "mesh" (domain_sampling.h: the mesh's
  // triangles and solid; needs `mesh`) or "voxels" (the paper's grid). Without a mesh the domain is the grid,
  // whatever params.domain says, and sampling().domain reports it ("voxels").
  DeformationSolver(const Cage& cage, const DeformParams& params,
                    const std::string& cache_dir = default_cache_dir(),
                    const std::function<void(const std::string&)>& log = {},
                    std::shared_ptr<const ComputeBackend> backend = nullptr);
  DeformationSolver(const Cage& cage, const TriMesh& mesh, const DeformParams& params,
                    const std::string& cache_dir = default_cache_dir(),
                    const std::function<void(const std::string&)>& log = {},
                    std::shared_ptr<const ComputeBackend> backend = nullptr);
  // The same with progress, cancellation, the cache limit and the mesh (setup.mesh). The sampling, the
  // reduced basis gradients and the certifier's derivatives come from the cache when it holds them for
  // exactly this cage, mesh domain, these parameters and this subspace (else they are computed and stored):
  // the solver is the same either way, byte for byte.
  DeformationSolver(const Cage& cage, const DeformParams& params, const PrecomputeSetup& setup,
                    std::shared_ptr<const ComputeBackend> backend = nullptr);
  ~DeformationSolver();

  // Handles: sources and targets #h by 3 (h ≥ 1). Throws InputError(where, ...) for a source outside the cage
  // (winding number < 1/2) or too close to it, or a non-finite coordinate. Keeps the current map.
  void set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where = "handles");
  void set_targets(const MatX3d& targets, const std::string& where = "targets");
  // Parameters that do not change the precomputation (weights, tolerances, certificate, weighting).
  void set_params(const DeformParams& params);
  // Dynamic weighting starts again from the user's weights (and its reset count from 0); the map is kept.
  // A new set of targets is a new problem: the continuation (continuation.h) calls it for every stage.
  void reset_weights();
  const DeformParams& params() const { return params_; }

  // Back to the identity map (certified; throws NumericalError if even the identity is not).
  void reset();
  // Starts from the map with full coefficients y (#V+#F by 3), e.g. a coefficients.txt written by `lidef
  // deform` with the same reduced_dof. Throws InputError(where, ...) when y has the wrong shape or is not in
  // the reduced subspace (relative residual ‖Ξ Ξᵀ y − y‖/‖y‖ > 1e-9: projecting would change the map), and
  // when the map is not certified locally injective on this sampling. Keeps the weights at their defaults and
  // clears the history.
  void set_initial_map(const MatX3d& y, const std::string& where);
  // Makes ỹ (s by 3, normalized frame, as reduced_coefficients()) the current map if the solver's certificate
  // certifies it — in global injectivity mode also proven globally injective, as every accepted step is —
  // otherwise returns false with the reason and keeps the map. Weights and history are kept (the
  // continuation's local/global warm start, continuation.h).
  bool set_reduced_map(const MatS3& y, std::string* reason = nullptr);

  // Newton iterations until a stop criterion. `on_iteration` is called after every iteration; returning false
  // stops (kInterrupted). `stop` (optional) is polled between line-search trials too (Ctrl-C): an iteration
  // cut short leaves the map unchanged.
  SolveResult solve(const std::function<bool(const IterationRecord&)>& on_iteration = {},
                    const std::atomic<bool>* stop = nullptr);
  // One Newton iteration (the studio's unit of work).
  IterationRecord step(const std::atomic<bool>* stop = nullptr);
  // While on, the first step after new targets may take its direction from the previous step's Hessian factor
  // (at most params().drag_hessian_reuse steps in a row; same weights; a direction that finds no certified
  // decrease is replaced by a fresh one in the same iteration). What is accepted is certified as always; only
  // the direction changes. Off by default; the studio turns it on while the handles are dragged.
  void set_dragging(bool on) { dragging_ = on; }
  bool dragging() const { return dragging_; }

  // The current (last certified) map. Reduced coefficients ỹ are in the normalized frame: Ξ ỹ are the
  // normalized cage's coefficients (frame().coefficients_from_normalized maps them to coefficients()).
  const MatS3& reduced_coefficients() const { return y_; }
  MatX3d coefficients() const;  // #V+#F by 3, model units
  // Of the current map (keep_leaves = false), model units (leaf centers, sides, L).
  const Certificate& certificate() const { return cert_; }
  // The reason of the last line-search trial of the last iteration that a distortion bound (max_distortion,
  // max_sigma1, min_sigma3) rejected: "distortion bound K not proven at (x, y, z)"; empty when none.
  const std::string& distortion_rejection() const { return distortion_rejection_; }
  // For stop messages: "; the distortion bound blocks it (max_distortion K, last rejected trial: ...)", or ""
  // when no trial was rejected by a distortion bound.
  std::string distortion_note() const;
  // Injectivity "global": why the last line-search trial refused by the global check was refused ("the shape
  // would pass through itself near (x, y, z)", model units); empty when none of the last iteration was.
  const std::string& global_rejection() const { return global_rejection_; }
  // The global injectivity verdict of the current map (global_injectivity.h; model units), computed on
  // demand and kept until the map changes. Not decided without the mesh domain or without a surface.
  GlobalInjectivity global_injectivity() const;
  // That verdict where the solver already holds it (global mode holds the one of each accepted map), else
  // nullptr; never computes.
  const GlobalInjectivity* held_global_injectivity() const {
    return global_y_.rows() == y_.rows() && global_y_ == y_ ? &global_verdict_ : nullptr;
  }
  // A full certificate of the current map with leaves (for reports), model units: the third-order bound
  // alone, or, where that does not certify a map a line search accepted with the spectral fallback
  // (docs/certificate.md, Step 4f), the fallback's (Certificate::spectral_fallback says which).
  Certificate certify_current(bool keep_leaves = true) const;
  EnergyTerms energy() const;  // at the current map, current weights (E_P2P on normalized distances)
  EnergyWeights weights() const { return weights_; }
  VecXd handle_errors() const;                               // #h, model units
  MatX3d handle_positions() const;                           // #h by 3, model units
  const MatX3d& handle_sources() const { return sources_; }  // #h by 3, model units, as set_handles got them
  const std::vector<IterationRecord>& history() const { return history_; }

  const Cage& cage() const { return cage_; }  // as given (model units)
  const Frame& frame() const { return frame_; }
  const Cage& normalized_cage() const { return ncage_; }
  const SpectralSubspace& subspace() const { return subspace_; }  // of the normalized cage
  const VoxelSampling& sampling() const { return sampling_; }     // model units
  const VoxelSampling& normalized_sampling() const { return nsampling_; }
  // Basis of the cage as given: for model-unit points with coefficients() (reports, comparisons).
  const HarmonicBasis& basis() const { return basis_; }
  // Basis of the normalized cage: for frame().points_to_normalized(P) with normalized coefficients (exact
  // at any model position; reduced_coefficients() through subspace()).
  const HarmonicBasis& normalized_basis() const { return nbasis_; }
  const OctreeCertifier& certifier() const { return *certifier_; }
  const DeformationEnergy& energy_function() const { return *energy_; }
  const ComputeBackend& backend() const { return *backend_; }
  // The Jacobians of the current map at the samples (3|I| by 3, JT layout), from the backend.
  MatJT current_jacobians() const { return kernels_->current_jacobians(); }
  double preprocess_seconds() const { return preprocess_seconds_; }
  // What the precomputation cache did ("hit", "miss", "rebuilt (...)", "disabled"; precompute_cache.h).
  const std::string& cache_outcome() const { return cache_outcome_; }
  // A background store (PrecomputeSetup::background_store): its outcome once written ("stored ...", "not
  // stored (...)"); invalid when there was none. Copies may outlive the solver (whose destructor waits for
  // it).
  std::shared_future<std::string> cache_store() const { return cache_store_; }
  SamplingParams sampling_params() const;
  CertifyParams certify_params(bool stop_on_failure, bool keep_leaves) const;

 private:
  // --- The stages of step()
  struct NewtonDirection {
    EnergyTerms e0;  // the energy at y_
    VecXd gvec;      // ∇E at y_ (3s)
    VecXd dvec;      // the direction (3s); the kernels' direction is set to it
  };
  enum class LineSearchEnd { kAccepted, kRetry, kExhausted, kInterrupted };
  void require_globally_injective_start();  // injectivity "global": throws InputError unless proven
  NewtonDirection newton_direction(bool reuse_factor, IterationRecord& rec);
  LineSearchEnd certified_line_search(const NewtonDirection& d, bool may_retry, IterationRecord& rec,
                                      const std::atomic<bool>* stop);
  Certificate certify_trial(const MatS3& yt, double t, const MatS3& delta, const EnergyTerms& et,
                            IterationRecord& rec);
  void screen_distortion(double t, CertifyParams& cp);
  bool globally_injective_trial(const MatS3& yt, IterationRecord& rec);
  void accept_trial(const MatS3& yt, double t, const MatS3& delta, const EnergyTerms& et, Certificate&& c,
                    IterationRecord& rec);
  void weaken_handles(IterationRecord& rec);  // dynamic weighting's retry: weaker handles, more smoothness
  void finish_record(IterationRecord& rec, bool interrupted, const EnergyWeights& weights_at_start);
  void update_weights(IterationRecord& rec);
  void check_targets(const MatX3d& targets, const std::string& where) const;
  const Cage& cage_;  // as given
  Frame frame_;
  Cage ncage_;  // cage_ in frame_: everything below is computed on it
  DeformParams params_;
  SpectralSubspace subspace_;
  VoxelSampling sampling_;   // model units (sample_voxels(cage_))
  VoxelSampling nsampling_;  // the same voxels in frame_
  HarmonicBasis basis_;      // of cage_
  HarmonicBasis nbasis_;     // of ncage_
  std::unique_ptr<OctreeCertifier> certifier_;
  std::unique_ptr<DeformationEnergy> energy_;
  std::shared_ptr<const ComputeBackend> backend_;
  std::unique_ptr<EnergyKernels> kernels_;  // holds the Jacobians of y_ (and of the direction) at the samples
  MatS3 y_;                                 // current reduced coefficients
  MatX3d sources_;                          // #h by 3 handle sources (set_handles), model units
  Certificate cert_;                        // model units
  EnergyWeights weights_;
  int weight_resets_ = 0;
  double bbox_diag2_ = 1;
  std::vector<IterationRecord> history_;
  double preprocess_seconds_ = 0;
  std::string cache_outcome_;
  std::shared_future<std::string> cache_store_;  // the background store, if any
  // The last assembled Newton system's Cholesky factor, kept while dragging (set_dragging) or for the next
  // iterations' CG steps (kept_factor_cg_steps).
  struct HessianFactor {
    MatXd L;                // dpotrf's lower factor of H + shift (3s by 3s); empty: none
    EnergyWeights weights;  // the weights it was assembled with
    int reuses = 0;         // steps that took it after the one that assembled it
  } factor_;
  // The distortion part of the reduced Hessian at the kernels' current map (distortion_pair_blocks), kept
  // until that map changes (emptied where the kernels' map is set or a step accepted): a direction recomputed
  // with other weights (dynamic weighting's retry, the iteration after a refused step) starts from the same
  // map, and only the weighted quadratic terms of DeformationEnergy::hessian_from differ.
  MatXd hessian_blocks_;
  bool hessian_blocks_double_ = false;
  // Those blocks at rest (the map rest_y_ that reset() sets), single precision: built once per model (at
  // construction or read from the precomputation cache) and taken for every first iteration from rest on the
  // CPU backend.
  MatXd rest_hessian_blocks_;
  MatS3 rest_y_;
  const MatXd& distortion_hessian_blocks();
  // The per-sample blocks of that part (DeformationEnergy::subset_hessian_blocks), kept likewise: the kept
  // factor's CG steps apply the subset Hessian through them.
  std::vector<Mat9> subset_blocks_;
  const std::vector<Mat9>& distortion_subset_blocks();
  // The subset Hessian's system solved with the kept factor as preconditioner (kept_factor_cg_steps); false
  // when there is none or the CG steps did not reach kept_factor_tolerance (dvec is then unchanged).
  bool kept_factor_direction(const VecXd& gvec, VecXd& dvec, IterationRecord& rec);
  bool dragging_ = false;
  // Base voxels whose proof failed in the last rejected line-search trial: the next trial refines them first
  // (CertifyParams::priority_voxels), so a trial failing at the same place is rejected early.
  std::vector<long> line_search_failed_;
  std::vector<Vec3> distortion_probes_;  // where the last trial refused by the distortion bound failed
  // The distortion screen of the current line search: its trials so far, and from the second on the kept
  // singular values of the current map's samples (DistortionScreen, over screen_J0_ and the direction's
  // Jacobians).
  int screened_trials_ = 0;
  MatJT screen_J0_;
  std::unique_ptr<DistortionScreen> screen_;
  // The last map the line search accepted and its certificate's per-voxel lower bounds (normalized frame):
  // the next trials certify by perturbation from it (CertifyParams::previous_y), used only while y_ is still
  // that map, bit for bit.
  MatS3 perturb_y_;
  std::vector<double> perturb_lower_;
  std::vector<double> perturb_upper_;  // and per voxel upper bounds of σ1 (CertifyParams::previous_upper)
  // The reason of the last line-search trial of this iteration rejected by the distortion bound
  // (CertifyParams::max_distortion, max_sigma1, min_sigma3), in the model's frame; empty when none was.
  std::string distortion_rejection_;
  // Global injectivity (injectivity "global"): the rest-state surface (#V by 3, #F by 3) when the domain is
  // the mesh's solid, its checker (built on first use, then reused for every trial), the last map proven
  // globally injective and the last refusal's reason.
  TriMesh mesh_;
  bool mesh_domain_ = false;
  mutable std::unique_ptr<GlobalInjectivityChecker> global_checker_;
  mutable MatS3 global_y_;  // the map global_verdict_ is about (empty: none)
  mutable GlobalInjectivity global_verdict_;
  std::string global_rejection_;
  // Why global injectivity cannot be decided for this solver at all ("" when it can).
  std::string global_problem() const;
  // The verdict for reduced coefficients ỹ (normalized frame; the report in model units).
  GlobalInjectivity check_global(const MatS3& y) const;
  // ≥ ‖d‖_F for the kernels' direction d, bounding the rounding of its Jacobians (CertifyParams::
  // direction_scale): Σ_k |α_k| ‖p_k‖_F when they were combined from CG iterates.
  double direction_scale_ = 0;
  long targets_version_ = 0, stepped_targets_version_ = 0;  // set_targets calls; as of the last step
  struct Precompute;  // the stages of the constructor (projected_newton.cpp)
  // Whether a distortion probe proves the map ỹ beyond a target (set_reduced_map's quick refusal; `refusal`
  // then holds the certificate's reason). False decides nothing.
  bool distortion_refuted_map(const MatS3& y, Certificate& refusal) const;
  // The plain direction p0 = −(factor)⁻¹ ∇E improved by params_.newton_cg_steps preconditioned CG iterates
  // on the exact Hessian; leaves the kernels' direction set to the result (and direction_scale_).
  VecXd conjugate_gradient_correction(const VecXd& gvec, const VecXd& p0, const MatXd& L,
                                      IterationRecord& rec);
};

}  // namespace lidef
