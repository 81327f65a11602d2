// The exact checks of a model's rest-state surface that every global injectivity checker runs once
// (docs/certificate.md, Step G1): the intersecting triangle pairs of the mesh and of the cage
// (find_self_intersections) and, where the mesh intersects itself, the exact boundary of its solid
// (rest_solid_boundary); then the whole checker's set-up (GlobalInjectivityChecker, at its default cache
// budget). Median and minimum ms of --reps runs per model.
//
// Usage: bench_rest_mesh [DATA_DIR] [--models bar,spot,horse,animal] [--reps 5] [--threads T] (--help)
#include <omp.h>

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/global_injectivity.h"
#include "lidef/internal/rest_solid.h"
#include "lidef/model_check.h"
#include "lidef/self_intersections.h"

using namespace lidef;

namespace {

// Median / minimum ms of `reps` calls of fn.
template <class Fn>
std::string timed(int reps, Fn fn) {
  std::vector<double> ms;
  for (int r = 0; r < reps; ++r) {
    const Clock::time_point t0 = Clock::now();
    fn();
    ms.push_back(1e3 * seconds_since(t0));
  }
  return bench::fixed(bench::median(ms), 1) + " / " + bench::fixed(bench::minimum(ms), 1);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"The rest-state surface checks of the global injectivity checker, per shared model"};
  std::string data_dir, cache_dir, models_text = "bar,spot,horse,animal";
  int reps = 5, threads = 0;
  bench::add_data_options(app, data_dir, threads, cache_dir);
  app.add_option("--models", models_text, "comma-separated model names (folders of DATA_DIR/models)");
  app.add_option("--reps", reps, "timed runs per cell (median and minimum reported)")
      ->check(CLI::PositiveNumber);
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  if (data_dir.empty()) data_dir = bench::default_data_dir(LIDEF_SHARED_DATA_DIR);
  if (threads > 0) omp_set_num_threads(threads);

  std::printf("Machine: %s, %d threads (OpenMP); %s; %d runs per cell, ms median / min.\n\n",
              bench::cpu_model().c_str(), omp_get_max_threads(), bench::utc_now().c_str(), reps);
  std::printf(
      "| model | mesh triangles | intersecting pairs (mesh, cage) | mesh pairs, ms | cage pairs, ms | "
      "boundary of "
      "the solid, ms | checker set-up, ms |\n|---|---:|---|---:|---:|---:|---:|\n");
  for (const std::string& name : bench::split_list(models_text)) {
    std::unique_ptr<Model> loaded;
    try {
      loaded = std::make_unique<Model>(load_model(data_dir + "/models/" + name));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bench_rest_mesh: %s\n", e.what());
      return 2;
    }
    const Model& m = *loaded;
    const auto mesh_pairs = find_self_intersections(m.mesh.V, m.mesh.F);
    const auto cage_pairs = find_self_intersections(m.cage.V, m.cage.F);
    const std::string t_mesh = timed(reps, [&] { find_self_intersections(m.mesh.V, m.mesh.F); });
    const std::string t_cage = timed(reps, [&] { find_self_intersections(m.cage.V, m.cage.F); });
    const std::string t_solid =
        mesh_pairs.empty() ? std::string("–")
                           : timed(reps, [&] { rest_solid_boundary(m.mesh.V, m.mesh.F, mesh_pairs); });
    const std::string t_setup = timed(reps, [&] { GlobalInjectivityChecker checker(m.cage, m.mesh); });
    std::printf("| %s | %ld | %zu, %zu | %s | %s | %s | %s |\n", name.c_str(),
                static_cast<long>(m.mesh.F.rows()), mesh_pairs.size(), cage_pairs.size(), t_mesh.c_str(),
                t_cage.c_str(), t_solid.c_str(), t_setup.c_str());
  }
  return 0;
}
