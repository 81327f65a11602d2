// The parts every figure shares: the registry of names, where the inputs are, the report files
// (summary.json, README.md), running a program, reading a CSV.
#include <sys/utsname.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "../gnuplot.h"
#include "lidef/atomic_file.h"
#include "lidef/csv.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "reproduce.h"

namespace lidef::cli::reproduce {

namespace fs = std::filesystem;

const std::vector<FigureInfo>& figures() {
  static const std::vector<FigureInfo> f = {
      {"table1",
       "Table 1: DOF, iterations and solve time of lidef, PWL(Tet) at the paper's DOF (and on the model's "
       "coarser mesh) and fine, VHM, PWL(Tri)",
       "lidef needs no more iterations than each other method; lidef's result is certified; lidef has the "
       "shortest solve time",
       run_table1},
      {"fig2", "Fig. 2: a bijective harmonic map of the ball whose sigma3 has an interior minimum",
       "the counterexample is verified (strict interior minimum, bijective on the ball)", run_fig2},
      {"fig5", "Fig. 5: first- vs third-order Lipschitz constant of sigma3 against sampled ground truth",
       "both bounds >= ground truth in every voxel; third order tighter on the median (with and without "
       "the smoothness term)",
       run_fig5},
      {"fig6", "Fig. 6: samples needed to reach the targets certified, with and without the smoothness term",
       ">= 10x fewer samples with the smoothness term", run_fig6},
      {"fig7", "Fig. 7: energy against the subspace dimension",
       "900 DOF (300 per coordinate) reach the full space's energy within 5%", run_fig7},
      {"fig8", "Fig. 8: Hessian subsampling ratio r_s against convergence",
       "every r_s >= 2% converges to the same result", run_fig8},
      {"fig9", "Fig. 9: fixed vs dynamic weights on a hard twist",
       "dynamic weighting reaches the targets where fixed weights stall", run_fig9},
      {"fig12", "Fig. 12: global and local volume ratio of a twisting bar per method",
       "lidef's global volume ratio >= 0.95", run_fig12},
      {"fig13", "Fig. 13: the time of one Newton iteration split into its stages, per model",
       "the four stages are balanced (none above half of the four stages' time)", run_fig13},
  };
  return f;
}

const FigureInfo* find_figure(const std::string& name) {
  for (const FigureInfo& f : figures())
    if (name == f.name) return &f;
  return nullptr;
}

Scenario Context::scenario(const std::string& name) const {
  const fs::path dir = published() ? fs::path(shared_dir) / "scenarios" : fs::path(data_dir) / "scenarios";
  const fs::path p = dir / (name + ".json");
  if (!fs::exists(p))
    throw InputError(p.string(), published() ? "not found: the shared data folder given by --models has no "
                                               "such scenario"
                                             : "not found: the project's data folder lacks this scenario "
                                               "(set LIDEF_DATA to the project's data/ folder)");
  return read_scenario(p.string());
}

DeformParams Context::params_for(const Scenario& sc) const {
  DeformParams p = sc.params;
  p.threads = threads;
  p.backend = BackendKind::kCpu;  // reproducible on any machine; the OpenCL backend gives the same verdicts
  // The figures measure the paper's method: one projected-Newton solve from the identity to the targets
  // (solve_scenario). lidef's continuation (continuation.h) is its own addition and would change what Fig. 9
  // compares (fixed vs dynamic weights in one solve): off, so that the recorded parameters say what ran.
  p.continuation = false;
  if (quick) {
    // Small enough for the test suite: 4000 voxels, 60 coefficients per coordinate.
    p.samples = 4000;
    p.reduced_dof = 60;
  }
  return p;
}

RunInfo machine_info() {
  RunInfo r;
  utsname u{};
  std::string host = "unknown host", cpu;
  if (::uname(&u) == 0)
    host = std::string(u.nodename) + " (" + u.sysname + " " + u.release + ", " + u.machine + ")";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  r.machine = host + "; " + (cpu.empty() ? "unknown CPU" : cpu) + "; " +
              std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
  const std::time_t t = std::time(nullptr);
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  r.started_utc = buf;
  return r;
}

namespace {

std::string json_text(const ojson& j) {
  if (j.is_null()) return "—";
  if (j.is_number_float()) return format_g(j.get<double>(), 4);
  if (j.is_string()) return j.get<std::string>();
  return j.dump();
}

}  // namespace

bool write_report(StagedOutputs& out, const FigureInfo& fig, const FigureOutput& res, const RunInfo& run) {
  bool all_measured = true, all_hold = true;
  ojson claims = ojson::array();
  for (const Claim& c : res.claims) {
    all_measured = all_measured && !c.measured.is_null();
    all_hold = all_hold && c.holds;
    claims.push_back({{"claim", c.claim},
                      {"paper", c.paper},
                      {"source", c.source},
                      {"measured", c.measured},
                      {"holds", c.holds}});
  }
  ojson s;
  s["name"] = fig.name;
  s["title"] = fig.title;
  s["quick"] = run.quick;
  s["threads"] = run.threads;
  s["models"] = res.models;
  s["claims"] = claims;
  s["all_claims_measured"] = all_measured;
  s["all_claims_hold"] = all_hold;
  s["files"] = res.files;
  s["plot"] = res.plot.empty() ? ojson(nullptr) : ojson(res.plot);
  if (!res.plot_note.empty()) s["plot_note"] = res.plot_note;
  s["data"] = res.data;
  // Everything below varies from run to run; everything above is a function of the inputs and threads.
  s["timings"] = res.timings;
  s["run"] = {{"command", run.command_line},
              {"machine", run.machine},
              {"started_utc", run.started_utc},
              {"seconds", run.seconds}};
  write_file_atomic(out.path("summary.json"), [&](std::ostream& f) { f << s.dump(2) << "\n"; });

  write_file_atomic(out.path("README.md"), [&](std::ostream& f) {
    f << "# " << fig.name << ": " << fig.title << "\n\n";
    f << "Made by `" << run.command_line << "` on " << run.started_utc << " (" << format_g(run.seconds, 3)
      << " s), machine: " << run.machine
      << ", threads: " << (run.threads > 0 ? std::to_string(run.threads) : "all")
      << (run.quick ? ". **Quick run** (smaller problems than the paper's; see below)" : "") << ".\n\n";
    f << "Models: " << res.models << "\n\n";
    if (!res.plot.empty()) f << "![" << fig.name << "](" << res.plot << ")\n\n";
    if (!res.plot_note.empty()) f << "Plot: " << res.plot_note << "\n\n";
    f << "## Claims\n\n"
      << (all_hold ? "Every claim holds." : "**Not every claim holds** (see the rows marked no).") << "\n\n";
    f << "| claim | paper | source | measured | holds |\n|---|---|---|---|---|\n";
    for (const Claim& c : res.claims)
      f << "| " << c.claim << " | " << json_text(c.paper) << " | " << (c.source.empty() ? "—" : c.source)
        << " | " << json_text(c.measured) << " | "
        << (c.measured.is_null() ? "not measured"
            : c.holds            ? "yes"
                                 : "**no**")
        << " |\n";
    if (!res.notes.empty()) {
      f << "\n## Notes\n\n";
      for (const std::string& n : res.notes) f << n << "\n\n";
    }
    f << "\n## Files\n\n";
    for (const std::string& n : res.files) f << "- `" << n << "`\n";
    f << "- `summary.json`: the claims (`claim`, `paper`, `source`, `measured`, `holds`), the data, the "
         "timings "
         "(the only fields that change between runs with the same input and thread count) and this run's "
         "command, machine and time\n";
  });
  return all_measured;
}

int run_program(const std::vector<std::string>& argv, const std::string& log_path) {
  std::string cmd;
  for (const std::string& a : argv) cmd += (cmd.empty() ? "" : " ") + shell_quote(a);
  cmd += " > " + shell_quote(log_path) + " 2>&1";
  const int rc = std::system(cmd.c_str());
  if (rc == -1 || !WIFEXITED(rc)) return -1;
  return WEXITSTATUS(rc);
}

std::vector<std::map<std::string, std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot read");
  std::string line;
  if (!std::getline(in, line)) throw InputError(path, "is empty (no header)");
  const std::vector<std::string> header = split_csv_line(line);
  std::vector<std::map<std::string, std::string>> rows;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    const std::vector<std::string> cells = split_csv_line(line);
    if (cells.size() != header.size())
      throw InputError(path, "row " + std::to_string(rows.size() + 2) + " has " +
                                 std::to_string(cells.size()) + " cells, the header " +
                                 std::to_string(header.size()));
    std::map<std::string, std::string> row;
    for (size_t k = 0; k < header.size(); ++k) row[header[k]] = cells[k];
    rows.push_back(std::move(row));
  }
  return rows;
}

double csv_number(const std::map<std::string, std::string>& row, const std::string& column) {
  const auto it = row.find(column);
  if (it == row.end() || it->second.empty()) return std::nan("");
  if (it->second == "inf") return INFINITY;
  if (it->second == "-inf") return -INFINITY;
  try {
    return std::stod(it->second);
  } catch (const std::exception&) {
    return std::nan("");
  }
}

ojson num_json(double x) {
  return std::isfinite(x) ? ojson(x) : ojson(nullptr);
}

}  // namespace lidef::cli::reproduce
