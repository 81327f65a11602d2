// Benchmark of the deformation solver (DeformationSolver, projected_newton.h) on the handle scenarios: the
// numbers of the paper's Table 1 (iterations, time to converge, ms per iteration) and Fig. 13 (per-iteration
// stage split), the effect of dynamic weighting, the reduced Hessian against a plain SYRK, and the
// per-iteration targets.
//
// Scenarios: every *.json in the shared scenarios folder (DATA_DIR/scenarios; DATA_DIR = first positional
// argument, else $LIDEF_SHARED_DATA, else ../shared/data beside the source tree; --scenarios DIR names the
// folder directly; skipped with a message when absent) and the project's data/scenarios/beam_bend.json.
// --only a,b picks scenarios by name (file stem) or by model. Scenarios of one model (with the same
// precomputation-shaping parameters) share one DeformationSolver: its construction (subspace, sampling,
// reduced gradients, certificate precomputation) is timed once as the model's preprocessing; the subspace is
// cached in --cache-dir (default /tmp/lidef-bench-cache), so only the very first run of a model computes it.
// Before each solve the solver is reset() to the identity, so every run starts from the rest pose exactly as
// a fresh solver would.
//
// Per scenario:
//  1. solve() with the scenario's parameters (the defaults: max_iterations 50, dynamic weighting on), except
//  that
//     bar_twist180 is capped at --cap iterations (default 8; its certificate refines a lot, seconds per
//     iteration) and reported as capped; --iterations N sets max_iterations for every scenario. The
//     per-iteration stage times are IterationRecord's ms_* fields, averaged over the iterations. The same
//     scenario is solved again with dynamic_weighting = false (--no-compare skips it) for the on/off table.
//  2. For the first scenario of the bar and the animal (--hessian-models), at the final map of the
//  dynamic-weighting
//     run: DeformationEnergy::distortion_hessian(JT, projected = true, all_samples = false) against a plain
//     dense single-precision SYRK of the shape the Kronecker formula avoids (C = Mᵀ M, M: 9|H| by 3s random
//     floats, cblas_ssyrk), and, for reference, one sgemm with the Kronecker block shape s × 3|H| × s and one
//     with the shape the implementation calls (s × 3|H| × 6s: the six blocks in one product). Median and min
//     of --reps timed repetitions after one warm-up, same process, same threads.
//  3. Per-iteration time at 900 DOF on the bar and animal scenarios: the mean of ms_total over
//  iterations 2..N
//     (iteration 1 takes the large first steps) against the targets (≤ 150 ms bar, ≤ 400 ms animal).
//
// Output: markdown on stdout (machine, then the tables; without --markdown also per-iteration details per
// scenario); progress on stderr. Exit code 0, 2 on bad input, 3 when a solve failed (an exception) or a final
// map is not certified.
//
// --newton-cg-steps N sets DeformParams::newton_cg_steps for every scenario (to compare the subset
// direction's conjugate-gradient correction with the plain direction in one build).
//
// Usage: bench_deform [DATA_DIR] [--scenarios DIR] [--only a,b] [--iterations N] [--cap N] [--threads T]
//                     [--reps R] [--cache-dir DIR] [--hessian-models bar,animal] [--no-compare] [--markdown]
//                     [--newton-cg-steps N]
#include <cblas.h>
#include <omp.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/cage.h"
#include "lidef/deform_params.h"
#include "lidef/deformation_energy.h"
#include "lidef/errors.h"
#include "lidef/model_check.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"
#include "lidef/subspace.h"
#include "lidef/symmetric_dirichlet.h"
#include "nlohmann/json.hpp"

// OpenBLAS extensions (declared by OpenBLAS's cblas.h; repeated so that another cblas.h still compiles).
extern "C" {
int openblas_get_num_threads(void);
void openblas_set_num_threads(int);
int openblas_get_parallel(void);
char* openblas_get_config(void);
char* openblas_get_corename(void);
}

using namespace lidef;
namespace fs = std::filesystem;

