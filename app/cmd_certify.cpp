// lidef certify: the local-injectivity certificate of a cage map, written as files for reports and ParaView.
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "lidef/atomic_file.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/certificate_report.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/octree_certifier.h"
#include "lidef/opencl_backend.h"
#include "lidef/sampling.h"
#include "lidef/subspace.h"
#include "lidef/vtk_export.h"
#include "staged_outputs.h"

namespace lidef::cli {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::string g6(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", x);
  return buf;
}

// Upper limits that keep a typo from exhausting memory (documented in --help).
constexpr long kMaxVoxels = 5000000;
constexpr int kMaxDepth = 20;
constexpr int kMaxGrid = 1024;

}  // namespace

void add_certify_command(CLI::App& app, Action& action) {
  struct Opts {
    std::string model, coeffs, out, bound = "third", backend = "cpu";
    int max_depth = 6, voxels = 30000, grid = 64, threads = 0;
    double voxel_side = 0, safety = 1.5;
    long max_refined = 200000;
  };
  auto opts = std::make_shared<Opts>();
  auto* sub =
      app.add_subcommand("certify", "Certify local injectivity of a cage map (Lipschitz bounds + octree)");
  sub->add_option("MODEL_DIR", opts->model,
                  "Model folder (cage.obj|off, mesh.obj|off), or a mesh file (automatic cage)")
      ->required();
  sub->add_option("--coeffs", opts->coeffs,
                  "Coefficient file: #V+#F rows 'x y z', vertex rows first; or the word 'identity'")
      ->required();
  sub->add_option("--out", opts->out, "Output folder (created if missing)")->required();
  sub->add_option("--bound", opts->bound, "Lipschitz bound of sigma3: 'first' (eq. 17) or 'third' (eq. 21)")
      ->capture_default_str();
  sub->add_option("--max-depth", opts->max_depth,
                  "Octree levels below the base voxels (0.." + std::to_string(kMaxDepth) + ")")
      ->capture_default_str();
  sub->add_option("--voxels", opts->voxels, "Target number of base voxels (the side is searched to match)")
      ->capture_default_str();
  auto* side_opt = sub->add_option("--voxel-side", opts->voxel_side, "Base voxel side (overrides --voxels)");
  sub->add_option("--safety", opts->safety, "Voxel center to cage distance >= safety * voxel radius (> 1)")
      ->capture_default_str();
  sub->add_option("--max-refined", opts->max_refined,
                  "Budget of child voxels evaluated in all; exhausted = not certified")
      ->capture_default_str();
  sub->add_option("--grid", opts->grid, "Points along the longest axis of field.vti (0 = no field.vti)")
      ->capture_default_str();
  sub->add_option("--threads", opts->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  sub->add_option("--backend", opts->backend,
                  "Compute backend: cpu, opencl or auto (OpenCL when a device with fp64 exists, else CPU)")
      ->check(CLI::IsMember({"cpu", "opencl", "auto"}))
      ->capture_default_str();
  sub->footer(
      "Writes into --out: certificate.json (verdict, counts, parameters; deterministic), voxels.csv (one row "
      "per\n"
      "octree leaf), leaves.vtu (the leaves for ParaView), field.vti (sigma1, sigma3, detJ, E_iso on a grid) "
      "and\n"
      "timings.json (wall-clock times, kept out of certificate.json so that it is byte-identical across "
      "runs).\n"
      "All files appear together or not at all. Exit code: 0 certified, 1 not certified, 2 error.\n"
      "The certificate covers the union of the base voxels only; certificate.json reports how many mesh\n"
      "vertices lie outside it. Details: docs/certificate-outputs.md.");
  sub->callback([opts, side_opt, &action] {
    action = [opts, side_opt] {
      const Opts& o = *opts;
      const auto t_start = Clock::now();
      // --- Parameters first: a bad option costs nothing and writes nothing.
      CertifyParams cp;
      try {
        cp.bound = lipschitz_bound_from_string(o.bound);
      } catch (const InputError& e) {
        throw InputError("--bound", e.message());
      }
      if (o.max_depth < 0 || o.max_depth > kMaxDepth)
        throw InputError("--max-depth", "must be in 0.." + std::to_string(kMaxDepth) + " (got " +
                                            std::to_string(o.max_depth) + ")");
      cp.max_depth = o.max_depth;
      if (o.max_refined < 0) throw InputError("--max-refined", "must be >= 0");
      cp.max_refined_voxels = o.max_refined;
      SamplingParams sp;
      if (side_opt->count() > 0) {
        if (!(o.voxel_side > 0) || !std::isfinite(o.voxel_side))
          throw InputError("--voxel-side", "must be a positive number (got " + g6(o.voxel_side) + ")");
        sp.voxel_side = o.voxel_side;
      } else {
        if (o.voxels < 1 || o.voxels > kMaxVoxels)
          throw InputError("--voxels", "must be in 1.." + std::to_string(kMaxVoxels) + " (got " +
                                           std::to_string(o.voxels) + ")");
        sp.target_count = o.voxels;
      }
      if (!(o.safety > 1) || !std::isfinite(o.safety))
        throw InputError("--safety", "must be a number > 1 (got " + g6(o.safety) + ")");
      sp.safety = o.safety;
      if (o.grid != 0 && (o.grid < 2 || o.grid > kMaxGrid))
        throw InputError("--grid", "must be 0 (no field.vti) or in 2.." + std::to_string(kMaxGrid) +
                                       " (got " + std::to_string(o.grid) + ")");
      if (o.threads < 0) throw InputError("--threads", "must be >= 0");
      if (o.threads > 0) omp_set_num_threads(o.threads);

      // --- Inputs.
      auto t0 = Clock::now();
      // A mesh file as the model: its automatic cage, made once and cached (lidef/cage/auto_cage.h).
      const Model model = load_model(resolve_model_path(
          o.model, [](const std::string& m) { std::cerr << "lidef certify: " << m << "\n"; }));
      for (size_t k = 0; k < model.report.warnings.size() && k < 5; ++k)
        std::cerr << "lidef certify: warning: " << model.report.warnings[k].str() << "\n";
      if (model.report.warnings.size() > 5)
        std::cerr << "lidef certify: warning: ... and " << model.report.warnings.size() - 5
                  << " more (run 'lidef check " << o.model << "')\n";
      const MatX3d y = read_coefficients(o.coeffs, model.cage);
      const double ms_load = ms_since(t0);
      if (sp.voxel_side > 0) {
        const double estimate = model.cage.volume / std::pow(sp.voxel_side, 3);
        if (estimate > kMaxVoxels)
          throw InputError("--voxel-side", g6(sp.voxel_side) + " gives about " + g6(estimate) +
                                               " voxels in this cage (limit " + std::to_string(kMaxVoxels) +
                                               ")");
      }

      // --- Sampling and certificate.
      t0 = Clock::now();
      const VoxelSampling sampling = sample_voxels(model.cage, sp);
      const double ms_sampling = ms_since(t0);
      if (sampling.size() == 0)
        throw InputError(o.model, "no voxel of side " + g6(sampling.side) +
                                      " fits inside the cage at safety " + g6(sp.safety) +
                                      " (use a smaller --voxel-side or more --voxels)");
      OctreeCertifier certifier(model.cage, sampling);
      std::string backend_msg;
      const auto backend = select_backend(o.backend, default_cache_dir(), &backend_msg);
      std::cerr << "lidef certify: " << backend_msg << "\n";
      certifier.set_backend(*backend);
      t0 = Clock::now();
      const Certificate cert = certifier.certify(y, cp);
      const double ms_certify = ms_since(t0);
      CertificateReport report =
          make_certificate_report(cert, model.cage, model.mesh.V, y, o.model, o.coeffs, sp, sampling, cp);

      // --- Outputs, all or nothing.
      t0 = Clock::now();
      StagedOutputs out(o.out);
      out.path("voxels.csv");
      out.path("certificate.json");
      write_certificate_files(out.staging_dir(), report);
      write_leaves_vtu(out.path("leaves.vtu"), cert.leaves);
      const double ms_files = ms_since(t0);
      FieldGrid field;
      double ms_field = 0;
      if (o.grid > 0) {
        t0 = Clock::now();
        field = write_field_vti(out.path("field.vti"), model.cage, certifier.basis(), y, sampling, o.grid);
        ms_field = ms_since(t0);
      }
      nlohmann::ordered_json tj;
      tj["threads"] = omp_get_max_threads();
      tj["backend"] = backend->name();
      tj["load_ms"] = ms_load;
      tj["sampling_ms"] = ms_sampling;
      tj["precompute_ms"] = certifier.precompute_seconds() * 1000;
      tj["certify_ms"] = ms_certify;
      tj["certify_breakdown_ms"] = {{"jacobian", cert.ms_jacobian},
                                    {"sigma", cert.ms_sigma},
                                    {"bound", cert.ms_bound},
                                    {"refine", cert.ms_refine},
                                    {"total", cert.ms_total}};
      tj["certificate_files_ms"] = ms_files;
      tj["field_ms"] = ms_field;
      tj["total_ms"] = ms_since(t_start);
      const std::string timings = tj.dump(2) + "\n";
      write_file_atomic(out.path("timings.json"), [&](std::ostream& s) { s << timings; });
      out.commit(o.grid > 0 ? std::vector<std::string>{} : std::vector<std::string>{"field.vti"});

      // --- Summary.
      const char* bound = to_string(cert.bound);
      if (cert.certified)
        std::cout << "lidef certify: CERTIFIED locally injective on the union of " << cert.voxels
                  << " voxels (" << bound << "-order bound)\n";
      else
        std::cout << "lidef certify: NOT CERTIFIED (" << bound << "-order bound): " << cert.reason << "\n";
      std::cout << "  voxels " << cert.voxels << " (side " << g6(cert.voxel_side) << "), leaves "
                << cert.num_leaves << ", refined " << cert.refined << ", depth used " << cert.max_depth_used
                << " of " << cp.max_depth << "\n";
      std::cout << "  min sigma3 at centers " << g6(cert.min_sigma3_center) << ", min margin "
                << g6(cert.min_margin) << ", min lower bound of sigma3 " << g6(cert.min_lower_bound) << "\n";
      std::cout << "  mesh coverage " << g6(100 * report.mesh_coverage) << "% ("
                << report.mesh_vertices_uncovered << " of " << report.mesh_vertices
                << " mesh vertices outside the voxels"
                << (report.mesh_vertices_uncovered > 0 ? ": not covered by the certificate" : "") << ")\n";
      if (!cert.failing.empty()) {
        const CertLeaf& f = cert.failing.front();
        std::cout << "  first failing leaf: center (" << g6(f.center.x()) << ", " << g6(f.center.y()) << ", "
                  << g6(f.center.z()) << "), depth " << f.depth << ", sigma3 " << g6(f.sigma3) << ", L "
                  << g6(f.L) << ", margin " << g6(f.margin) << "\n";
      }
      std::cout << "  time: sampling " << g6(ms_sampling) << " ms, precompute "
                << g6(certifier.precompute_seconds() * 1000) << " ms, certify " << g6(ms_certify) << " ms";
      if (o.grid > 0)
        std::cout << ", field " << field.dims[0] << "x" << field.dims[1] << "x" << field.dims[2] << " "
                  << g6(ms_field) << " ms";
      std::cout << ", total " << g6(ms_since(t_start)) << " ms (" << omp_get_max_threads() << " threads)\n";
      std::cout << "  wrote " << out.final_path("") << "{certificate.json, voxels.csv, leaves.vtu"
                << (o.grid > 0 ? ", field.vti" : "") << ", timings.json}\n";
      return cert.certified ? kOk : kNotCertified;
    };
  });
}

}  // namespace lidef::cli
