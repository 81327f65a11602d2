// Benchmark of the harmonic basis (HarmonicBasis::evaluate): values, gradients and Hessians of all #V+#F
// basis functions at the published sample points of a model, with 1..T OpenMP threads; and, for comparison,
// the dense GEMM that applies a precomputed gradient matrix G (3N by #V+#F) to coefficients y (#V+#F by 3) —
// the per-map cost once G is stored, against the cost of evaluating the basis on the fly.
//
// Usage: bench_basis [DATA_DIR] [--reps R] [--points N] [--threads T] [--models a,b]
//   DATA_DIR   shared data folder (default: $LIDEF_SHARED_DATA, else the build's ../shared/data)
//   --reps     timed repetitions per configuration (default 3); the median and the minimum are reported
//   --points   use at most N points of each model's samples.xyz (default 30000)
//   --threads  largest thread count; runs 1 and T (default 2)
//   --models   comma-separated model names (default animal,bar)
// Each model is evaluated at its own samples.xyz (voxel centers, all inside the cage): the real workload.
// Prints a markdown table with wall-clock and process CPU times (the CPU time per point x face is the cost
// per core and stays meaningful when other processes share the machine); exit code 2 when the data is
// missing.
#include <omp.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/cage.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_io.h"
#include "nlohmann/json.hpp"

using namespace lidef;

namespace {

struct Options {
  std::string data;
  int reps = 3;
  int max_points = 30000;
  int max_threads = 2;
  std::vector<std::string> models;
};

// Times `work` (bench::time_reps) and stops the program (exit code 3) when its checksum changed between
// repetitions.
bench::Timing time_checked(int reps, const std::function<double()>& work) {
  const bench::Timing t = bench::time_reps(reps, work);
  if (!t.checksum_same) {
    std::cerr << "bench_basis: checksum changed between repetitions\n";
    std::exit(3);
  }
  return t;
}

// Evaluates the basis at every point with the given order, keeping only the quantity of that order
// (order 0: values, 1: gradients, 2: Hessians). Returns a checksum so the work cannot be skipped.
double evaluate_all(const HarmonicBasis& B, const MatX3d& P, int order) {
  const int n = B.size();
  const int width = order == 0 ? 1 : order == 1 ? 3 : kSym;
  double checksum = 0;
#pragma omp parallel reduction(+ : checksum)
  {
    std::vector<double> buf(static_cast<size_t>(width) * n);
#pragma omp for schedule(static)
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      const Vec3 p = P.row(i).transpose();
      B.evaluate(p, order, order == 0 ? buf.data() : nullptr, order == 1 ? buf.data() : nullptr,
                 order == 2 ? buf.data() : nullptr);
      checksum += buf[(i * 7919) % buf.size()];
    }
  }
  return checksum;
}