namespace {

struct Options {
  std::string data;       // shared data folder
  std::string scenarios;  // folder of scenario JSONs (default data/scenarios)
  std::vector<std::string> only;
  int iterations = 0;  // > 0: max_iterations for every scenario
  int cap = 8;         // max_iterations of the capped scenarios
  int threads = 0;     // > 0: OpenMP and OpenBLAS threads
  int reps = 7;        // Hessian / SYRK repetitions
  int cg_steps = -1;   // >= 0: newton_cg_steps for every scenario (-1: the scenario's)
  std::string cache_dir = "/tmp/lidef-bench-cache";
  std::vector<std::string> hessian_models;
  bool compare = true;
  bool markdown_only = false;
};

// Scenarios that get the iteration cap (their certificate refines heavily; seconds per iteration).
const std::vector<std::string> kCapped = {"bar_twist180"};
// Run order: the bar first (its Hessian comparison), the slow twist last among the bars, the project's beam
// last.
const std::vector<std::string> kOrder = {"bar_bend",         "bar_twist90",    "bar_twist180",
                                         "animal_tail_lift", "horse_leg_lift", "spot_head_turn",
                                         "beam_bend"};
// Per-iteration targets at 900 DOF (ms, mean over iterations 2..N).
const std::map<std::string, double> kTargets = {{"bar", 150.0}, {"animal", 400.0}};

bool contains(const std::vector<std::string>& v, const std::string& x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

// ---------------------------------------------------------------------------------------------------------------

struct RunResult {
  std::string scenario, model, variant;  // variant: "on" / "off" (dynamic weighting)
  bool ok = false;
  std::string error;
  int cage_v = 0, cage_f = 0, dof = 0, samples = 0, hsub = 0, handles = 0;
  double preprocess_s = 0;
  bool preprocess_shared = false;  // the solver was built for an earlier scenario of the same model
  int max_iterations = 0;
  bool capped = false;
  SolveResult res;
  std::vector<IterationRecord> hist;
  double max_err = 0, min_lb = 0, min_sigma3 = 0;
  bool certified = false;
  long refined = 0;
  double lambda1 = 0, lambda2 = 0;
};

double mean_of(const std::vector<IterationRecord>& h, double IterationRecord::*f, size_t from = 0) {
  if (h.size() <= from) return std::nan("");
  double s = 0;
  for (size_t k = from; k < h.size(); ++k) s += h[k].*f;
  return s / static_cast<double>(h.size() - from);
}
template <class T>
double mean_count(const std::vector<IterationRecord>& h, T IterationRecord::*f) {
  if (h.empty()) return std::nan("");
  double s = 0;
  for (const IterationRecord& r : h) s += static_cast<double>(r.*f);
  return s / static_cast<double>(h.size());
}

std::string stop_text(const RunResult& r) {
  if (!r.ok) return "ERROR";
  std::string s = to_string(r.res.reason);
  if (r.capped && r.res.reason == StopReason::kMaxIterations)
    s += " (capped at " + std::to_string(r.max_iterations) + ")";
  return s;
}

struct HessRow {
  std::string scenario, model;
  int s = 0, h = 0;
  bench::Timing hess, psd, syrk, block, fused;
  double hess_flops = 0, syrk_flops = 0, block_flops = 0, fused_flops = 0;
  double checksum = 0;
};

// distortion_hessian at the solver's current map vs a dense SYRK of the same problem (see the header
// comment).
HessRow hessian_vs_syrk(const DeformationSolver& solver, const std::string& scenario,
                        const std::string& model, int reps) {
  HessRow row;
  row.scenario = scenario;
  row.model = model;
  const DeformationEnergy& E = solver.energy_function();
  const int s = E.reduced_size();
  const int m = static_cast<int>(E.hessian_subset().size());
  row.s = s;
  row.h = m;
  const MatJT JT = E.jacobians(solver.reduced_coefficients());
  MatXd Hd;
  row.hess = bench::time_reps(reps, [&] { Hd = E.distortion_hessian(JT, true, false); });
  row.checksum = Hd.trace();
  // The per-sample part alone: the |H| PSD-projected 9x9 blocks (the same OpenMP loop as the library's).
  std::vector<Mat9> blocks(m);
  const std::vector<int>& sub = E.hessian_subset();
  row.psd = bench::time_reps(reps, [&] {
#pragma omp parallel for schedule(static)
    for (int q = 0; q < m; ++q) blocks[q] = sd_hessian_psd(JT.middleRows<3>(3 * sub[q]).transpose());
  });

  std::mt19937 rng(12345);
  std::uniform_real_distribution<float> U(-1.0f, 1.0f);
  // SYRK: C (3s x 3s, upper triangle) = Mᵀ M, M 9|H| x 3s column-major.
  const int n = 3 * s, k = 9 * m;
  std::vector<float> M(static_cast<size_t>(k) * n), C(static_cast<size_t>(n) * n);
  for (float& x : M) x = U(rng);
  // SYRK has no split over OpenMP's threads: OpenBLAS's own threads run it, then the library's setting (one
  // BLAS thread, blas_kernel.h) is restored.
  openblas_set_num_threads(omp_get_max_threads());
  row.syrk = bench::time_reps(reps, [&] {
    cblas_ssyrk(CblasColMajor, CblasUpper, CblasTrans, n, k, 1.0f, M.data(), k, 0.0f, C.data(), n);
  });
  openblas_set_num_threads(1);
  row.syrk_flops = double(n) * (n + 1) * k;  // one triangle: n(n+1)/2 dot products of length k, 2 flops each
  // Kronecker block: s x s = (s x 3|H|)(3|H| x s); A column-major s x 3|H| (GHᵀ), B = Aᵀ-shaped 3|H| x s.
  const int kb = 3 * m;
  std::vector<float> A(static_cast<size_t>(s) * kb), B(static_cast<size_t>(kb) * 6 * s),
      Cb(static_cast<size_t>(s) * 6 * s);
  for (float& x : A) x = U(rng);
  for (float& x : B) x = U(rng);
  row.block = bench::time_reps(
      reps, [&] { lidef::gemm_parallel(false, false, s, s, kb, A.data(), s, B.data(), kb, Cb.data(), s); });
  row.block_flops = 2.0 * s * s * kb;
  // The six blocks as one product (the implementation's call shape): s x 6s = (s x 3|H|)(3|H| x 6s).
  row.fused = bench::time_reps(reps, [&] {
    lidef::gemm_parallel(false, false, s, 6 * s, kb, A.data(), s, B.data(), kb, Cb.data(), s);
  });
  row.fused_flops = 2.0 * s * 6.0 * s * kb;
  row.hess_flops = row.fused_flops;  // the products only; the 9x9 projections and W are extra
  return row;
}

struct ScenarioEntry {
  std::string path, name;
  int rank = 0;
};

void print_iterations(const RunResult& r) {
  std::cout << "\n### " << r.scenario << " (dynamic weighting " << r.variant << ")\n\n";
  if (!r.ok) {
    std::cout << "ERROR: " << r.error << "\n";
    return;
  }
  std::cout << "stop: " << stop_text(r) << " — " << r.res.message << "; solve "
            << bench::fixed(r.res.seconds, 2) << " s\n\n";
  std::cout << "| it | energy | t | armijo rej | cert rej | refined | min σ3 LB | min σ3 sampled | max "
               "handle err | λ1 | λ2 | action | "
               "grad ms | Hess ms | solve ms | LS ms | cert ms | total ms |\n";
  std::cout << "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|\n";
  for (const IterationRecord& it : r.hist)
    std::cout << "| " << it.iteration << " | " << bench::sci(it.terms.total, 6) << " | "
              << bench::sci(it.step, 3) << " | " << it.armijo_rejections << " | " << it.certificate_rejections
              << " | " << it.refined << " | " << bench::fixed(it.min_lower_bound, 4) << " | "
              << bench::fixed(it.min_sigma3, 4) << " | " << bench::sci(it.max_handle_error, 3) << " | "
              << bench::sci(it.lambda_p2p, 3) << " | " << bench::sci(it.lambda_smooth, 3) << " | "
              << it.weight_action << " | " << bench::fixed(it.ms_gradient, 1) << " | "
              << bench::fixed(it.ms_hessian, 1) << " | " << bench::fixed(it.ms_solve, 1) << " | "
              << bench::fixed(it.ms_line_search, 1) << " | " << bench::fixed(it.ms_certificate, 1) << " | "
              << bench::fixed(it.ms_total, 1) << " |\n";
}

}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  Options opt;
  opt.data = bench::default_data_dir(LIDEF_SHARED_DATA_DIR);
  std::string only, hessian_models = "bar,animal";
  bool no_compare = false;
  CLI::App app{
      "bench_deform: the deformation solver on the handle scenarios (Table 1 / Fig. 13 of the paper, "
      "dynamic weighting on vs off, the reduced Hessian against a plain SYRK, per-iteration targets); "
      "a markdown report on stdout"};
  app.option_defaults()->always_capture_default();
  bench::add_data_options(app, opt.data, opt.threads, opt.cache_dir);
  app.add_option("--scenarios", opt.scenarios, "folder of scenario JSONs (default: DATA_DIR/scenarios)");
  app.add_option("--only", only, "comma-separated scenario names (file stems) or model names");
  app.add_option("--iterations,--max-iterations", opt.iterations,
                 "max_iterations for every scenario (0: the scenario's own)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--cap", opt.cap, "max_iterations of the capped scenarios (bar_twist180)")
      ->check(CLI::PositiveNumber);
  app.add_option("--reps", opt.reps,
                 "timed repetitions of the Hessian / SYRK comparison (at least 5 are run)")
      ->check(CLI::PositiveNumber);
  app.add_option("--hessian-models", hessian_models,
                 "comma-separated models whose first scenario gets the Hessian vs SYRK comparison");
  app.add_option("--newton-cg-steps", opt.cg_steps,
                 "DeformParams::newton_cg_steps for every scenario (-1: the scenario's own)")
      ->check(CLI::Range(-1, 1 << 20));
  app.add_flag("--no-compare", no_compare, "skip the second solve with dynamic weighting off");
  app.add_flag("--markdown", opt.markdown_only, "the tables only, without the per-iteration details");
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  opt.compare = !no_compare;
  opt.only = bench::split_list(only);
  opt.hessian_models = bench::split_list(hessian_models);
  if (opt.reps < 5) {
    // --reps is shared with the other benchmarks through scripts/bench.sh; a median needs at least 5 here.
    std::cerr << "bench_deform: --reps " << opt.reps << " raised to 5 for the Hessian / SYRK medians\n";
    opt.reps = 5;
  }
  if (opt.threads > 0) {
    omp_set_num_threads(opt.threads);  // the products split over OpenMP's threads (blas_kernel.h)
  }
  const auto t_program = Clock::now();

