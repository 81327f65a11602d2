// Benchmark of the OpenCL backend against the CPU backend, in one process, same parameters, same inputs:
//  1. Per scenario: the full solve on each backend (iterations, ms per iteration and its stage split, the
//     solve time), with the parity of the two runs: the same accepted steps and certificate verdicts, and the
//     relative difference of the final coefficients.
//  2. Per model, at the CPU run's final map: each stage alone (median of --reps after a warm-up): Jacobians
//  at
//     the samples (G y), the energy sum, the energy gradient (per-sample ∂E/∂J and Gᵀ P), the PSD Hessian
//     blocks with the dense product (single precision), the certificate of the map (base stage + refinement),
//     and the evaluation of a batch of octree nodes (the refinement kernel).
//
// Scenarios: every *.json in DATA_DIR/scenarios (DATA_DIR = first positional argument, else
// $LIDEF_SHARED_DATA, else ../shared/data beside the source tree) plus the project's beam_bend.json; --only
// a,b picks scenarios by file stem. bar_twist180 is capped at --cap iterations (default 8) on both backends.
// Output: markdown on stdout, progress on stderr. Exit 0; 2 on bad input; 3 when no OpenCL device works or
// the two backends disagree on a verdict.
//
//  3. With --drag S: the studio's drag on the engine alone (no window), S seconds per scenario and backend:
//     certified maps and Newton steps per second, and each step's stage split.
//
// Usage: bench_opencl [DATA_DIR] [--only a,b] [--iterations N] [--cap N] [--reps R] [--threads T]
//                     [--cache-dir DIR] [--drag S] [--drag-only a,b]
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_util.h"
#include "drag_path.h"
#include "lidef/analysis/interactive_session.h"
#include "lidef/blas_kernel.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/model_check.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"

using namespace lidef;
namespace fs = std::filesystem;