// Vector instruction sets enabled for this translation unit (Eigen's string does not name AVX2/FMA
// separately).
std::string target_macros() {
  std::string s;
  auto add = [&](const char* name) { s += (s.empty() ? "" : " ") + std::string(name); };
#ifdef __SSE4_2__
  add("SSE4.2");
#endif
#ifdef __AVX__
  add("AVX");
#endif
#ifdef __AVX2__
  add("AVX2");
#endif
#ifdef __FMA__
  add("FMA");
#endif
#ifdef __AVX512F__
  add("AVX512F");
#endif
  return s.empty() ? "none beyond SSE2" : s;
}

}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  Options opt;
  opt.data = bench::default_data_dir(LIDEF_SHARED_DATA_DIR);
  std::string models = "animal,bar";
  CLI::App app{
      "bench_basis: harmonic basis evaluation (values, gradients, Hessians) at each model's samples.xyz, "
      "and the GEMM with the stored gradient matrix; a markdown report on stdout"};
  app.option_defaults()->always_capture_default();
  app.add_option("DATA_DIR", opt.data, "shared data folder (default: $LIDEF_SHARED_DATA, else the build's)");
  app.add_option("--reps", opt.reps,
                 "timed repetitions per configuration; the median and the minimum are reported")
      ->check(CLI::PositiveNumber);
  app.add_option("--points", opt.max_points, "use at most N points of each model's samples.xyz")
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", opt.max_threads, "largest thread count; runs 1 and T")
      ->check(CLI::PositiveNumber);
  app.add_option("--models", models, "comma-separated model names");
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  opt.models = bench::split_list(models);
  if (opt.models.empty()) {
    std::cerr << "bench_basis: --models: no model named\n";
    return 2;
  }
  std::vector<int> thread_counts = {1};
  if (opt.max_threads > 1) thread_counts.push_back(opt.max_threads);

  std::cout << "# bench_basis: harmonic basis evaluation\n\n";
  std::cout << "- data: " << opt.data << "\n";
  std::cout << "- Eigen " << EIGEN_WORLD_VERSION << "." << EIGEN_MAJOR_VERSION << "." << EIGEN_MINOR_VERSION
            << ", Eigen::SimdInstructionSetsInUse(): " << Eigen::SimdInstructionSetsInUse()
            << "; compiler target macros: " << target_macros() << "\n";
  std::cout << "- compiler: GCC-compatible " << __VERSION__ << "; green_coordinates.cpp compiled with: "
            << bench::compile_flags(LIDEF_BUILD_DIR, "/deform/src/green_coordinates.cpp") << "\n";
  std::cout << "- OpenMP: omp_get_num_procs() = " << omp_get_num_procs() << ", thread counts run: ";
  for (size_t k = 0; k < thread_counts.size(); ++k) std::cout << (k ? ", " : "") << thread_counts[k];
  std::cout << "\n- repetitions: " << opt.reps
            << " timed (after 1 untimed warm-up); median and min reported\n";
  std::cout << "- load average at start (/proc/loadavg): " << bench::load_average() << "\n";

  struct Row {
    std::string model, what;
    int faces, n, threads;
    Eigen::Index points;
    bench::Timing t;
    bool per_face;  // report points/s and ns per point×face
    std::string extra;
  };
  std::vector<Row> rows;

  for (const std::string& name : opt.models) {
    const std::string dir = opt.data + "/models/" + name;
    MatX3d P;
    std::unique_ptr<Cage> cage;
    try {
      cage = std::make_unique<Cage>(read_mesh(dir + "/cage.obj"));
      P = read_points_xyz(dir + "/samples.xyz");
    } catch (const Error& e) {
      std::cerr << "bench_basis: " << e.what() << "\n";
      return 2;
    }
    if (P.rows() > opt.max_points) P.conservativeResize(opt.max_points, 3);
    const HarmonicBasis B(*cage);
    const int nf = B.num_faces(), n = B.size();
    const Eigen::Index N = P.rows();
    std::cerr << "bench_basis: " << name << ": " << B.num_vertices() << " vertices, " << nf << " faces, " << N
              << " points\n";

    const char* names[3] = {"values", "gradients", "Hessians"};
    for (int order = 0; order < 3; ++order)
      for (const int th : thread_counts) {
        omp_set_num_threads(th);
        const bench::Timing t = time_checked(opt.reps, [&] { return evaluate_all(B, P, order); });
        rows.push_back({name, names[order], nf, n, th, N, t, true, ""});
        std::cerr << "  " << names[order] << ", " << th << " thread(s): " << bench::fixed(t.med(), 1)
                  << " ms\n";
      }

    // The precomputed gradient matrix G (3N by n, what HarmonicBasis::gradient_matrix returns) and the
    // per-map contraction J-stack = G y, a dense (3N by n) x (n by 3) product.
    omp_set_num_threads(thread_counts.back());
    MatXd G;
    const bench::Timing tg = time_checked(1, [&] {
      G = B.gradient_matrix(P);
      return G(0, 0);
    });
    rows.push_back({name, "gradient_matrix build (3N x n, stored)", nf, n, thread_counts.back(), N, tg, true,
                    bench::fixed(8.0 * G.size() / (1 << 30), 2) + " GiB"});
    // Memory bandwidth reference: one pass reading G (a sum), 1 thread. GEMM cannot beat this.
    {
      omp_set_num_threads(1);
      const bench::Timing t = time_checked(opt.reps, [&] { return G.sum(); });
      rows.push_back({name, "read G once (G.sum(), bandwidth reference)", nf, n, 1, N, t, false,
                      bench::fixed(8.0 * G.size() / (t.med() * 1e6), 2) + " GB/s"});
    }
    // Identity coefficients: G y must stack J(p_i)ᵀ = I, a sanity check that G is what is being multiplied.
    const MatXd y = cage->identity_coefficients();
    MatXd JJ;
    for (const int th : thread_counts) {
      omp_set_num_threads(th);
      Eigen::setNbThreads(th);
      const bench::Timing t = time_checked(opt.reps, [&] {
        JJ.noalias() = G * y;
        return JJ.sum();
      });
      double err = 0;
      for (Eigen::Index i = 0; i < N; ++i)
        err = std::max(err, (JJ.middleRows(3 * i, 3) - MatXd::Identity(3, 3)).cwiseAbs().maxCoeff());
      const double flops = 2.0 * G.rows() * G.cols() * 3, bytes = 8.0 * G.size();
      rows.push_back({name,
                      "GEMM G y: (" + std::to_string(G.rows()) + " x " + std::to_string(G.cols()) + ") x (" +
                          std::to_string(G.cols()) + " x 3)",
                      nf, n, th, N, t, false,
                      bench::fixed(flops / (t.med() * 1e6), 2) + " GFLOP/s, " +
                          bench::fixed(bytes / (t.med() * 1e6), 2) +
                          " GB/s; max abs(J-I) = " + bench::sci(err)});
      std::cerr << "  GEMM, " << th << " thread(s): " << bench::fixed(t.med(), 1) << " ms, max|J-I| " << err
                << "\n";

      // The same product as three matrix-vector products (three passes over G), for comparison.
      const bench::Timing tv = time_checked(opt.reps, [&] {
        for (int c = 0; c < 3; ++c) JJ.col(c).noalias() = G * y.col(c);
        return JJ.sum();
      });
      double errv = 0;
      for (Eigen::Index i = 0; i < N; ++i)
        errv = std::max(errv, (JJ.middleRows(3 * i, 3) - MatXd::Identity(3, 3)).cwiseAbs().maxCoeff());
      rows.push_back({name, "same product as 3 GEMVs G y_c", nf, n, th, N, tv, false,
                      bench::fixed(flops / (tv.med() * 1e6), 2) + " GFLOP/s, " +
                          bench::fixed(3 * bytes / (tv.med() * 1e6), 2) +
                          " GB/s; max abs(J-I) = " + bench::sci(errv)});
    }
  }

  std::cout << "- load average at end (/proc/loadavg): " << bench::load_average() << "\n\n";
  std::cout << "| model | faces | basis fns | points | quantity | threads | median ms | min ms | CPU ms | "
               "points/s | "
               "ns / (point x face) | CPU ns / (point x face) | notes |\n";
  std::cout << "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---|\n";
  for (const Row& r : rows) {
    const double s = r.t.med() * 1e-3;
    std::cout << "| " << r.model << " | " << r.faces << " | " << r.n << " | " << r.points << " | " << r.what
              << " | " << r.threads << " | " << bench::fixed(r.t.med(), 1) << " | "
              << bench::fixed(r.t.min(), 1) << " | " << bench::fixed(r.t.med_cpu(), 1) << " | "
              << (r.per_face ? bench::sci(r.points / s) : "") << " | "
              << (r.per_face ? bench::fixed(1e9 * s / (double(r.points) * r.faces), 1) : "") << " | "
              << (r.per_face ? bench::fixed(1e6 * r.t.med_cpu() / (double(r.points) * r.faces), 1) : "")
              << " | " << r.extra << " |\n";
  }
  std::cout
      << "\nmedian/min ms: wall clock. CPU ms: process CPU time of the timed run (user + system, all "
         "threads). "
         "ns / (point x face) = median wall time / (points x faces); CPU ns / (point x face) = CPU time / "
         "(points x faces), the cost per core, less sensitive to other load on the machine.\n";
  // Ratio of on-the-fly gradient evaluation to the stored-matrix product, per model and thread count.
  std::cout << "\nOn-the-fly gradient evaluation vs. GEMM with the stored G (median times):\n\n";
  for (const Row& g : rows)
    if (g.what == "gradients")
      for (const Row& m : rows)
        if (m.model == g.model && m.threads == g.threads && m.what.rfind("GEMM", 0) == 0)
          std::cout << "- " << g.model << ", " << g.threads << " thread(s): gradients "
                    << bench::fixed(g.t.med(), 1) << " ms vs GEMM " << bench::fixed(m.t.med(), 1) << " ms (x"
                    << bench::fixed(g.t.med() / m.t.med(), 0) << ")\n";
  return 0;
}
