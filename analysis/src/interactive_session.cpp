#include "lidef/interactive_session.h"

#include <omp.h>

#include <chrono>
#include <cmath>
#include <limits>

#include "lidef/errors.h"
#include "lidef/signed_svd.h"
#include "lidef/symmetric_dirichlet.h"

namespace lidef {

const char* to_string(SessionState s) {
  switch (s) {
    case SessionState::kEmpty:
      return "empty";
    case SessionState::kPreparing:
      return "preparing";
    case SessionState::kIterating:
      return "iterating";
    case SessionState::kResting:
      return "resting";
    case SessionState::kFailed:
      return "failed";
  }
  return "?";
}

namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace

struct InteractiveSession::Command {
  enum Kind { kLoad, kHandles, kTargets, kParams, kSolve, kStop, kReset, kExtras, kVerify } kind;
  explicit Command(Kind k) : kind(k) {}
  std::shared_ptr<const Model> model;
  Scenario scenario;  // kLoad
  bool iterate = false;
  MatX3d sources, targets;
  DeformParams params;
  ExtrasRequest extras;
  int samples_per_voxel = 32;
};

// State owned by the engine thread.
struct InteractiveSession::Engine {
  std::shared_ptr<const Model> model;
  DeformParams params;
  MatX3d sources, targets;
  std::shared_ptr<const ComputeBackend> backend;
  std::unique_ptr<DeformationSolver> solver;
  // Mesh vertices in the reduced space: f(V) = Mv ỹ (#Vm by s), Jᵀ rows = Mg ỹ (3#Vm by s).
  MatXd Mv, Mg;
  bool want_iterate = false;
  std::string status;
  SessionState state = SessionState::kEmpty;
  ExtrasRequest extras;
  long serial = 0, map_version = 0, model_version = 0;
  std::shared_ptr<const Certificate> leaves;
  long leaves_version = -1;
  std::shared_ptr<const FieldGrid> field;
  std::shared_ptr<const std::vector<float>> field_deformed;
  long field_version = -1;
  std::shared_ptr<const VerificationResult> verification;
  long verification_version = -1;
  Clock::time_point last_extras = Clock::now() - std::chrono::hours(1);
  int verify_samples = 0;  // > 0: a verification is pending
  Scenario scenario;       // what the engine runs (restored into scenario_ when a command fails)
};

InteractiveSession::InteractiveSession(FrameCallback on_frame, ErrorCallback on_error,
                                       BackendFactory backends)
    : on_frame_(std::move(on_frame)),
      on_error_(std::move(on_error)),
      backends_(std::move(backends)),
      engine_(std::make_unique<Engine>()) {
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
    queue_.push_back(std::move(c));
    idle_ = false;
  }
  wake_.notify_all();
}

