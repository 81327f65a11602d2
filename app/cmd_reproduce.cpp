// lidef reproduce NAME|all --out DIR: the paper's table and figures regenerated, one folder each, with the
// paper's claims checked (docs/reproduction.md). The work is in reproduce/ (one module per figure).
#include <omp.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>

#include "commands.h"
#include "gnuplot.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/number_format.h"
#include "lidef/staged_outputs.h"
#include "lidef/subspace.h"
#include "reproduce/reproduce.h"

namespace lidef::cli {

namespace {

namespace fs = std::filesystem;
using namespace reproduce;

// --models DIR: the shared data folder (models/ and scenarios/), or its models/ folder.
std::string shared_data_root(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw InputError(dir, "--models: not a folder");
  if (fs::is_directory(fs::path(dir) / "scenarios", ec) && fs::is_directory(fs::path(dir) / "models", ec))
    return dir;
  const fs::path parent = fs::absolute(dir, ec).lexically_normal().parent_path();
  if (fs::is_directory(parent / "scenarios", ec) && fs::is_directory(parent / "models", ec))
    return parent.string();
  throw InputError(dir,
                   "--models: expected the shared data folder holding models/ and scenarios/ (or its models/ "
                   "folder)");
}

// This process's command line as typed (argv from /proc/self/cmdline, program name shortened to lidef).
std::string command_line() {
  std::ifstream in("/proc/self/cmdline", std::ios::binary);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()), s;
  size_t start = 0;
  for (int k = 0; start < all.size(); ++k) {
    size_t end = all.find('\0', start);
    if (end == std::string::npos) end = all.size();
    const std::string arg = all.substr(start, end - start);
    s += k == 0 ? std::string("lidef")
                : " " + (arg.find_first_of(" '\"") == std::string::npos ? arg : shell_quote(arg));
    start = end + 1;
  }
  return s.empty() ? "lidef reproduce" : s;
}

std::string names_list() {
  std::string s;
  for (const FigureInfo& f : figures()) s += (s.empty() ? "" : ", ") + std::string(f.name);
  return s;
}

}  // namespace

void add_reproduce_command(CLI::App& app, Action& action) {
  struct Opts {
    std::string name, out, models, cache_dir = "<default>";
    bool quick = false;
    int threads = 0;
  };
  auto opts = std::make_shared<Opts>();
  auto* sub =
      app.add_subcommand("reproduce", "Regenerate one of the paper's table/figures and check its claims");
  sub->add_option("NAME", opts->name, "table1, fig2, fig5, fig6, fig7, fig8, fig9, fig12, fig13 or all")
      ->required();
  sub->add_option("--out", opts->out, "Output folder: NAME's files go to DIR/NAME/")->required();
  sub->add_option("--models", opts->models,
                  "The paper's published models: the shared data folder (models/ and scenarios/). Without "
                  "it: the project's own models and scenarios (data/, $LIDEF_DATA)");
  sub->add_flag("--quick", opts->quick, "Smaller problems (4000 voxels, 60 DOF per coordinate, fewer runs)");
  sub->add_option("--threads", opts->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  sub->add_option("--cache-dir", opts->cache_dir,
                  "Subspace cache folder ('' = no cache; default $LIDEF_CACHE_DIR or ~/.cache/lidef)");
  std::string footer =
      "Each NAME writes DIR/NAME/ (all files together, or none): its data as CSV, a plot (PNG, gnuplot),\n"
      "summary.json (claims as {claim, paper, source, measured, holds}, data, timings, command, machine,\n"
      "time) and README.md. A claim that does not hold is reported, not hidden. Names and claims:\n";
  for (const FigureInfo& f : figures())
    footer += "  " + std::string(f.name) + std::string(8 - std::string(f.name).size(), ' ') + f.title +
              "\n          claim: " + f.claims + "\n";
  footer +=
      "Exit code: 0 every claim was measured (whether or not it holds), 1 some claim could not be measured,\n"
      "2 error (unknown NAME, bad input). Details: docs/reproduction.md.";
  sub->footer(footer);
  sub->callback([opts, &action] {
    action = [opts]() -> int {
      const Opts& o = *opts;
      std::vector<const FigureInfo*> todo;
      if (o.name == "all") {
        for (const FigureInfo& f : figures()) todo.push_back(&f);
      } else if (const FigureInfo* f = find_figure(o.name)) {
        todo.push_back(f);
      } else {
        throw InputError(o.name, "unknown name for 'lidef reproduce' (known: " + names_list() + ", all)");
      }
      if (o.threads < 0 || o.threads > 1024) throw InputError("--threads", "must be in 0..1024");
      Context ctx;
      if (!o.models.empty()) ctx.shared_dir = shared_data_root(o.models);
      const char* data_env = std::getenv("LIDEF_DATA");
      ctx.data_dir = data_env && *data_env ? data_env : LIDEF_SOURCE_DATA_DIR;
      ctx.quick = o.quick;
      ctx.threads = o.threads;
      ctx.cache_dir = o.cache_dir == "<default>" ? default_cache_dir() : o.cache_dir;
      std::error_code ec;
      ctx.lidef_exe = fs::read_symlink("/proc/self/exe", ec).string();
      if (ec) throw InputError("/proc/self/exe", "cannot find this program's path: " + ec.message());
      if (o.threads > 0) omp_set_num_threads(o.threads);
      int rc = kOk;
      for (const FigureInfo* f : todo) {
        ctx.progress = [name = std::string(f->name)](const std::string& m) {
          std::cerr << "[" << name << "] " << m << "\n";
        };
        RunInfo run = machine_info();
        run.command_line = command_line();
        run.threads = o.threads;
        run.quick = o.quick;
        if (!f->run) {
          std::cerr << "lidef reproduce: error: " << f->name << " is not implemented\n";
          rc = kError;
          continue;
        }
        const auto t0 = Clock::now();
        try {
          StagedOutputs out((fs::path(o.out) / f->name).string());
          FigureOutput res;
          ctx.progress("start: " + std::string(f->title));
          f->run(ctx, out, res);
          run.seconds = seconds_since(t0);
          const bool measured = write_report(out, *f, res, run);
          out.commit();
          long holding = 0;
          for (const Claim& c : res.claims) holding += c.holds;
          std::cout << "lidef reproduce " << f->name << ": " << holding << " of " << res.claims.size()
                    << " claims hold" << (measured ? "" : " (some not measured)") << "; wrote "
                    << (fs::path(o.out) / f->name).string() << "/ (" << format_g(run.seconds, 3) << " s)\n";
          if (!measured && rc == kOk) rc = kNotCertified;
        } catch (const lidef::Error& e) {
          if (todo.size() == 1) throw;
          std::cerr << "lidef reproduce: error: " << f->name << ": " << e.what() << "\n";
          rc = kError;
        }
      }
      return rc;
    };
  });
}

}  // namespace lidef::cli