  // --- Scenarios.
  std::vector<ScenarioEntry> entries;
  const std::string scen_dir = opt.scenarios.empty() ? opt.data + "/scenarios" : opt.scenarios;
  std::vector<std::string> notes;
  std::error_code ec;
  if (fs::is_directory(scen_dir, ec)) {
    for (const auto& e : fs::directory_iterator(scen_dir, ec))
      if (e.path().extension() == ".json")
        entries.push_back({e.path().string(), e.path().stem().string(), 0});
  } else {
    const std::string msg =
        "shared scenarios not found: " + scen_dir +
        " (set LIDEF_SHARED_DATA or pass DATA_DIR / --scenarios); only the project's scenario runs";
    std::cerr << "bench_deform: " << msg << "\n";
    notes.push_back(msg);
  }
  const std::string beam = std::string(LIDEF_SOURCE_DIR) + "/data/scenarios/beam_bend.json";
  if (fs::exists(beam, ec)) entries.push_back({beam, "beam_bend", 0});
  for (ScenarioEntry& e : entries) {
    const auto it = std::find(kOrder.begin(), kOrder.end(), e.name);
    e.rank = it == kOrder.end() ? 100 : static_cast<int>(it - kOrder.begin());
  }
  std::sort(entries.begin(), entries.end(), [](const ScenarioEntry& a, const ScenarioEntry& b) {
    return a.rank != b.rank ? a.rank < b.rank : a.name < b.name;
  });
  std::vector<Scenario> scenarios;
  for (const ScenarioEntry& e : entries) {
    try {
      scenarios.push_back(read_scenario(e.path));
      scenarios.back().name = e.name;  // the file stem: the name --only and the tables use
    } catch (const Error& err) {
      std::cerr << "bench_deform: " << err.what() << "\n";
      return 2;
    }
  }
  if (!opt.only.empty()) {
    // --only takes scenario names (file stems) or model names (every scenario of that model).
    auto picked = [&](const Scenario& sc) {
      return contains(opt.only, sc.name) || contains(opt.only, sc.model);
    };
    for (const std::string& n : opt.only)
      if (std::none_of(scenarios.begin(), scenarios.end(),
                       [&](const Scenario& sc) { return sc.name == n || sc.model == n; })) {
        std::cerr << "bench_deform: --only: no scenario or model named '" << n << "'; available:";
        for (const Scenario& sc : scenarios) std::cerr << " " << sc.name << " (" << sc.model << ")";
        std::cerr << "\n";
        return 2;
      }
    scenarios.erase(
        std::remove_if(scenarios.begin(), scenarios.end(), [&](const Scenario& sc) { return !picked(sc); }),
        scenarios.end());
  }
  fs::create_directories(opt.cache_dir, ec);

