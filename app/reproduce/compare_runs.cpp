// table1 and fig12: the comparison with PWL(Tet), VHM and PWL(Tri) (paper Table 1, Fig. 12). The methods run
// in lidef-compare (the one program that links TetGen and CHOLMOD, docs/architecture.md), executed with the
// same arguments a user would give `lidef compare`; this module reads its table.csv.
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
// Column of kPaperTable1 for a method (-1: the paper has no such column; PWL(Tet) is its coarse mesh).
int paper_column(const std::string& m) {
  return m == "pwl-tri" ? 0 : m == "pwl-tet" ? 1 : m == "vhm" ? 2 : m == "lidef" ? 3 : -1;
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
    results.push_back(std::move(r));
  }
  auto paper_row = [](const std::string& model) -> const PaperRow* {
    for (const PaperRow& p : kPaperTable1)
      if (model == p.model) return &p;
    return nullptr;
  };
  write_file_atomic(out.path("table1.csv"), [&](std::ostream& f) {
    f << "scenario,method,status,dof,iterations,converged,certified,inverted_mesh_vertices,max_handle_error,"
         "paper_dof,paper_iterations,time_s,time_ratio_to_lidef,paper_time_s\n";
    for (const Result& r : results)
      for (const std::string& m : kMethods) {
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
          << row.at("time_ratio_to_lidef") << ',' << (p && col >= 0 ? format_g(p->time[col]) : "") << '\n';
      }
  });
  res.files.insert(res.files.begin(), "table1.csv");
  // Plot: iterations per method and scenario (log scale).
  write_file_atomic(out.path("table1.dat"), [&](std::ostream& f) {
    f << "# scenario, then iterations of lidef pwl-tet pwl-tet-fine vhm pwl-tri (NaN: failed)\n";
    for (const Result& r : results) {
      f << '"' << r.s.name << '"';
      for (const std::string& m : kMethods) {
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
         "ytics\nset key top left\n"
         "set title 'iterations to convergence (or to the limit)'\n"
         "plot 'table1.dat' using 2:xtic(1) title 'lidef', '' using 3 title 'PWL(Tet) coarse', '' using 4 "
         "title "
         "'PWL(Tet) fine', '' using 5 title 'VHM', '' using 6 title 'PWL(Tri)'\n";
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
    for (const std::string& m : kMethods) {
      const auto it = r.rows.find(m);
      if (it == r.rows.end()) continue;
      const auto& row = it->second;
      data[m] = {{"status", row.at("status")},
                 {"dof", num_json(csv_number(row, "dof"))},
                 {"iterations", num_json(csv_number(row, "iterations"))},
                 {"certified", num_json(csv_number(row, "certified"))},
                 {"inverted_mesh_vertices", num_json(csv_number(row, "inverted_mesh_vertices"))},
                 {"max_handle_error", num_json(csv_number(row, "max_handle_error"))}};
      times[m] = {{"time_s", num_json(csv_number(row, "time_s"))},
                  {"time_ratio_to_lidef", num_json(csv_number(row, "time_ratio_to_lidef"))}};
      if (row.at("status") == "failed") continue;
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
    res.claims.push_back({"lidef has the shortest solve time on " + r.s.name +
                              " (other methods' time / lidef's; timing-dependent)",
                          p ? ojson("ratios from Table 1's times") : ojson(nullptr), "Table 1, Sec. 8",
                          lidef_ok ? ratios : ojson(nullptr), lidef_ok && fastest});
  }
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
