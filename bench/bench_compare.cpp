// Benchmark of `lidef compare` (analysis/compare.h): every method of the paper's Table 1 on every shared
// scenario, in one process, one scenario after the other, so the time ratios to lidef are measured side by
// side.
//
// Scenarios: every *.json in DATA_DIR/scenarios (DATA_DIR = first positional argument, else
// $LIDEF_SHARED_DATA, else ../shared/data beside the source tree); --only a,b picks by name or model.
// Methods: --methods (default all: lidef, pwl-tet at the model's tet.node/.ele = Table 1's DOF, pwl-tet-fine
// on TetGen with max tet volume =
// --fine-volume-factor × lidef's voxel volume, vhm, pwl-tri). --threads T sets OpenMP and OpenBLAS threads
// for every method (the same for all). lidef's subspace is cached in --cache-dir (default
// /tmp/lidef-bench-cache).
//
// Output: markdown on stdout — per scenario the Table-1-style table (comparison_table_md), then a summary of
// solve times and ratios; progress on stderr. Exit 0; 2 on bad input.
//
// Usage: bench_compare [DATA_DIR] [--only a,b] [--methods m1,m2] [--threads T] [--fine-volume-factor F]
//                      [--tet-max-iterations N] [--cache-dir DIR]
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/compare/compare.h"
#include "lidef/errors.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/scenario.h"

namespace fs = std::filesystem;

namespace {
std::string g(double x, int p = 3) {
  return std::isnan(x) ? "—" : lidef::format_g(x, p);
}
}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  std::string data = lidef::bench::default_data_dir(LIDEF_SHARED_DATA_DIR), cache = "/tmp/lidef-bench-cache";
  std::string only_list, methods;
  lidef::CompareOptions opt;
  for (const std::string& m : opt.methods) methods += (methods.empty() ? "" : ",") + m;
  int threads = 0;
  CLI::App app{
      "bench_compare: every method of `lidef compare` (the paper's Table 1) on every shared scenario, "
      "in one process; per scenario the Table-1-style table, then solve times and ratios to lidef"};
  app.option_defaults()->always_capture_default();
  lidef::bench::add_data_options(app, data, threads, cache);
  app.add_option("--only", only_list, "comma-separated scenario or model names");
  app.add_option("--methods", methods, "comma-separated methods");
  app.add_option("--fine-volume-factor", opt.fine_volume_factor,
                 "pwl-tet-fine: TetGen's max tet volume over lidef's voxel volume");
  app.add_option("--tet-max-iterations", opt.tet_max_iterations, "iteration limit of the tet methods");
  if (const int rc = lidef::bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  const std::vector<std::string> only = lidef::bench::split_list(only_list);
  opt.methods = lidef::bench::split_list(methods);
  if (!fs::is_directory(fs::path(data) / "scenarios")) {
    std::cerr << "bench_compare: no scenarios folder in " << data << " (skipped)\n";
    return 0;
  }
  // The library's products split over OpenMP's threads, OpenBLAS in each calling thread (blas_kernel.h).
  if (threads > 0) omp_set_num_threads(threads);
  opt.cache_dir = cache;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(fs::path(data) / "scenarios"))
    if (e.path().extension() == ".json") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  char host[256] = "?";
  gethostname(host, sizeof host);
  std::cout << "# bench_compare\n\nhost " << host << ", " << omp_get_max_threads() << " OpenMP threads"
            << (threads > 0 ? " (OpenBLAS the same)" : "") << ", fine tets: max volume "
            << opt.fine_volume_factor << " x voxel side^3\n\n";
  struct Sum {
    std::string name;
    std::vector<lidef::MethodResult> rows;
  };
  std::vector<Sum> sums;
  for (const fs::path& f : files) {
    try {
      lidef::Scenario sc = lidef::read_scenario(f.string());
      if (!only.empty() && std::find(only.begin(), only.end(), sc.name) == only.end() &&
          std::find(only.begin(), only.end(), sc.model) == only.end())
        continue;
      const lidef::Model model = lidef::load_model(sc.model_dir);
      std::cerr << "== " << sc.name << "\n";
      auto rows = lidef::run_comparison(sc, model, opt, [&](const std::string& m, const std::string& l) {
        if (l.rfind("it ", 0) != 0) std::cerr << "[" << sc.name << " " << m << "] " << l << "\n";
      });
      std::cout << lidef::comparison_table_md(rows, sc) << "\n" << std::flush;
      for (auto& r : rows) {  // keep only the numbers
        r.V.resize(0, 3);
        r.e_iso.resize(0);
        r.det_j.resize(0);
        r.log.clear();
      }
      sums.push_back({sc.name, rows});
    } catch (const std::exception& e) {
      std::cerr << "bench_compare: " << f << ": " << e.what() << "\n";
      return 2;
    }
  }
  std::cout << "## Summary: solve time in s (ratio to lidef in the same run); crease (°) in brackets\n\n| "
               "scenario |";
  for (const std::string& m : lidef::compare_methods())
    if (std::find(opt.methods.begin(), opt.methods.end(), m) != opt.methods.end())
      std::cout << " " << m << " |";
  std::cout << "\n|---|";
  for (const std::string& m : lidef::compare_methods())
    if (std::find(opt.methods.begin(), opt.methods.end(), m) != opt.methods.end()) std::cout << "---|";
  std::cout << "\n";
  for (const Sum& s : sums) {
    std::cout << "| " << s.name << " |";
    for (const auto& r : s.rows)
      std::cout << " "
                << (r.ok ? g(r.seconds) + " (" + g(r.time_ratio) + "x) [" + g(r.crease_deg, 2) + "]"
                         : "failed")
                << " |";
    std::cout << "\n";
  }
  return 0;
}
