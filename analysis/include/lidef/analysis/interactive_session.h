// The engine behind lidef-studio: one model, one DeformationSolver running on its own thread, and "frames" —
// immutable snapshots of the last certified map with everything a view needs (deformed mesh and its
// per-vertex fields, deformed cage, handle images, and on request the certificate's leaves, a σ3 field grid
// and a verification). Qt- and VTK-free, so the CLI, tests and benchmarks drive exactly what the studio
// drives.
//
// Threading: every public method may be called from any thread and returns at once; commands are queued and
// applied by the engine thread between Newton iterations. The solver never waits for a consumer: frames are
// handed to `on_frame` (called on the engine thread; the studio re-posts them to its UI thread and renders
// only the newest). A frame's map is always certified: the solver only ever holds certified maps
// (projected_newton.h).
//
// While handles are being dragged the engine calls DeformationSolver::solve() from the last map, one frame
// per iteration, and restarts it whenever the targets change; it rests when the solve stops (converged,
// blocked, no certified step, iteration limit) until something changes or solve() is asked for.
#pragma once
#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/analysis/field_grid.h"
#include "lidef/compute_backend.h"
#include "lidef/deform_params.h"
#include "lidef/global_injectivity.h"
#include "lidef/model_check.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"

namespace lidef {

// What the engine is doing.
enum class SessionState { kEmpty, kPreparing, kIterating, kResting, kFailed };
const char* to_string(SessionState s);

// One certified map and what the views show of it. Immutable once published (shared between threads).
struct SessionFrame {
  long serial = 0;         // increases with every frame of a session
  long map_version = 0;    // changes whenever the map (or the model) changes
  long model_version = 0;  // changes when a model is (re)loaded or the solver rebuilt
  SessionState state = SessionState::kEmpty;
  std::string status;  // one line: what happened last ("converged: ...", "preprocessing: ...")
  // While preparing, or verifying (verify(): state resting, the map's frame): the stage running and the
  // fraction of the whole done (0..1); else -1.
  // A preparing frame already carries the new model at rest (mesh_V, cage_V = the rest pose, the identity
  // map's fields, no certificate yet); the studio shows only its progress and keeps drawing the model of
  // the last frame that was not preparing (the model solver_model() names) until the preparation ends.
  std::string stage;
  double progress = -1;
  std::shared_ptr<const Model> model;    // the model this frame belongs to (rest mesh, cage)
  std::vector<IterationRecord> history;  // all iterations since the model was loaded or the map reset
  // Certificate of this map (the solver's line-search certificate, no leaves).
  bool certified = false;
  double min_lower_bound = 0;  // min over leaves of σ3 − r L
  double min_sigma3 = 0;       // min σ3 at the evaluated voxel centers
  std::string not_certified_reason;
  EnergyTerms energy;  // as the last iteration recorded it (with its weights, like the plots), else at the
                       // current weights
  double max_handle_error = 0;
  // Geometry (model units).
  MatX3d mesh_V;     // #Vm by 3: the deformed mesh vertices f(v)
  VecXd mesh_e_iso;  // #Vm: E_iso − 6 at the mesh vertices (NaN where det J ≤ 0)
  VecXd mesh_det;    // #Vm: det J, the local volume ratio
  VecXd
      mesh_distortion;  // #Vm: σ1/σ3 (NaN where σ3 ≤ 0); only when ExtrasRequest::mesh_distortion, else empty
  MatX3d cage_V;        // #Vc by 3: the deformed cage (the vertex coefficients y_v)
  MatX3d sources, targets, images;  // #h by 3: handle sources, targets and their images f(source)
  MatX3d coefficients;              // #Vc+#Fc by 3: the map (coefficients.txt)
  // Extras, computed only when requested (set_extras) and then at most every `extras_interval` seconds while
  // iterating, always when resting. Each carries the map_version it belongs to (it may lag the frame's).
  std::shared_ptr<const Certificate> leaves;  // certificate with leaves (keep_leaves = true)
  long leaves_version = -1;
  // How `leaves` was computed, for writing it as lidef deform writes its certificate
  // (make_certificate_report): the solver's sampling (model units) and certifier parameters.
  std::shared_ptr<const VoxelSampling> leaves_sampling;
  SamplingParams leaves_sampling_params;
  CertifyParams leaves_certify_params;
  std::shared_ptr<const FieldGrid> field;                    // σ3 etc. on a grid in rest space
  std::shared_ptr<const std::vector<float>> field_deformed;  // 3 per grid point: f(p) (NaN outside the cage)
  long field_version = -1;
  std::shared_ptr<const VerificationResult> verification;  // dense-sampling check of `leaves` (Fig. 5)
  long verification_version = -1;
  // Global injectivity of the map (ExtrasRequest::global_injectivity; global_injectivity.h): checked only
  // when the engine rests, since one check takes seconds. A new map leaves global_version behind map_version
  // until its own check ends (a view says "checking" meanwhile, never the verdict of an earlier map).
  std::shared_ptr<const GlobalInjectivity> global;
  long global_version = -1;
  double ms_frame = 0;  // time to build this frame's geometry
};

// What the views need besides the mesh; the engine computes only what is asked for.
struct ExtrasRequest {
  bool leaves = false;
  bool field = false;
  bool mesh_distortion = false;  // σ1/σ3 at the mesh vertices with every frame (a signed SVD per vertex)
  // Global injectivity (global_injectivity.h) of the map the engine rests at, once it has rested 0.25 s with
  // no command: one GlobalInjectivityChecker per model, one check per resting map; a command posted meanwhile
  // cancels the check (it runs again at the next rest).
  bool global_injectivity = false;
  int field_resolution = 48;     // grid points along the longest axis of the cage's bounding box
  double extras_interval = 1.0;  // seconds between extras while iterating (0 = every frame)
};

class InteractiveSession {
 public:
  using FrameCallback = std::function<void(std::shared_ptr<const SessionFrame>)>;
  // Problems found on the engine thread (a handle outside the cage, a solver that cannot be built): the
  // command is dropped, the previous state kept, and this is called with the message.
  using ErrorCallback = std::function<void(const std::string&)>;