  // --- Machine.
  const std::string src = LIDEF_SOURCE_DIR;
  std::cout << "# bench_deform: the deformation solver on the handle scenarios\n\n";
  std::cout << "- date: " << bench::utc_now() << "\n";
  std::cout << "- machine: " << lidef::bench::cpu_model() << "; nproc (online CPUs) "
            << sysconf(_SC_NPROCESSORS_ONLN) << "; RAM " << bench::mem_total() << "\n";
  std::cout << "- OpenMP: omp_get_max_threads() = " << omp_get_max_threads()
            << ", omp_get_num_procs() = " << omp_get_num_procs()
            << (opt.threads > 0 ? " (--threads " + std::to_string(opt.threads) + ")"
                                : std::string(" (all cores)"))
            << "\n";
  lidef::use_blas_in_calling_thread();
  const int par = openblas_get_parallel();
  std::cout << "- OpenBLAS: " << openblas_get_config() << " (core " << openblas_get_corename() << "), "
            << openblas_get_num_threads() << " threads, "
            << (par == 0   ? "sequential"
                : par == 1 ? "pthreads"
                : par == 2 ? "OpenMP"
                           : "unknown")
            << " build; the library calls it in one thread per OpenMP thread (blas_kernel.h)\n";
  std::cout << "- compiler: GCC-compatible " << __VERSION__ << "; projected_newton.cpp compiled with "
            << bench::compile_flags(LIDEF_BUILD_DIR, "/deform/src/projected_newton.cpp") << "\n";
  {
    const std::string head =
        bench::command_output("git -C '" + src + "' log -1 --format='%h %cI %s' 2>/dev/null");
    const std::string dirty =
        bench::command_output("git -C '" + src + "' status --porcelain -- deform 2>/dev/null");
    std::string d = dirty;
    std::replace(d.begin(), d.end(), '\n', ';');
    std::cout << "- source: " << (head.empty() ? "unknown (no git)" : head.substr(0, 100))
              << (d.empty() ? "; deform/ unmodified" : "; deform/ has uncommitted changes: " + d) << "\n";
  }
  std::cout << "- scenarios: " << (fs::is_directory(scen_dir, ec) ? scen_dir : "(shared folder absent)")
            << " + " << beam << "; subspace cache " << opt.cache_dir << "\n";
  std::cout << "- runs: scenario parameters (defaults: max_iterations 50, dynamic weighting on)";
  if (opt.iterations > 0)
    std::cout << ", max_iterations " << opt.iterations << " for every scenario (--iterations)";
  if (opt.cg_steps >= 0) std::cout << ", newton_cg_steps " << opt.cg_steps << " for every scenario";
  std::cout << "; capped at " << opt.cap << " iterations: ";
  for (size_t k = 0; k < kCapped.size(); ++k) std::cout << (k ? ", " : "") << kCapped[k];
  std::cout << (opt.compare ? "; each scenario again with dynamic_weighting = false" : "") << "\n";
  std::cout << "- load average at start: " << bench::load_average()
            << "; CPU pressure: " << bench::cpu_pressure() << "\n";
  std::cout.flush();

