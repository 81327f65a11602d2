// lidef-studio while dragging: a scripted drag of the pushed end of the shared `bar`
// (bar_bend) in the real window, one Newton step + certificate per view update. Reports view updates per
// second (frames rendered that show a new certified map), Newton steps per second, and the time of each part;
// the same drag on the engine alone (no window) shows whether rendering slows the solver.
//
// `--configs global` (`global-quick`: the interactive preset only) instead times drag *steps* with pauses
// (move the targets, wait until the window shows the resting map and, with the check on, its global
// injectivity verdict), with the global check off and on;
// `--global on|off` sets the check for the drag rows (the check runs only when the engine rests).
//
// Usage: bench_studio [DATA_DIR] [--seconds S]
// [--configs all|quick|default|lipschitz|subset|refinement|global|global-quick] [--global on|off] [--steps N]
// [--scenario NAME] (--help). Needs an X display; without DISPLAY it re-runs itself under xvfb-run.
#include <QVTKOpenGLNativeWidget.h>
#include <omp.h>
#include <unistd.h>

#include <QApplication>
#include <QSurfaceFormat>
#include <QTimer>
#include <chrono>
#include <clocale>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "drag_path.h"
#include "lidef/internal/stopwatch.h"
#include "omp_wait.h"
#include "studio_window.h"

using namespace lidef;
using namespace lidef::studio;

