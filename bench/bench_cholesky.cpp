// The reduced Newton system's Cholesky factor (3s by 3s; 900 x 900 at the default 300 DOF per coordinate):
// the blocked factor over OpenMP's threads that the solver uses (lidef/internal/cholesky.h) against LAPACK's
// dpotrf in the calling thread (what the solver used before) and, for reference only, OpenBLAS's own threaded
// dpotrf (not used by lidef: its pthread workers spin after each call, blas_kernel.h). Median and minimum ms
// of --reps factorizations of a random SPD matrix per size, and the largest difference of each factor from
// dpotrf's relative to its largest entry. A second table times the solve with the factor (the kept factor's
// preconditioner at every CG step): LAPACK's dpotrs against cholesky_solve_factored (two dtrsv), both in the
// calling thread (median and minimum µs per solve over --reps batches of 100 solves), and the largest
// difference of the solutions from dpotrs's relative to its largest entry.
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
void dpotrs_(const char* uplo, const int* n, const int* nrhs, const double* a, const int* lda, double* b,
             const int* ldb, int* info);
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

// µs per solve with the factor L: --reps batches of 100 solves of the same right-hand side.
template <class F>
Timing time_solve(const MatXd& L, const VecXd& b, const VecXd& reference, int reps, F solve) {
  std::vector<double> us;
  VecXd x;
  for (int r = 0; r <= reps; ++r) {
    const auto t0 = Clock::now();
    for (int k = 0; k < 100; ++k) {
      x = b;
      if (!solve(L, x)) std::fprintf(stderr, "bench_cholesky: a solve failed\n");
    }
    if (r > 0) us.push_back(ms_since(t0) * 10);  // 1000 µs per ms over 100 solves
  }
  Timing t{bench::median(us), bench::minimum(us), 0};
  if (reference.size())
    t.difference = (x - reference).cwiseAbs().maxCoeff() / reference.cwiseAbs().maxCoeff();
  return t;
}

bool lapack_solve(const MatXd& L, VecXd& x) {
  const int n = static_cast<int>(L.rows()), one = 1;
  int info = 0;
  dpotrs_("L", &n, &one, L.data(), &n, x.data(), &n, &info);
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
  std::printf(
      "\n| n | solve, dpotrs: median / min µs | cholesky_solve_factored (two dtrsv) | difference (max rel.) "
      "|\n|---:|---:|---:|---:|\n");
  for (const std::string& s : bench::split_list(sizes_text)) {
    const int n = std::stoi(s);
    MatXd L = random_spd(n);
    lapack_factor(L);
    std::mt19937 rng(7);
    std::normal_distribution<double> N(0, 1);
    VecXd b(n);
    for (int i = 0; i < n; ++i) b(i) = N(rng);
    VecXd x0 = b;
    lapack_solve(L, x0);
    const Timing lapack = time_solve(L, b, x0, reps, lapack_solve);
    const Timing ours = time_solve(L, b, x0, reps, cholesky_solve_factored);
    const auto cell = [](const Timing& t) {
      return bench::fixed(t.median, 0) + " / " + bench::fixed(t.min, 0);
    };
    std::printf("| %d | %s | %s | %s |\n", n, cell(lapack).c_str(), cell(ours).c_str(),
                bench::sci(ours.difference, 1).c_str());
  }
  return 0;
}
