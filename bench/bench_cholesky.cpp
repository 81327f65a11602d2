// The reduced Newton system's Cholesky factor (3s by 3s; 900 x 900 at the default 300 DOF per coordinate):
// the blocked factor over OpenMP's threads that the solver uses (lidef/internal/cholesky.h) against LAPACK's
// dpotrf in the calling thread (what the solver used before) and, for reference only, OpenBLAS's own threaded
// dpotrf (not used by lidef: its pthread workers spin after each call, blas_kernel.h). Median and minimum ms
// of --reps factorizations of a random SPD matrix per size, and the largest difference of each factor from
// dpotrf's relative to its largest entry.
//
// Usage: bench_cholesky [DATA_DIR (not read)] [--sizes 300,600,900] [--reps 30] [--threads T] (--help)
#include <omp.h>

#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/internal/cholesky.h"

extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
void openblas_set_num_threads(int);
}

using namespace lidef;

namespace {

MatXd random_spd(int n) {
  std::mt19937 rng(5);
  std::normal_distribution<double> N(0, 1);
  MatXd B(n, n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) B(i, j) = N(rng);
  MatXd H = B * B.transpose() / n;
  H.diagonal().array() += 1e-2;
  return H;
}

struct Timing {
  double median = 0, min = 0, difference = 0;
};

template <class F>
Timing time_factor(const MatXd& H, const MatXd& reference, int reps, F factor) {
  std::vector<double> ms;
  MatXd A;
  for (int r = 0; r <= reps; ++r) {  // the first run warms up
    A = H;
    const auto t0 = Clock::now();
    if (!factor(A)) std::fprintf(stderr, "bench_cholesky: a factorization failed\n");
    if (r > 0) ms.push_back(ms_since(t0));
  }
  Timing t{bench::median(ms), bench::minimum(ms), 0};
  if (reference.size())
    t.difference = (MatXd(A.triangularView<Eigen::Lower>()) - reference).cwiseAbs().maxCoeff() /
                   reference.cwiseAbs().maxCoeff();
  return t;
}

bool lapack_factor(MatXd& A) {
  const int n = static_cast<int>(A.rows());
  int info = 0;
  dpotrf_("L", &n, A.data(), &n, &info);
  return info == 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Cholesky factor of the reduced Newton system: blocked over OpenMP vs LAPACK dpotrf"};
  std::string sizes_text = "300,600,900";
  int reps = 30, threads = 0;
  std::string data_dir, cache_dir;  // accepted like every benchmark's (scripts/bench.sh); nothing is read
  bench::add_data_options(app, data_dir, threads, cache_dir);
  app.add_option("--sizes", sizes_text, "comma-separated matrix sizes n (3s for s DOF per coordinate)");
  app.add_option("--reps", reps, "timed factorizations per size and method (median reported)")
      ->check(CLI::PositiveNumber);
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  if (threads > 0) omp_set_num_threads(threads);
  threads = omp_get_max_threads();
  use_blas_in_calling_thread();

  std::printf("Machine: %s, %d threads (OpenMP), OpenBLAS kernels %s; %s; %d repetitions per cell.\n\n",
              bench::cpu_model().c_str(), threads, blas_kernel_info().core.c_str(), bench::utc_now().c_str(),
              reps);
  std::printf(
      "| n | dpotrf, calling thread: median / min ms | blocked, 1 thread | blocked, %d threads | dpotrf, "
      "OpenBLAS "
      "%d threads (reference) | blocked vs dpotrf (max rel. diff.) |\n|---:|---:|---:|---:|---:|---:|\n",
      threads, threads);
  for (const std::string& s : bench::split_list(sizes_text)) {
    const int n = std::stoi(s);
    const MatXd H = random_spd(n);
    MatXd L0 = H;
    lapack_factor(L0);
    L0 = MatXd(L0.triangularView<Eigen::Lower>());
    const Timing lapack = time_factor(H, L0, reps, lapack_factor);
    omp_set_num_threads(1);
    const Timing one = time_factor(H, L0, reps, [](MatXd& A) { return cholesky_factor(A); });
    omp_set_num_threads(threads);
    const Timing many = time_factor(H, L0, reps, [](MatXd& A) { return cholesky_factor(A); });
    openblas_set_num_threads(threads);
    const Timing threaded = time_factor(H, L0, reps, lapack_factor);
    openblas_set_num_threads(1);
    const auto cell = [](const Timing& t) {
      return bench::fixed(t.median, 2) + " / " + bench::fixed(t.min, 2);
    };
    std::printf("| %d | %s | %s | %s | %s | %s |\n", n, cell(lapack).c_str(), cell(one).c_str(),
                cell(many).c_str(), cell(threaded).c_str(),
                bench::sci(std::max(one.difference, many.difference), 1).c_str());
  }
  return 0;
}