  // --- Runs.
  std::vector<RunResult> runs;
  std::vector<HessRow> hess_rows;
  std::vector<std::string> hess_done;
  int exit_code = 0;

  std::unique_ptr<Model> model;
  std::unique_ptr<DeformationSolver> solver;
  std::string solver_key;
  double preprocess_s = 0;

  auto shaping_key = [](const Scenario& sc) {
    const DeformParams& p = sc.params;
    std::ostringstream k;
    k.precision(17);
    k << sc.model_dir << '|' << p.reduced_dof << '|' << p.samples << '|' << p.voxel_side << '|' << p.safety
      << '|' << p.hessian_fraction;
    return k.str();
  };

  for (const Scenario& sc : scenarios) {
    const std::string key = shaping_key(sc);
    const std::string model_name = fs::path(sc.model_dir).filename().string();
    bool shared = true;
    if (key != solver_key) {
      solver.reset();
      model.reset();
      solver_key.clear();
      shared = false;
      try {
        model = std::make_unique<Model>(load_model(sc.model_dir));
        DeformParams p = sc.params;
        if (opt.threads > 0) p.threads = opt.threads;
        const bool cached = fs::exists(subspace_cache_path(model->cage, p.reduced_dof, opt.cache_dir), ec);
        std::cerr << "bench_deform: " << model_name << ": preprocessing (subspace "
                  << (cached ? "cached" : "not cached yet") << ")\n";
        const auto t0 = Clock::now();
        solver =
            std::make_unique<DeformationSolver>(model->cage, model->mesh, p, opt.cache_dir,
                                                [](const std::string& s) { std::cerr << "  " << s << "\n"; });
        preprocess_s = seconds_since(t0);
        solver_key = key;
        if (!cached)
          notes.push_back(model_name +
                          ": the subspace was computed (not cached) in this run's preprocessing");
      } catch (const std::exception& e) {
        RunResult r;
        r.scenario = sc.name;
        r.model = model_name;
        r.variant = "on";
        r.error = e.what();
        runs.push_back(r);
        std::cerr << "bench_deform: " << sc.name << ": " << e.what() << "\n";
        exit_code = 3;
        continue;
      }
    }

    for (const bool dyn : {true, false}) {
      if (!dyn && !opt.compare) break;
      RunResult r;
      r.scenario = sc.name;
      r.model = model_name;
      r.variant = dyn ? "on" : "off";
      r.cage_v = model->cage.num_vertices();
      r.cage_f = model->cage.num_faces();
      r.dof = 3 * solver->subspace().size();
      r.samples = solver->sampling().size();
      r.hsub = static_cast<int>(solver->energy_function().hessian_subset().size());
      r.handles = sc.num_handles();
      r.preprocess_s = preprocess_s;
      r.preprocess_shared = shared;
      DeformParams p = sc.params;
      if (opt.threads > 0) p.threads = opt.threads;
      p.dynamic_weighting = dyn;
      r.capped = contains(kCapped, sc.name) && opt.iterations == 0;
      if (opt.iterations > 0) p.max_iterations = opt.iterations;
      if (opt.cg_steps >= 0) p.newton_cg_steps = opt.cg_steps;
      if (r.capped) p.max_iterations = std::min(p.max_iterations, opt.cap);
      r.max_iterations = p.max_iterations;
      std::cerr << "bench_deform: " << sc.name << " (dynamic weighting " << r.variant << ", max "
                << p.max_iterations << " iterations)\n";
      try {
        solver->set_params(p);
        solver->reset();
        solver->set_handles(sc.sources, sc.targets, sc.path);
        r.res = solver->solve([](const IterationRecord& it) {
          char line[256];
          std::snprintf(
              line, sizeof line,
              "  it %2d  %7.0f ms (grad %.0f, Hess %.0f, solve %.0f, LS %.0f of which cert %.0f)  t %.3g  "
              "rej %d/%d  refined %ld  LB %.3g  err %.3g %s\n",
              it.iteration, it.ms_total, it.ms_gradient, it.ms_hessian, it.ms_solve, it.ms_line_search,
              it.ms_certificate, it.step, it.armijo_rejections, it.certificate_rejections, it.refined,
              it.min_lower_bound, it.max_handle_error, it.weight_action.c_str());
          std::cerr << line;
          return true;
        });
        r.hist = solver->history();
        const VecXd herr = solver->handle_errors();
        r.max_err = herr.size() ? herr.maxCoeff() : 0.0;
        const Certificate& c = solver->certificate();
        r.certified = c.certified;
        r.min_lb = c.min_lower_bound;
        r.min_sigma3 = c.min_sigma3_center;
        r.refined = c.refined;
        r.lambda1 = solver->weights().p2p;
        r.lambda2 = solver->weights().smooth;
        r.ok = true;
        if (!r.certified) {
          notes.push_back(sc.name + " (weighting " + r.variant +
                          "): the final map's certificate says NOT certified");
          exit_code = 3;
        }
        std::cerr << "  -> " << stop_text(r) << ", " << r.hist.size() << " iterations, "
                  << bench::fixed(r.res.seconds, 2) << " s, max handle error " << bench::sci(r.max_err)
                  << ", min sigma3 LB " << bench::fixed(r.min_lb, 4) << "\n";
      } catch (const std::exception& e) {
        r.error = e.what();
        std::cerr << "bench_deform: " << sc.name << ": " << e.what() << "\n";
        exit_code = 3;
      }
      runs.push_back(r);
      // Hessian vs SYRK at this run's final map (first scenario of each listed model, weighting on).
      if (dyn && r.ok && contains(opt.hessian_models, model_name) && !contains(hess_done, model_name)) {
        std::cerr << "bench_deform: " << model_name << ": distortion_hessian vs SYRK (" << opt.reps
                  << " reps)\n";
        hess_rows.push_back(hessian_vs_syrk(*solver, sc.name, model_name, opt.reps));
        hess_done.push_back(model_name);
      }
    }
  }
  solver.reset();
  model.reset();
  const double total_s = seconds_since(t_program);

