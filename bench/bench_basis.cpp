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
#include <sys/resource.h>

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
  std::vector<std::string> models = {"animal", "bar"};
};

struct Timing {
  double median_ms = 0, min_ms = 0;  // wall clock
  double median_cpu_ms = 0;          // process CPU time (user + system, all threads)
  double checksum = 0;
};

double cpu_ms() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return 1e3 * (u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-3 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

std::string loadavg() {
  std::FILE* f = std::fopen("/proc/loadavg", "r");
  char buf[128] = {0};
  if (f) {
    if (!std::fgets(buf, sizeof buf, f)) buf[0] = 0;
    std::fclose(f);
  }
  std::string s = buf;
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s.empty() ? "unknown" : s;
}

// Runs `fn` once untimed (warm-up: page faults, caches), then `reps` times; returns median and min.
Timing time_it(int reps, const std::function<double()>& fn) {
  Timing t;
  t.checksum = fn();
  std::vector<double> ms, cpu;
  for (int r = 0; r < reps; ++r) {
    const double c0 = cpu_ms();
    const auto t0 = Clock::now();
    const double c = fn();
    ms.push_back(ms_since(t0));
    cpu.push_back(cpu_ms() - c0);
    if (std::abs(c - t.checksum) > 1e-9 * std::max(1.0, std::abs(t.checksum))) {
      std::cerr << "bench_basis: checksum changed between repetitions (" << c << " vs " << t.checksum
                << ")\n";
      std::exit(3);
    }
  }
  t.min_ms = *std::min_element(ms.begin(), ms.end());
  t.median_ms = median(ms);
  t.median_cpu_ms = median(cpu);
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

std::string fmt(double v, int prec) {
  return bench::fixed(v, prec);
}

std::string fmt_sci(double v) {
  return bench::sci(v, 3);
}

// The optimization/target flags green_coordinates.cpp was compiled with, read from the build's
// compile_commands.json (CMAKE_EXPORT_COMPILE_COMMANDS), so the report shows what the measured code really
// used.
std::string basis_compile_flags() {
  const std::string path = std::string(LIDEF_BUILD_DIR) + "/compile_commands.json";
  std::ifstream in(path);
  if (!in) return "unknown (" + path + " not found)";
  nlohmann::json db;
  try {
    in >> db;
  } catch (const std::exception&) {
    return "unknown (" + path + " unreadable)";
  }
  const std::string suffix = "/deform/src/green_coordinates.cpp";
  for (const auto& entry : db) {
    const std::string file = entry.value("file", "");
    if (file.size() < suffix.size() || file.compare(file.size() - suffix.size(), suffix.size(), suffix) != 0)
      continue;
    std::istringstream cmd(entry.value("command", ""));
    std::string tok, flags;
    while (cmd >> tok)
      if (tok.rfind("-O", 0) == 0 || tok.rfind("-m", 0) == 0 || tok.rfind("-f", 0) == 0 ||
          tok.rfind("-std", 0) == 0 || tok == "-DNDEBUG" || tok.rfind("-g", 0) == 0)
        flags += (flags.empty() ? "" : " ") + tok;
    return flags;
  }
  return "unknown (green_coordinates.cpp not in " + path + ")";
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

void usage() {
  std::cerr << "usage: bench_basis [DATA_DIR] [--reps R] [--points N] [--threads T] [--models a,b]\n";
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (const char* env = std::getenv("LIDEF_SHARED_DATA")) opt.data = env;
  if (opt.data.empty()) opt.data = LIDEF_SHARED_DATA_DIR;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        usage();
        std::exit(2);
      }
      return argv[++i];
    };
    try {
      if (a == "--reps")
        opt.reps = std::stoi(next());
      else if (a == "--points")
        opt.max_points = std::stoi(next());
      else if (a == "--threads")
        opt.max_threads = std::stoi(next());
      else if (a == "--models") {
        opt.models.clear();
        std::stringstream ss(next());
        std::string m;
        while (std::getline(ss, m, ','))
          if (!m.empty()) opt.models.push_back(m);
      } else if (a == "-h" || a == "--help") {
        usage();
        return 0;
      } else if (!a.empty() && a[0] == '-') {
        usage();
        return 2;
      } else
        opt.data = a;
    } catch (const std::exception&) {
      usage();
      return 2;
    }
  }
  if (opt.reps < 1 || opt.max_points < 1 || opt.max_threads < 1 || opt.models.empty()) {
    usage();
    return 2;
  }
  std::vector<int> thread_counts = {1};
  if (opt.max_threads > 1) thread_counts.push_back(opt.max_threads);

  std::cout << "# bench_basis: harmonic basis evaluation\n\n";
  std::cout << "- data: " << opt.data << "\n";
  std::cout << "- Eigen " << EIGEN_WORLD_VERSION << "." << EIGEN_MAJOR_VERSION << "." << EIGEN_MINOR_VERSION
            << ", Eigen::SimdInstructionSetsInUse(): " << Eigen::SimdInstructionSetsInUse()
            << "; compiler target macros: " << target_macros() << "\n";
  std::cout << "- compiler: GCC-compatible " << __VERSION__
            << "; green_coordinates.cpp compiled with: " << basis_compile_flags() << "\n";
  std::cout << "- OpenMP: omp_get_num_procs() = " << omp_get_num_procs() << ", thread counts run: ";
  for (size_t k = 0; k < thread_counts.size(); ++k) std::cout << (k ? ", " : "") << thread_counts[k];
  std::cout << "\n- repetitions: " << opt.reps
            << " timed (after 1 untimed warm-up); median and min reported\n";
  std::cout << "- load average at start (/proc/loadavg): " << loadavg() << "\n";

  struct Row {
    std::string model, what;
    int faces, n, threads;
    Eigen::Index points;
    Timing t;
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
        const Timing t = time_it(opt.reps, [&] { return evaluate_all(B, P, order); });
        rows.push_back({name, names[order], nf, n, th, N, t, true, ""});
        std::cerr << "  " << names[order] << ", " << th << " thread(s): " << fmt(t.median_ms, 1) << " ms\n";
      }

    // The precomputed gradient matrix G (3N by n, what HarmonicBasis::gradient_matrix returns) and the
    // per-map contraction J-stack = G y, a dense (3N by n) x (n by 3) product.
    omp_set_num_threads(thread_counts.back());
    MatXd G;
    const Timing tg = time_it(1, [&] {
      G = B.gradient_matrix(P);
      return G(0, 0);
    });
    rows.push_back({name, "gradient_matrix build (3N x n, stored)", nf, n, thread_counts.back(), N, tg, true,
                    fmt(8.0 * G.size() / (1 << 30), 2) + " GiB"});
    // Memory bandwidth reference: one pass reading G (a sum), 1 thread. GEMM cannot beat this.
    {
      omp_set_num_threads(1);
      const Timing t = time_it(opt.reps, [&] { return G.sum(); });
      rows.push_back({name, "read G once (G.sum(), bandwidth reference)", nf, n, 1, N, t, false,
                      fmt(8.0 * G.size() / (t.median_ms * 1e6), 2) + " GB/s"});
    }
    // Identity coefficients: G y must stack J(p_i)ᵀ = I, a sanity check that G is what is being multiplied.
    const MatXd y = cage->identity_coefficients();
    MatXd JJ;
    for (const int th : thread_counts) {
      omp_set_num_threads(th);
      Eigen::setNbThreads(th);
      const Timing t = time_it(opt.reps, [&] {
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
                      fmt(flops / (t.median_ms * 1e6), 2) + " GFLOP/s, " +
                          fmt(bytes / (t.median_ms * 1e6), 2) + " GB/s; max abs(J-I) = " + fmt_sci(err)});
      std::cerr << "  GEMM, " << th << " thread(s): " << fmt(t.median_ms, 1) << " ms, max|J-I| " << err
                << "\n";

      // The same product as three matrix-vector products (three passes over G), for comparison.
      const Timing tv = time_it(opt.reps, [&] {
        for (int c = 0; c < 3; ++c) JJ.col(c).noalias() = G * y.col(c);
        return JJ.sum();
      });
      double errv = 0;
      for (Eigen::Index i = 0; i < N; ++i)
        errv = std::max(errv, (JJ.middleRows(3 * i, 3) - MatXd::Identity(3, 3)).cwiseAbs().maxCoeff());
      rows.push_back({name, "same product as 3 GEMVs G y_c", nf, n, th, N, tv, false,
                      fmt(flops / (tv.median_ms * 1e6), 2) + " GFLOP/s, " +
                          fmt(3 * bytes / (tv.median_ms * 1e6), 2) +
                          " GB/s; max abs(J-I) = " + fmt_sci(errv)});
    }
  }

  std::cout << "- load average at end (/proc/loadavg): " << loadavg() << "\n\n";
  std::cout << "| model | faces | basis fns | points | quantity | threads | median ms | min ms | CPU ms | "
               "points/s | "
               "ns / (point x face) | CPU ns / (point x face) | notes |\n";
  std::cout << "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---|\n";
  for (const Row& r : rows) {
    const double s = r.t.median_ms * 1e-3;
    std::cout << "| " << r.model << " | " << r.faces << " | " << r.n << " | " << r.points << " | " << r.what
              << " | " << r.threads << " | " << fmt(r.t.median_ms, 1) << " | " << fmt(r.t.min_ms, 1) << " | "
              << fmt(r.t.median_cpu_ms, 1) << " | " << (r.per_face ? fmt_sci(r.points / s) : "") << " | "
              << (r.per_face ? fmt(1e9 * s / (double(r.points) * r.faces), 1) : "") << " | "
              << (r.per_face ? fmt(1e6 * r.t.median_cpu_ms / (double(r.points) * r.faces), 1) : "") << " | "
              << r.extra << " |\n";
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
                    << fmt(g.t.median_ms, 1) << " ms vs GEMM " << fmt(m.t.median_ms, 1) << " ms (x"
                    << fmt(g.t.median_ms / m.t.median_ms, 0) << ")\n";
  return 0;
}
