// lidef deform: the main job. Reads a handle scenario, runs the certified projected Newton solver and writes
// the last certified map with its certificate, ready for ParaView.
#include <omp.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <type_traits>
#include <variant>

#include "cache_flags.h"
#include "commands.h"
#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/deform_outputs.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/coefficients.h"
#include "lidef/deform.h"
#include "lidef/deform_params.h"
#include "lidef/domain_sampling.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/scenario.h"
#include "param_flags.h"

namespace lidef::cli {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_sigint(int) {
  g_stop.store(true);
  std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C kills at once
}

}  // namespace

void add_deform_command(CLI::App& app, Action& action) {
  struct Opts {
    std::string scenario, out, models, init;
    CacheFlags cache;
    int grid = 0;
    bool quiet = false;
    ParamOverrides overrides;  // parameter name → text from the command line
  };
  auto opts = std::make_shared<Opts>();
  auto* sub =
      app.add_subcommand("deform", "Deform a model to a handle scenario; every accepted step is certified");
  sub->add_option("SCENARIO", opts->scenario, "Scenario JSON (model, handles, optional parameters)")
      ->required();
  sub->add_option("--out", opts->out, "Output folder (created if missing)")->required();
  sub->add_option("--models", opts->models, "Folder that holds the model named in the scenario");
  sub->add_option(
      "--init", opts->init,
      "Start from this certified map (a coefficients.txt of an earlier run with the same reduced_dof) "
      "instead of the identity");
  add_cache_flags(sub, &opts->cache);
  sub->add_option("--grid", opts->grid,
                  "Also write field.vti with this many points along the longest axis (0 = no)")
      ->capture_default_str();
  sub->add_flag("--quiet", opts->quiet, "No per-iteration progress lines");
  // One flag per row of the parameter table: the scenario's "parameters" and these flags use the same names.
  add_param_flags(sub, &opts->overrides, "Parameters: ");
  sub->footer(
      "Writes into --out (all files appear together, or none): coefficients.txt (#V+#F rows, readable by\n"
      "'lidef eval/certify'), deformed.obj, deformed.vtp (point data E_iso_minus_6, detJ, sigma3, sigma1, "
      "distortion = sigma1/sigma3),\n"
      "certificate.json + voxels.csv + leaves.vtu (certificate of the written map), iterations.csv, "
      "summary.json,\n"
      "scenario.json (the scenario with the parameters used). Ctrl-C stops after the current line-search "
      "trial\n"
      "and writes the last certified map. Exit code: 0 targets reached (stop reason converged, or\n"
      "reached_not_converged: handles within tolerance, Newton stopped before its convergence test), 1 "
      "stopped\n"
      "early (the output is still the last certified map), 2 error. When the handles pin the subspace, the\n"
      "run first checks whether the targets are provably out of reach (every reaching map folds:\n"
      "blocked_by_certificate; no map reaches them: targets_unreachable) and then tries only a direct "
      "solve;\n"
      "summary.json's \"unreachable\" says what was proven, or why nothing was. Parameters: "
      "docs/parameters.md;\nsolver: docs/solver.md.");
  sub->callback([opts, &action] {
    action = [opts]() -> int {
      const Opts& o = *opts;
      const auto t_start = Clock::now();
      // --- Inputs and parameters; nothing is written before they all check out.
      Scenario sc = read_scenario(o.scenario, o.models);
      apply_param_overrides(sc.params, o.overrides, &sc.params_given);
      validate_params(sc.params, o.scenario);
      if (o.grid != 0 && (o.grid < 2 || o.grid > 1024)) throw InputError("--grid", "must be 0 or in 2..1024");
      {
        std::error_code ec;
        if (std::filesystem::exists(o.out, ec) && !std::filesystem::is_directory(o.out, ec))
          throw InputError(o.out, "exists and is not a folder");
        // A parent that is a file would only fail after the solve: check before spending the time.
        for (std::filesystem::path q = std::filesystem::absolute(o.out, ec).parent_path(); !q.empty();
             q = q.parent_path()) {
          if (std::filesystem::exists(q, ec)) {
            if (!std::filesystem::is_directory(q, ec))
              throw InputError(o.out, q.string() + " is not a folder");
            break;
          }
          if (q == q.parent_path()) break;
        }
      }
      if (sc.params.threads > 0) omp_set_num_threads(sc.params.threads);
      // A mesh file as the model: its automatic cage, made once and cached (lidef/cage/auto_cage.h).
      const Model model = load_model(resolve_model_path(
          sc.model_dir, [](const std::string& m) { std::cerr << "lidef deform: " << m << "\n"; },
          o.cache.folder()));
      for (size_t k = 0; k < model.report.warnings.size() && k < 5; ++k)
        std::cerr << "lidef deform: warning: " << model.report.warnings[k].str() << "\n";
      if (model.report.warnings.size() > 5)
        std::cerr << "lidef deform: warning: ... and " << model.report.warnings.size() - 5
                  << " more (run 'lidef check " << sc.model_dir << "')\n";

      auto log = [&](const std::string& s) {
        if (!o.quiet) std::cerr << "lidef deform: " << s << "\n";
      };
      DeformOptions options;
      options.cache_dir = o.cache.folder();
      options.cache_max_bytes = o.cache.max_bytes();
      options.log = log;
      options.waypoints = sc.waypoints;
      options.groups = sc.groups;
      options.handles_source = sc.path;
      if (!o.init.empty()) {
        options.initial_map = read_coefficients(o.init, model.cage);
        options.initial_map_source = o.init;
      }
      std::string backend_msg;
      options.backend = select_backend(sc.params, options.cache_dir, &backend_msg);
      std::cerr << "lidef deform: " << backend_msg << "\n";

      // --- Solve, one progress line per iteration; Ctrl-C stops cleanly.
      g_stop.store(false);
      std::signal(SIGINT, on_sigint);
      options.stop = &g_stop;
      // Test hook (parameter test_interrupt_after): a real SIGINT after this many iterations.
      const int interrupt_after = sc.params.test_interrupt_after;
      if (!o.quiet)
        std::cout
            << "  it       energy      step   min sigma3 LB  cert  handle err   lambda1   lambda2      ms\n";
      bool iterated = false;
      options.on_iteration = [&](const IterationRecord& r) {
        iterated = true;
        if (!o.quiet) {
          char line[256];
          std::snprintf(
              line, sizeof line, "%4d  %11.7g  %8.3g  %13.4g  %4s  %10.3g  %8.3g  %8.3g  %6.0f %s\n",
              r.iteration, r.terms.total, r.step, r.min_lower_bound, r.certified ? "yes" : "NO",
              r.max_handle_error, r.lambda_p2p, r.lambda_smooth, r.ms_total, r.weight_action.c_str());
          std::cout << line << std::flush;
        }
        if (interrupt_after > 0 && r.iteration == interrupt_after) std::raise(SIGINT);
        return !g_stop.load();
      };
      options.on_stage = [&](const std::string& line) {
        if (!o.quiet) std::cout << "  -- " << line << "\n" << std::flush;
      };
      // The solver, the solve (continuation as needed) and the final certificate with leaves: lidef/deform.h.
      DeformResult result;
      try {
        result = deform(model, sc.sources, sc.targets, sc.params, options);
      } catch (const OpenCLError& e) {
        // The device was found but cannot hold this problem (or failed while uploading it): auto falls back.
        if (sc.params.backend != BackendKind::kAuto || iterated) throw;
        std::cerr << "lidef deform: backend: cpu (auto: " << e.what() << ")\n";
        options.backend = cpu_backend();
        result = deform(model, sc.sources, sc.targets, sc.params, options);
      }
      std::signal(SIGINT, SIG_DFL);
      const SolveResult& res = result.solve;
      const Certificate& cert = result.certificate;
      const UnreachabilityProof& un = result.path.unreachable;
      const double max_err = result.max_handle_error;
      const double tolerance = result.handle_tolerance;

      // --- Outputs, all or nothing (lidef/analysis/deform_outputs.h).
      DeformOutputOptions out_options;
      out_options.grid = o.grid;
      out_options.total_seconds = ms_since(t_start) / 1000;
      const DeformOutputs out = write_deform_outputs(o.out, model, sc, result, out_options);
      const double vol_ratio = out.volume_ratio;

      std::cout << "lidef deform: " << sc.name << ": " << to_string(res.reason) << " (" << res.message
                << ") after " << result.iterations << " iterations, " << format_g(res.seconds, 3) << " s\n"
                << "  max handle error " << format_g(max_err, 3)
                << (max_err <= tolerance ? " (reached)" : " (NOT reached)") << ", global volume ratio "
                << (std::isfinite(vol_ratio) ? format_g(vol_ratio, 5) : std::string("n/a (no faces)")) << "\n"
                << (max_err <= tolerance
                        ? ""
                        : std::string("  ") + (un.proven ? "PROVEN: " : "") + un.reason + "\n")
                << (out.global.verdict == GlobalInjectivity::Verdict::kInjective
                        ? "  CERTIFIED injective on "
                        : "  CERTIFIED locally injective on ")
                << (result.sampling.domain == "mesh"
                        ? "the domain (" + mesh_domain_of(model.mesh.V, model.mesh.F).description() + ": "
                        : std::string("the union of "))
                << cert.voxels << (result.sampling.domain == "mesh" ? " voxels)" : " voxels")
                << ", min lower bound of sigma3 " << format_bound(cert.min_lower_bound, false, 4)
                << ", mesh coverage " << format_g(100 * out.mesh_coverage, 3) << "%\n"
                << (cert.targets().any() ? "  " + distortion_targets_summary(cert) + "\n" : "")
                << (out.global.verdict == GlobalInjectivity::Verdict::kInjective
                        ? "  " + no_overlap_words(out.global) + "\n"
                    : out.global.verdict == GlobalInjectivity::Verdict::kOverlap
                        ? "  locally injective only: " + out.global.reason + "\n"
                        : "  global injectivity not decided: " + out.global.reason + "\n")
                << "  wrote " << (std::filesystem::path(o.out) / "").string() << "{";
      for (std::size_t k = 0; k < out.files.size(); ++k) std::cout << (k ? ", " : "") << out.files[k];
      std::cout << "}\n";
      return res.targets_met() ? kOk : kStoppedEarly;
    };
  });
}

}  // namespace lidef::cli