  // `backends` builds the compute backend named by the parameters (cpu_backend_factory() when this program
  // has no OpenCL; the studio passes opencl_backend_factory()).
  explicit InteractiveSession(FrameCallback on_frame, ErrorCallback on_error = {},
                              BackendFactory backends = cpu_backend_factory());
  ~InteractiveSession();  // stops the engine thread (interrupting a running iteration)
  InteractiveSession(const InteractiveSession&) = delete;
  InteractiveSession& operator=(const InteractiveSession&) = delete;

  // --- Loading. These read and check the files synchronously in the caller's thread and throw InputError
  // naming the file (the current session is then untouched); the solver's precomputation runs on the engine.
  // A scenario starts solving at once; a model starts with no handles at the identity.
  // Turns a scenario's or the caller's model path into a model folder (the studio passes one that makes and
  // caches an automatic cage for a mesh file, lidef/cage/auto_cage.h); identity by default.
  using ModelResolver = std::function<std::string(const std::string& path)>;
  void set_model_resolver(ModelResolver resolver) { resolver_ = std::move(resolver); }
  // `coefficients` (optional): a coefficients.txt of this scenario's model (written by `lidef deform` with
  // the same parameters) to start from instead of solving: the engine rests at that map (InputError naming
  // the file when it cannot be read; an error when the solver's subspace or certificate does not take it).
  void open_scenario(const std::string& path, const std::string& models_dir = "",
                     const std::string& coefficients = "");
  void open_model(const std::string& model_dir, const DeformParams& params = {});

  // The session as a scenario (handles, parameters; `studio` left for the caller), for saving. Empty
  // model_dir when nothing is loaded.
  Scenario scenario() const;
  // The loaded model (nullptr when none). Constant for a model_version; safe to read from any thread.
  std::shared_ptr<const Model> model() const;
  // The model of the solver the engine runs now (nullptr when none): what every frame that is not a
  // preparing frame shows. Unlike model(), which names a model from the moment it is opened, this changes
  // only when a preparation succeeds, so a view that shows this model shows what was certified.
  std::shared_ptr<const Model> solver_model() const;

