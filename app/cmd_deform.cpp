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
#include "lidef/atomic_file.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/certificate_report.h"
#include "lidef/coefficients.h"
#include "lidef/continuation.h"
#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/mesh_export.h"
#include "lidef/mesh_fields.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/opencl_backend.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"
#include "lidef/vtk_export.h"
#include "param_flags.h"
#include "staged_outputs.h"

namespace lidef::cli {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::atomic<bool> g_stop{false};
extern "C" void on_sigint(int) {
  g_stop.store(true);
  std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C kills at once
}

// Signed volume of a closed triangle mesh (divergence theorem); the ratio deformed/rest is the global volume
// ratio of Fig. 12.
double mesh_volume(const MatX3d& V, const MatX3i& F) {
  double v = 0;
  for (Eigen::Index t = 0; t < F.rows(); ++t)
    v += V.row(F(t, 0)).dot(V.row(F(t, 1)).cross(V.row(F(t, 2)))) / 6.0;
  return v;
}

const char* kIterationsHeader =
    "iteration,energy_before,energy,e_dis,e_p2p,e_smooth,lambda_p2p,lambda_smooth,gradient_norm,step,step_"
    "norm,"
    "armijo_rejections,certificate_rejections,accepted,certified,min_sigma3_sampled,min_lower_bound,refined,"
    "max_handle_error,weight_action,ms_gradient,ms_hessian,ms_solve,ms_line_search,ms_certificate,ms_total,"
    "cg_steps,cg_scale";

std::string iteration_row(const IterationRecord& r) {
  std::ostringstream s;
  auto d = [](double x) { return format_double(x); };
  s << r.iteration << ',' << d(r.energy_before) << ',' << d(r.terms.total) << ',' << d(r.terms.dis) << ','
    << d(r.terms.p2p) << ',' << d(r.terms.smooth) << ',' << d(r.lambda_p2p) << ',' << d(r.lambda_smooth)
    << ',' << d(r.gradient_norm) << ',' << d(r.step) << ',' << d(r.step_norm) << ',' << r.armijo_rejections
    << ',' << r.certificate_rejections << ',' << (r.accepted ? 1 : 0) << ',' << (r.certified ? 1 : 0) << ','
    << d(r.min_sigma3) << ',' << d(r.min_lower_bound) << ',' << r.refined << ',' << d(r.max_handle_error)
    << ',' << '"' << r.weight_action << '"' << ',' << format_g(r.ms_gradient, 6) << ','
    << format_g(r.ms_hessian, 6) << ',' << format_g(r.ms_solve, 6) << ',' << format_g(r.ms_line_search, 6)
    << ',' << format_g(r.ms_certificate, 6) << ',' << format_g(r.ms_total, 6) << ',' << r.cg_steps << ','
    << d(r.cg_scale);
  return s.str();
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
      const std::string cache = o.cache.folder();
      PrecomputeSetup setup;
      setup.cache_dir = cache;
      setup.cache_max_bytes = o.cache.max_bytes();
      setup.log = log;
      setup.mesh = &model.mesh;  // the certified domain (params.domain "mesh": its triangles and solid)
      std::string backend_msg;
      const auto backend = select_backend(sc.params, cache, &backend_msg);
      std::cerr << "lidef deform: " << backend_msg << "\n";
      std::unique_ptr<DeformationSolver> solver_ptr;
      try {
        solver_ptr = std::make_unique<DeformationSolver>(model.cage, sc.params, setup, backend);
      } catch (const OpenCLError& e) {
        // The device was found but cannot hold this problem (or failed while uploading it): auto falls back.
        if (sc.params.backend != BackendKind::kAuto) throw;
        std::cerr << "lidef deform: backend: cpu (auto: " << e.what() << ")\n";
        solver_ptr = std::make_unique<DeformationSolver>(model.cage, sc.params, setup, cpu_backend());
      }
      DeformationSolver& solver = *solver_ptr;
      solver.set_handles(sc.sources, sc.targets, sc.path);
      if (!o.init.empty()) solver.set_initial_map(read_coefficients(o.init, model.cage), o.init);

      // --- Solve, one progress line per iteration; Ctrl-C stops cleanly.
      g_stop.store(false);
      std::signal(SIGINT, on_sigint);
      // Test hook (parameter test_interrupt_after): a real SIGINT after this many iterations.
      const int interrupt_after = sc.params.test_interrupt_after;
      if (!o.quiet)
        std::cout
            << "  it       energy      step   min sigma3 LB  cert  handle err   lambda1   lambda2      ms\n";
      auto on_iter = [&](const IterationRecord& r) {
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
      auto on_stage = [&](const std::string& line) {
        if (!o.quiet) std::cout << "  -- " << line << "\n" << std::flush;
      };
      PathSolveReport path_report;
      const SolveResult res = solve_to_targets(solver, sc.waypoints, sc.targets, sc.groups, on_iter, &g_stop,
                                               on_stage, &path_report);
      std::signal(SIGINT, SIG_DFL);

      // --- The written map is the solver's current (last certified) one; certify it again with leaves.
      auto t0 = Clock::now();
      const MatX3d y = solver.coefficients();
      const Certificate cert = solver.certify_current(true);
      if (!cert.certified)
        throw NumericalError("internal: the final map is not certified although every accepted step was (" +
                             cert.reason + ")");
      const SamplingParams sp = solver.sampling_params();
      CertificateReport report =
          make_certificate_report(cert, model.cage, model.mesh, y, sc.model_dir, "coefficients.txt", sp,
                                  solver.sampling(), solver.certify_params(false, true));
      // Evaluated in the solver's normalized frame (a model far from the origin would otherwise lose the
      // Jacobian's digits to the cancellation of large vertex coefficients), positions mapped back.
      const Frame& frame = solver.frame();
      MeshFields mf =
          mesh_fields(solver.normalized_basis(), solver.subspace().basis * solver.reduced_coefficients(),
                      frame.points_to_normalized(model.mesh.V), {/*sigma3=*/true});
      mf.V = frame.points_from_normalized(mf.V);
      const double ms_final = ms_since(t0);
      const VecXd herr = solver.handle_errors();
      const double max_err = herr.size() ? herr.maxCoeff() : 0.0;
      // handle_tolerance is relative to the model's size (deform_params.h).
      const double tolerance = sc.params.handle_tolerance * frame.scale;
      const double vol_ratio = mesh_volume(mf.V, model.mesh.F) / mesh_volume(model.mesh.V, model.mesh.F);

      // --- Outputs, all or nothing.
      StagedOutputs out(o.out);
      write_file_atomic(out.path("coefficients.txt"), [&](std::ostream& s) { write_coefficients(s, y); });
      write_file_atomic(out.path("deformed.obj"), [&](std::ostream& s) {
        write_obj(s, mf.V, model.mesh.F, "lidef deform " + sc.name + ": last certified map");
      });
      write_mesh_vtp(out.path("deformed.vtp"), mf.V, model.mesh.F,
                     {{"E_iso_minus_6", mf.e_iso},
                      {"detJ", mf.det_j},
                      {"sigma3", mf.sigma3},
                      {"sigma1", mf.sigma1},
                      {"distortion", mf.distortion}});
      out.path("certificate.json");
      out.path("voxels.csv");
      write_certificate_files(out.staging_dir(), report);
      write_leaves_vtu(out.path("leaves.vtu"), cert.leaves);
      if (o.grid > 0)
        write_field_vti(out.path("field.vti"), model.cage, solver.basis(), y, solver.sampling(), o.grid);
      write_file_atomic(out.path("iterations.csv"), [&](std::ostream& s) {
        s << kIterationsHeader << "\n";
        for (const IterationRecord& r : solver.history()) s << iteration_row(r) << "\n";
      });
      Scenario used = sc;
      write_scenario(out.path("scenario.json"), used);
      const EnergyTerms et = solver.energy();
      nlohmann::ordered_json sj;
      sj["scenario"] = sc.name;
      sj["model"] = sc.model;
      sj["converged"] = res.converged();
      sj["stop_reason"] = to_string(res.reason);
      sj["continuation"] = {{"strategies", path_report.strategies},
                            {"intermediate_stages", path_report.stages},
                            {"shortened_stages", path_report.stage_retries},
                            {"max_group_rotation_deg", path_report.max_angle_deg},
                            {"path_segments", path_report.segments},
                            {"path_reached", path_report.path_reached}};
      const UnreachabilityProof& un = path_report.unreachable;
      sj["unreachable"] = {{"proven", un.proven},
                           {"kind", un.kind},
                           {"reason", un.reason},
                           {"handle_matrix_condition", un.condition},
                           {"least_squares_residual", un.residual}};
      if (un.kind == "orientation")
        sj["unreachable"]["fold"] = {{"point", {un.point.x(), un.point.y(), un.point.z()}},
                                     {"sigma_min_least_squares", un.sigma_min},
                                     {"jacobian_change_bound", un.jacobian_bound}};
      sj["message"] = res.message;
      sj["iterations"] = static_cast<int>(solver.history().size());
      sj["certified"] = cert.certified;
      sj["min_sigma3_lower_bound"] = cert.min_lower_bound;
      sj["min_sigma3_sampled"] = cert.min_sigma3_center;
      // Bounded distortion: the certified upper bounds over the leaves, the sampled maximum over the mesh
      // vertices, and the target (max_distortion, 0: none).
      sj["max_sigma1_upper_bound"] = cert.max_sigma1_upper_bound;
      sj["max_distortion_upper_bound"] = cert.max_distortion_upper_bound;
      double max_k_vertices = 0;  // NaN (σ3 ≤ 0) never occurs at a certified map's covered vertices
      for (Eigen::Index i = 0; i < mf.distortion.size(); ++i)
        if (std::isfinite(mf.distortion(i))) max_k_vertices = std::max(max_k_vertices, mf.distortion(i));
      sj["max_distortion_vertices"] = max_k_vertices;
      sj["max_distortion"] = sc.params.max_distortion;
      sj["mesh_coverage"] = report.mesh_coverage;
      sj["domain"] = report.domain;
      sj["max_handle_error"] = max_err;
      sj["handles_reached"] = max_err <= tolerance;
      sj["handle_tolerance"] = sc.params.handle_tolerance;
      sj["handle_tolerance_model_units"] = tolerance;
      sj["frame"] = {{"center", {frame.center.x(), frame.center.y(), frame.center.z()}},
                     {"scale", frame.scale}};
      sj["global_volume_ratio"] = vol_ratio;
      sj["energy"] = {{"total", et.total}, {"dis", et.dis}, {"p2p", et.p2p}, {"smooth", et.smooth}};
      sj["final_weights"] = {{"lambda_p2p", solver.weights().p2p},
                             {"lambda_smooth", solver.weights().smooth}};
      sj["dof"] = 3 * solver.subspace().size();
      sj["samples"] = solver.sampling().size();
      sj["hessian_samples"] = static_cast<int>(solver.sampling().hessian_subset.size());
      sj["handles"] = sc.num_handles();
      sj["time_s"] = {{"preprocess", solver.preprocess_seconds()},
                      {"solve", res.seconds},
                      {"final_certificate_and_fields", ms_final / 1000},
                      {"total", ms_since(t_start) / 1000}};
      sj["threads"] = omp_get_max_threads();
      sj["backend"] = solver.backend().name();
      sj["parameters"] = params_to_json(sc.params);
      const std::string summary = sj.dump(2) + "\n";
      write_file_atomic(out.path("summary.json"), [&](std::ostream& s) { s << summary; });
      out.commit(o.grid > 0 ? std::vector<std::string>{} : std::vector<std::string>{"field.vti"});

      std::cout << "lidef deform: " << sc.name << ": " << to_string(res.reason) << " (" << res.message
                << ") after " << solver.history().size() << " iterations, " << format_g(res.seconds, 3)
                << " s\n"
                << "  max handle error " << format_g(max_err, 3)
                << (max_err <= tolerance ? " (reached)" : " (NOT reached)") << ", global volume ratio "
                << format_g(vol_ratio, 5) << "\n"
                << (max_err <= tolerance
                        ? ""
                        : std::string("  ") + (un.proven ? "PROVEN: " : "") + un.reason + "\n")
                << "  CERTIFIED locally injective on "
                << (solver.sampling().domain == "mesh" ? "the whole mesh and its solid (" : "the union of ")
                << cert.voxels << (solver.sampling().domain == "mesh" ? " voxels)" : " voxels")
                << ", min lower bound of sigma3 " << format_g(cert.min_lower_bound, 4) << ", mesh coverage "
                << format_g(100 * report.mesh_coverage, 3) << "%\n"
                << "  wrote " << out.final_path("")
                << "{coefficients.txt, deformed.obj, deformed.vtp, certificate.json, "
                   "voxels.csv, leaves.vtu, iterations.csv, summary.json, scenario.json"
                << (o.grid > 0 ? ", field.vti" : "") << "}\n";
      return res.targets_met() ? kOk : kStoppedEarly;
    };
  });
}

}  // namespace lidef::cli