namespace {

std::string e(double x) {
  char b[64];
  std::snprintf(b, sizeof b, "%.1e", x);
  return b;
}

// Median wall-clock ms of `reps` timed runs of `work` after one warm-up.
template <class F>
double median_ms(int reps, F&& work) {
  return bench::time_reps(reps, work).med();
}

struct Run {
  SolveResult result;
  std::vector<IterationRecord> history;
  MatS3 y;
  bool certified = false;
};

Run solve(DeformationSolver& s, const Scenario& sc, int max_iter) {
  DeformParams p = sc.params;
  p.max_iterations = max_iter;
  s.set_params(p);
  s.reset();
  s.set_handles(sc.sources, sc.targets, sc.path);
  Run r;
  r.result = s.solve();
  r.history = s.history();
  r.y = s.reduced_coefficients();
  r.certified = s.certificate().certified;
  return r;
}

struct StageMeans {
  double total = 0, grad = 0, hess = 0, solve = 0, ls = 0, cert = 0;
};
StageMeans means(const std::vector<IterationRecord>& h) {
  StageMeans m;
  if (h.empty()) return m;
  for (const auto& r : h) {
    m.total += r.ms_total;
    m.grad += r.ms_gradient;
    m.hess += r.ms_hessian;
    m.solve += r.ms_solve;
    m.ls += r.ms_line_search - r.ms_certificate;
    m.cert += r.ms_certificate;
  }
  const double n = static_cast<double>(h.size());
  m.total /= n, m.grad /= n, m.hess /= n, m.solve /= n, m.ls /= n, m.cert /= n;
  return m;
}

// The studio's drag on the engine alone (InteractiveSession, no window): the scenario solved to rest on
// `kind`, then its pushed handles circle (drag_path.h) with a target change every 16 ms (the mouse's rate)
// for `seconds`. Certified maps per second (distinct maps the engine published, each certified), Newton steps
// per second and each step's stage means. What the studio would show on top is the renderer's cost
// (bench_studio).
struct DragRate {
  double seconds = 0;
  long maps = 0;
  std::vector<IterationRecord> steps;
  bool all_certified = true;
  std::string error;
};

DragRate drag_engine(const Scenario& sc, BackendKind kind, const std::string& cache_dir, double seconds) {
  DragRate r;
  std::atomic<long> maps{0}, last_version{-1};
  std::atomic<bool> uncertified{false};
  std::mutex error_mutex;
  InteractiveSession s(
      [&](std::shared_ptr<const SessionFrame> f) {
        if (f->state != SessionState::kIterating && f->state != SessionState::kResting) return;
        if (f->map_version == last_version.exchange(f->map_version)) return;
        ++maps;
        if (!f->certified) uncertified = true;
      },
      [&](const std::string& e) {  // on the engine thread
        std::lock_guard<std::mutex> lock(error_mutex);
        r.error = e;
      },
      opencl_backend_factory(cache_dir));
  s.set_cache(cache_dir);
  DeformParams p = sc.params;
  p.backend = kind;
  p.opencl_device = opencl_device_filter_from_env();
  s.open_model(sc.model_dir, p);
  s.set_handles(sc.sources, sc.targets);
  if (!s.wait_until_resting(600) || s.state() != SessionState::kResting) {
    std::lock_guard<std::mutex> lock(error_mutex);
    if (r.error.empty()) r.error = "did not come to rest: " + s.latest_frame()->status;
    return r;
  }
  const auto m = s.model();
  const double amp = 0.05 * (m->cage.bbox_max - m->cage.bbox_min).norm();
  const size_t it0 = s.latest_frame()->history.size();
  maps = 0;
  uncertified = false;
  const auto t0 = Clock::now();
  while (seconds_since(t0) < seconds) {
    s.set_targets(bench::drag_targets(sc.sources, sc.targets, seconds_since(t0), amp));
    std::this_thread::sleep_for(std::chrono::milliseconds(16));
  }
  r.seconds = seconds_since(t0);
  r.maps = maps;
  r.all_certified = !uncertified;
  s.stop();
  s.wait_until_resting(60);
  const auto f = s.latest_frame();
  r.steps.assign(f->history.begin() + std::min(it0, f->history.size()), f->history.end());
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  std::string data_dir = bench::default_data_dir(LIDEF_SHARED_DATA_DIR), only,
              cache_dir = "/tmp/lidef-bench-cache";
  int iterations = 0, cap = 8, reps = 5, threads = 0;
  double drag_seconds = 0;
  std::string drag_only;
  CLI::App app{
      "bench_opencl: the OpenCL backend against the CPU backend in one process: whole solves with "
      "their parity, and each stage alone; a markdown report on stdout"};
  app.option_defaults()->always_capture_default();
  bench::add_data_options(app, data_dir, threads, cache_dir);
  app.add_option("--only", only, "comma-separated scenario names (file stems)");
  app.add_option("--iterations", iterations, "max_iterations for every scenario (0: the scenario's own)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--cap", cap, "max_iterations of bar_twist180 on both backends")->check(CLI::PositiveNumber);
  app.add_option("--reps", reps, "timed repetitions of each stage alone (median reported)")
      ->check(CLI::PositiveNumber);
  app.add_option("--drag", drag_seconds,
                 "seconds of the studio's drag on the engine alone per scenario and backend (0: none)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--drag-only", drag_only,
                 "comma-separated scenarios of the drag rows (default: every one run)");
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  if (threads > 0) omp_set_num_threads(threads);
  std::vector<Scenario> scenarios;
  try {
    std::vector<fs::path> files;
    if (fs::is_directory(fs::path(data_dir) / "scenarios")) {
      for (const auto& en : fs::directory_iterator(fs::path(data_dir) / "scenarios"))
        if (en.path().extension() == ".json") files.push_back(en.path());
    } else {
      std::cerr << "bench_opencl: no scenarios under " << data_dir
                << " (shared data absent); project scenario only\n";
    }
    std::sort(files.begin(), files.end());
    const fs::path beam = fs::path(LIDEF_SOURCE_DIR) / "data/scenarios/beam_bend.json";
    if (fs::exists(beam)) files.push_back(beam);
    std::map<std::string, bool> seen;
    for (const auto& p : files) {
      if (seen[p.stem().string()]) continue;  // the project's beam_bend may also sit in DATA_DIR
      seen[p.stem().string()] = true;
      if (!only.empty() && ("," + only + ",").find("," + p.stem().string() + ",") == std::string::npos)
        continue;
      scenarios.push_back(read_scenario(p.string()));
    }
  } catch (const Error& ex) {
    std::cerr << "bench_opencl: " << ex.what() << "\n";
    return 2;
  }

  std::shared_ptr<const ComputeBackend> ocl;
  try {
    ocl = make_opencl_backend({opencl_device_filter_from_env()}, cache_dir);
  } catch (const OpenCLError& ex) {
    std::cerr << "bench_opencl: " << ex.what() << "\n";
    return 3;
  }
  std::string why;
  std::cout << "## OpenCL backend vs CPU backend (bench_opencl)\n\n";
  std::cout << "- host: " << lidef::bench::cpu_model() << "; nproc " << sysconf(_SC_NPROCESSORS_ONLN)
            << "; OpenMP threads " << omp_get_max_threads() << "\n";
  std::cout << "- OpenCL device: " << ocl->name() << "\n";
  for (const auto& d : opencl_devices(&why))
    std::cout << "  - available: " << d.name << " (" << d.platform << ", " << d.type << ", " << d.version
              << ", fp64 " << (d.fp64 ? "yes" : "no") << ", " << d.compute_units << " compute units, "
              << (d.global_mem >> 20) << " MiB)\n";
  std::cout << "\n";

  std::ostringstream solve_table, stage_table;
  solve_table
      << "| scenario | backend | iterations | ms/iteration | gradient | Hessian | Cholesky | line search "
         "(energy) | certificate | solve s | same steps & verdicts | coefficient rel. diff |\n"
      << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  stage_table << "| model | stage | CPU ms | OpenCL ms | OpenCL / CPU |\n|---|---|---|---|---|\n";
  bool disagree = false;
  std::map<std::string, bool> staged;
  for (const Scenario& sc : scenarios) {
    std::cerr << "bench_opencl: " << sc.name << "\n";
    const Model model = load_model(sc.model_dir);
    std::unique_ptr<DeformationSolver> cpu, gpu;
    double pre_cpu = 0, pre_gpu = 0;
    {
      auto t0 = Clock::now();
      cpu = std::make_unique<DeformationSolver>(model.cage, sc.params, cache_dir);
      pre_cpu = ms_since(t0);
      t0 = Clock::now();
      gpu = std::make_unique<DeformationSolver>(model.cage, sc.params, cache_dir,
                                                std::function<void(const std::string&)>{}, ocl);
      pre_gpu = ms_since(t0);
    }
    int max_iter = iterations > 0 ? iterations : sc.params.max_iterations;
    if (sc.name == "bar_twist180") max_iter = std::min(max_iter, cap);
    const Run rc = solve(*cpu, sc, max_iter);
    const Run rg = solve(*gpu, sc, max_iter);
    bool same = rc.history.size() == rg.history.size() && rc.certified == rg.certified;
    for (size_t i = 0; same && i < rc.history.size(); ++i)
      same = rc.history[i].accepted == rg.history[i].accepted && rc.history[i].step == rg.history[i].step &&
             rc.history[i].certified == rg.history[i].certified;
    if (rc.certified != rg.certified) disagree = true;
    const double diff = (rc.y - rg.y).norm() / rc.y.norm();
    for (int b = 0; b < 2; ++b) {
      const Run& r = b == 0 ? rc : rg;
      const StageMeans m = means(r.history);
      solve_table << "| " << sc.name << " | " << (b == 0 ? "cpu" : "opencl") << " | " << r.history.size()
                  << " | " << bench::fixed(m.total, 1) << " | " << bench::fixed(m.grad, 1) << " | "
                  << bench::fixed(m.hess, 1) << " | " << bench::fixed(m.solve, 1) << " | "
                  << bench::fixed(m.ls, 1) << " | " << bench::fixed(m.cert, 1) << " | "
                  << bench::fixed(r.result.seconds, 2) << " | " << (b == 0 ? "" : (same ? "yes" : "**no**"))
                  << " | " << (b == 0 ? "" : e(diff)) << " |\n";
    }
    std::cerr << "  preprocessing ms: cpu " << bench::fixed(pre_cpu, 0) << ", opencl "
              << bench::fixed(pre_gpu, 0) << "\n";

    // --- Stages alone, once per model, at the CPU run's final map.
    const std::string key = sc.model_dir;
    if (staged[key]) continue;
    staged[key] = true;
    const DeformationEnergy& en = cpu->energy_function();
    auto kc = cpu_backend()->energy_kernels(en);
    auto kg = ocl->energy_kernels(en);
    const MatS3 y = rc.y;
    const MatS3 d =
        0.01 * (rc.y - cpu->subspace().basis.transpose() * cpu->normalized_cage().identity_coefficients());
    for (auto* k : {kc.get(), kg.get()}) {
      k->set_current(y);
      k->set_direction(d);
    }
    auto row = [&](const std::string& stage, double a, double b) {
      stage_table << "| " << sc.model << " | " << stage << " | " << bench::fixed(a, 2) << " | "
                  << bench::fixed(b, 2) << " | " << bench::fixed(b / a, 2) << " |\n";
    };
    row("Jacobians G y (" + std::to_string(en.num_samples()) + " samples)",
        median_ms(reps, [&] { kc->set_current(y); }), median_ms(reps, [&] { kg->set_current(y); }));
    row("energy sum at J + t dJ", median_ms(reps, [&] { kc->distortion_sum(0.5); }),
        median_ms(reps, [&] { kg->distortion_sum(0.5); }));
    // The kernels keep the gradient until the map changes: each timed call follows a set_current (not timed).
    const auto gradient_ms = [&](EnergyKernels& k) {
      std::vector<double> ms;
      for (int r = 0; r <= reps; ++r) {
        k.set_current(y);
        const auto t0 = Clock::now();
        k.distortion_gradient_sum();
        if (r > 0) ms.push_back(ms_since(t0));  // the first call warms up
      }
      return bench::median(ms);
    };
    row("energy gradient", gradient_ms(*kc), gradient_ms(*kg));
    row("PSD Hessian blocks + product (single)", median_ms(reps, [&] { kc->distortion_pair_blocks(false); }),
        median_ms(reps, [&] { kg->distortion_pair_blocks(false); }));
    row("PSD Hessian blocks + product (double)", median_ms(reps, [&] { kc->distortion_pair_blocks(true); }),
        median_ms(reps, [&] { kg->distortion_pair_blocks(true); }));
    const CertifyParams cp = cpu->certify_params(false, false);
    Certificate cc, cg;
    const double tc = median_ms(reps, [&] { cc = cpu->certifier().certify_reduced(y, cp); });
    const double tg = median_ms(reps, [&] { cg = gpu->certifier().certify_reduced(y, cp); });
    row("certificate of the final map (" + std::to_string(cc.refined) + " refined)", tc, tg);
    row("  of which base stage (J, H, σ3, bound)", cc.ms_jacobian + cc.ms_sigma + cc.ms_bound,
        cg.ms_jacobian + cg.ms_sigma + cg.ms_bound);
    row("  of which refinement", cc.ms_refine, cg.ms_refine);
    if (cc.certified != cg.certified) disagree = true;
    std::cerr << "  certificate: cpu " << cc.certified << " " << cc.refined << ", opencl " << cg.certified
              << " " << cg.refined << "\n";
  }
  std::cout << "### Solves (same process, same parameters; stage columns are ms per iteration)\n\n"
            << solve_table.str() << "\n### Stages alone (median of " << reps << ")\n\n"
            << stage_table.str() << "\n";
  if (drag_seconds > 0) {
    std::cout << "### Dragging, the engine alone (no window; " << bench::fixed(drag_seconds, 0)
              << " s per row, targets moved every 16 ms)\n\n"
              << "| scenario | backend | certified maps/s | Newton steps/s | ms/step | gradient | Hessian | "
                 "Cholesky "
                 "| line search (energy) | certificate | all certified |\n"
              << "|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Scenario& sc : scenarios)
      for (const BackendKind kind : {BackendKind::kCpu, BackendKind::kOpenCL}) {
        if (!drag_only.empty() && ("," + drag_only + ",").find("," + sc.name + ",") == std::string::npos)
          continue;
        const char* name = kind == BackendKind::kCpu ? "cpu" : "opencl";
        std::cerr << "bench_opencl: drag " << sc.name << " " << name << "\n";
        const DragRate d = drag_engine(sc, kind, cache_dir, drag_seconds);
        if (!d.error.empty()) {
          std::cout << "| " << sc.name << " | " << name << " | failed: " << d.error << " |||||||||\n";
          continue;
        }
        const StageMeans m = means(d.steps);
        std::cout << "| " << sc.name << " | " << name << " | " << bench::fixed(d.maps / d.seconds, 1) << " | "
                  << bench::fixed(d.steps.size() / d.seconds, 1) << " | " << bench::fixed(m.total, 1) << " | "
                  << bench::fixed(m.grad, 1) << " | " << bench::fixed(m.hess, 1) << " | "
                  << bench::fixed(m.solve, 1) << " | " << bench::fixed(m.ls, 1) << " | "
                  << bench::fixed(m.cert, 1) << " | " << (d.all_certified ? "yes" : "**no**") << " |\n";
      }
    std::cout << "\n";
  }
  if (disagree) {
    std::cout << "**The backends disagreed on a certificate verdict.**\n";
    return 3;
  }
  return 0;
}