  // --- Handles (#h by 3 each; sources in rest space). Checked here against the cage (inside, not on it) and
  // thrown as InputError before anything is queued.
  void set_handles(const MatX3d& sources, const MatX3d& targets);
  void set_targets(const MatX3d& targets);  // same count as the current handles; the drag path
  // Checks one source point as set_handles would (handle_source_problem); "" when fine, else the reason.
  std::string check_source(const Vec3& p) const;

  // --- Preprocessing. The solver's precomputation (and the mesh matrices) is cached on disk
  // (precompute_cache.h) in `dir` ("" = no cache; default_cache_dir() until set) up to `max_bytes`.
  void set_cache(const std::string& dir, std::uint64_t max_bytes = default_cache_max_bytes());
  // Computed cache entries (the solver's precomputation, the mesh matrices) are written in the background
  // while the session rests (PrecomputeSetup::background_store). Waits for every one started so far and
  // returns their outcomes ("" when there was none); tests and benchmarks call it before looking at the cache
  // folder. The destructor waits for them too.
  std::string wait_for_cache_store() const;
  // Stops a running preprocessing (a load or a parameter change) at its next chunk of work: the model and map
  // before it stay (or the session stays empty), the frame's status says "cancelled". Also stops a running
  // verification (verify()) at its next chunk of leaves: no verification result. No effect otherwise.
  void cancel_preparation();
  // Test hook: called on the engine thread at every progress point of a preprocessing (`stage`, before the
  // cancel is polled there) and once with stage "ready" when the new solver is committed. A test may call
  // cancel_preparation() or block in it (to look at the window while the engine stands at that point), so
  // a cancel lands at a chosen stage without sleeps. Set it while the engine is idle.
  using StageHook = std::function<void(const std::string& stage)>;
  void set_stage_hook(StageHook hook) { stage_hook_ = std::move(hook); }

  // --- Solver control.
  void set_params(const DeformParams& params);  // rebuilds the solver when a precomputation parameter changed
  void solve();  // iterate from the current map (after stop(), or to continue after the iteration limit)
  void stop();   // interrupts the running iteration (the map stays the last certified one) and rests
  void reset();  // back to the identity map (history cleared)
  void set_extras(const ExtrasRequest& request);
  // Dense sampling of the leaves of the map the engine rests at next (Fig. 5); verify_certificate().
  void verify(int samples_per_voxel = 32);

  // --- Waiting (tests, benchmarks, headless screenshots).
  // Blocks until the engine rests (or fails) with no command pending and extras up to date; false on timeout.
  bool wait_until_resting(double timeout_seconds);
  std::shared_ptr<const SessionFrame> latest_frame() const;
  SessionState state() const;

 private:
  struct Command;
  struct Engine;
  void post(Command c);
  void load(std::shared_ptr<const Model> model, const Scenario& sc, bool iterate, MatX3d initial = {},
            const std::string& initial_from = "");
  void run();

  FrameCallback on_frame_;
  ErrorCallback on_error_;
  BackendFactory backends_;
  ModelResolver resolver_;
  StageHook stage_hook_;
  std::unique_ptr<Engine> engine_;  // touched by the engine thread only (after construction)
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable rested_;
  std::vector<Command> queue_;
  bool quit_ = false;
  std::atomic<bool> interrupt_{false};
  std::atomic<bool> cancel_{false};  // cancel_preparation(); cleared when the engine takes new commands
  std::atomic<bool> posted_{false};  // a command waits: a running global check stops (cleared as cancel_)
  std::shared_ptr<const SessionFrame> latest_;
  SessionState state_ = SessionState::kEmpty;
  bool idle_ = true;  // engine waiting with an empty queue and nothing to do
  std::shared_ptr<const Model> model_;
  std::shared_ptr<const Model> solver_model_;  // the engine's committed model (guarded by mutex_)
  Scenario scenario_;                          // handles and parameters as last set (guarded by mutex_)
  std::string cache_dir_;                      // guarded by mutex_
  // Background stores of cache entries (guarded by mutex_). Declared before thread_, so destroyed after the
  // engine thread is joined: the destruction of the last copy of an async future waits for its write.
  std::vector<std::shared_future<std::string>> cache_stores_;
  std::uint64_t cache_max_bytes_ = 0;
  std::thread thread_;
};

}  // namespace lidef
