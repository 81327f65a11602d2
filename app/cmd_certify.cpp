// lidef certify: the local-injectivity certificate of a cage map, written as files for reports and ParaView.
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <set>

#include "cache_flags.h"
#include "commands.h"
#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/vtk_export.h"
#include "lidef/atomic_file.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/coefficients.h"
#include "lidef/domain_sampling.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/normalization.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/sampling.h"
#include "lidef/staged_outputs.h"
#include "lidef/subspace.h"
#include "param_flags.h"

namespace lidef::cli {
namespace {

// Upper limits that keep a typo from exhausting memory (documented in --help); the parameter table bounds the
// others (samples <= 5e6, max_depth <= 20).
constexpr long kMaxVoxels = 5000000;
constexpr int kMaxGrid = 1024;

// The rows of the parameter table that shape a certificate (the others belong to the solver).
bool certify_param(const ParamInfo& p) {
  static const std::set<std::string> names = {"samples",    "voxel_side",      "safety",     "max_depth",
                                              "domain",     "max_refined",     "bound",      "threads",
                                              "backend",    "bound_tolerance", "refinement", "max_distortion",
                                              "max_sigma1", "min_sigma3"};
  return names.count(p.name) > 0;
}

}  // namespace

void add_certify_command(CLI::App& app, Action& action) {
  struct Opts {
    std::string model, coeffs, out;
    int grid = 64;
    ParamOverrides overrides;
    CacheFlags cache;
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
  sub->add_option("--grid", opts->grid, "Points along the longest axis of field.vti (0 = no field.vti)")
      ->capture_default_str();
  // The same names as `lidef deform` and a scenario's "parameters" (one table, docs/parameters.md).
  add_param_flags(sub, &opts->overrides, "Parameters: ", certify_param);
  add_cache_flags(sub, &opts->cache);
  sub->footer(
      "Writes into --out: certificate.json (verdict, counts, parameters; deterministic), voxels.csv (one row "
      "per\n"
      "octree leaf), leaves.vtu (the leaves for ParaView), field.vti (sigma1, sigma3, detJ, E_iso on a grid) "
      "and\n"
      "timings.json (wall-clock times, kept out of certificate.json so that it is byte-identical across "
      "runs).\n"
      "All files appear together or not at all. Exit code: 0 certified, 1 not certified, 2 error.\n"
      "--domain mesh (default): the voxels cover the mesh's triangles and solid, refined toward the cage;\n"
      "--domain voxels: the paper's grid only (certificate.json reports how many mesh vertices lie "
      "outside).\n"
      "Details: docs/outputs.md.");
  sub->callback([opts, &action] {
    action = [opts] {
      const Opts& o = *opts;
      const auto t_start = Clock::now();
      // --- Parameters first: a bad option costs nothing and writes nothing.
      DeformParams dp;
      apply_param_overrides(dp, o.overrides);
      // Here an explicit voxel side must be a side (the table's 0 means "search from samples").
      if (o.overrides.count("voxel_side") && !(dp.voxel_side > 0))
        throw InputError("--voxel-side", "must be a positive number (got " + format_g(dp.voxel_side) + ")");
      const CertifyParams cp = certify_params_of(dp, false, true);
      const SamplingParams sp = sampling_params_of(dp);
      if (o.grid != 0 && (o.grid < 2 || o.grid > kMaxGrid))
        throw InputError("--grid", "must be 0 (no field.vti) or in 2.." + std::to_string(kMaxGrid) +
                                       " (got " + std::to_string(o.grid) + ")");
      if (dp.threads > 0) omp_set_num_threads(dp.threads);

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
          throw InputError("--voxel-side", format_g(sp.voxel_side) + " gives about " + format_g(estimate) +
                                               " voxels in this cage (limit " + std::to_string(kMaxVoxels) +
                                               ")");
      }

      // --- Sampling and certificate.
      t0 = Clock::now();
      // The sampling through the precomputation cache: the same voxels, byte for byte, either way.
      const PrecomputeCache cache(o.cache.folder(), o.cache.max_bytes());
      CacheEvent cache_event;
      const VoxelSampling sampling = cached_sample_for_domain(to_string(dp.domain), model.cage, model.mesh.V,
                                                              model.mesh.F, sp, cache, &cache_event);
      const double ms_sampling = ms_since(t0);
      if (sampling.size() == 0)
        throw InputError(o.model, "no voxel of side " + format_g(sampling.side) +
                                      " fits inside the cage at safety " + format_g(sp.safety) +
                                      " (use a smaller --voxel-side or more --samples)");
      // In the model's normalized frame, as lidef deform certifies (normalization.h).
      NormalizedCertifier certifier(model.cage, sampling);
      std::string backend_msg;
      const auto backend = select_backend(dp, o.cache.folder(), &backend_msg);
      std::cerr << "lidef certify: " << backend_msg << "\n";
      certifier.set_backend(*backend);
      t0 = Clock::now();
      const Certificate cert = certifier.certify(y, cp);
      const double ms_certify = ms_since(t0);
      CertificateReport report =
          make_certificate_report(cert, model.cage, model.mesh, y, o.model, o.coeffs, sp, sampling, cp);

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
        field = write_field_vti(out.path("field.vti"), model.cage, HarmonicBasis(model.cage), y, sampling,
                                o.grid);
        ms_field = ms_since(t0);
      }
      nlohmann::ordered_json tj;
      tj["threads"] = omp_get_max_threads();
      tj["backend"] = backend->name();
      tj["load_ms"] = ms_load;
      tj["sampling_ms"] = ms_sampling;
      tj["sampling_cache"] = cache_event.outcome;
      tj["precompute_ms"] = certifier.precompute_seconds() * 1000;
      tj["certify_ms"] = ms_certify;
      tj["certify_breakdown_ms"] = {{"jacobian", cert.ms_jacobian},
                                    {"sigma", cert.ms_sigma},
                                    {"bound", cert.ms_bound},
                                    {"refine", cert.ms_refine},
                                    {"total", cert.ms_total}};
      tj["global_injectivity_ms"] = report.global.ms;
      tj["certificate_files_ms"] = ms_files;
      tj["field_ms"] = ms_field;
      tj["total_ms"] = ms_since(t_start);
      const std::string timings = tj.dump(2) + "\n";
      write_file_atomic(out.path("timings.json"), [&](std::ostream& s) { s << timings; });
      out.commit(o.grid > 0 ? std::vector<std::string>{} : std::vector<std::string>{"field.vti"});

      // --- Summary.
      const char* bound = to_string(cert.bound);
      const GlobalInjectivity& g = report.global;
      if (cert.certified && sampling.domain == "mesh" && g.verdict == GlobalInjectivity::Verdict::kInjective)
        std::cout << "lidef certify: CERTIFIED injective on the whole mesh and its solid (" << cert.num_leaves
                  << " leaves, " << report.leaves_meeting_domain << " meeting it; " << bound
                  << "-order bound; " << no_overlap_words(g) << ")\n";
      else if (cert.certified && sampling.domain == "mesh" &&
               g.verdict == GlobalInjectivity::Verdict::kOverlap)
        std::cout << "lidef certify: CERTIFIED locally injective on the whole mesh and its solid — but "
                  << g.reason << "\n";
      else if (cert.certified && sampling.domain == "mesh")
        std::cout << "lidef certify: CERTIFIED locally injective on the whole mesh and its solid ("
                  << cert.num_leaves << " leaves, " << report.leaves_meeting_domain << " meeting it; "
                  << bound << "-order bound); global injectivity not decided: " << g.reason << "\n";
      else if (cert.certified)
        std::cout << "lidef certify: CERTIFIED locally injective on the union of " << cert.voxels
                  << " voxels (" << bound << "-order bound)\n";
      else
        std::cout << "lidef certify: NOT CERTIFIED (" << bound << "-order bound): " << cert.reason << "\n";
      std::cout << "  voxels " << cert.voxels << " (side " << format_g(cert.voxel_side) << "), leaves "
                << cert.num_leaves << ", refined " << cert.refined << ", depth used " << cert.max_depth_used
                << " of " << cp.max_depth << "\n";
      std::cout << "  min sigma3 at centers " << format_g(cert.min_sigma3_center) << ", min margin "
                << format_bound(cert.min_margin, false) << ", min lower bound of sigma3 "
                << format_bound(cert.min_lower_bound, false) << "\n";
      if (cert.targets().any()) std::cout << "  " << distortion_targets_summary(cert) << "\n";
      std::cout << "  mesh coverage " << format_g(100 * report.mesh_coverage) << "% ("
                << report.mesh_vertices_uncovered << " of " << report.mesh_vertices
                << " mesh vertices outside the voxels"
                << (report.mesh_vertices_uncovered > 0 ? ": not covered by the certificate" : "") << ")\n";
      if (!cert.failing.empty()) {
        const CertLeaf& f = cert.failing.front();
        std::cout << "  first failing leaf: center (" << format_g(f.center.x()) << ", "
                  << format_g(f.center.y()) << ", " << format_g(f.center.z()) << "), depth " << f.depth
                  << ", sigma3 " << format_g(f.sigma3) << ", L " << format_g(f.L) << ", margin "
                  << format_g(f.margin) << "\n";
      }
      std::cout << "  time: sampling " << format_g(ms_sampling) << " ms, precompute "
                << format_g(certifier.precompute_seconds() * 1000) << " ms, certify " << format_g(ms_certify)
                << " ms";
      if (o.grid > 0)
        std::cout << ", field " << field.dims[0] << "x" << field.dims[1] << "x" << field.dims[2] << " "
                  << format_g(ms_field) << " ms";
      std::cout << ", total " << format_g(ms_since(t_start)) << " ms (" << omp_get_max_threads()
                << " threads)\n";
      std::cout << "  wrote " << out.final_path("") << "{certificate.json, voxels.csv, leaves.vtu"
                << (o.grid > 0 ? ", field.vti" : "") << ", timings.json}\n";
      return cert.certified ? kOk : kNotCertified;
    };
  });
}

}  // namespace lidef::cli
