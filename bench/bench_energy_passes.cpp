// The deformation energy's passes over its samples, each alone (DeformationEnergy, deformation_energy.h): the
// Jacobians G y (a forward pass over the float rows of G), the energy sum at given Jacobians, the gradient's
// transposed pass Gᵀ P, the exact curvature along a direction, the subset Hessian's 9x9 blocks and one
// product with them (a kept-factor CG step's operator). Each is the median of --reps calls after one warm-up,
// at the scenario model's rest map and a fixed pseudo-random direction, so two builds can be compared on the
// same work (each row's checksum must agree between them). A whole solve mixes these with the certificate and
// the line search, and its time moves by more between runs on a shared VM than most changes to one pass.
//
// Usage: bench_energy_passes [DATA_DIR] [--only bar_bend,...] [--threads T] [--reps R] [--cache-dir DIR]
// (DATA_DIR: the shared data folder, default $LIDEF_SHARED_DATA, else the build's). Markdown on stdout.
#include <omp.h>

#include <cstdlib>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/deformation_energy.h"
#include "lidef/errors.h"
#include "lidef/model_check.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"

using namespace lidef;

int main(int argc, char** argv) {
  CLI::App app{"bench_energy_passes: the energy's passes over its samples, each alone; markdown on stdout"};
  std::string data_dir = bench::default_data_dir(LIDEF_SHARED_DATA_DIR), cache_dir = "/tmp/lidef-bench-cache";
  std::string only = "bar_bend,spot_head_turn,horse_leg_lift,animal_tail_lift";
  int threads = 2, reps = 101;
  bench::add_data_options(app, data_dir, threads, cache_dir);
  app.add_option("--only", only, "comma-separated scenario names (file stems), one row block per model");
  app.add_option("--reps", reps, "timed calls per pass (median reported)")->check(CLI::PositiveNumber);
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  if (threads > 0) omp_set_num_threads(threads);
  use_blas_in_calling_thread();
  try {
    std::cout << "Machine: " << bench::cpu_model() << ", " << omp_get_max_threads() << " threads, "
              << bench::utc_now() << "\n\n| model | pass | ms (median of " << reps
              << ") | checksum |\n|---|---|---:|---|\n";
    for (const std::string& name : bench::split_list(only)) {
      const Scenario sc = read_scenario(data_dir + "/scenarios/" + name + ".json");
      const Model model = load_model(sc.model_dir);
      DeformationSolver solver(model.cage, sc.params, cache_dir);
      const DeformationEnergy& en = solver.energy_function();
      const int s = solver.subspace().size();
      const MatS3 y = solver.subspace().basis.transpose() * solver.normalized_cage().identity_coefficients();
      std::srand(1);  // Eigen's Random: the same direction in every build
      const MatS3 d = 0.01 * MatS3::Random(s, 3);
      MatJT J = en.jacobians(y);
      const MatJT dJ = en.jacobians(d);
      std::vector<Mat9> blocks = en.subset_hessian_blocks(J);
      const auto row = [&](const std::string& pass, const bench::Timing& t) {
        std::cout << "| " << sc.model << " | " << pass << " | " << bench::fixed(t.med(), 3) << " | "
                  << bench::sci(t.checksum, 12) << (t.checksum_same ? "" : " (**differs between calls**)")
                  << " |\n";
      };
      row("Jacobians G y (" + std::to_string(en.num_samples()) + " samples)",
          bench::time_reps(reps, [&] { return (J = en.jacobians(y)).sum(); }));
      row("energy sum", bench::time_reps(reps, [&] { return en.distortion_sum(J); }));
      row("gradient's transposed pass",
          bench::time_reps(reps, [&] { return en.distortion_gradient_sum(J).sum(); }));
      row("curvature along a direction",
          bench::time_reps(reps, [&] { return en.distortion_curvature(J, dJ); }));
      row("subset Hessian blocks (" + std::to_string(blocks.size()) + " samples)",
          bench::time_reps(reps, [&] {
            blocks = en.subset_hessian_blocks(J);
            return blocks.front().sum();
          }));
      row("subset Hessian product",
          bench::time_reps(5 * reps, [&] { return en.subset_hessian_times(blocks, d).sum(); }));
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_energy_passes: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
