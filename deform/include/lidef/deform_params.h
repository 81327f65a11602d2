// The one parameter table of the deformation solver. Every parameter has one name (snake_case), a type, a
// default, a valid range and a help line; the same table feeds the scenario JSON ("parameters": {...}), the
// `lidef deform` command-line flags (--name-with-dashes) and the studio's panels. Defaults follow the paper
// (Sec. 7.4: λ1 = 1e5, λ2 = 0.1, 6 octree levels, |I| ≈ 3e4, |H| = 5%, 300 DOF per coordinate) where it gives
// them; the others are documented in docs/solver.md.
#pragma once
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <variant>
#include <vector>

#include "lidef/lipschitz_bound.h"

namespace lidef {

// Precision of the products that assemble the reduced Hessian.
enum class HessianPrecision { kSingle, kDouble };
// Where the per-sample stages run: the CPU, an OpenCL device, or OpenCL when a device with fp64 works.
enum class BackendKind { kCpu, kOpenCL, kAuto };
// What the voxels (energy samples and certified leaves) cover: the mesh and its solid (domain_sampling.h), or
// the paper's grid of cells clear of the cage (sample_voxels), kept for comparison with the paper.
enum class DomainKind { kMesh, kVoxels };
// What the line search proves of an accepted map: local injectivity (the octree certificate), or also that
// the shape does not pass through itself (global_injectivity.h; docs/solver.md, "Global injectivity mode").
enum class InjectivityMode { kLocal, kGlobal };
const char* to_string(HessianPrecision p);  // "single" / "double"
const char* to_string(BackendKind b);       // "cpu" / "opencl" / "auto"
const char* to_string(DomainKind d);        // "mesh" / "voxels"
const char* to_string(InjectivityMode m);   // "local" / "global"

struct DeformParams {
  // --- Subspace and sampling
  int reduced_dof = 300;                  // s: reduced coefficients per coordinate (3s unknowns)
  int samples = 30000;                    // |I|: target number of voxels (the side is searched to match)
  double voxel_side = 0;                  // > 0: use this voxel side instead of searching from `samples`
  double safety = 1.5;                    // voxel center to cage >= safety * voxel radius
  double hessian_fraction = 0.05;         // |H| / |I|
  DomainKind domain = DomainKind::kMesh;  // the certified domain (samples = its leaf count)
  // --- Energy E = E_dis + λ1 E_P2P + λ2 E_smooth
  double lambda_p2p = 1e5;     // λ1
  double lambda_smooth = 0.1;  // λ2
  // --- Projected Newton
  int max_iterations = 50;
  double step_tolerance = 1e-6;    // converged when t‖δ‖ <= step_tolerance · max(1, ‖ỹ‖)
  double energy_tolerance = 1e-5;  // ... or when the relative energy decrease of a step is below this
  double armijo = 1e-4;            // sufficient-decrease constant c1
  int max_halvings = 40;           // line-search halvings before "no certified step"
  double diagonal_shift = 1e-5;    // added to the reduced Hessian's diagonal
  // While the handles are dragged (DeformationSolver::set_dragging: the studio), a Newton step right after
  // new targets may solve with the previous step's Hessian factor instead of assembling its own, at most this
  // many steps in a row (0 = never). The CLI never drags. docs/solver.md, "Dragging".
  int drag_hessian_reuse = 2;
  // Preconditioned conjugate-gradient iterates on the exact (all-sample) Hessian after the subset Hessian's
  // solve: 1 = scale the direction to the exact quadratic model's minimum along it, each more = one exact
  // Hessian-vector product (0 = off). docs/solver.md, "Correcting the subset Hessian".
  int newton_cg_steps = 1;
  // A Newton iteration after the first may solve its subset-Hessian system with the factor of an earlier
  // iteration's Hessian as the preconditioner of at most this many conjugate-gradient steps, the Hessian
  // applied through its per-sample blocks (no assembly), to the relative residual kept_factor_tolerance (in
  // the factor's norm, sqrt(rᵀ(LLᵀ)⁻¹r): about the error's in the Hessian's norm); only
  // where they do not get there is the Hessian assembled and factored anew (0 = every iteration assembles).
  // docs/solver.md, "The kept factor".
  int kept_factor_cg_steps = 20;
  double kept_factor_tolerance = 1e-3;
  HessianPrecision hessian_precision = HessianPrecision::kSingle;  // products of the reduced Hessian
  // Handle error reported as "reached", as a fraction of the model size (Frame::scale, normalization.h: half
  // the largest extent of the cage's bounding box), so that it means the same for a scaled model.
  double handle_tolerance = 1e-3;
  // --- Continuation (target_path.h, continuation.h; docs/solver.md)
  bool continuation = true;               // rotation-aware intermediate targets for large motions and stalls
  double continuation_angle = 90;         // degrees: the largest rotation of a handle group per stage
  int continuation_stage_iterations = 3;  // Newton iterations at most per intermediate stage
  // --- Certificate (line search and output)
  int max_depth = 6;
  LipschitzBound bound = LipschitzBound::kThirdOrder;     // first (17) or third (21) order
  RefinementEval refinement = RefinementEval::kFarField;  // how octree children are evaluated (CertifyParams)
  long max_refined = 200000;             // child voxels evaluated per certification of a result
  long line_search_max_refined = 20000;  // the same budget for line-search trials: a trial that needs more is
                                         // rejected (sound: "not certified") and the step halved
  bool line_search_spectral_fallback = true;  // line searches: CertifyParams::base_spectral_fallback
  double bound_tolerance = 0;  // > 0: refine a certified map's leaves until the lower bound of σ3 is within
                               // this fraction of the smallest sampled σ3 (CertifyParams::bound_tolerance)
  double max_distortion =
      0;  // > 0: certified maps have σ1/σ3 ≤ this on every leaf (CertifyParams::max_distortion)
  double max_sigma1 = 0;  // > 0: certified maps have σ1 ≤ this on every leaf (isometric distortion bound)
  double min_sigma3 = 0;  // > 0: certified maps have σ3 ≥ this on every leaf (isometric distortion bound)
  // global: an accepted step must also be proven globally injective on the mesh's solid (the shape stops
  // where it would pass through itself). local by default: the check costs far more than a Newton step
  // (docs/solver.md, "Global injectivity mode").
  InjectivityMode injectivity = InjectivityMode::kLocal;
  // Memory (MB) the global mode's and the studio's checker keeps for what no map changes
  // (GlobalInjectivityChecker's cache_mb): the more of it fits, the less each check evaluates.
  double global_cache_mb = 2048;
  // --- Dynamic weighting (Sec. 7.3; docs/solver.md)
  bool dynamic_weighting = true;
  double e0 = 1e-4;                // E_P2P threshold, relative to the squared cage bounding-box diagonal
  double kappa1 = 0.5;             // λ1 ← κ1 λ1 when E_P2P >= E0 and (36) fails
  double kappa2 = 2.0;             // λ2 ← κ2 λ2
  double epsilon = 0.05;           // margin of condition (36): min over leaves of σ3 − r L >= ε
  double max_smooth_factor = 1e3;  // λ2 stays <= this times its default
  double min_p2p_factor = 1e-3;    // λ1 stays >= this times its default
  int direction_retries = 3;       // per iteration: recompute the direction with weaker handles when its full
                                   // step fails the certificate while E_P2P >= E0
  int max_weight_resets =
      2;  // convergence with changed weights resets them and continues, at most this often
  // --- Execution
  int threads = 0;                          // OpenMP threads (0 = all cores)
  BackendKind backend = BackendKind::kCpu;  // OpenCL, or auto (OpenCL when a device with fp64 exists)
  std::string opencl_device;       // substring of "<platform> <device>" choosing the device ("" = any)
  bool opencl_gpu_layout = false;  // a CPU OpenCL device takes the GPU code paths (tests them on PoCL)
  bool trace_line_search = false;  // print every line-search trial to stderr
  // --- Test hooks (group "testing": not shown in --help or the studio; docs/parameters.md)
  int test_interrupt_after = 0;     // lidef deform raises SIGINT after this many iterations (0 = never)
  bool test_break_kernels = false;  // OpenCL: append a line that does not compile to the kernels
  long test_opencl_max_alloc = 0;   // OpenCL: pretend the device allows buffers of at most this many bytes
};

struct SamplingParams;  // sampling.h
struct CertifyParams;   // octree_certifier.h
// The voxel sampling and the certificate that the parameters name: the one mapping, used by the solver,
// `lidef certify` and `lidef compare`.
SamplingParams sampling_params_of(const DeformParams& params);
CertifyParams certify_params_of(const DeformParams& params, bool stop_on_failure, bool keep_leaves);

// One row of the table. `member` points into DeformParams.
struct ParamInfo {
  using Member =
      std::variant<int DeformParams::*, long DeformParams::*, double DeformParams::*, bool DeformParams::*,
                   std::string DeformParams::*, LipschitzBound DeformParams::*,
                   HessianPrecision DeformParams::*, BackendKind DeformParams::*, DomainKind DeformParams::*,
                   RefinementEval DeformParams::*, InjectivityMode DeformParams::*>;
  const char* name;   // JSON key; the CLI flag is "--" + name with '_' → '-'
  const char* group;  // "sampling", "energy", "newton", "certificate", "weighting", "execution", "testing"
  Member member;
  double min, max;  // valid range (inclusive) for numbers; ignored for bool/string
  const char* help;
};

// The table, in display order.
const std::vector<ParamInfo>& deform_param_table();
// Row by JSON name; nullptr when unknown.
const ParamInfo* find_param(const std::string& name);
// "--lambda-p2p" for "lambda_p2p".
std::string param_flag(const ParamInfo& p);
// The names an enum parameter takes, in enum order (empty for the other types).
std::vector<std::string> param_choices(const ParamInfo& p);
// Test hooks (group "testing") are parameters like the others but are left out of --help and the studio.
bool is_test_hook(const ParamInfo& p);

// Sets one parameter from a JSON value; throws InputError(where, ...) for an unknown name (listing the close
// ones), a wrong type, a non-finite number or a value out of range.
void set_param(DeformParams& params, const std::string& name, const nlohmann::json& value,
               const std::string& where);
// The same from command-line text: string parameters take `text` verbatim, the others read it as JSON (a
// number or true/false); throws InputError(where, ...) for text that is neither, and as set_param does.
void set_param_from_text(DeformParams& params, const std::string& name, const std::string& text,
                         const std::string& where);
// Applies every key of a JSON object (set_param for each); throws on the first bad key.
void apply_params(DeformParams& params, const nlohmann::json& object, const std::string& where);
// Checks cross-parameter consistency (ranges of each field and e.g. bound spelled right); throws InputError.
void validate_params(const DeformParams& params, const std::string& where);
// True when a and b differ in a parameter that shapes DeformationSolver's precomputation (reduced_dof,
// samples, voxel_side, safety, hessian_fraction, threads, backend and the OpenCL options): the change needs a
// new solver, not set_params().
bool changes_precomputation(const DeformParams& a, const DeformParams& b);
// All parameters as a JSON object in table order (for summary.json and saved sessions). ordered_json because
// nlohmann::json sorts keys, which would scatter the groups; assign it to a nlohmann::json if order is moot.
nlohmann::ordered_json params_to_json(const DeformParams& params);
// Current value as text (for --help and the studio).
std::string param_value_string(const DeformParams& params, const ParamInfo& p);

}  // namespace lidef
