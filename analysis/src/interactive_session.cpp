#include "lidef/analysis/interactive_session.h"

#include <omp.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <future>
#include <limits>

#include "lidef/analysis/certificate_report.h"
#include "lidef/blas_kernel.h"
#include "lidef/coefficients.h"
#include "lidef/continuation.h"
#include "lidef/errors.h"
#include "lidef/internal/enum_names.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_fields.h"
#include "lidef/precompute_cache.h"

namespace lidef {

template <>
struct EnumNames<SessionState> {
  static constexpr const char* names[] = {"empty", "preparing", "iterating", "resting", "failed"};
};

const char* to_string(SessionState s) {
  return enum_name(s);
}

namespace {
// Seconds the engine rests with no command before it checks global injectivity (a pause of the drag).
constexpr double kGlobalCheckPause = 0.25;

}  // namespace

struct InteractiveSession::Command {
  enum Kind { kLoad, kHandles, kTargets, kParams, kSolve, kStop, kReset, kExtras, kVerify } kind;
  explicit Command(Kind k) : kind(k) {}
  std::shared_ptr<const Model> model;
  Scenario scenario;  // kLoad
  bool iterate = false;
  MatX3d initial;            // kLoad: the map to start from (0 rows: the identity)
  std::string initial_from;  // its file
  MatX3d sources, targets;
  DeformParams params;
  ExtrasRequest extras;
  int samples_per_voxel = 32;
};

// State owned by the engine thread, and the stages of its loop (run()).
struct InteractiveSession::Engine {
  explicit Engine(InteractiveSession& s) : session(s) {}
  InteractiveSession& session;  // queue, mutex, callbacks and what the other threads read

  std::shared_ptr<const Model> model;
  DeformParams params;
  MatX3d sources, targets;
  std::shared_ptr<const ComputeBackend> backend;
  std::unique_ptr<DeformationSolver> solver;
  // Mesh vertices in the reduced space, in the solver's normalized frame: f(V) = frame.from_normalized(Mv ỹ)
  // (#Vm by s), Jᵀ rows = Mg ỹ (3#Vm by s; Jacobians are frame-invariant).
  MatXd Mv, Mg;
  bool want_iterate = false;
  std::string status;
  SessionState state = SessionState::kEmpty;
  ExtrasRequest extras;
  long serial = 0, map_version = 0, model_version = 0;
  std::shared_ptr<const Certificate> leaves;
  std::shared_ptr<const VoxelSampling> leaves_sampling;  // the solver's sampling, as of leaves_sampling_model
  long leaves_sampling_model = -1;
  SamplingParams leaves_sampling_params;
  CertifyParams leaves_certify_params;
  long leaves_version = -1;
  std::shared_ptr<const FieldGrid> field;
  std::shared_ptr<const std::vector<float>> field_deformed;
  long field_version = -1;
  std::shared_ptr<const VerificationResult> verification;
  long verification_version = -1;
  // Global injectivity: the checker of the model of model_version checker_model (built at its first check).
  std::unique_ptr<GlobalInjectivityChecker> checker;
  long checker_model = -1;
  double checker_cache_mb = 0;  // the cache budget it was built with (DeformParams::global_cache_mb)
  std::shared_ptr<const GlobalInjectivity> global;
  long global_version = -1;
  Clock::time_point last_extras = Clock::now() - std::chrono::hours(1);
  int verify_samples = 0;  // > 0: a verification is pending
  Scenario scenario;       // what the engine runs (restored into scenario_ when a command fails)
  // A loaded scenario's waypoints, for its first solve only: after any other target change or an interrupted
  // solve they would send the handles back along a path they already left.
  std::vector<MatX3d> waypoints;

  // --- Waiting for work.
  bool take_commands(std::vector<Command>& cmds);  // false: the session is closing
  bool commands_queued(bool or_quit) const;        // commands wait (or, with or_quit, the session closes)

  // --- Commands, in the order they were posted; a failing one is dropped and the state before it kept.
  void apply_commands(const std::vector<Command>& cmds);
  void apply_command(const std::vector<Command>& cmds, size_t k);
  static bool targets_superseded(const std::vector<Command>& cmds, size_t k);
  void apply_load(const Command& c);
  void apply_handles(const Command& c);
  void apply_targets(const Command& c, bool superseded);
  void apply_params(const Command& c);
  void apply_solve();
  void apply_stop();
  void apply_reset();
  void apply_extras(const Command& c);
  void apply_verify(const Command& c);
  void drop_command(const std::exception& e);

  // --- The solver.
  // The model being prepared, its handles and the stage (preparing frames show it at rest).
  std::shared_ptr<const Model> preparing;
  std::string stage;
  double progress = -1;
  MatX3d prep_sources, prep_targets;
  void build_solver(const std::shared_ptr<const Model>& new_model, const DeformParams& new_params,
                    const MatX3d& new_sources, const MatX3d& new_targets);
  void build_solver_stages(const std::shared_ptr<const Model>& new_model, const DeformParams& new_params,
                           PrecomputeSetup& setup);
  void on_progress(const std::string& name, double fraction);  // a preparing frame; throws Cancelled
  void handles_to_solver();
  bool iterate();  // false: go straight back for the waiting commands (no resting frame)
  bool on_iteration(const IterationRecord& r);