  // --- Report.
  std::cout << "- load average at end: " << bench::load_average()
            << "; CPU pressure: " << bench::cpu_pressure() << "; whole program " << bench::fixed(total_s, 0)
            << " s\n";

  std::vector<const RunResult*> on;
  for (const RunResult& r : runs)
    if (r.variant == "on") on.push_back(&r);

  std::cout << "\n## Solver per scenario (Table 1 of the paper; dynamic weighting on)\n\n";
  std::cout
      << "| scenario | model | cage V / F | DOF | samples \\|I\\| | \\|H\\| | handles | preprocessing s | "
         "iterations | time to converge s | ms / iteration | stop reason | max handle error | final min σ3 "
         "lower bound | final min σ3 sampled | certified |\n";
  std::cout << "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---|\n";
  for (const RunResult* r : on) {
    if (!r->ok && r->dof == 0) {
      std::cout << "| " << r->scenario << " | " << r->model << " | ERROR: " << r->error
                << " | | | | | | | | | | | | | |\n";
      continue;
    }
    std::cout << "| " << r->scenario << " | " << r->model << " | " << r->cage_v << " / " << r->cage_f << " | "
              << r->dof << " | " << r->samples << " | " << r->hsub << " | " << r->handles << " | "
              << bench::fixed(r->preprocess_s, 1) << (r->preprocess_shared ? " (shared)" : "") << " | "
              << r->hist.size() << (r->capped ? " (cap)" : "") << " | " << bench::fixed(r->res.seconds, 2)
              << " | " << bench::fixed(mean_of(r->hist, &IterationRecord::ms_total), 0) << " | "
              << stop_text(*r) << " | " << bench::sci(r->max_err) << " | " << bench::fixed(r->min_lb, 4)
              << " | " << bench::fixed(r->min_sigma3, 4) << " | " << (r->certified ? "yes" : "NO") << " |\n";
  }
  std::cout
      << "\nPreprocessing = DeformationSolver construction (subspace from the cache, sampling, reduced basis "
         "gradients at the samples, certificate precomputation, identity certificate); \"(shared)\": the "
         "solver built for the previous scenario of the same model was reused (reset() to the identity). "
         "Time to converge = SolveResult::seconds (for a capped run: the time of its iterations). "
         "ms / iteration = mean IterationRecord::ms_total. Final min σ3 lower bound = min over leaves of "
         "σ3 − rL of the last accepted map's line-search certificate (refinement stops as soon as a leaf's "
         "bound is positive, so with refinement this is a small positive number by construction); final min "
         "σ3 "
         "sampled = min σ3 at the evaluated voxel centers of that certificate.\n";