void InteractiveSession::open_scenario(const std::string& path, const std::string& models_dir) {
  Scenario sc = read_scenario(path, models_dir);
  auto model = std::make_shared<const Model>(load_model(sc.model_dir));
  for (Eigen::Index i = 0; i < sc.sources.rows(); ++i) {
    const std::string why = handle_source_problem(model->cage, sc.sources.row(i).transpose());
    if (!why.empty()) throw InputError(path, "handle " + std::to_string(i + 1) + ": source " + why);
  }
  load(model, sc, true);
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

void InteractiveSession::load(std::shared_ptr<const Model> model, const Scenario& sc, bool iterate) {
  Command c(Command::kLoad);
  c.model = model;
  c.scenario = sc;
  c.iterate = iterate;
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

// ---------------------------------------------------------------------------------------------- engine
// thread

namespace {

// Mesh vertices in the reduced space, in blocks so that the full-space matrices (#Vm by #Vc+#Fc) never
// exist at once (the animal's would take 1.4 GB).
void reduced_mesh_matrices(const HarmonicBasis& basis, const MatXd& Xi, const MatX3d& V, MatXd& Mv,
                           MatXd& Mg) {
  const Eigen::Index n = V.rows(), s = Xi.cols(), block = 2048;
  Mv.resize(n, s);
  Mg.resize(3 * n, s);
  for (Eigen::Index b = 0; b < n; b += block) {
    const Eigen::Index m = std::min(block, n - b);
    const MatX3d P = V.middleRows(b, m);
    Mv.middleRows(b, m).noalias() = basis.value_matrix(P) * Xi;
    Mg.middleRows(3 * b, 3 * m).noalias() = basis.gradient_matrix(P) * Xi;
  }
}

}  // namespace

void InteractiveSession::run() {
  Engine& E = *engine_;
  auto publish_state = [&](SessionState st, const std::string& status) {
    E.state = st;
    E.status = status;
    std::lock_guard<std::mutex> lk(mutex_);
    state_ = st;
  };
  auto fail = [&](const std::string& what) {
    if (on_error_) on_error_(what);
  };
  // A frame of the solver's current map.
  auto make_frame = [&]() {
    const auto t0 = Clock::now();
    auto f = std::make_shared<SessionFrame>();
    f->serial = ++E.serial;
    f->map_version = E.map_version;
    f->model_version = E.model_version;
    f->state = E.state;
    f->status = E.status;
    f->model = E.model;
    f->sources = E.sources;
    f->targets = E.targets;
    f->leaves = E.leaves;
    f->leaves_version = E.leaves_version;
    f->field = E.field;
    f->field_deformed = E.field_deformed;
    f->field_version = E.field_version;
    f->verification = E.verification;
    f->verification_version = E.verification_version;
    if (E.solver) {
      const DeformationSolver& S = *E.solver;
      f->history = S.history();
      const Certificate& c = S.certificate();
      f->certified = c.certified;
      f->min_lower_bound = c.min_lower_bound;
      f->min_sigma3 = c.min_sigma3_center;
      f->not_certified_reason = c.reason;
      const auto& yr = S.reduced_coefficients();
      f->coefficients = S.coefficients();
      f->cage_V = f->coefficients.topRows(E.model->cage.num_vertices());
      f->mesh_V = E.Mv * yr;
      const MatXd JT = E.Mg * yr;
      const Eigen::Index n = f->mesh_V.rows();
      f->mesh_e_iso.resize(n);
      f->mesh_det.resize(n);
#pragma omp parallel for schedule(static)
      for (Eigen::Index i = 0; i < n; ++i) {
        const Mat3 J = JT.middleRows(3 * i, 3).transpose();
        const double e = sd_energy(J);
        f->mesh_e_iso(i) = std::isfinite(e) ? e - 6.0 : std::numeric_limits<double>::quiet_NaN();
        f->mesh_det(i) = J.determinant();
      }
      if (E.sources.rows() > 0) {
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
  };
  auto publish = [&](std::shared_ptr<const SessionFrame> f) {
    {
      std::lock_guard<std::mutex> lk(mutex_);
      latest_ = f;
    }
    if (on_frame_) on_frame_(f);
  };
  // Extras for the current map, when requested and due. Returns true when something was computed.
  auto update_extras = [&](bool resting) {
    if (!E.solver) return false;
    const bool due = resting || seconds_since(E.last_extras) >= E.extras.extras_interval;
    bool did = false;
    const DeformationSolver& S = *E.solver;
    // A verification is of the map the engine rests at (one requested mid-drag waits for the rest).
    const bool verify_now = E.verify_samples > 0 && resting;
    const bool need_leaves = (E.extras.leaves || verify_now) && E.leaves_version != E.map_version;
    if (need_leaves && (due || verify_now)) {
      E.leaves = std::make_shared<const Certificate>(S.certify_current(true));
      E.leaves_version = E.map_version;
      did = true;
    }
    if (E.extras.field && E.field_version != E.map_version && due) {
      const MatX3d y = S.coefficients();
      auto grid = std::make_shared<FieldGrid>(
          compute_field_grid(E.model->cage, S.basis(), y, S.sampling(), E.extras.field_resolution));
      // f at the grid points inside the cage (the deformed-space view); NaN elsewhere.
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
      E.field = grid;
      E.field_deformed = def;
      E.field_version = E.map_version;
      did = true;
    }
    if (verify_now && E.leaves && E.leaves_version == E.map_version) {
      E.verification = std::make_shared<const VerificationResult>(
          verify_certificate(S.basis(), S.coefficients(), E.leaves->leaves, E.verify_samples));
      E.verification_version = E.map_version;
      E.verify_samples = 0;
      did = true;
    }
    if (did) E.last_extras = Clock::now();
    return did;
  };
  auto build_solver = [&](const std::shared_ptr<const Model>& model, const DeformParams& params) {
    publish_state(SessionState::kPreparing, "preprocessing " + model->dir);
    publish(make_frame());
    if (params.threads > 0)
      omp_set_num_threads(params.threads);
    else
      omp_set_num_threads(omp_get_num_procs());
    std::string msg;
    auto backend = backends_(params, &msg);
    auto log = [&](const std::string& line) {
      E.status = "preprocessing: " + line;
      publish(make_frame());
    };
    std::unique_ptr<DeformationSolver> solver;
    try {
      solver = std::make_unique<DeformationSolver>(model->cage, params, default_cache_dir(), log, backend);
    } catch (const Error&) {
      // "auto" chose a device that cannot hold this problem: the CPU takes it.
      if (params.backend != BackendKind::kAuto || backend->is_cpu()) throw;
      backend = cpu_backend();
      solver = std::make_unique<DeformationSolver>(model->cage, params, default_cache_dir(), log, backend);
    }
    MatXd Mv, Mg;
    E.status = "preprocessing: mesh vertices in the subspace";
    reduced_mesh_matrices(solver->basis(), solver->subspace().basis, model->mesh.V, Mv, Mg);
    // Committed only now: a failure above leaves the previous session as it was.
    E.solver = std::move(solver);
    E.backend = backend;
    E.Mv = std::move(Mv);
    E.Mg = std::move(Mg);
    E.model = model;
    E.params = params;
    ++E.model_version;
    ++E.map_version;
    E.leaves.reset();
    E.field.reset();
    E.field_deformed.reset();
    E.verification.reset();
    E.leaves_version = E.field_version = E.verification_version = -1;
  };
  auto apply_handles = [&]() {
    if (!E.solver) return;
    if (E.sources.rows() > 0) E.solver->set_handles(E.sources, E.targets, "handles");
  };
  auto apply_handles_checked = [&](const MatX3d& sources, const MatX3d& targets) {
    if (E.solver && sources.rows() > 0) E.solver->set_handles(sources, targets, "handles");
    E.sources = sources;
    E.targets = targets;
    E.scenario.sources = sources;
    E.scenario.targets = targets;
  };

  for (;;) {
    std::vector<Command> cmds;
    {
      std::unique_lock<std::mutex> lk(mutex_);
      for (;;) {
        if (quit_) return;
        if (!queue_.empty() || E.want_iterate) break;
        idle_ = true;
        rested_.notify_all();
        wake_.wait(lk);
      }
      cmds.swap(queue_);
      interrupt_.store(false);  // every interrupting command is in `cmds`
      idle_ = false;
    }
    for (size_t k = 0; k < cmds.size(); ++k) {
      Command& c = cmds[k];
      try {
        switch (c.kind) {
          case Command::kLoad: {
            E.want_iterate = false;
            build_solver(c.model, c.scenario.params);
            E.sources = c.scenario.sources;
            E.targets = c.scenario.targets;
            apply_handles();
            E.want_iterate = c.iterate && E.sources.rows() > 0;
            E.scenario = c.scenario;
            publish_state(SessionState::kResting, E.sources.rows() > 0 ? "loaded" : "loaded: no handles yet");
            break;
          }
          case Command::kHandles:
            apply_handles_checked(c.sources, c.targets);
            E.want_iterate = E.sources.rows() > 0;
            break;
          case Command::kTargets: {
            // Only the newest target set of a burst matters (the drag path between steps is not solved).
            bool later = false;
            for (size_t j = k + 1; j < cmds.size(); ++j)
              if (cmds[j].kind == Command::kTargets || cmds[j].kind == Command::kHandles ||
                  cmds[j].kind == Command::kLoad)
                later = true;
            if (later || !E.solver || c.targets.rows() != E.sources.rows()) break;
            E.solver->set_targets(c.targets, "targets");
            E.targets = c.targets;
            E.scenario.targets = c.targets;
            E.want_iterate = E.sources.rows() > 0;
            break;
          }
          case Command::kParams:
            if (!E.solver) {
              E.params = c.params;
              break;
            }
            if (changes_precomputation(E.params, c.params)) {
              build_solver(E.model, c.params);
              apply_handles();
            } else {
              E.solver->set_params(c.params);
              E.params = c.params;
            }
            E.scenario.params = c.params;
            E.want_iterate = E.sources.rows() > 0;
            break;
          case Command::kSolve:
            E.want_iterate = E.solver && E.sources.rows() > 0;
            break;
          case Command::kStop:
            E.want_iterate = false;
            publish_state(SessionState::kResting, "stopped");
            break;
          case Command::kReset:
            if (E.solver) {
              E.solver->reset();
              ++E.map_version;
              publish_state(SessionState::kResting, "reset to the identity");
            }
            E.want_iterate = false;
            break;
          case Command::kExtras:
            E.extras = c.extras;
            break;
          case Command::kVerify:
            E.verify_samples = std::max(1, c.samples_per_voxel);
            break;
        }
      } catch (const std::exception& e) {
        // The command is dropped; what was there before stays (build_solver commits only on success).
        E.want_iterate = false;
        {
          std::lock_guard<std::mutex> lk(mutex_);
          model_ = E.model;
          scenario_ = E.scenario;
        }
        publish_state(E.solver ? SessionState::kResting : SessionState::kFailed,
                      std::string("error: ") + e.what());
        fail(e.what());
      }
    }

    if (E.want_iterate && E.solver) {
      publish_state(SessionState::kIterating, "iterating");
      bool commands_pending = false;
      SolveResult res;
      try {
        res = E.solver->solve(
            [&](const IterationRecord& r) {
              if (r.accepted) ++E.map_version;
              update_extras(false);
              publish(make_frame());
              std::lock_guard<std::mutex> lk(mutex_);
              commands_pending = !queue_.empty() || quit_;
              return !commands_pending;
            },
            &interrupt_);
      } catch (const std::exception& e) {
        E.want_iterate = false;
        publish_state(SessionState::kResting, std::string("error: ") + e.what());
        fail(e.what());
        continue;
      }
      if (res.reason == StopReason::kInterrupted) {
        // Pending commands (new targets) continue the drag; an explicit stop is among them.
        E.want_iterate = true;
        {
          std::lock_guard<std::mutex> lk(mutex_);
          if (queue_.empty() && !quit_) E.want_iterate = false;
        }
        if (E.want_iterate) continue;
        publish_state(SessionState::kResting, "stopped");
      } else {
        E.want_iterate = false;
        publish_state(SessionState::kResting, std::string(to_string(res.reason)) + ": " + res.message);
      }
    }
    // Resting: bring the requested extras up to date and show the final state.
    {
      std::lock_guard<std::mutex> lk(mutex_);
      if (!queue_.empty()) continue;  // more work first; extras when the engine rests
    }
    if (E.solver && E.state != SessionState::kIterating) {
      try {
        update_extras(true);
      } catch (const std::exception& e) {
        fail(e.what());
      }
    }
    publish(make_frame());
  }
}

}  // namespace lidef