namespace {

void pump(double seconds) {
  const auto t0 = Clock::now();
  while (seconds_since(t0) < seconds) {
    QApplication::processEvents(QEventLoop::AllEvents, 10);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

bool settle(InteractiveSession& s, StudioWindow* w, double seconds) {
  const auto t0 = Clock::now();
  while (seconds_since(t0) < seconds) {
    if (w) QApplication::processEvents(QEventLoop::AllEvents, 10);
    if (s.wait_until_resting(0.01)) {
      if (!w) return true;
      const auto f = s.latest_frame();
      const auto shown = w->shown_frame();
      if (f && shown && f->serial == shown->serial) return true;
    }
  }
  return false;
}

struct Config {
  const char* name;
  int dof, samples;
  View view;
  int hessian_reuse = -1;        // DeformParams::drag_hessian_reuse; -1: the table's default
  double hessian_fraction = -1;  // DeformParams::hessian_fraction; < 0: the table's default
  int cg_steps = -1;             // DeformParams::newton_cg_steps; -1: the table's default
  int refinement = -1;           // DeformParams::refinement (RefinementEval); -1: the table's default
};

struct Result {
  double seconds = 0;
  long frames = 0, new_maps = 0, steps = 0, accepted = 0;
  double ms_step = 0, ms_certificate = 0, ms_frame = 0, ms_render = 0;
  double ms_gradient = 0, ms_hessian = 0, ms_solve = 0, ms_line_search = 0, refined = 0, trials = 0,
         reused = 0;
  bool all_certified = true;
  double final_error = 0;
};

Result drag(InteractiveSession& s, StudioWindow* w, double seconds) {
  Result r;
  const Scenario sc = s.scenario();
  const auto m = s.model();
  const double amp = 0.05 * (m->cage.bbox_max - m->cage.bbox_min).norm();
  const auto f0 = s.latest_frame();
  const size_t it0 = f0->history.size();
  long last_version = f0->map_version;
  long frames0 = w ? w->rendered_frames() : 0;
  std::vector<double> render_ms;
  QMetaObject::Connection conn;
  if (w)
    conn = QObject::connect(w, &StudioWindow::frame_shown, [&] {
      const auto f = w->shown_frame();
      render_ms.push_back(w->last_render_ms());
      if (f->map_version != last_version) {
        last_version = f->map_version;
        ++r.new_maps;
      }
      if (f->mesh_V.rows() > 0 && !f->certified) r.all_certified = false;
    });
  const auto t0 = Clock::now();
  long engine_maps = 0;
  while (seconds_since(t0) < seconds) {
    s.set_targets(bench::drag_targets(sc.sources, sc.targets, seconds_since(t0), amp));
    const auto tick = Clock::now();
    while (seconds_since(tick) < 0.016) {  // ~60 Hz mouse events
      if (w)
        QApplication::processEvents(QEventLoop::AllEvents, 5);
      else
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    if (!w) {
      const auto f = s.latest_frame();
      if (f->map_version != last_version) {
        last_version = f->map_version;
        ++engine_maps;
      }
    }
  }
  r.seconds = seconds_since(t0);
  const auto f = s.latest_frame();
  if (w) {
    QObject::disconnect(conn);
    r.frames = w->rendered_frames() - frames0;
  } else {
    r.new_maps = engine_maps;  // maps the engine published (the consumer polled them at 60 Hz)
  }
  for (size_t i = it0; i < f->history.size(); ++i) {
    const IterationRecord& rec = f->history[i];
    ++r.steps;
    r.accepted += rec.accepted;
    r.ms_step += rec.ms_total;
    r.ms_certificate += rec.ms_certificate;
    r.ms_gradient += rec.ms_gradient;
    r.ms_hessian += rec.ms_hessian;
    r.ms_solve += rec.ms_solve;
    r.ms_line_search += rec.ms_line_search;
    r.refined += static_cast<double>(rec.refined);
    r.trials += 1 + rec.armijo_rejections + rec.certificate_rejections;
    r.reused += rec.hessian_reused;
  }
  if (r.steps) {
    for (double* x : {&r.ms_step, &r.ms_certificate, &r.ms_gradient, &r.ms_hessian, &r.ms_solve,
                      &r.ms_line_search, &r.refined, &r.trials, &r.reused})
      *x /= static_cast<double>(r.steps);
  }
  r.ms_frame = f->ms_frame;
  for (double x : render_ms) r.ms_render += x / render_ms.size();
  r.final_error = f->max_handle_error;
  return r;
}

// The studio's window at 1280x800 with `scenario` open under parameters `p` and view settings `vs`, resting;
// null (after a message) when the scenario does not open or settle within 600 s.
std::unique_ptr<StudioWindow> open_window(const std::string& scenario, const DeformParams& p,
                                          const ViewSettings& vs) {
  auto win = std::make_unique<StudioWindow>();
  win->set_error_sink([](const std::string& e) { std::fprintf(stderr, "bench_studio: %s\n", e.c_str()); });
  win->resize(1280, 800);
  win->show();
  pump(0.3);
  if (!win->open_path(scenario)) return nullptr;
  win->set_params(p);
  win->set_settings(vs);
  if (!settle(win->session(), win.get(), 600)) {
    std::fprintf(stderr, "bench_studio: %s did not settle\n", scenario.c_str());
    return nullptr;
  }
  return win;
}

// Drag steps with pauses: each moves the pushed targets 1/steps of the circle on and waits until the window
// shows the resting map (with the check on: and its global verdict). Times per step (wall, from the target
// change to the shown rest) and per check.
struct StepResult {
  double ms_step = 0, ms_check = 0, ms_check_max = 0;
  long checks = 0, injective = 0, overlap = 0, not_decided = 0;
  bool ok = true;
};

StepResult drag_steps(StudioWindow& w, int steps) {
  InteractiveSession& s = w.session();
  const Scenario sc = s.scenario();
  const auto m = s.model();
  const double amp = 0.05 * (m->cage.bbox_max - m->cage.bbox_min).norm();
  const bool global = w.settings().global_injectivity;
  StepResult r;
  for (int k = 1; k <= steps; ++k) {
    const auto t0 = Clock::now();
    s.set_targets(bench::drag_targets(sc.sources, sc.targets, 4.0 * k / steps, amp));
    bool done = false;
    while (!done && seconds_since(t0) < 600) {
      QApplication::processEvents(QEventLoop::AllEvents, 5);
      if (!s.wait_until_resting(0.0)) continue;
      const auto f = s.latest_frame();
      const auto shown = w.shown_frame();
      done = f && shown && f->serial == shown->serial && (!global || f->global_version == f->map_version);
    }
    r.ok = r.ok && done;
    r.ms_step += 1000 * seconds_since(t0) / steps;
    const auto f = w.shown_frame();
    if (global && f->global && f->global_version == f->map_version) {
      ++r.checks;
      r.ms_check += f->global->ms;
      r.ms_check_max = std::max(r.ms_check_max, f->global->ms);
      r.injective += f->global->verdict == GlobalInjectivity::Verdict::kInjective;
      r.overlap += f->global->verdict == GlobalInjectivity::Verdict::kOverlap;
      r.not_decided += f->global->verdict == GlobalInjectivity::Verdict::kNotDecided;
    }
  }
  if (r.checks) r.ms_check /= static_cast<double>(r.checks);
  return r;
}

int global_steps(const std::string& scenario, int steps, bool preset_only) {
  std::printf(
      "Machine: %s, %d threads (OpenMP). %s in the window (1280x800), mesh view; %d drag steps of the\n"
      "pushed end along the circle of the drag rows (radius 5%% of the bounding-box diagonal), each waited "
      "until\n"
      "the window shows the resting map (and, with the check, its verdict).\n\n",
      lidef::bench::cpu_model().c_str(), omp_get_max_threads(),
      std::filesystem::path(scenario).stem().string().c_str(), steps);
  std::printf(
      "| parameters | global check | ms per step (to the shown rest) | ms per check (mean / max) | verdicts "
      "(injective / overlap / not decided) |\n|---|---|---:|---:|---|\n");
  const std::pair<const char*, std::pair<int, int>> params[] = {
      {"interactive preset (100 DOF/coord, 10k voxels)", {100, 10000}},
      {"default (300 DOF/coord, 30k voxels)", {300, 30000}}};
  for (const auto& [name, dims] : params)
    for (const bool global : {false, true}) {
      if (preset_only && dims.first != 100) continue;
      DeformParams p;
      p.reduced_dof = dims.first;
      p.samples = dims.second;
      ViewSettings vs;
      vs.global_injectivity = global;
      const auto win = open_window(scenario, p, vs);
      if (!win) return 1;
      const StepResult r = drag_steps(*win, steps);
      if (!r.ok) std::fprintf(stderr, "bench_studio: a step did not settle\n");
      if (global)
        std::printf("| %s | on | %.0f | %.0f / %.0f | %ld / %ld / %ld |\n", name, r.ms_step, r.ms_check,
                    r.ms_check_max, r.injective, r.overlap, r.not_decided);
      else
        std::printf("| %s | off | %.0f | – | – |\n", name, r.ms_step);
      std::fflush(stdout);
    }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string data = bench::default_data_dir(LIDEF_SHARED_DATA_DIR), which = "all", on_off;
  double seconds = 10;
  int steps = 8;
  std::string global_scenario = "bar_bend";  // --configs global: a shared scenario's name
  CLI::App cli{
      "bench_studio: lidef-studio while dragging bar_bend's pushed end (view updates per second, the time of "
      "each part, the engine alone), or with --configs global drag steps with pauses and the global "
      "injectivity check off and on; a markdown report on stdout. Needs an X display (else re-runs itself "
      "under xvfb-run)"};
  cli.option_defaults()->always_capture_default();
  cli.add_option("DATA_DIR", data, "shared data folder (default: $LIDEF_SHARED_DATA, else the build's)");
  cli.add_option("--seconds", seconds, "seconds of dragging per row")->check(CLI::PositiveNumber);
  cli.add_option("--configs", which, "rows to run")
      ->check(CLI::IsMember(
          {"all", "quick", "default", "lipschitz", "subset", "refinement", "global", "global-quick"}));
  cli.add_option("--global", on_off, "the global injectivity check in the drag rows (default: the studio's)")
      ->check(CLI::IsMember({"on", "off"}));
  cli.add_option("--steps", steps, "--configs global: drag steps")->check(CLI::PositiveNumber);
  cli.add_option("--scenario", global_scenario, "--configs global: a shared scenario's name");
  if (const int rc = bench::parse_command_line(cli, argc, argv); rc >= 0) return rc;
  const bool global = on_off.empty() ? ViewSettings{}.global_injectivity : on_off == "on";
  if (!std::getenv("DISPLAY")) {
    std::vector<char*> args = {const_cast<char*>("xvfb-run"), const_cast<char*>("-a"),
                               const_cast<char*>("-s"), const_cast<char*>("-screen 0 1280x800x24")};
    for (int i = 0; i < argc; ++i) args.push_back(argv[i]);
    args.push_back(nullptr);
    execvp("xvfb-run", args.data());
    std::perror("bench_studio: xvfb-run");
    return 2;
  }
  ensure_studio_environment(
      argv);  // as lidef-studio does (omp_wait.h); OMP_WAIT_POLICY=ACTIVE measures the default
  setenv("QT_QPA_PLATFORM", "xcb", 1);
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication app(argc, argv);
  std::setlocale(LC_NUMERIC, "C");  // as lidef-studio does (gui/src/main.cpp): printf keeps its '.'
  if (which == "global" || which == "global-quick")
    return global_steps(data + "/scenarios/" + global_scenario + ".json", steps, which == "global-quick");
  std::vector<Config> configs = {{"default (300 DOF/coord, 30k voxels)", 300, 30000, View::kMesh},
                                 {"200 DOF/coord, 20k voxels", 200, 20000, View::kMesh},
                                 {"interactive preset (100 DOF/coord, 10k voxels)", 100, 10000, View::kMesh},
                                 {"interactive preset, Lipschitz view", 100, 10000, View::kLipschitz}};
  if (which == "quick")
    configs = {configs[2]};
  else if (which == "default")  // the paper's parameters, with and without reusing the Hessian factor
    configs = {configs[0], {"default, drag_hessian_reuse 0", 300, 30000, View::kMesh, 0}};
  else if (which == "lipschitz")  // the two preset rows: mesh and Lipschitz view
    configs = {configs[2], configs[3]};
  else if (which == "subset")  // the defaults against a 3% Hessian subset, with one and two CG iterates
    configs = {configs[0],
               {"default, hessian_fraction 0.03", 300, 30000, View::kMesh, -1, 0.03},
               {"default, hessian_fraction 0.03, newton_cg_steps 2", 300, 30000, View::kMesh, -1, 0.03, 2}};
  else if (which == "refinement")  // the defaults (far-field refinement) against the batched refinement
    configs = {configs[0],
               {"default, refinement batched", 300, 30000, View::kMesh, -1, -1, -1,
                static_cast<int>(RefinementEval::kPerEdgeBatched)}};
  std::printf("OMP_WAIT_POLICY=%s. Global injectivity check %s. ", std::getenv("OMP_WAIT_POLICY"),
              global ? "on" : "off");
  std::printf(
      "Machine: %s, %d threads (OpenMP). Scripted drag of bar_bend's pushed end (circle of radius 5%% of\n"
      "the bounding-box diagonal, 4 s period, target updates at 60 Hz) for %.0f s per row after the\n"
      "scenario has converged; window 1280x800 (view 3D area ~900x700).\n\n",
      lidef::bench::cpu_model().c_str(), omp_get_max_threads(), seconds);
  std::printf(
      "| parameters | view | view updates/s (new certified map shown) | frames rendered/s | Newton steps/s "
      "| accepted | ms per step | of which certificate | ms frame geometry | ms render | steps/s engine "
      "alone | every shown map certified | handle error at end |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|\n");
  const std::string scenario = data + "/scenarios/bar_bend.json";
  struct Split {
    const char* name;
    Result window, alone;
  };
  std::vector<Split> splits;
  for (const Config& c : configs) {
    DeformParams p;
    p.reduced_dof = c.dof;
    p.samples = c.samples;
    if (c.hessian_reuse >= 0) p.drag_hessian_reuse = c.hessian_reuse;
    if (c.hessian_fraction > 0) p.hessian_fraction = c.hessian_fraction;
    if (c.cg_steps >= 0) p.newton_cg_steps = c.cg_steps;
    if (c.refinement >= 0) p.refinement = static_cast<RefinementEval>(c.refinement);
    Result with_window, alone;
    {
      ViewSettings vs;
      vs.view = c.view;
      vs.global_injectivity = global;
      const auto win = open_window(scenario, p, vs);
      if (!win) return 1;
      with_window = drag(win->session(), win.get(), seconds);
    }
    {
      InteractiveSession s({}, {});
      s.open_scenario(scenario);
      s.set_params(p);
      ExtrasRequest ex;
      ex.leaves = c.view == View::kLipschitz;
      ex.global_injectivity = global;
      s.set_extras(ex);
      if (!settle(s, nullptr, 600)) return 1;
      alone = drag(s, nullptr, seconds);
    }
    const Result& r = with_window;
    std::printf("| %s | %s | %.1f | %.1f | %.1f | %ld/%ld | %.0f | %.0f | %.1f | %.1f | %.1f | %s | %.3g |\n",
                c.name, to_string(c.view), r.new_maps / r.seconds, r.frames / r.seconds, r.steps / r.seconds,
                r.accepted, r.steps, r.ms_step, r.ms_certificate, r.ms_frame, r.ms_render,
                alone.steps / alone.seconds, r.all_certified ? "yes" : "NO", r.final_error);
    splits.push_back({c.name, with_window, alone});
    std::fflush(stdout);
  }
  // Where a step's time goes (means per Newton step), in the window and for the engine alone.
  std::printf(
      "\n| parameters | run | ms per step | gradient | Hessian | solve (Cholesky, direction) | line search "
      "| of which certificate | refined voxels (accepted certificate) | line-search trials | steps reusing "
      "the Hessian factor |\n"
      "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const auto& sp : splits)
    for (int k = 0; k < 2; ++k) {
      const Result& q = k ? sp.alone : sp.window;
      std::printf("| %s | %s | %.0f | %.1f | %.1f | %.1f | %.1f | %.1f | %.0f | %.2f | %.0f%% |\n", sp.name,
                  k ? "engine alone" : "window", q.ms_step, q.ms_gradient, q.ms_hessian, q.ms_solve,
                  q.ms_line_search, q.ms_certificate, q.refined, q.trials, 100 * q.reused);
    }
  return 0;
}
