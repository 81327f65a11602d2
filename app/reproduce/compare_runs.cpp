// table1 and fig12: the comparison with PWL(Tet), VHM and PWL(Tri) (paper Table 1, Fig. 12). The methods run
// in lidef-compare (the one program that links TetGen and CHOLMOD, docs/architecture.md), executed with the
// same arguments a user would give `lidef compare`; this module reads its table.csv.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "../gnuplot.h"
#include "lidef/atomic_file.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "reproduce.h"

namespace lidef::cli::reproduce {

namespace fs = std::filesystem;

std::map<std::string, std::map<std::string, std::string>> run_compare(
    const Context& ctx, StagedOutputs& out, const std::string& scenario_path, const std::string& models_dir,
    const std::string& work, const std::string& log_name, const std::vector<std::string>& extra) {
  const std::string exe = (fs::path(ctx.lidef_exe).parent_path() / "lidef-compare").string();
  std::vector<std::string> args = {exe,           scenario_path, "--out",
                                   work,          "--threads",   std::to_string(ctx.threads),
                                   "--cache-dir", ctx.cache_dir};
  if (!models_dir.empty()) {
    args.push_back("--models");
    args.push_back(models_dir);
  }
  if (ctx.quick)
    for (const char* a : {"--samples", "4000", "--reduced-dof", "60", "--tet-max-iterations", "50"})
      args.push_back(a);
  for (const std::string& a : extra) args.push_back(a);
  std::string cmd = "lidef compare";
  for (size_t i = 1; i < args.size(); ++i) cmd += " " + args[i];
  ctx.progress(cmd + " ...");
  const std::string log = out.path(log_name);
  const int rc = run_program(args, log);
  // 0: every method ran; 1: some method failed (its row says why); anything else is an error.
  if (rc != 0 && rc != 1)
    throw NumericalError("lidef-compare failed on " + scenario_path + " (exit " + std::to_string(rc) +
                         "); its output: " + out.final_path(log_name));
  std::map<std::string, std::map<std::string, std::string>> rows;
  for (auto& r : read_csv((fs::path(work) / "table.csv").string())) rows[r["method"]] = r;
  return rows;
}

namespace {

const std::vector<std::string> kMethods = {"lidef", "pwl-tet", "pwl-tet-fine", "vhm", "pwl-tri"};
// Table 1's extra row: PWL(Tet) on the model's own tet mesh when it is coarser than the paper's DOF.
const char* const kModelMeshRow = "pwl-tet-model-mesh";
const std::vector<std::string> kTable1Rows = {"lidef",        "pwl-tet", kModelMeshRow,
                                              "pwl-tet-fine", "vhm",     "pwl-tri"};

// Table 1 of the paper, for the models it shares with the published data: DOF, time (s), iterations.
struct PaperRow {
  const char* model;
  int dof[4];  // pwl-tri, pwl-tet, vhm, lidef
  double time[4];
  int iterations[4];
};
const PaperRow kPaperTable1[] = {
    {"animal", {58566, 7920, 6873, 900}, {2.87, 1.02, 6.53, 0.34}, {129, 26, 71, 15}},
    {"bar", {19974, 3312, 1032, 900}, {2.00, 0.30, 1.50, 0.32}, {250, 23, 393, 14}},
    {"horse", {59550, 5727, 447, 300}, {10.05, 0.40, 0.54, 0.19}, {407, 16, 124, 11}},
};
// Column of kPaperTable1 for a method (-1: the paper has no such column). Table 1's PWL(Tet) ran on meshes of
// the DOF it lists ("a low resolution mesh for better efficiency", Sec. 8): `pwl-tet` is PWL(Tet) at those
// DOF; `pwl-tet-model-mesh` is the model's own tet mesh where that is coarser (kept as an extra row).
int paper_column(const std::string& m) {
  return m == "pwl-tri"                         ? 0
         : m == "pwl-tet" || m == kModelMeshRow ? 1
         : m == "vhm"                           ? 2
         : m == "lidef"                         ? 3
                                                : -1;
}

std::vector<ScenarioFile> comparison_scenarios(const Context& ctx, const std::vector<std::string>& names,
                                               const std::string& work) {
  std::vector<ScenarioFile> v;
  for (const std::string& n : names) {
    if (n == "elephant_pull") {
      // Debian's CGAL demo mesh (docs/cages.md): only when libcgal-dev's data archive is installed.
      const std::string tarball = "/usr/share/doc/libcgal-dev/data.tar.gz";
      if (!fs::exists(tarball)) {
        ctx.progress("elephant_pull skipped: " + tarball + " not installed");
        continue;
      }
      const fs::path dir = fs::path(work) / "cgal";
      fs::create_directories(dir);
      const std::string cmd = "tar xzf " + shell_quote(tarball) + " -C " + shell_quote(dir.string()) +
                              " data/meshes/elephant.off 2>/dev/null";
      if (std::system(cmd.c_str()) != 0 || !fs::exists(dir / "data/meshes/elephant.off")) {
        ctx.progress("elephant_pull skipped: cannot extract elephant.off from " + tarball);
        continue;
      }
      v.push_back({n, (fs::path(ctx.data_dir) / "scenarios" / (n + ".json")).string(),
                   (dir / "data/meshes").string()});
      continue;
    }
    const Scenario sc = ctx.scenario(n);  // checks that it exists and reads
    v.push_back({n, sc.path, ""});
  }
  return v;
}

const PaperRow* paper_row(const std::string& model) {
  for (const PaperRow& p : kPaperTable1)
    if (model == p.model) return &p;
  return nullptr;
}

// The tet mesh of a PWL(Tet) row, for table1.csv: whether it has the paper's resolution and where it is from.
// Free text without commas (a plain CSV cell): lidef-compare's detail up to its ':' ("model tet mesh" or
// "TetGen SWITCHES (...)"), its commas made semicolons.
std::string tet_mesh_label(const std::string& method, const std::map<std::string, std::string>& row,
                           const PaperRow* p) {
  if (method != "pwl-tet" && method != kModelMeshRow) return "";
  const std::string detail = row.count("detail") ? row.at("detail") : "";
  std::string mesh = detail.substr(0, detail.find(':'));
  std::replace(mesh.begin(), mesh.end(), ',', ';');
  if (method == kModelMeshRow) return "model tet mesh (coarser than the paper's; extra row)";
  if (!p) return mesh + " (the paper has no row for this model)";
  return mesh + (csv_number(row, "dof") >= p->dof[paper_column(method)] ? "; at least the paper's DOF"
                                                                        : "; FEWER DOF than the paper's");
}

// Runs of each of the two timed methods (run_timed_pair).
int timing_runs(const Context& ctx) {
  return ctx.quick ? 2 : 5;
}

// The solve times compared: lidef and PWL(Tet) at the paper's resolution, timing_runs times each, the two
// interleaved (`lidef compare --methods lidef,pwl-tet --repeat N`), each time the median of its runs —
// single runs on a shared VM moved by more than the difference between the two (docs/reproduction.md).
// PWL(Tet) runs a second series with CHOLMOD's BLAS in the calling thread (`--blas-threads 1`); its row is
// the series with the smaller median (table1.csv's `pwl_blas_threads`).
// PWL(Tet) runs on a mesh with at least the paper's DOF (`--tet-min-dof D`: the model's mesh when fine
// enough, else TetGen with a searched max volume); where the first run's mesh (the model's own) is coarser,
// that row stays as the extra row `pwl-tet-model-mesh`. Every row's time ratio is then taken to lidef's
// median.
void run_timed_pair(const Context& ctx, StagedOutputs& out, const ScenarioFile& s, const PaperRow* p,
                    const std::string& work, std::map<std::string, std::map<std::string, std::string>>& rows,
                    FigureOutput& res) {
  const int runs = timing_runs(ctx);
  std::vector<std::string> extra = {"--methods", "lidef,pwl-tet", "--repeat", std::to_string(runs)};
  const long paper_dof = p ? p->dof[paper_column("pwl-tet")] : 0;
  if (paper_dof > 0) {
    extra.push_back("--tet-min-dof");
    extra.push_back(std::to_string(paper_dof));
  }
  const std::string log = "compare_" + s.name + "_timed.log";
  auto timed = run_compare(ctx, out, s.path, s.models_dir, (fs::path(work) / (s.name + "_timed")).string(),
                           log, extra);
  res.files.push_back(log);
  for (const char* m : {"lidef", "pwl-tet"})
    if (!timed.count(m))
      throw NumericalError("lidef-compare wrote no " + std::string(m) + " row for " + s.path);
  timed["pwl-tet"]["blas_threads"] = std::to_string(ctx.threads > 0 ? ctx.threads : omp_get_max_threads());
  // PWL(Tet) again with CHOLMOD's BLAS in the calling thread: which of the two is faster depends on the
  // machine (docs/compare.md, "Threads"), and the comparison takes PWL(Tet)'s faster series.
  extra[1] = "pwl-tet";  // the value of --methods
  extra.push_back("--blas-threads");
  extra.push_back("1");
  const std::string log1 = "compare_" + s.name + "_timed_blas1.log";
  auto blas1 = run_compare(ctx, out, s.path, s.models_dir,
                           (fs::path(work) / (s.name + "_timed_blas1")).string(), log1, extra);
  res.files.push_back(log1);
  const auto b1 = blas1.find("pwl-tet");
  if (b1 != blas1.end() && b1->second.at("status") != "failed" &&
      (timed["pwl-tet"].at("status") == "failed" ||
       csv_number(b1->second, "time_s") < csv_number(timed["pwl-tet"], "time_s"))) {
    timed["pwl-tet"] = b1->second;
    timed["pwl-tet"]["blas_threads"] = "1";
  }
  const auto coarse = rows.find("pwl-tet");
  if (coarse != rows.end() && coarse->second.at("status") != "failed" && paper_dof > 0 &&
      csv_number(coarse->second, "dof") < paper_dof)
    rows[kModelMeshRow] = coarse->second;
  rows["lidef"] = timed["lidef"];
  rows["pwl-tet"] = timed["pwl-tet"];
  const double lidef_t = rows["lidef"].at("status") == "failed" ? NAN : csv_number(rows["lidef"], "time_s");
  for (auto& [m, row] : rows) {
    const double t = row.at("status") == "failed" ? NAN : csv_number(row, "time_s");
    row["time_ratio_to_lidef"] =
        std::isfinite(lidef_t) && lidef_t > 0 && std::isfinite(t) ? format_g(t / lidef_t, 6) : "";
  }
}

// A cell of a lidef-compare row, or `fallback` where it is empty or absent.
std::string cell_or(const std::map<std::string, std::string>& row, const std::string& column,
                    const std::string& fallback) {
  const auto it = row.find(column);
  return it == row.end() || it->second.empty() ? fallback : it->second;
}

}  // namespace

void run_table1(const Context& ctx, StagedOutputs& out, FigureOutput& res) {
  std::vector<std::string> names;
  if (ctx.published())
    names = ctx.quick ? std::vector<std::string>{"bar_bend"}
                      : std::vector<std::string>{"bar_bend",       "bar_twist90",    "bar_twist180",
                                                 "horse_leg_lift", "spot_head_turn", "animal_tail_lift"};
  else
    names = ctx.quick ? std::vector<std::string>{"beam_bend"}
                      : std::vector<std::string>{"beam_bend", "beam_twist150", "elephant_pull"};
  const std::string work = (fs::path(out.staging_dir()) / "work").string();
  const std::vector<ScenarioFile> scen = comparison_scenarios(ctx, names, work);
  struct Result {
    ScenarioFile s;
    std::string model;
    std::map<std::string, std::map<std::string, std::string>> rows;
  };
  std::vector<Result> results;
  for (const ScenarioFile& s : scen) {
    Result r{s, "", {}};
    const Scenario sc = read_scenario(s.path, s.models_dir);
    r.model = sc.model;
    r.rows = run_compare(ctx, out, s.path, s.models_dir, (fs::path(work) / s.name).string(),
                         "compare_" + s.name + ".log");
    res.files.push_back("compare_" + s.name + ".log");
    run_timed_pair(ctx, out, s, paper_row(r.model), work, r.rows, res);
    results.push_back(std::move(r));
  }
  write_file_atomic(out.path("table1.csv"), [&](std::ostream& f) {
    f << "scenario,method,status,dof,iterations,converged,certified,inverted_mesh_vertices,max_handle_error,"
         "paper_dof,paper_iterations,time_s,time_ratio_to_lidef,paper_time_s,tet_mesh,time_runs,time_s_min,"
         "time_s_max,pwl_blas_threads\n";
    for (const Result& r : results)
      for (const std::string& m : kTable1Rows) {
        const auto it = r.rows.find(m);
        if (it == r.rows.end()) continue;
        const auto& row = it->second;
        const PaperRow* p = paper_row(r.model);
        const int col = paper_column(m);
        f << r.s.name << ',' << m << ',' << row.at("status") << ',' << row.at("dof") << ','
          << row.at("iterations") << ',' << row.at("converged") << ',' << row.at("certified") << ','
          << row.at("inverted_mesh_vertices") << ',' << row.at("max_handle_error") << ','
          << (p && col >= 0 ? std::to_string(p->dof[col]) : "") << ','
          << (p && col >= 0 ? std::to_string(p->iterations[col]) : "") << ',' << row.at("time_s") << ','
          << row.at("time_ratio_to_lidef") << ',' << (p && col >= 0 ? format_g(p->time[col]) : "") << ','
          << tet_mesh_label(m, row, p) << ',' << cell_or(row, "repeats", "1") << ','
          << cell_or(row, "time_s_min", row.at("time_s")) << ','
          << cell_or(row, "time_s_max", row.at("time_s")) << ','
          << (m == "pwl-tet" ? cell_or(row, "blas_threads", "") : "") << '\n';
      }
  });
  res.files.insert(res.files.begin(), "table1.csv");
  // Plot: iterations per method and scenario (log scale).
  write_file_atomic(out.path("table1.dat"), [&](std::ostream& f) {
    f << "# scenario, then iterations of lidef pwl-tet pwl-tet-model-mesh pwl-tet-fine vhm pwl-tri\n"
         "# (NaN: failed or not run)\n";
    for (const Result& r : results) {
      f << '"' << r.s.name << '"';
      for (const std::string& m : kTable1Rows) {
        const auto it = r.rows.find(m);
        const double v = it == r.rows.end() ? NAN : csv_number(it->second, "iterations");
        f << ' ' << (std::isfinite(v) ? format_g(v) : "NaN");
      }
      f << '\n';
    }
  });
  write_file_atomic(out.path("table1.gp"), [&](std::ostream& f) {
    f << "# Paper Table 1: iterations to convergence per method. Render with: gnuplot table1.gp\n"
         "set terminal pngcairo enhanced size 1000,500 font 'sans,10'\nset output 'table1.png'\n"
         "set style data histogram\nset style histogram clustered gap 1\nset style fill solid 0.8 border -1\n"
         "set xtics noenhanced\nset logscale y\nset ylabel 'Newton / local-global iterations'\nset grid "
         "ytics\nset key below\n"
         "set title 'iterations to convergence (or to the limit)'\n"
         "plot 'table1.dat' using 2:xtic(1) title 'lidef', '' using 3 title 'PWL(Tet) at the paper''s DOF', "
         "'' using 4 title 'PWL(Tet) model mesh (coarser)', '' using 5 title 'PWL(Tet) fine', '' using 6 "
         "title 'VHM', '' using 7 title 'PWL(Tri)'\n";
  });
  res.files.push_back("table1.dat");
  res.files.push_back("table1.gp");
  res.plot_note = render_staged_png(out, "table1");
  if (res.plot_note.empty()) {
    res.plot = "table1.png";
    res.files.push_back("table1.png");
  }

  std::string used;
  for (const Result& r : results) used += (used.empty() ? "" : ", ") + r.s.name;
  res.models = std::string(ctx.published() ? "the paper's published models (shared data)"
                                           : "the project's own models (data/models, and Debian's CGAL demo "
                                             "elephant with its automatic cage made by `lidef cage` when "
                                             "installed)") +
               ", scenarios " + used +
               (ctx.quick ? " (quick: 4000 voxels, 60 DOF per coordinate, PWL(Tet) "
                            "capped at 50 iterations)"
                          : "");
  for (const Result& r : results) {
    const PaperRow* p = paper_row(r.model);
    ojson measured_it = ojson::object(), paper_it = p ? ojson::object() : ojson(nullptr);
    ojson data = ojson::object(), times = ojson::object();
    const auto li = r.rows.find("lidef");
    const bool lidef_ok = li != r.rows.end() && li->second.at("status") != "failed";
    const double lidef_it = lidef_ok ? csv_number(li->second, "iterations") : NAN;
    const double lidef_t = lidef_ok ? csv_number(li->second, "time_s") : NAN;
    bool fewest = lidef_ok, fastest = lidef_ok;
    ojson ratios = ojson::object();
    for (const std::string& m : kTable1Rows) {
      const auto it = r.rows.find(m);
      if (it == r.rows.end()) continue;
      const auto& row = it->second;
      data[m] = {{"status", row.at("status")},
                 {"dof", num_json(csv_number(row, "dof"))},
                 {"paper_dof", p && paper_column(m) >= 0 ? ojson(p->dof[paper_column(m)]) : ojson(nullptr)},
                 {"iterations", num_json(csv_number(row, "iterations"))},
                 {"certified", num_json(csv_number(row, "certified"))},
                 {"inverted_mesh_vertices", num_json(csv_number(row, "inverted_mesh_vertices"))},
                 {"max_handle_error", num_json(csv_number(row, "max_handle_error"))}};
      if (!tet_mesh_label(m, row, p).empty()) data[m]["tet_mesh"] = tet_mesh_label(m, row, p);
      if (m == "pwl-tet" && row.count("blas_threads"))
        data[m]["blas_threads"] = num_json(csv_number(row, "blas_threads"));
      times[m] = {{"time_s", num_json(csv_number(row, "time_s"))},
                  {"time_ratio_to_lidef", num_json(csv_number(row, "time_ratio_to_lidef"))}};
      // The claims compare lidef with the methods at the paper's resolution; the coarser extra row is data.
      if (row.at("status") == "failed" || m == kModelMeshRow) continue;
      measured_it[m] = num_json(csv_number(row, "iterations"));
      if (p && paper_column(m) >= 0) paper_it[m] = p->iterations[paper_column(m)];
      if (m != "lidef") {
        fewest = fewest && lidef_it <= csv_number(row, "iterations");
        fastest = fastest && lidef_t <= csv_number(row, "time_s");
        ratios[m] = num_json(csv_number(row, "time_ratio_to_lidef"));
      }
    }
    res.data[r.s.name] = data;
    res.timings[r.s.name] = times;
    const std::string src = p ? std::string("Table 1 (model ") + p->model + "; the paper's handles differ)"
                              : std::string("Table 1 (no row for this model)");
    res.claims.push_back(
        {"lidef needs no more iterations than each other method on " + r.s.name + " (iterations per method)",
         paper_it, src, lidef_ok ? measured_it : ojson(nullptr), lidef_ok && fewest});
    const double cert = lidef_ok ? csv_number(li->second, "certified") : NAN;
    res.claims.push_back({"lidef's result is certified locally injective on " + r.s.name, true,
                          "Sec. 8 (\"designed to produce locally injective maps\")",
                          std::isfinite(cert) ? ojson(cert == 1) : ojson(nullptr), cert == 1});
    res.claims.push_back(
        {"lidef has the shortest solve time on " + r.s.name +
             " (other methods' time / lidef's; lidef and PWL(Tet): medians of " +
             std::to_string(timing_runs(ctx)) +
             " interleaved runs, PWL(Tet) the faster of its two BLAS settings; timing-dependent)",
         p ? ojson("ratios from Table 1's times") : ojson(nullptr), "Table 1, Sec. 8",
         lidef_ok ? ratios : ojson(nullptr), lidef_ok && fastest});
  }
  // PWL(Tet)'s resolution per scenario, next to the paper's.
  std::string resolution;
  for (const Result& r : results) {
    const auto it = r.rows.find("pwl-tet");
    if (it == r.rows.end() || it->second.at("status") == "failed") continue;
    const PaperRow* p = paper_row(r.model);
    const auto coarse = r.rows.find(kModelMeshRow);
    resolution += std::string(resolution.empty() ? "" : "; ") + r.s.name + " " + it->second.at("dof") +
                  " DOF (" +
                  (p ? "paper " + std::to_string(p->dof[paper_column("pwl-tet")]) : "no paper row") + ", " +
                  tet_mesh_label("pwl-tet", it->second, p) + ")" +
                  (coarse == r.rows.end() ? ""
                                          : ", the model's tet mesh " + coarse->second.at("dof") +
                                                " DOF as the extra row " + kModelMeshRow);
  }
  if (!resolution.empty())
    res.notes.push_back(
        "PWL(Tet) runs at the paper's resolution (Table 1's PWL(Tet) DOF): on the model's tet mesh where it "
        "has "
        "at least those DOF, else on a TetGen mesh of the cage whose max tet volume is searched for them "
        "(`lidef compare --methods lidef,pwl-tet --tet-min-dof D --repeat N`, docs/compare.md); the claims "
        "compare lidef with that row. PWL(Tet): " +
        resolution + ".");
  // The timed runs: their spread, and whether every run of a method ended at the same map.
  std::string spread, differ;
  for (const Result& r : results)
    for (const char* m : {"lidef", "pwl-tet"}) {
      const auto it = r.rows.find(m);
      if (it == r.rows.end() || it->second.at("status") == "failed") continue;
      spread += std::string(spread.empty() ? "" : "; ") + r.s.name + " " + m + " " +
                cell_or(it->second, "time_s_min", "?") + "–" + cell_or(it->second, "time_s_max", "?");
      if (cell_or(it->second, "repeats_identical", "1") != "1") differ += " " + r.s.name + " " + m;
    }
  std::string blas;
  for (const Result& r : results) {
    const auto it = r.rows.find("pwl-tet");
    if (it != r.rows.end() && it->second.count("blas_threads"))
      blas += std::string(blas.empty() ? "" : ", ") + r.s.name + " " + it->second.at("blas_threads");
  }
  if (!blas.empty())
    res.notes.push_back(
        "PWL(Tet)'s time is the faster of two series: CHOLMOD's BLAS on the run's threads (as a process "
        "running "
        "it alone) and in the calling thread (`--blas-threads 1`, as lidef's BLAS calls); which is faster "
        "depends on the machine (docs/compare.md, \"Threads\"). BLAS threads of the series taken: " +
        blas + ".");
  if (!spread.empty())
    res.notes.push_back("lidef's and PWL(Tet)'s times are medians of " + std::to_string(timing_runs(ctx)) +
                        " runs, the two interleaved (`--repeat`); fastest–slowest run, s: " + spread + "." +
                        (differ.empty() ? " Every run of each ended at the same map."
                                        : " NOT every run ended at the first run's map:" + differ + "."));
  res.notes.push_back(
      "VHM and PWL(Tri) carry no guarantee: the CSV's `certified` (VHM: lidef's certificate on lidef's "
      "voxels) "
      "and `inverted_mesh_vertices` columns say whether each one folded. PWL(Tet) is exactly injective per "
      "tet by construction. Methods, criteria and limits: docs/compare.md. The paper's handles are not "
      "published: our scenarios are other deformations of the same models, so the paper's numbers are a "
      "reference, not a target.");
}

void run_fig12(const Context& ctx, StagedOutputs& out, FigureOutput& res) {
  const std::string name = ctx.published() ? "bar_twist90" : "beam_twist150";
  const std::string work = (fs::path(out.staging_dir()) / "work").string();
  const Scenario sc = ctx.scenario(name);
  const auto rows = run_compare(ctx, out, sc.path, "", work, "compare_" + name + ".log");
  write_file_atomic(out.path("fig12.csv"), [&](std::ostream& f) {
    f << "method,status,global_volume_ratio,local_volume_ratio_min,local_volume_ratio_max,"
         "local_volume_change_mean,inverted_mesh_vertices\n";
    for (const std::string& m : kMethods) {
      const auto it = rows.find(m);
      if (it == rows.end()) continue;
      const auto& r = it->second;
      f << m << ',' << r.at("status") << ',' << r.at("global_volume_ratio") << ','
        << r.at("local_volume_ratio_min") << ',' << r.at("local_volume_ratio_max") << ','
        << r.at("local_volume_change_mean") << ',' << r.at("inverted_mesh_vertices") << '\n';
    }
  });
  write_file_atomic(out.path("fig12.dat"), [&](std::ostream& f) {
    f << "# method global_volume_ratio local_min local_max (NaN: not applicable)\n";
    for (const std::string& m : kMethods) {
      const auto it = rows.find(m);
      if (it == rows.end()) continue;
      auto v = [&](const char* c) {
        const double x = csv_number(it->second, c);
        return std::isfinite(x) ? format_g(x) : std::string("NaN");
      };
      f << '"' << m << "\" " << v("global_volume_ratio") << ' ' << v("local_volume_ratio_min") << ' '
        << v("local_volume_ratio_max") << '\n';
    }
  });
  write_file_atomic(out.path("fig12.gp"), [&](std::ostream& f) {
    f << "# Paper Fig. 12: global volume ratio and range of the local volume ratio (det J at the mesh\n"
         "# vertices) per method. Render with: gnuplot fig12.gp\n"
         "set terminal pngcairo enhanced size 900,500 font 'sans,10'\nset output 'fig12.png'\n"
         "set style fill solid 0.6 border -1\nset boxwidth 0.5\nset xtics noenhanced\nset grid ytics\nset "
         "key top left\n"
         "set ylabel 'volume ratio'\nset title 'twisting bar: global volume ratio (bars), local det J range "
         "(whiskers)'\nset yrange [0:*]\n"
         "plot 'fig12.dat' using 0:2:xtic(1) with boxes title 'global volume ratio', "
         "'' using 0:2:3:4 with yerrorbars lc rgb '#d62728' pt 0 title 'local det J: min..max', "
         "1 with lines dt 2 lc rgb 'black' title 'volume preserved'\n";
  });
  res.files = {"fig12.csv", "fig12.dat", "fig12.gp", "compare_" + name + ".log"};
  res.plot_note = render_staged_png(out, "fig12");
  if (res.plot_note.empty()) {
    res.plot = "fig12.png";
    res.files.push_back("fig12.png");
  }
  res.models = std::string(ctx.published() ? "the paper's published bar" : "the project's own beam") +
               " (scenario " + name + ")" + (ctx.quick ? " (quick: 4000 voxels, 60 DOF per coordinate)" : "");
  for (const std::string& m : kMethods) {
    const auto it = rows.find(m);
    if (it == rows.end()) continue;
    const auto& r = it->second;
    res.data[m] = {{"status", r.at("status")},
                   {"global_volume_ratio", num_json(csv_number(r, "global_volume_ratio"))},
                   {"local_volume_ratio_min", num_json(csv_number(r, "local_volume_ratio_min"))},
                   {"local_volume_ratio_max", num_json(csv_number(r, "local_volume_ratio_max"))},
                   {"local_volume_change_mean", num_json(csv_number(r, "local_volume_change_mean"))}};
  }
  const auto li = rows.find("lidef");
  const double g = li == rows.end() ? NAN : csv_number(li->second, "global_volume_ratio");
  res.claims.push_back({"lidef's global volume ratio on the twisting bar >= 0.95", nullptr,
                        "Fig. 12 (percentages printed in the figure only)", num_json(g), g >= 0.95});
  res.notes.push_back(
      "Global volume ratio = deformed / rest volume of the mesh. The local volume ratio is det J at the mesh "
      "vertices (volumetric methods; PWL(Tri) has none): its min, max and mean |det J - 1| per method. The "
      "paper's twist angle is not published; " +
      name + " is the project's twist of the same kind.");
}

}  // namespace lidef::cli::reproduce
