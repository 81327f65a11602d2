// lidef compare: the paper's comparison (Table 1, Figs. 11-12) in one run — lidef, PWL(Tet) at two
// resolutions, VHM and PWL(Tri) on the same handles — with a Table-1-shaped table (docs/compare.md).
#include <omp.h>

#include <algorithm>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <variant>

#include "commands.h"
#include "lidef/analysis/mesh_export.h"
#include "lidef/atomic_file.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/coefficients.h"
#include "lidef/compare/compare.h"
#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/scenario.h"
#include "lidef/staged_outputs.h"
#include "lidef/subspace.h"
#include "param_flags.h"

namespace lidef::cli {

// The options of lidef-compare (`lidef compare`), on its top-level app.
void add_compare_options(CLI::App& app, Action& action) {
  struct Opts {
    std::string scenario, out, models, methods = "lidef,pwl-tet,pwl-tet-fine,vhm,pwl-tri",
                                       cache_dir = "<default>";
    bool quiet = false, no_model_tets = false;
    CompareOptions c;
    ParamOverrides overrides;
  };
  auto opts = std::make_shared<Opts>();
  CLI::App* sub = &app;
  sub->add_option("SCENARIO", opts->scenario, "Scenario JSON (model, handles, optional parameters)")
      ->required();
  sub->add_option("--out", opts->out, "Output folder (created if missing)")->required();
  sub->add_option("--methods", opts->methods, "Comma-separated: lidef,pwl-tet,pwl-tet-fine,vhm,pwl-tri")
      ->capture_default_str();
  sub->add_option("--models", opts->models, "Folder that holds the model named in the scenario");
  sub->add_option("--cache-dir", opts->cache_dir, "Subspace cache folder of lidef ('' = no cache)");
  sub->add_flag("--quiet", opts->quiet, "No progress lines");
  auto& c = opts->c;
  sub->add_flag("--no-model-tets", opts->no_model_tets,
                "pwl-tet: tetrahedralize the cage with TetGen even when the model has tet.node/tet.ele");
  sub->add_option("--tet-quality", c.coarse_tet.min_ratio,
                  "pwl-tet (TetGen): max radius-edge ratio, -q (<= 0: off)")
      ->capture_default_str();
  sub->add_option("--tet-max-volume", c.coarse_tet.max_volume,
                  "pwl-tet (TetGen): max tet volume, -a (0: none)")
      ->capture_default_str();
  sub->add_option(
         "--tet-min-dof", c.coarse_min_dof,
         "pwl-tet: at least this many DOF (3 x tet vertices): the model's tet mesh when it has them, "
         "else TetGen with the max volume searched for them (0: off)")
      ->capture_default_str();
  sub->add_option("--fine-tet-quality", c.fine_tet.min_ratio, "pwl-tet-fine: max radius-edge ratio, -q")
      ->capture_default_str();
  sub->add_option("--fine-tet-max-volume", c.fine_tet.max_volume,
                  "pwl-tet-fine: max tet volume, -a (0: --fine-volume-factor x lidef's voxel volume)")
      ->capture_default_str();
  sub->add_option("--fine-volume-factor", c.fine_volume_factor, "pwl-tet-fine: max tet volume / voxel side^3")
      ->capture_default_str();
  sub->add_option("--tet-max-iterations", c.tet_max_iterations, "pwl-tet: Newton iteration limit")
      ->capture_default_str();
  sub->add_option("--anchors", c.anchors,
                  "vhm: anchor points (x y z per line; default MODEL/vhm_anchors.xyz)");
  sub->add_option("--anchor-count", c.anchor_count,
                  "vhm: voxel centers used as anchors when the model has none")
      ->capture_default_str();
  sub->add_option("--vhm-smooth", c.vhm.smooth_weight, "vhm: weight of the Hessian smoothness term")
      ->capture_default_str();
  sub->add_option("--vhm-boundary", c.vhm_boundary,
                  "vhm: at most this many mesh vertices as boundary samples of the smoothness term")
      ->capture_default_str();
  sub->add_option("--vhm-max-iterations", c.vhm.max_iterations, "vhm: local/global iteration limit")
      ->capture_default_str();
  sub->add_option("--tri-alpha", c.tri.alpha, "pwl-tri: SR-ARAP smooth-rotation weight alpha")
      ->capture_default_str();
  sub->add_option("--tri-max-iterations", c.tri.max_iterations, "pwl-tri: local/global iteration limit")
      ->capture_default_str();
  sub->add_option("--repeat", c.repeat,
                  "Solve with every method this many times, the methods interleaved; the time is the median "
                  "(table.csv: every run's min and max, and whether all runs ended at the same map)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  sub->add_option(
         "--blas-threads", c.blas_threads,
         "pwl-tet, pwl-tri: OpenBLAS threads of the CHOLMOD factorizations (0: --threads, as a process "
         "running them alone; 1: in the calling thread, as lidef's BLAS calls)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  add_param_flags(sub, &opts->overrides, "lidef parameters (shared weights/tolerances): ");
  sub->footer(
      "Writes into --out (all files together, or none): table.csv, table.md (paper Table 1 columns), and "
      "per\n"
      "method METHOD.obj, METHOD.vtp (E_iso_minus_6 and detJ for the volumetric methods), METHOD.log and, "
      "for\n"
      "the harmonic methods (lidef, vhm), METHOD.coefficients.txt.\n"
      "A failing method is reported in the table and the others still run. Exit code: 0 every method ran,\n"
      "1 some method failed (the table says why), 2 bad input. Methods and criteria: docs/compare.md.");
  sub->callback([opts, &action] {
    action = [opts]() -> int {
      Opts o = *opts;
      Scenario sc = read_scenario(o.scenario, o.models);
      apply_param_overrides(sc.params, o.overrides);
      validate_params(sc.params, o.scenario);
      o.c.methods.clear();
      std::stringstream ms(o.methods);
      for (std::string m; std::getline(ms, m, ',');)
        if (!m.empty()) o.c.methods.push_back(m);
      for (const std::string& m : o.c.methods)
        if (std::find(compare_methods().begin(), compare_methods().end(), m) == compare_methods().end())
          throw InputError("--methods",
                           "unknown method '" + m + "' (known: lidef, pwl-tet, pwl-tet-fine, vhm, pwl-tri)");
      if (o.c.methods.empty()) throw InputError("--methods", "no method given");
      o.c.use_model_tets = !o.no_model_tets;
      if (o.c.coarse_min_dof < 0) throw InputError("--tet-min-dof", "must be >= 0");
      if (o.c.coarse_min_dof > 300000000) throw InputError("--tet-min-dof", "too large (at most 300000000)");
      if (o.c.coarse_min_dof > 0 && o.c.coarse_tet.max_volume > 0)
        throw InputError("--tet-min-dof",
                         "cannot be combined with --tet-max-volume (the max volume is searched for the DOF)");
      o.c.cache_dir = o.cache_dir == "<default>" ? default_cache_dir() : o.cache_dir;
      if (sc.params.threads > 0) omp_set_num_threads(sc.params.threads);
      // A mesh file as the model: its automatic cage, made once and cached (lidef/cage/auto_cage.h).
      const Model model = load_model(resolve_model_path(
          sc.model_dir, [](const std::string& m) { std::cerr << "lidef compare: " << m << "\n"; },
          o.cache_dir));
      StagedOutputs out(o.out);  // checks --out before the long run

      auto progress = [&](const std::string& m, const std::string& line) {
        if (!o.quiet) std::cerr << "[" << m << "] " << line << "\n";
      };
      const std::vector<MethodResult> rows = run_comparison(sc, model, o.c, progress);

      std::vector<std::string> stale;
      bool any_failed = false;
      for (const MethodResult& r : rows) {
        if (!r.ok) {
          any_failed = true;
          for (const char* ext : {".obj", ".vtp", ".coefficients.txt"}) stale.push_back(r.method + ext);
        } else {
          // The harmonic methods' maps (lidef, VHM), so that `lidef certify` / `verify` can judge them on any
          // domain (the table's "certified" is on the paper's grid).
          if (r.coefficients.rows() > 0)
            write_file_atomic(out.path(r.method + ".coefficients.txt"),
                              [&](std::ostream& s) { write_coefficients(s, r.coefficients); });
          write_file_atomic(out.path(r.method + ".obj"), [&](std::ostream& s) {
            write_obj(s, r.V, model.mesh.F, "lidef compare " + sc.name + ": " + r.method);
          });
          std::vector<PointArray> arrays;
          if (r.e_iso.size()) arrays = {{"E_iso_minus_6", r.e_iso}, {"detJ", r.det_j}};
          write_mesh_vtp(out.path(r.method + ".vtp"), r.V, model.mesh.F, arrays);
        }
        write_file_atomic(out.path(r.method + ".log"), [&](std::ostream& s) {
          s << "# lidef compare " << sc.name << ": " << r.method << "\n";
          if (!r.ok)
            s << "# FAILED: " << r.error << "\n";
          else
            s << "# " << r.detail << "\n# " << r.stop << "\n" << r.log;
        });
      }
      const std::string csv = comparison_table_csv(rows), md = comparison_table_md(rows, sc);
      write_file_atomic(out.path("table.csv"), [&](std::ostream& s) { s << csv; });
      write_file_atomic(out.path("table.md"), [&](std::ostream& s) { s << md; });
      out.commit(stale);
      std::cout << md << "wrote " << out.final_path("") << "{table.csv, table.md, METHOD.obj/.vtp/.log}\n";
      return any_failed ? kStoppedEarly : kOk;
    };
  });
}

}  // namespace lidef::cli