  std::cout
      << "\n## Per-iteration stage split (mean ms per iteration, like the paper's Fig. 13; dynamic weighting "
         "on)\n\n";
  std::cout
      << "| scenario | iterations | gradient | Hessian (assembly + projection) | solve | line search | of "
         "which certificate | line search w/o certificate | other | total | certificate share | trials / "
         "iteration (Armijo rej. + cert. rej. + accepted) | refined voxels / iteration |\n";
  std::cout << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const RunResult* r : on) {
    if (!r->ok) continue;
    const auto& h = r->hist;
    const double g = mean_of(h, &IterationRecord::ms_gradient), H = mean_of(h, &IterationRecord::ms_hessian),
                 so = mean_of(h, &IterationRecord::ms_solve),
                 ls = mean_of(h, &IterationRecord::ms_line_search),
                 ce = mean_of(h, &IterationRecord::ms_certificate),
                 to = mean_of(h, &IterationRecord::ms_total);
    const double trials = mean_count(h, &IterationRecord::armijo_rejections) +
                          mean_count(h, &IterationRecord::certificate_rejections) +
                          mean_count(h, &IterationRecord::accepted);
    std::cout << "| " << r->scenario << " | " << h.size() << " | " << bench::fixed(g, 1) << " | "
              << bench::fixed(H, 1) << " | " << bench::fixed(so, 1) << " | " << bench::fixed(ls, 1) << " | "
              << bench::fixed(ce, 1) << " | " << bench::fixed(ls - ce, 1) << " | "
              << bench::fixed(to - g - H - so - ls, 1) << " | " << bench::fixed(to, 1) << " | "
              << bench::fixed(100 * ce / to, 0) << "% | " << bench::fixed(trials, 2) << " | "
              << bench::fixed(mean_count(h, &IterationRecord::refined), 0) << " |\n";
  }
  std::cout
      << "\nColumns: means over all iterations of IterationRecord::ms_gradient (energy + gradient on all "
         "samples), ms_hessian (9x9 PSD projections on H, the Kronecker products, quadratic terms), ms_solve "
         "(dense Cholesky, the direction's Jacobians G δ and the CG iterates), ms_line_search (all trials: "
         "Armijo energy evaluations and certificates), "
         "ms_certificate (the certificates of the line search only); other = total − the four stages "
         "(handle errors, dynamic weighting, bookkeeping). Refined = voxels subdivided by the accepted map's "
         "certificate.\n";

  if (opt.compare) {
    std::cout << "\n## Dynamic weighting on vs off\n\n";
    std::cout << "| scenario | dynamic weighting | iterations | time s | ms / iteration | max handle error | "
                 "final min σ3 "
                 "lower bound | stop reason | final λ1 / λ2 |\n";
    std::cout << "|---|---|---:|---:|---:|---:|---:|---|---|\n";
    for (const RunResult& r : runs) {
      if (!r.ok) {
        std::cout << "| " << r.scenario << " | " << r.variant << " | ERROR: " << r.error
                  << " | | | | | | |\n";
        continue;
      }
      std::cout << "| " << r.scenario << " | " << r.variant << " | " << r.hist.size()
                << (r.capped ? " (cap)" : "") << " | " << bench::fixed(r.res.seconds, 2) << " | "
                << bench::fixed(mean_of(r.hist, &IterationRecord::ms_total), 0) << " | "
                << bench::sci(r.max_err) << " | " << bench::fixed(r.min_lb, 4) << " | " << stop_text(r)
                << " | " << bench::sci(r.lambda1) << " / " << bench::sci(r.lambda2) << " |\n";
    }
  }

  if (!hess_rows.empty()) {
    std::cout << "\n## Reduced Hessian (Kronecker, 6 sgemm blocks) vs a plain SYRK (same process, same "
                 "threads)\n\n";
    std::cout
        << "| model | at the final map of | s | \\|H\\| | distortion_hessian ms (median / min) | of which "
           "9x9 PSD projections ms (timed alone) | SYRK 3s x 9\\|H\\| "
           "-> 3s x 3s ms (median / min) | ratio Hessian / SYRK | target | sgemm s x 3\\|H\\| x s (one "
           "block) ms "
           "| sgemm s x 3\\|H\\| x 6s (the six blocks, one call) ms | GFlop/s SYRK | GFlop/s six blocks | "
           "GFlop/s Hessian products |\n";
    std::cout << "|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|\n";
    for (const HessRow& h : hess_rows) {
      const double ratio = h.hess.med() / h.syrk.med();
      std::cout << "| " << h.model << " | " << h.scenario << " | " << h.s << " | " << h.h << " | "
                << bench::fixed(h.hess.med(), 1) << " / " << bench::fixed(h.hess.min(), 1) << " | "
                << bench::fixed(h.psd.med(), 1) << " | " << bench::fixed(h.syrk.med(), 1) << " / "
                << bench::fixed(h.syrk.min(), 1) << " | " << bench::fixed(ratio, 2)
                << " | ≤ 2: " << (ratio <= 2 ? "met" : "NOT met") << " | " << bench::fixed(h.block.med(), 1)
                << " | " << bench::fixed(h.fused.med(), 1) << " | "
                << bench::fixed(h.syrk_flops / (h.syrk.med() * 1e6), 1) << " | "
                << bench::fixed(h.fused_flops / (h.fused.med() * 1e6), 1) << " | "
                << bench::fixed(h.hess_flops / (h.hess.med() * 1e6), 1) << " |\n";
    }
    std::cout
        << "\nMedian / min of " << opt.reps
        << " timed repetitions after one warm-up. distortion_hessian(JT, projected = true, all_samples = "
           "false): the 9x9 PSD projections on H (also timed alone: sd_hessian_psd at the |H| samples, the "
           "same "
           "OpenMP loop), the float W matrix (3|H| x 6s), one cblas_sgemm "
           "s x 3|H| x 6s and the symmetric assembly into 3s x 3s doubles. SYRK: cblas_ssyrk of random "
           "floats M (9|H| x 3s), upper triangle of Mᵀ M, n(n+1)k flops with n = 3s, k = 9|H|. GFlop/s of "
           "the "
           "Hessian products: 36 s² |H| flops (the six s x s blocks) over the whole distortion_hessian "
           "time.\n";
  }

  std::cout << "\n## Per-iteration time at 900 DOF (targets: ≤ 150 ms bar, ≤ 400 ms animal)\n\n";
  std::cout << "| scenario | model | DOF | iterations averaged | mean ms / iteration (2..N) | target | met | "
               "mean ms "
               "/ iteration (1..N) | of which certificate (2..N) |\n";
  std::cout << "|---|---|---:|---|---:|---:|---|---:|---:|\n";
  bool any_target = false;
  for (const RunResult* r : on) {
    const auto t = kTargets.find(r->model);
    if (t == kTargets.end() || !r->ok) continue;
    any_target = true;
    const double m2 = mean_of(r->hist, &IterationRecord::ms_total, 1);
    const std::string avg =
        r->hist.size() >= 2 ? "2.." + std::to_string(r->hist.size()) : "none (1 iteration)";
    std::cout << "| " << r->scenario << " | " << r->model << " | " << r->dof << " | " << avg << " | "
              << bench::fixed(m2, 0) << " | ≤ " << bench::fixed(t->second, 0) << " | "
              << (std::isnan(m2)    ? "n/a"
                  : m2 <= t->second ? "met"
                                    : "NOT met")
              << " | " << bench::fixed(mean_of(r->hist, &IterationRecord::ms_total), 0) << " | "
              << bench::fixed(mean_of(r->hist, &IterationRecord::ms_certificate, 1), 0) << " |\n";
  }
  if (!any_target) std::cout << "| (no bar or animal scenario was run) | | | | | | | | |\n";

  for (const std::string& n : notes) std::cout << "\n- " << n;
  if (!notes.empty()) std::cout << "\n";

  if (!opt.markdown_only) {
    std::cout << "\n## Per-iteration details\n";
    for (const RunResult& r : runs) print_iterations(r);
  }
  return exit_code;
}
