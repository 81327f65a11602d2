// `lidef reproduce NAME`: the paper's table and figures regenerated from the project's own code
// (docs/reproduction.md). One module per figure (reproduce_*.cpp) fills a FigureOutput; report.cpp writes the
// common files (summary.json, README.md) and cmd_reproduce.cpp is the command. Figures call the libraries
// (solver, certifier, verification) directly and run lidef-compare / `lidef explore` as programs where those
// own the work (lidef links neither TetGen nor CHOLMOD, docs/architecture.md).
#pragma once
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lidef/deform_params.h"
#include "lidef/scenario.h"
#include "lidef/staged_outputs.h"

namespace lidef::cli::reproduce {

using ojson = nlohmann::ordered_json;

// One claim of the paper, checked: `paper` is the paper's value (null when the paper gives none),
// `measured` ours (null when it could not be measured), `source` cites the table/figure/section.
struct Claim {
  std::string claim;
  ojson paper;  // value or null
  std::string source;
  ojson measured;  // value or null (not measured)
  bool holds = false;
};

// What one figure produced besides the files it staged itself.
struct FigureOutput {
  std::vector<Claim> claims;
  std::string models;              // which models/scenarios were used, one sentence
  std::vector<std::string> files;  // the files written (CSV, PNG, ...), for README.md and summary.json
  std::string plot;                // the PNG's name ("" when none was drawn)
  std::string plot_note;           // why no PNG ("" when drawn)
  ojson data = ojson::object();    // deterministic results (summary.json "data")
  ojson timings =
      ojson::object();  // wall-clock times (summary.json "timings"; the only non-deterministic part)
  std::vector<std::string> notes;  // README.md paragraphs: method, deviations from the paper
};

// Where the figures find their inputs and how they run.
struct Context {
  // The shared data folder (holding models/ and scenarios/) when --models was given; else empty and the
  // project's own data folder (data_dir) is used.
  std::string shared_dir;
  std::string data_dir;   // the project's data/ folder ($LIDEF_DATA, else the source tree's)
  bool quick = false;     // smaller problems (tests): same claims, fewer samples
  int threads = 0;        // OpenMP threads (0 = all); also passed to the programs run
  std::string cache_dir;  // subspace cache ("" = none)
  std::string lidef_exe;  // this program (for `lidef explore`) and lidef-compare beside it
  std::function<void(const std::string&)> progress;  // one line per stage on stderr

  bool published() const { return !shared_dir.empty(); }
  // A scenario by name from the shared data (published) or the project's data/scenarios.
  Scenario scenario(const std::string& name) const;
  // Parameters of a solve: the scenario's, threads set, and the quick sizes when quick.
  DeformParams params_for(const Scenario& sc) const;
};

using FigureFn = void (*)(const Context&, StagedOutputs&, FigureOutput&);

struct FigureInfo {
  const char* name;
  const char* title;   // what the paper's figure/table shows
  const char* claims;  // the claims checked, one line (for --help)
  FigureFn run;        // nullptr: not implemented (the command says so)
};

// table1, fig2, fig5, fig6, fig7, fig8, fig9, fig12, fig13 in this order.
const std::vector<FigureInfo>& figures();
const FigureInfo* find_figure(const std::string& name);

// The figures (one module each).
void run_table1(const Context&, StagedOutputs&, FigureOutput&);
void run_fig2(const Context&, StagedOutputs&, FigureOutput&);
void run_fig5(const Context&, StagedOutputs&, FigureOutput&);
void run_fig6(const Context&, StagedOutputs&, FigureOutput&);
void run_fig7(const Context&, StagedOutputs&, FigureOutput&);
void run_fig8(const Context&, StagedOutputs&, FigureOutput&);
void run_fig9(const Context&, StagedOutputs&, FigureOutput&);
void run_fig12(const Context&, StagedOutputs&, FigureOutput&);
void run_fig13(const Context&, StagedOutputs&, FigureOutput&);

// How a run was made, for README.md and summary.json.
struct RunInfo {
  std::string command_line;
  std::string machine;  // host, CPU model, cores
  std::string started_utc;
  double seconds = 0;
  int threads = 0;
  bool quick = false;
};
RunInfo machine_info();  // fills machine (and started_utc: now)

// Writes summary.json and README.md into `out` (staged). Every claim with a non-null `measured` counts as
// measured; returns whether every claim was measured.
bool write_report(StagedOutputs& out, const FigureInfo& fig, const FigureOutput& res, const RunInfo& run);

// --- Helpers shared by the figure modules.
// Runs a program (argv[0] is its path) with stdout+stderr captured into `log_path`; returns its exit code
// (-1 when it could not run). Progress goes to the context's progress function.
int run_program(const std::vector<std::string>& argv, const std::string& log_path);
// A CSV file (RFC 4180 quotes, header row) as rows of column name → text.
std::vector<std::map<std::string, std::string>> read_csv(const std::string& path);
// A number cell of read_csv ("" → NaN, "inf").
double csv_number(const std::map<std::string, std::string>& row, const std::string& column);
// JSON value of a double: null when not finite (JSON has no inf/NaN).
ojson num_json(double x);

}  // namespace lidef::cli::reproduce

// --- Solver runs (runs.cpp), shared by fig5-fig9 and fig13.
#include <memory>

#include "lidef/model_check.h"
#include "lidef/projected_newton.h"

namespace lidef::cli::reproduce {

// The scenario's model, loaded and checked (a mesh file gets its automatic cage, cached).
Model load_scenario_model(const Context& ctx, const Scenario& sc);

struct SolveRun {
  std::string label;
  DeformParams params;
  SolveResult result;
  std::vector<IterationRecord> history;
  MatX3d y;            // full coefficients of the final (certified) map, #V+#F by 3
  EnergyTerms energy;  // at the final map with the user's (default) weights of `params`
  double max_handle_error = 0;
  bool certified = false;  // the solver's certificate of the final map
  double min_lower_bound = 0;
  long samples = 0;  // voxels of the sampling
  double preprocess_s = 0, solve_s = 0;
  bool reached(double tol) const { return certified && max_handle_error <= tol; }
};

// Precomputes a solver for (model, params), sets the scenario's handles and solves from the identity.
// `keep_solver` receives the solver when the caller needs its basis/certifier afterwards.
SolveRun solve_scenario(const Context& ctx, const Model& model, const Scenario& sc,
                        const DeformParams& params, const std::string& label,
                        std::unique_ptr<DeformationSolver>* keep_solver = nullptr);

// The energy E with the weights of `params` (not the solver's dynamically changed ones) at the solver's map.
EnergyTerms energy_at_user_weights(const DeformationSolver& solver, const DeformParams& params);

}  // namespace lidef::cli::reproduce

namespace lidef::cli::reproduce {

// One lidef-compare run (the program beside lidef, as `lidef compare` runs it) on a scenario file: its
// table.csv rows (method → column → text). `work` is a folder of the staging area (not an output); the run's
// log is copied to `log_name` in `out`. `extra` are further lidef-compare options.
std::map<std::string, std::map<std::string, std::string>> run_compare(
    const Context& ctx, StagedOutputs& out, const std::string& scenario_path, const std::string& models_dir,
    const std::string& work, const std::string& log_name, const std::vector<std::string>& extra = {});

// The scenarios of the comparison figures (table1, fig12): file paths and the --models folder each needs.
struct ScenarioFile {
  std::string name, path, models_dir;
};

}  // namespace lidef::cli::reproduce