  // --- Extras (certificate leaves, σ3 field grid, verification) of the current map.
  bool compute_extras(bool resting);  // true when something was computed
  void compute_leaves();
  void compute_field();
  void compute_verification();
  bool compute_global();  // false: cancelled by a posted command

  // --- What the other threads see.
  void rest();  // extras up to date, then a frame of the final state
  std::shared_ptr<SessionFrame> make_frame();
  void publish_frame(std::shared_ptr<const SessionFrame> f);
  void publish_state(SessionState st, const std::string& text);
  std::shared_ptr<SessionFrame> make_preparing_frame();
  void report_error(const std::string& what);
};

InteractiveSession::InteractiveSession(FrameCallback on_frame, ErrorCallback on_error,
                                       BackendFactory backends)
    : on_frame_(std::move(on_frame)),
      on_error_(std::move(on_error)),
      backends_(std::move(backends)),
      engine_(std::make_unique<Engine>(*this)),
      cache_dir_(default_cache_dir()),
      cache_max_bytes_(default_cache_max_bytes()) {
  thread_ = std::thread([this] { run(); });
}

InteractiveSession::~InteractiveSession() {
  {
    std::lock_guard<std::mutex> lk(mutex_);
    quit_ = true;
    interrupt_.store(true);
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void InteractiveSession::post(Command c) {
  {
    std::lock_guard<std::mutex> lk(mutex_);
    // Commands that make the running iteration pointless interrupt it (the map stays the last certified one).
    if (c.kind == Command::kLoad || c.kind == Command::kStop || c.kind == Command::kReset ||
        c.kind == Command::kParams)
      interrupt_.store(true);
    // A newer model replaces one still being prepared.
    if (c.kind == Command::kLoad) cancel_.store(true);
    posted_.store(true);
    queue_.push_back(std::move(c));
    idle_ = false;
  }
  wake_.notify_all();
}

void InteractiveSession::open_scenario(const std::string& path, const std::string& models_dir,
                                       const std::string& coefficients) {
  Scenario sc = read_scenario(path, models_dir);
  if (resolver_) sc.model_dir = resolver_(sc.model_dir);
  auto model = std::make_shared<const Model>(load_model(sc.model_dir));
  for (Eigen::Index i = 0; i < sc.sources.rows(); ++i) {
    const std::string why = handle_source_problem(model->cage, sc.sources.row(i).transpose());
    if (!why.empty()) throw InputError(path, "handle " + std::to_string(i + 1) + ": source " + why);
  }
  if (coefficients.empty()) return load(model, sc, true);
  MatX3d y = read_coefficients(coefficients, model->cage);
  load(model, sc, false, std::move(y), coefficients);
}

void InteractiveSession::open_model(const std::string& model_dir, const DeformParams& params) {
  validate_params(params, model_dir);
  auto model = std::make_shared<const Model>(load_model(model_dir));
  Scenario sc;
  sc.model = model_dir;
  sc.model_dir = model_dir;
  sc.name = std::filesystem::path(model_dir).filename().string();
  sc.params = params;
  sc.sources.resize(0, 3);
  sc.targets.resize(0, 3);
  load(model, sc, false);
}

void InteractiveSession::load(std::shared_ptr<const Model> model, const Scenario& sc, bool iterate,
                              MatX3d initial, const std::string& initial_from) {
  Command c(Command::kLoad);
  c.model = model;
  c.scenario = sc;
  c.iterate = iterate;
  c.initial = std::move(initial);
  c.initial_from = initial_from;
  {
    std::lock_guard<std::mutex> lk(mutex_);
    model_ = std::move(model);
    scenario_ = sc;
  }
  post(std::move(c));
}

Scenario InteractiveSession::scenario() const {
  std::lock_guard<std::mutex> lk(mutex_);
  return scenario_;
}

std::shared_ptr<const Model> InteractiveSession::model() const {
  std::lock_guard<std::mutex> lk(mutex_);
  return model_;
}

std::shared_ptr<const Model> InteractiveSession::solver_model() const {
  std::lock_guard<std::mutex> lk(mutex_);
  return solver_model_;
}

std::string InteractiveSession::check_source(const Vec3& p) const {
  const auto m = model();
  if (!m) return "no model is loaded";
  return handle_source_problem(m->cage, p);
}

void InteractiveSession::set_handles(const MatX3d& sources, const MatX3d& targets) {
  const auto m = model();
  if (!m) throw InputError("handles", "no model is loaded");
  if (sources.rows() != targets.rows()) throw InputError("handles", "as many targets as sources are needed");
  if (!targets.allFinite()) throw InputError("handles", "a target is not finite");
  for (Eigen::Index i = 0; i < sources.rows(); ++i) {
    const std::string why = handle_source_problem(m->cage, sources.row(i).transpose());
    if (!why.empty()) throw InputError("handles", "handle " + std::to_string(i + 1) + ": source " + why);
  }
  {
    std::lock_guard<std::mutex> lk(mutex_);
    scenario_.sources = sources;
    scenario_.targets = targets;
  }
  Command c(Command::kHandles);
  c.sources = sources;
  c.targets = targets;
  post(std::move(c));
}

void InteractiveSession::set_targets(const MatX3d& targets) {
  {
    std::lock_guard<std::mutex> lk(mutex_);
    if (targets.rows() != scenario_.sources.rows())
      throw InputError("targets", "one target per handle is needed (" +
                                      std::to_string(scenario_.sources.rows()) + " handles, " +
                                      std::to_string(targets.rows()) + " targets)");
    if (!targets.allFinite()) throw InputError("targets", "a target is not finite");
    scenario_.targets = targets;
  }
  Command c(Command::kTargets);
  c.targets = targets;
  post(std::move(c));
}

void InteractiveSession::set_params(const DeformParams& params) {
  validate_params(params, "parameters");
  {
    std::lock_guard<std::mutex> lk(mutex_);
    scenario_.params = params;
  }
  Command c(Command::kParams);
  c.params = params;
  post(std::move(c));
}

void InteractiveSession::set_cache(const std::string& dir, std::uint64_t max_bytes) {
  std::lock_guard<std::mutex> lk(mutex_);
  cache_dir_ = dir;
  cache_max_bytes_ = max_bytes;
}

std::string InteractiveSession::wait_for_cache_store() const {
  std::vector<std::shared_future<std::string>> fs;
  {
    std::lock_guard<std::mutex> lk(mutex_);
    fs = cache_stores_;
  }
  std::string out;
  for (const auto& f : fs) out += (out.empty() ? "" : "; ") + f.get();
  return out;
}

void InteractiveSession::cancel_preparation() {
  cancel_.store(true);
}

void InteractiveSession::solve() {
  post(Command(Command::kSolve));
}
void InteractiveSession::stop() {
  post(Command(Command::kStop));
}
void InteractiveSession::reset() {
  post(Command(Command::kReset));
}
void InteractiveSession::set_extras(const ExtrasRequest& request) {
  Command c(Command::kExtras);
  c.extras = request;
  post(std::move(c));
}
void InteractiveSession::verify(int samples_per_voxel) {
  if (samples_per_voxel < 0) throw InputError("verify", "samples per voxel must be >= 0");
  Command c(Command::kVerify);
  c.samples_per_voxel = samples_per_voxel;
  post(std::move(c));
}

bool InteractiveSession::wait_until_resting(double timeout_seconds) {
  std::unique_lock<std::mutex> lk(mutex_);
  return rested_.wait_for(lk, std::chrono::duration<double>(timeout_seconds), [this] {
    return idle_ && queue_.empty() && state_ != SessionState::kPreparing &&
           state_ != SessionState::kIterating;
  });
}

std::shared_ptr<const SessionFrame> InteractiveSession::latest_frame() const {
  std::lock_guard<std::mutex> lk(mutex_);
  return latest_;
}

SessionState InteractiveSession::state() const {
  std::lock_guard<std::mutex> lk(mutex_);
  return state_;
}

// ------------------------------------------------------------------------------------------- engine thread

namespace {

// Mesh vertices in the reduced space, in blocks so that the full-space matrices (#Vm by #Vc+#Fc) never
// exist at once (the animal's would take 1.4 GB): Mv = (basis values at the mesh vertices) Ξ (#Vm by s),
// Mg = (basis gradients) Ξ (3#Vm by s), in the solver's normalized frame. From the cache when it holds them
// for this cage, mesh and subspace; else computed, and stored in the background (the returned future; invalid
// after a hit). `tick` gets the fraction done (and may throw Cancelled).
std::shared_future<std::string> reduced_mesh_matrices(const DeformationSolver& S, const MatX3d& mesh_V,
                                                      const PrecomputeCache& cache,
                                                      const std::function<void(double)>& tick, MatXd& Mv,
                                                      MatXd& Mg) {
  CacheKey key("mesh");
  key.add_matrix(S.cage().V).add_matrix(S.cage().F).add_matrix(mesh_V).add_matrix(S.subspace().basis);
  key.add_numerics();
  std::vector<char> payload;
  const Eigen::Index n = mesh_V.rows(), s = S.subspace().size(), block = 2048;
  if (cache.load(key, payload)) {
    try {
      CacheReader r(std::move(payload));
      r.matrix(Mv, n, s);
      r.matrix(Mg, 3 * n, s);
      if (r.at_end()) return {};
    } catch (const CacheReader::Bad&) {
    }
    std::error_code ec;
    std::filesystem::remove(cache.path(key), ec);  // malformed: rebuilt below
  }
  const HarmonicBasis& basis = S.normalized_basis();
  const MatXd& Xi = S.subspace().basis;
  const MatX3d V = S.frame().points_to_normalized(mesh_V);
  Mv.resize(n, s);
  Mg.resize(3 * n, s);
  MatXdR D, R;  // per block: 4 rows per vertex (value, ∂x, ∂y, ∂z) by #V+#F, then times Ξ
  for (Eigen::Index b = 0; b < n; b += block) {
    const Eigen::Index m = std::min(block, n - b);
    basis.evaluate_rows(V.middleRows(b, m), true, true, false, D);
    blas_product(D, Xi, R);
    for (Eigen::Index i = 0; i < m; ++i) {
      Mv.row(b + i) = R.row(4 * i);
      Mg.middleRows(3 * (b + i), 3) = R.middleRows(4 * i + 1, 3);
    }
    tick(static_cast<double>(b + m) / static_cast<double>(n));
  }
  if (!cache.enabled()) return {};
  // Copies: the session's matrices may be replaced while the entry is written.
  auto mats = std::make_shared<const std::pair<MatXd, MatXd>>(Mv, Mg);
  return std::async(std::launch::async,
                    [cache, key, mats] {
                      omp_set_num_threads(1);  // the engine goes on computing on all cores meanwhile
                      lower_calling_thread_priority();
                      CacheWriter w;
                      w.matrix(mats->first);
                      w.matrix(mats->second);
                      CacheEvent ev;
                      cache.store(key, w, &ev);
                      return describe(ev);
                    })
      .share();
}

}  // namespace

// The engine thread: take the posted commands and apply them, iterate while there is something to solve (a
// frame per iteration; new commands interrupt), then rest (extras brought up to date, a final frame).
void InteractiveSession::run() {
  Engine& E = *engine_;
  for (;;) {
    std::vector<Command> cmds;
    if (!E.take_commands(cmds)) return;
    E.apply_commands(cmds);
    if (E.want_iterate && E.solver && !E.iterate()) continue;
    E.rest();
  }
}

// --- Waiting for work.

bool InteractiveSession::Engine::take_commands(std::vector<Command>& cmds) {
  std::unique_lock<std::mutex> lk(session.mutex_);
  for (;;) {
    if (session.quit_) return false;
    if (!session.queue_.empty() || want_iterate) break;
    session.idle_ = true;
    session.rested_.notify_all();
    session.wake_.wait(lk);
  }
  cmds.swap(session.queue_);
  session.interrupt_.store(false);  // every interrupting command is in `cmds`
  session.cancel_.store(false);     // a cancel is of a preparation that ended (these commands come after it)
  session.posted_.store(false);
  session.idle_ = false;
  return true;
}

bool InteractiveSession::Engine::commands_queued(bool or_quit) const {
  std::lock_guard<std::mutex> lk(session.mutex_);
  return !session.queue_.empty() || (or_quit && session.quit_);
}

// --- Commands.

void InteractiveSession::Engine::apply_commands(const std::vector<Command>& cmds) {
  for (size_t k = 0; k < cmds.size(); ++k) {
    try {
      apply_command(cmds, k);
    } catch (const std::exception& e) {
      drop_command(e);
    }
  }
}

void InteractiveSession::Engine::apply_command(const std::vector<Command>& cmds, size_t k) {
  const Command& c = cmds[k];
  switch (c.kind) {
    case Command::kLoad:
      return apply_load(c);
    case Command::kHandles:
      return apply_handles(c);
    case Command::kTargets:
      return apply_targets(c, targets_superseded(cmds, k));
    case Command::kParams:
      return apply_params(c);
    case Command::kSolve:
      return apply_solve();
    case Command::kStop:
      return apply_stop();
    case Command::kReset:
      return apply_reset();
    case Command::kExtras:
      return apply_extras(c);
    case Command::kVerify:
      return apply_verify(c);
  }
}

// Only the newest target set of a burst matters (the drag path between steps is not solved).
bool InteractiveSession::Engine::targets_superseded(const std::vector<Command>& cmds, size_t k) {
  for (size_t j = k + 1; j < cmds.size(); ++j)
    if (cmds[j].kind == Command::kTargets || cmds[j].kind == Command::kHandles ||
        cmds[j].kind == Command::kLoad)
      return true;
  return false;
}

void InteractiveSession::Engine::apply_load(const Command& c) {
  want_iterate = false;
  build_solver(c.model, c.scenario.params, c.scenario.sources, c.scenario.targets);
  sources = c.scenario.sources;
  targets = c.scenario.targets;
  handles_to_solver();
  want_iterate = c.iterate && sources.rows() > 0;
  scenario = c.scenario;
  waypoints = c.scenario.waypoints;
  publish_state(SessionState::kResting, sources.rows() > 0 ? "loaded" : "loaded: no handles yet");
  if (c.initial.rows() > 0) {
    // The model is loaded whatever happens here: a map the solver refuses leaves it at the identity.
    try {
      solver->set_initial_map(c.initial, c.initial_from);
      ++map_version;
      waypoints.clear();
      publish_state(SessionState::kResting, "loaded the map of " + c.initial_from + " (not solved)");
    } catch (const std::exception& e) {
      publish_state(SessionState::kResting, std::string("error: ") + e.what());
      report_error(e.what());
    }
  }
}

void InteractiveSession::Engine::apply_handles(const Command& c) {
  if (solver && c.sources.rows() > 0) solver->set_handles(c.sources, c.targets, "handles");
  if (solver) solver->set_dragging(false);
  sources = c.sources;
  targets = c.targets;
  scenario.sources = c.sources;
  scenario.targets = c.targets;
  scenario.waypoints.clear();
  scenario.groups.clear();
  waypoints.clear();
  want_iterate = sources.rows() > 0;
}

void InteractiveSession::Engine::apply_targets(const Command& c, bool superseded) {
  if (superseded || !solver || c.targets.rows() != sources.rows()) return;
  solver->set_targets(c.targets, "targets");
  solver->set_dragging(true);  // until an explicit solve, new handles or a reset (drag_hessian_reuse)
  targets = c.targets;
  scenario.targets = c.targets;
  scenario.waypoints.clear();
  waypoints.clear();
  want_iterate = sources.rows() > 0;
}

void InteractiveSession::Engine::apply_params(const Command& c) {
  if (!solver) {
    params = c.params;
    return;
  }
  if (changes_precomputation(params, c.params)) {
    build_solver(model, c.params, sources, targets);
    handles_to_solver();
    // build_solver left the state at "preparing": a final state, or the progress would stay on screen.
    publish_state(SessionState::kResting, "parameters applied: solver rebuilt");
  } else {
    solver->set_params(c.params);
    params = c.params;
  }
  scenario.params = c.params;
  want_iterate = sources.rows() > 0;
}

void InteractiveSession::Engine::apply_solve() {
  if (solver) solver->set_dragging(false);  // an explicit solve converges with a fresh Hessian every step
  want_iterate = solver && sources.rows() > 0;
}

void InteractiveSession::Engine::apply_stop() {
  want_iterate = false;
  publish_state(SessionState::kResting, "stopped");
}

void InteractiveSession::Engine::apply_reset() {
  if (solver) {
    solver->set_dragging(false);
    solver->reset();
    ++map_version;
    publish_state(SessionState::kResting, "reset to the identity");
  }
  want_iterate = false;
}

void InteractiveSession::Engine::apply_extras(const Command& c) {
  extras = c.extras;
}

void InteractiveSession::Engine::apply_verify(const Command& c) {
  verify_samples = std::max(1, c.samples_per_voxel);
}

// The command is dropped; what was there before stays (build_solver commits only on success).
void InteractiveSession::Engine::drop_command(const std::exception& e) {
  want_iterate = false;
  {
    std::lock_guard<std::mutex> lk(session.mutex_);
    session.model_ = model;
    session.scenario_ = scenario;
  }
  if (dynamic_cast<const Cancelled*>(&e)) {  // the user's own request: no error dialog
    publish_state(solver ? SessionState::kResting : SessionState::kEmpty,
                  solver ? "preprocessing cancelled; the model before is kept" : "preprocessing cancelled");
    return;
  }
  publish_state(solver ? SessionState::kResting : SessionState::kFailed, std::string("error: ") + e.what());
  report_error(e.what());
}

// --- The solver.

// Prepares a solver for the model on this thread and commits it only when done: a failure or a cancel
// (cancel_preparation()) leaves the session as it was. Meanwhile preparing frames show the new model at rest
// with the stage and its progress.
void InteractiveSession::Engine::build_solver(const std::shared_ptr<const Model>& new_model,
                                              const DeformParams& new_params, const MatX3d& new_sources,
                                              const MatX3d& new_targets) {
  PrecomputeSetup setup;
  {
    std::lock_guard<std::mutex> lk(session.mutex_);
    setup.cache_dir = session.cache_dir_;
    setup.cache_max_bytes = session.cache_max_bytes_;
  }
  preparing = new_model;
  prep_sources = new_sources;
  prep_targets = new_targets;
  // The views adopt the new model now (at rest) and keep it when the solver is ready.
  ++model_version;
  publish_state(SessionState::kPreparing, "preprocessing " + new_model->dir);
  stage = "starting";
  progress = 0;
  publish_frame(make_preparing_frame());
  try {
    build_solver_stages(new_model, new_params, setup);
  } catch (...) {
    preparing.reset();
    progress = -1;
    stage.clear();
    ++model_version;  // back to the model before (or to none)
    throw;
  }
  preparing.reset();
  progress = -1;
  stage.clear();
}

void InteractiveSession::Engine::build_solver_stages(const std::shared_ptr<const Model>& new_model,
                                                     const DeformParams& new_params, PrecomputeSetup& setup) {
  if (new_params.threads > 0)
    omp_set_num_threads(new_params.threads);
  else
    omp_set_num_threads(omp_get_num_procs());
  std::string msg;
  auto new_backend = session.backends_(new_params, &msg);
  // The solver's stages take 90% of the bar, the mesh matrices the rest.
  setup.log = [&](const std::string& line) { status = "preprocessing: " + line; };
  setup.progress = [&](const std::string& name, double f) { on_progress(name, 0.9 * f); };
  setup.cancel = &session.cancel_;
  setup.mesh = &new_model->mesh;  // the certified domain (params.domain "mesh": its triangles and solid)
  // A computed entry is written while the mesh matrices are computed and the session rests (the solver's
  // destructor waits for it).
  setup.background_store = true;
  std::unique_ptr<DeformationSolver> built;
  try {
    built = std::make_unique<DeformationSolver>(new_model->cage, new_params, setup, new_backend);
  } catch (const Cancelled&) {
    throw;
  } catch (const Error&) {
    // "auto" chose a device that cannot hold this problem: the CPU takes it.
    if (new_params.backend != BackendKind::kAuto || new_backend->is_cpu()) throw;
    new_backend = cpu_backend();
    built = std::make_unique<DeformationSolver>(new_model->cage, new_params, setup, new_backend);
  }
  if (built->cache_store().valid()) {
    std::lock_guard<std::mutex> lk(session.mutex_);
    session.cache_stores_.push_back(built->cache_store());
  }
  MatXd v, g;
  const PrecomputeCache cache(setup.cache_dir, setup.cache_max_bytes);
  status = "preprocessing: mesh vertices in the subspace";
  auto mesh_store = reduced_mesh_matrices(
      *built, new_model->mesh.V, cache,
      [&](double f) { on_progress("mesh vertices in the subspace", 0.9 + 0.1 * f); }, v, g);
  if (mesh_store.valid()) {
    std::lock_guard<std::mutex> lk(session.mutex_);
    session.cache_stores_.push_back(mesh_store);
  }
  // Committed only now: a failure above leaves the previous session as it was.
  {
    std::lock_guard<std::mutex> lk(session.mutex_);
    session.solver_model_ = new_model;
  }
  solver = std::move(built);
  backend = new_backend;
  Mv = std::move(v);
  Mg = std::move(g);
  model = new_model;
  params = new_params;
  ++map_version;
  leaves.reset();
  field.reset();
  field_deformed.reset();
  verification.reset();
  leaves_version = field_version = verification_version = -1;
  global.reset();
  global_version = -1;
  if (session.stage_hook_) session.stage_hook_("ready");
}

void InteractiveSession::Engine::on_progress(const std::string& name, double fraction) {
  if (session.stage_hook_) session.stage_hook_(name);
  if (session.cancel_.load()) throw Cancelled();
  stage = name;
  progress = fraction;
  publish_frame(make_preparing_frame());
}

void InteractiveSession::Engine::handles_to_solver() {
  if (!solver) return;
  if (sources.rows() > 0) solver->set_handles(sources, targets, "handles");
}

bool InteractiveSession::Engine::iterate() {
  publish_state(SessionState::kIterating, "iterating");
  SolveResult res;
  try {
    // The same path to the targets as `lidef deform` (continuation.h): a large turn of the handles — a
    // loaded scenario's, or a jump of the targets — goes through rotation-aware stages; a small drag step is
    // one direct solve as before.
    const std::vector<MatX3d> path = std::move(waypoints);
    waypoints.clear();
    res = solve_to_targets(
        *solver, path, targets, scenario.groups, [this](const IterationRecord& r) { return on_iteration(r); },
        &session.interrupt_);
  } catch (const std::exception& e) {
    want_iterate = false;
    publish_state(SessionState::kResting, std::string("error: ") + e.what());
    report_error(e.what());
    return false;
  }
  if (res.reason == StopReason::kInterrupted) {
    // Pending commands (new targets) continue the drag; an explicit stop is among them.
    want_iterate = commands_queued(true);
    if (want_iterate) return false;
    publish_state(SessionState::kResting, "stopped");
  } else {
    want_iterate = false;
    publish_state(SessionState::kResting, std::string(to_string(res.reason)) + ": " + res.message);
  }
  return true;
}

// After each iteration: a frame of the solver's map; false (stop) when commands or the close are waiting.
bool InteractiveSession::Engine::on_iteration(const IterationRecord& r) {
  if (r.accepted) ++map_version;
  compute_extras(false);
  publish_frame(make_frame());
  return !commands_queued(true);
}

// --- Extras.

bool InteractiveSession::Engine::compute_extras(bool resting) {
  if (!solver) return false;
  const bool due = resting || seconds_since(last_extras) >= extras.extras_interval;
  bool did = false;
  // A verification is of the map the engine rests at (one requested mid-drag waits for the rest).
  const bool verify_now = verify_samples > 0 && resting;
  const bool need_leaves = (extras.leaves || verify_now) && leaves_version != map_version;
  if (need_leaves && (due || verify_now)) {
    if (verify_now) {  // the leaves of a large model take seconds too: say so before
      stage = "verifying: the certificate's leaves";
      progress = 0;
      publish_frame(make_frame());
      stage.clear();
      progress = -1;
    }
    compute_leaves();
    did = true;
  }
  if (extras.field && field_version != map_version && due) {
    compute_field();
    did = true;
  }
  if (verify_now && leaves && leaves_version == map_version) {
    compute_verification();
    did = true;
  }
  // Seconds per map: only at rest (a drag's intermediate maps are never checked), after the other extras.
  if (extras.global_injectivity && resting && global_version != map_version) did = compute_global() || did;
  if (did) last_extras = Clock::now();
  return did;
}

void InteractiveSession::Engine::compute_leaves() {
  leaves = std::make_shared<const Certificate>(solver->certify_current(true));
  leaves_version = map_version;
  if (!leaves_sampling || leaves_sampling_model != model_version) {  // copied once per solver
    leaves_sampling = std::make_shared<const VoxelSampling>(solver->sampling());
    leaves_sampling_model = model_version;
  }
  leaves_sampling_params = solver->sampling_params();
  leaves_certify_params = solver->certify_params(false, true);
}

// σ3 on a grid, and f at the grid points inside the cage (the deformed-space view); NaN elsewhere.
void InteractiveSession::Engine::compute_field() {
  const DeformationSolver& S = *solver;
  const MatX3d y = S.coefficients();
  auto grid = std::make_shared<FieldGrid>(
      compute_field_grid(model->cage, S.basis(), y, S.sampling(), extras.field_resolution));
  std::vector<long> inside;
  for (long i = 0; i < grid->points(); ++i)
    if (grid->inside_cage[static_cast<size_t>(i)]) inside.push_back(i);
  MatX3d P(static_cast<Eigen::Index>(inside.size()), 3);
  const long nx = grid->dims[0], ny = grid->dims[1];
  for (size_t k = 0; k < inside.size(); ++k) {
    const long i = inside[k];
    P.row(static_cast<Eigen::Index>(k)) =
        (grid->origin + grid->spacing * Vec3(i % nx, (i / nx) % ny, i / (nx * ny))).transpose();
  }
  const MatX3d FP = S.basis().map_values(y, P);
  auto def = std::make_shared<std::vector<float>>(3 * static_cast<size_t>(grid->points()),
                                                  std::numeric_limits<float>::quiet_NaN());
  for (size_t k = 0; k < inside.size(); ++k)
    for (int a = 0; a < 3; ++a)
      (*def)[3 * static_cast<size_t>(inside[k]) + a] =
          static_cast<float>(FP(static_cast<Eigen::Index>(k), a));
  field = grid;
  field_deformed = def;
  field_version = map_version;
}

// In chunks of leaves, so that a long verification (tens of seconds on a large model) publishes its progress
// and stops at a cancel (cancel_preparation()). Chunk k samples its leaves with seed k + 1 (the samples of a
// leaf depend on its chunk and its index there; the same for every run).
void InteractiveSession::Engine::compute_verification() {
  const std::vector<CertLeaf>& all = leaves->leaves;
  const long n = static_cast<long>(all.size()), chunk = std::max<long>(128, (n + 39) / 40);
  auto result = std::make_shared<VerificationResult>();
  result->min_sigma3 = std::numeric_limits<double>::infinity();
  const std::string saved_status = status;
  for (long b = 0, k = 0; b < n; b += chunk, ++k) {
    if (session.cancel_.load()) {
      verify_samples = 0;
      stage.clear();
      progress = -1;
      status = "verification cancelled";
      return;
    }
    stage = "verifying the certificate (dense sampling)";
    progress = static_cast<double>(b) / static_cast<double>(n);
    status = stage;
    if (b > 0) publish_frame(make_frame());
    const std::vector<CertLeaf> part(all.begin() + b, all.begin() + std::min(n, b + chunk));
    VerificationResult r = verify_certificate(solver->basis(), solver->coefficients(), part, verify_samples,
                                              static_cast<unsigned>(k + 1));
    result->points += r.points;
    if (!r.voxels.empty()) result->min_sigma3 = std::min(result->min_sigma3, r.min_sigma3);
    result->nonpositive_in_certified += r.nonpositive_in_certified;
    result->violations += r.violations;
    for (VoxelVerification& v : r.voxels) {
      v.leaf += b;
      result->voxels.push_back(v);
    }
    for (BoundViolation& v : r.violation_list)
      if (result->violation_list.size() < 100) {
        v.leaf += b;
        result->violation_list.push_back(v);
      }
  }
  stage.clear();
  progress = -1;
  status = saved_status;
  verification = std::move(result);
  verification_version = map_version;
  verify_samples = 0;
}

// The verdict of the current map. A certified map on the mesh's solid is checked with the model's checker;
// otherwise the verdict is not decided for the reason certificate_report.h states. While it runs, a resting
// frame says so (the view shows "checking" for this map rather than the verdict of an earlier one).
bool InteractiveSession::Engine::compute_global() {
  const Certificate& cert = solver->certificate();
  const std::string why = global_injectivity_undecidable(cert, solver->sampling().domain, model->mesh);
  GlobalInjectivity g;
  if (!why.empty()) {
    g = global_injectivity_not_decided(why);
  } else {
    publish_frame(make_frame());
    // A drag that goes on posts its next targets within a few frames: the check starts only after a pause,
    // so that a drag does not pay for the uncancellable start of checks it would cancel at once.
    {
      std::unique_lock<std::mutex> lk(session.mutex_);
      if (session.wake_.wait_for(lk, std::chrono::duration<double>(kGlobalCheckPause),
                                 [this] { return !session.queue_.empty() || session.quit_; }))
        return false;
    }
    if (!checker || checker_model != model_version || checker_cache_mb != params.global_cache_mb) {
      checker.reset();  // the old model's checker is freed before the new one is built
      checker = std::make_unique<GlobalInjectivityChecker>(model->cage, model->mesh, params.global_cache_mb);
      checker_model = model_version;
      checker_cache_mb = params.global_cache_mb;
    }
    GlobalInjectivityParams gp;
    gp.cancel = &session.posted_;
    g = checker->check(solver->coefficients(), gp);
    // Stopped early by a command (the map is about to change): no verdict; the next rest checks again.
    if (session.posted_.load() && g.verdict == GlobalInjectivity::Verdict::kNotDecided &&
        g.reason == "cancelled")
      return false;
  }
  global = std::make_shared<const GlobalInjectivity>(std::move(g));
  global_version = map_version;
  return true;
}

// --- What the other threads see.

void InteractiveSession::Engine::rest() {
  if (commands_queued(false)) return;  // more work first; extras when the engine rests
  // Whatever command ended a preparation, the engine rests now: never leave "preparing" as the last word.
  if (state == SessionState::kPreparing)
    publish_state(solver ? SessionState::kResting : SessionState::kEmpty, status);
  if (solver && state != SessionState::kIterating) {
    try {
      compute_extras(true);
    } catch (const std::exception& e) {
      report_error(e.what());
    }
  }
  publish_frame(make_frame());
}

// A frame of the solver's current map.
std::shared_ptr<SessionFrame> InteractiveSession::Engine::make_frame() {
  const auto t0 = Clock::now();
  auto f = std::make_shared<SessionFrame>();
  f->serial = ++serial;
  f->map_version = map_version;
  f->model_version = model_version;
  f->state = state;
  f->status = status;
  f->model = model;
  f->sources = sources;
  f->targets = targets;
  f->leaves = leaves;
  f->leaves_version = leaves_version;
  f->leaves_sampling = leaves_sampling;
  f->leaves_sampling_params = leaves_sampling_params;
  f->leaves_certify_params = leaves_certify_params;
  f->field = field;
  f->field_deformed = field_deformed;
  f->field_version = field_version;
  f->verification = verification;
  f->verification_version = verification_version;
  f->global = global;
  f->global_version = global_version;
  f->stage = stage;  // a verification in progress (preparing frames are make_preparing_frame's)
  f->progress = progress;
  if (solver) {
    const DeformationSolver& S = *solver;
    f->history = S.history();
    const Certificate& c = S.certificate();
    f->certified = c.certified;
    f->min_lower_bound = c.min_lower_bound;
    f->min_sigma3 = c.min_sigma3_center;
    f->not_certified_reason = c.reason;
    const auto& yr = S.reduced_coefficients();
    f->coefficients = S.coefficients();
    f->cage_V = f->coefficients.topRows(model->cage.num_vertices());
    // OpenBLAS, not Eigen: the two products stream the mesh matrices (94 MB for the bar at the defaults) once
    // per frame on the engine's thread, between Newton steps.
    const MatXd y = yr;
    MatXd v, g;
    blas_product(Mv, y, v);
    blas_product(Mg, y, g);
    MatX3d mesh_V = S.frame().points_from_normalized(v);
    MeshFieldOptions options;
    options.sigma3 = extras.mesh_distortion;
    MeshFields m = mesh_fields(std::move(mesh_V), g, options);
    f->mesh_V = std::move(m.V);
    f->mesh_e_iso = std::move(m.e_iso);
    f->mesh_det = std::move(m.det_j);
    f->mesh_distortion = std::move(m.distortion);
    if (sources.rows() > 0) {
      // The solver recorded the energy of its last iteration; recomputing it (a pass over all samples, or a
      // device round trip) per frame would repeat that work.
      f->energy = S.history().empty() ? S.energy() : S.history().back().terms;
      f->images = S.handle_positions();
      const VecXd err = S.handle_errors();
      f->max_handle_error = err.size() ? err.maxCoeff() : 0.0;
    } else {
      f->images.resize(0, 3);
    }
  }
  f->ms_frame = 1000 * seconds_since(t0);
  return f;
}

// A frame of the model being prepared, at rest: the identity map (E_iso − 6 = 0, det J = 1), not yet
// certified.
std::shared_ptr<SessionFrame> InteractiveSession::Engine::make_preparing_frame() {
  auto f = std::make_shared<SessionFrame>();
  f->serial = ++serial;
  f->map_version = map_version;
  f->model_version = model_version;
  f->state = SessionState::kPreparing;
  f->status = status;
  f->stage = stage;
  f->progress = progress;
  f->model = preparing;
  f->not_certified_reason = "preprocessing";
  f->sources = prep_sources;
  f->targets = prep_targets;
  f->images = prep_sources;
  const Model& m = *preparing;
  f->mesh_V = m.mesh.V;
  f->mesh_e_iso = VecXd::Zero(m.mesh.V.rows());
  f->mesh_det = VecXd::Ones(m.mesh.V.rows());
  if (extras.mesh_distortion) f->mesh_distortion = VecXd::Ones(m.mesh.V.rows());
  f->cage_V = m.cage.V;
  f->coefficients = m.cage.identity_coefficients();
  return f;
}

void InteractiveSession::Engine::publish_frame(std::shared_ptr<const SessionFrame> f) {
  {
    std::lock_guard<std::mutex> lk(session.mutex_);
    session.latest_ = f;
  }
  if (session.on_frame_) session.on_frame_(f);
}

void InteractiveSession::Engine::publish_state(SessionState st, const std::string& text) {
  state = st;
  status = text;
  std::lock_guard<std::mutex> lk(session.mutex_);
  session.state_ = st;
}

void InteractiveSession::Engine::report_error(const std::string& what) {
  if (session.on_error_) session.on_error_(what);
}

}  // namespace lidef
