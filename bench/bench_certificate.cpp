// Benchmark of the local-injectivity certificate in the reduced space (OctreeCertifier::certify_reduced), the
// per-map cost of the certificate once the per-cage precomputation is done (target: ≤ 50 ms per certification
// on the bar).
//
// Per model: load_model, sample_voxels (target 30,000 voxels), load_or_compute_subspace(cage, s = 300,
// default_cache_dir()), then OctreeCertifier(cage, sampling, &Ξ) (the reduced path; its construction and the
// lazily built per-voxel per-edge bound factors of each bound are timed separately as precomputation).
// Two maps given in the reduced space are certified:
//   identity  ỹ = Ξᵀ y_id (affine: no refinement; a baseline, and min σ3 must be 1)
//   deformed  ỹ = Ξᵀ y_id + c D, D a fixed mix of the smooth non-affine subspace columns 4..11, with c found
//   by
//             bisection so that min σ3 over the base centers is --sigma-target (default 0.45): certified,
//             with some refinement.
// Bounds: first, third and combined (docs/certificate.md Step 3b). The deformed map (the only one that
// refines) is certified with each evaluation of the children (CertifyParams::refinement: per-face, per-edge,
// batched — docs/certificate.md Steps 4b, 4c) side by side in the same run, and the three must agree on the
// verdict, the refined and the leaf counts; "µs per child" = refine ms / (8 × subdivided nodes). Each (map,
// bound, refinement, threads) is run 2 times untimed (warm-up), then --reps times (default 10); the per-stage
// times of Certificate (ms_jacobian, ms_sigma, ms_bound, ms_refine, ms_total) are reported as median and
// minimum over the timed runs. keep_leaves = false in the timed runs (the verdict never depends on it).
//
// Memory traffic: one certification streams the precomputed reduced matrices (3|I| by s gradient rows and
// 6|I| by s Hessian rows) and the |I| by #E bound-factor matrix of the bound used. Their element size is not
// in the public API; it is measured from the growth of the resident set (/proc/self/statm) when the certifier
// is built and when each bound's factors are first built, and cross-checked against the header (a declared
// float storage allowance, OctreeCertifier::kFloatStorageRel, means float storage). As the memory-bandwidth
// reference, the same number of bytes is read once by a plain OpenMP reduction over arrays of that type,
// in the same run and with the same thread counts.
//
// Validation (once per model, printed): the deformed map is also certified in the full space by a certifier
// that evaluates the basis on the fly in double (OctreeCertifier(cage, sampling, nullptr, 0).certify(Ξ ỹ));
// the min σ3, the verdict and the σ3 of every base voxel left unrefined by both must agree (1e-9 when the
// reduced matrices are stored as doubles; float storage is allowed 1e-5). Every timed run must reproduce the
// verdict, min σ3, refined and leaf counts of the first run. Exit code 3 when a check fails, 2 on bad input.
//
// Usage: bench_certificate [DATA_DIR] [--reps R] [--threads T] [--models a,b] [--voxels N] [--s S]
//                          [--sigma-target X] [--no-validate]
#include <omp.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/cage.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/model_check.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/subspace.h"
#include "nlohmann/json.hpp"

using namespace lidef;

namespace {

using MatX3dCol = Eigen::Matrix<double, Eigen::Dynamic, 3>;  // reduced coefficients ỹ (s by 3)

struct Options {
  std::string data;
  int reps = 10;
  int warmup = 2;
  int max_threads = 2;
  int voxels = 30000;
  int s = 300;
  double sigma_target = 0.45;
  double far_reach = CertifyParams{}.far_field_reach;
  bool validate = true;
  std::vector<std::string> models;
};

// Resident set size in bytes (/proc/self/statm, second field); 0 when unavailable.
double rss_bytes() {
  std::ifstream in("/proc/self/statm");
  long size = 0, resident = 0;
  if (!(in >> size >> resident)) return 0;
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE));
}

// Whether the header declares a float-storage allowance (the float storage of the reduced matrices).
template <class T, class = void>
struct declares_float_storage : std::false_type {};
template <class T>
struct declares_float_storage<T, std::void_t<decltype(T::kFloatStorageRel)>> : std::true_type {};

// Modification times of the certifier source and of the library this program was linked with, so a report
// shows which version of octree_certifier.cpp it measured (and warns when the source is newer than the
// build).
std::string file_time(const std::string& path) {
  std::error_code ec;
  const auto ft = std::filesystem::last_write_time(path, ec);
  if (ec) return "unknown";
  const auto sys = std::chrono::time_point_cast<std::chrono::system_clock::duration>(
      ft - std::filesystem::file_time_type::clock::now() + std::chrono::system_clock::now());
  return bench::utc_text(std::chrono::system_clock::to_time_t(sys));
}

struct RunResult {
  bool certified = false;
  double min_sigma3 = 0;
  long refined = 0, leaves = 0;
  int depth = 0;
  double min_margin = 0;
  bool operator==(const RunResult& o) const {
    return certified == o.certified && min_sigma3 == o.min_sigma3 && refined == o.refined &&
           leaves == o.leaves;
  }
};
RunResult summarize(const Certificate& c) {
  return {c.certified, c.min_sigma3_center, c.refined, c.num_leaves, c.max_depth_used, c.min_margin};
}

struct Stages {
  std::vector<double> jac, sig, bnd, ref, tot, wall, cpu;
};

struct Row {
  std::string model, map, bound;
  std::string refine = "batched";  // CertifyParams::refinement (to_string)
  int threads = 1;
  RunResult r;
  Stages st;
  double bytes = 0, flops = 0, stream_gbs = 0, stream_ms = 0;
};

[[noreturn]] void fail(const std::string& msg) {
  std::cerr << "bench_certificate: CHECK FAILED: " << msg << "\n";
  std::exit(3);
}

// One pass reading every element of `v` (a reduction): the bandwidth reference. Returns the checksum.
template <class T>
double read_pass(const std::vector<T>& v) {
  const T* p = v.data();
  const long n = static_cast<long>(v.size());
  double acc = 0;
#pragma omp parallel for schedule(static) reduction(+ : acc)
  for (long blk = 0; blk < n; blk += 4096) {
    const long e = std::min(n, blk + 4096);
    double s = 0;
#pragma omp simd reduction(+ : s)
    for (long k = blk; k < e; ++k) s += static_cast<double>(p[k]);
    acc += s;
  }
  return acc;
}

template <class T>
std::vector<T> filled(size_t n) {
  std::vector<T> v(n);
#pragma omp parallel for schedule(static)
  for (long i = 0; i < static_cast<long>(n); ++i) v[i] = static_cast<T>((i % 1000) * 1e-3);
  return v;
}

struct StreamTiming {
  double median_ms = 0, min_ms = 0, bytes = 0;
};
// Median and min ms of one read pass over an array of n1 T1 plus one of n2 T2 (the stored matrices' sizes).
template <class T1, class T2>
StreamTiming time_read(size_t n1, size_t n2, int reps, int threads) {
  const std::vector<T1> a = filled<T1>(n1);
  const std::vector<T2> b = filled<T2>(n2);
  omp_set_num_threads(threads);
  const bench::Timing t = bench::time_reps(reps, [&] { return read_pass(a) + read_pass(b); });
  if (!t.checksum_same) fail("read-pass checksum changed");
  return {t.med(), t.min(), double(n1) * sizeof(T1) + double(n2) * sizeof(T2)};
}

StreamTiming time_read_dispatch(int e1, size_t n1, int e2, size_t n2, int reps, int threads) {
  if (e1 == 4 && e2 == 4) return time_read<float, float>(n1, n2, reps, threads);
  if (e1 == 4) return time_read<float, double>(n1, n2, reps, threads);
  if (e2 == 4) return time_read<double, float>(n1, n2, reps, threads);
  return time_read<double, double>(n1, n2, reps, threads);
}

}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  Options opt;
  opt.data = bench::default_data_dir(LIDEF_SHARED_DATA_DIR);
  std::string models = "bar,animal";
  bool no_validate = false;
  CLI::App app{
      "bench_certificate: the local-injectivity certificate in the reduced space (certify_reduced) "
      "on an identity and a deformed map per model: per-stage times, bytes streamed and a read-pass "
      "bandwidth reference; a markdown report on stdout"};
  app.option_defaults()->always_capture_default();
  app.add_option("DATA_DIR", opt.data, "shared data folder (default: $LIDEF_SHARED_DATA, else the build's)");
  app.add_option("--reps", opt.reps, "timed repetitions per configuration (after 2 untimed warm-ups)")
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", opt.max_threads, "largest thread count; runs 1 and T")
      ->check(CLI::PositiveNumber);
  app.add_option("--models", models, "comma-separated model names");
  app.add_option("--voxels", opt.voxels, "target voxel count of sample_voxels")->check(CLI::PositiveNumber);
  app.add_option("--s", opt.s, "subspace size s")->check(CLI::Range(5, 1 << 20));
  app.add_option("--sigma-target", opt.sigma_target,
                 "min sigma3 over the base centers of the deformed map, in (0, 1)")
      ->check(CLI::Validator(
          [](std::string& v) {
            const double x = std::atof(v.c_str());
            return x > 0 && x < 1 ? std::string() : "must lie strictly between 0 and 1";
          },
          "in (0, 1)"));
  app.add_option("--far-reach", opt.far_reach, "CertifyParams::far_field_reach of the far-field rows");
  app.add_flag("--no-validate", no_validate, "skip the validation against the full-space certifier");
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  opt.validate = !no_validate;
  opt.models = bench::split_list(models);
  if (opt.models.empty()) {
    std::cerr << "bench_certificate: --models: no model named\n";
    return 2;
  }
  std::vector<int> thread_counts = {1};
  if (opt.max_threads > 1) thread_counts.push_back(opt.max_threads);
  const std::string src = std::string(LIDEF_SOURCE_DIR) + "/deform/src/octree_certifier.cpp";
  const bool header_float = declares_float_storage<OctreeCertifier>::value;

  std::cout << "# bench_certificate: reduced-space certificate (certify_reduced)\n\n";
  std::cout << "- data: " << opt.data << "\n";
  std::cout << "- octree_certifier.cpp: source modified " << file_time(src) << "; linked library "
            << LIDEF_CORE_FILE << " built " << file_time(LIDEF_CORE_FILE) << "\n";
  std::cout << "- compiler: GCC-compatible " << __VERSION__ << "; octree_certifier.cpp compiled with: "
            << bench::compile_flags(LIDEF_BUILD_DIR, "/deform/src/octree_certifier.cpp") << "\n";
  std::cout << "- OpenMP: omp_get_num_procs() = " << omp_get_num_procs() << ", thread counts run: ";
  for (size_t k = 0; k < thread_counts.size(); ++k) std::cout << (k ? ", " : "") << thread_counts[k];
  std::cout
      << "\n- repetitions: " << opt.warmup << " untimed warm-ups, then " << opt.reps
      << " timed; median and min reported; keep_leaves = false, other CertifyParams at their defaults\n";
  std::cout << "- header declares float storage allowance (kFloatStorageRel): "
            << (header_float ? "yes" : "no") << "\n";
  std::cout << "- load average at start (/proc/loadavg): " << bench::load_average()
            << "; CPU pressure (/proc/pressure/cpu): " << bench::cpu_pressure() << "\n";

  std::vector<Row> rows;
  std::vector<std::string> notes;

  for (const std::string& name : opt.models) {
    const std::string dir = opt.data + "/models/" + name;
    omp_set_num_threads(thread_counts.back());
    auto t0 = Clock::now();
    std::unique_ptr<Model> model;
    try {
      model = std::make_unique<Model>(load_model(dir));
    } catch (const Error& e) {
      std::cerr << "bench_certificate: " << e.what() << "\n";
      return 2;
    }
    const double ms_load = ms_since(t0);
    const Cage& cage = model->cage;
    SamplingParams sp;
    sp.target_count = opt.voxels;
    t0 = Clock::now();
    const VoxelSampling sampling = sample_voxels(cage, sp);
    const double ms_sample = ms_since(t0);
    t0 = Clock::now();
    const SpectralSubspace sub = load_or_compute_subspace(cage, opt.s, default_cache_dir());
    const double ms_sub = ms_since(t0);
    const MatXd& Xi = sub.basis;
    const long N = sampling.size(), s = Xi.cols(), E = cage.num_edges(), n = cage.num_coeffs();
    std::cerr << "bench_certificate: " << name << ": |I| = " << N << ", s = " << s << ", #E = " << E << "\n";

    const double rss0 = rss_bytes();
    t0 = Clock::now();
    OctreeCertifier cert(cage, sampling, &Xi);
    const double ms_build = ms_since(t0);
    const double rss_build = rss_bytes() - rss0;
    const double elem_gh_meas = rss_build / (9.0 * N * s);
    const int elem_gh = elem_gh_meas < 6 ? 4 : 8;

    // Identity in the reduced space: Ξᵀ y_id reproduces y_id exactly (affine maps lie in span Ξ).
    const MatX3d y_id = cage.identity_coefficients();
    const MatX3dCol yr_id = Xi.transpose() * y_id;
    const double id_resid = (Xi * yr_id - MatXd(y_id)).cwiseAbs().maxCoeff() / y_id.cwiseAbs().maxCoeff();
    if (!(id_resid < 1e-10))
      fail(name + ": identity not in span Xi (rel. residual " + bench::sci(id_resid) + ")");

    // First call per bound: builds that bound's |I| by #E factor matrix (per-cage precomputation).
    CertifyParams timed;
    timed.keep_leaves = false;
    std::map<std::string, double> ms_first, elem_f_meas;
    std::map<std::string, int> elem_f;
    for (const LipschitzBound b : {LipschitzBound::kFirstOrder, LipschitzBound::kThirdOrder}) {
      CertifyParams p = timed;
      p.bound = b;
      const double r0 = rss_bytes();
      const auto t1 = Clock::now();
      const Certificate c = cert.certify_reduced(yr_id, p);
      ms_first[to_string(b)] = ms_since(t1);
      elem_f_meas[to_string(b)] = (rss_bytes() - r0) / (double(N) * E);
      // Under 2 bytes per entry: the factors were not built by this call (no lazy build); fall back to the
      // header's storage hint and say so in the report.
      const double em = elem_f_meas[to_string(b)];
      elem_f[to_string(b)] = em < 2 ? (header_float ? 4 : 8) : em < 6 ? 4 : 8;
      if (em < 2)
        notes.push_back(name + ": the " + std::string(to_string(b)) +
                        " factors were not allocated by the first call; their element size is taken from the "
                        "header (" +
                        std::to_string(elem_f[to_string(b)]) + " bytes)");
      if (!c.certified || c.refined != 0 || !(std::abs(c.min_sigma3_center - 1) < 1e-5))
        fail(name + ": identity map: certified " + std::to_string(c.certified) + ", refined " +
             std::to_string(c.refined) + ", min sigma3 " + bench::sci(c.min_sigma3_center, 17));
    }

    // The deformed map: ỹ = ỹ_id + c D, D a fixed mix of the smooth non-affine columns 4..11.
    MatX3dCol D = MatX3dCol::Zero(s, 3);
    const double w[8] = {1.0, -0.8, 0.6, -0.5, 0.4, -0.3, 0.25, -0.2};
    for (int k = 4; k < 12 && k < s; ++k) D(k, k % 3) = w[k - 4];
    D *= y_id.cwiseAbs().maxCoeff();  // model units
    auto base_min_sigma = [&](double c) {
      CertifyParams p = timed;
      p.max_depth = 0;  // base centers only
      return cert.certify_reduced(yr_id + c * D, p).min_sigma3_center;
    };
    omp_set_num_threads(thread_counts.back());
    double lo = 0, hi = 0.01;
    while (base_min_sigma(hi) > opt.sigma_target && hi < 1e3) {
      lo = hi;
      hi *= 2;
    }
    for (int it = 0; it < 30; ++it) {
      const double mid = 0.5 * (lo + hi);
      (base_min_sigma(mid) > opt.sigma_target ? lo : hi) = mid;
    }
    const double scale = lo;  // largest probed scale with min σ3 above the target
    const MatX3dCol yr_def = yr_id + scale * D;
    const double smin_base = base_min_sigma(scale);
    std::cerr << "  deformation scale " << scale << ", base min sigma3 " << smin_base << "\n";

    // Validation against the full-space certifier evaluating the basis on the fly in double.
    std::string validation = "skipped (--no-validate)";
    if (opt.validate) {
      CertifyParams p;  // defaults, keep_leaves = true
      const auto tv = Clock::now();
      const Certificate red = cert.certify_reduced(yr_def, p);
      const MatX3d y_def = Xi * yr_def;
      const OctreeCertifier full(cage, sampling, nullptr, 0.0);
      const Certificate ful = full.certify(y_def, p);
      const double d_min = std::abs(red.min_sigma3_center - ful.min_sigma3_center);
      std::vector<double> base_r(N, std::nan("")), base_f(N, std::nan(""));
      for (const CertLeaf& l : red.leaves)
        if (l.depth == 0) base_r[l.base] = l.sigma3;
      for (const CertLeaf& l : ful.leaves)
        if (l.depth == 0) base_f[l.base] = l.sigma3;
      double d_base = 0;
      long compared = 0;
      for (long i = 0; i < N; ++i)
        if (!std::isnan(base_r[i]) && !std::isnan(base_f[i])) {
          d_base = std::max(d_base, std::abs(base_r[i] - base_f[i]));
          ++compared;
        }
      const double tol = elem_gh == 8 ? 1e-9 : 1e-5;
      validation = "reduced (stored, " + std::to_string(elem_gh) +
                   "-byte) vs full-space on-the-fly double, " + "third bound: min sigma3 " +
                   bench::sci(red.min_sigma3_center, 15) + " vs " + bench::sci(ful.min_sigma3_center, 15) +
                   " (|diff| " + bench::sci(d_min) + "); sigma3 at " + std::to_string(compared) +
                   " unrefined base voxels: max |diff| " + bench::sci(d_base) + "; verdict " +
                   (red.certified ? "certified" : "NOT certified") + " vs " +
                   (ful.certified ? "certified" : "NOT certified") + "; refined " +
                   std::to_string(red.refined) + " vs " + std::to_string(ful.refined) + "; leaves " +
                   std::to_string(red.num_leaves) + " vs " + std::to_string(ful.num_leaves) + "; tolerance " +
                   bench::sci(tol) + " (" + bench::fixed(ms_since(tv) / 1000, 1) + " s)";
      std::cerr << "  validation: " << validation << "\n";
      if (!(d_min <= tol) || !(d_base <= tol) || compared == 0 || red.certified != ful.certified)
        fail(name + ": " + validation);
    }

    elem_f["combined"] = elem_f["third"];  // both factor matrices, each of the same element type
    elem_f["spectral"] = elem_f["third"];
    // Timed runs: every bound on both maps with the default (batched) refinement; on the deformed map (the
    // only one that refines) also the per-face and the one-child-at-a-time per-edge evaluation, side by side.
    struct Config {
      std::string map;
      const MatX3dCol* yr;
      LipschitzBound bound;
      RefinementEval refinement;
    };
    std::vector<Config> configs;
    for (const auto& [mapname, yr] : {std::pair<std::string, const MatX3dCol*>{"identity", &yr_id},
                                      std::pair<std::string, const MatX3dCol*>{"deformed", &yr_def}})
      for (const LipschitzBound b : {LipschitzBound::kFirstOrder, LipschitzBound::kThirdOrder,
                                     LipschitzBound::kCombined, LipschitzBound::kSpectral}) {
        if (mapname == "deformed") {
          configs.push_back({mapname, yr, b, RefinementEval::kPerFace});
          configs.push_back({mapname, yr, b, RefinementEval::kPerEdge});
        }
        configs.push_back({mapname, yr, b, RefinementEval::kPerEdgeBatched});
        // Far field (third-order bound only): its remainder can change which nodes refine, not the verdict.
        if (mapname == "deformed" && b == LipschitzBound::kThirdOrder)
          configs.push_back({mapname, yr, b, RefinementEval::kFarField});
      }
    for (const Config& cfg : configs)
      for (const int th : thread_counts) {
        const std::string& mapname = cfg.map;
        const MatX3dCol* yr = cfg.yr;
        omp_set_num_threads(th);
        CertifyParams p = timed;
        p.bound = cfg.bound;
        p.refinement = cfg.refinement;
        p.far_field_reach = opt.far_reach;
        Row row;
        row.model = name;
        row.map = mapname;
        row.bound = to_string(cfg.bound);
        row.refine = to_string(cfg.refinement);
        row.threads = th;
        for (int k = 0; k < opt.warmup; ++k) row.r = summarize(cert.certify_reduced(*yr, p));
        for (int k = 0; k < opt.reps; ++k) {
          const double c0 = bench::cpu_ms();
          const auto t1 = Clock::now();
          const Certificate c = cert.certify_reduced(*yr, p);
          row.st.wall.push_back(ms_since(t1));
          row.st.cpu.push_back(bench::cpu_ms() - c0);
          if (!(summarize(c) == row.r)) fail(name + ": certificate changed between repetitions");
          row.st.jac.push_back(c.ms_jacobian);
          row.st.sig.push_back(c.ms_sigma);
          row.st.bnd.push_back(c.ms_bound);
          row.st.ref.push_back(c.ms_refine);
          row.st.tot.push_back(c.ms_total);
        }
        if (mapname == "deformed" && !row.r.certified)
          notes.push_back(name + ", " + row.bound + " bound: the deformed map is NOT certified");
        if (mapname == "deformed" && row.r.refined == 0)
          notes.push_back(name + ", " + row.bound + " bound: the deformed map needed no refinement");
        const bool two = row.bound == "combined" || row.bound == "spectral";  // both factor matrices
        row.bytes = 9.0 * N * s * elem_gh + (two ? 2.0 : 1.0) * N * E * elem_f[row.bound];
        row.flops = 2.0 * 9 * N * s * 3;
        // The three exact evaluations of the children must take the same decisions (same thread count); the
        // far field the same verdict.
        const bool approx = cfg.refinement == RefinementEval::kFarField;
        for (const Row& o : rows)
          if (o.model == name && o.map == mapname && o.bound == row.bound && o.threads == th &&
              (o.r.certified != row.r.certified ||
               (!approx && (o.r.refined != row.r.refined || o.r.leaves != row.r.leaves))))
            fail(name + ", " + mapname + ", " + row.bound + ": refinement " + row.refine + " and " +
                 o.refine + " disagree (refined " + std::to_string(row.r.refined) + " vs " +
                 std::to_string(o.r.refined) + ", leaves " + std::to_string(row.r.leaves) + " vs " +
                 std::to_string(o.r.leaves) + ")");
        rows.push_back(row);
        std::cerr << "  " << mapname << ", " << row.bound << ", " << row.refine << ", " << th
                  << " thread(s): " << bench::fixed(bench::median(row.st.tot), 1) << " ms\n";
      }

    // Bandwidth reference: read the same bytes (same element types) once, per thread count.
    std::map<std::pair<std::string, int>, StreamTiming> stream;
    for (const char* b : {"first", "third", "combined", "spectral"})
      for (const int th : thread_counts) {
        const std::string bs = b;
        const size_t factors = size_t(N) * E * (bs == "combined" || bs == "spectral" ? 2 : 1);
        stream[{b, th}] = time_read_dispatch(elem_gh, size_t(9) * N * s, elem_f[b], factors, opt.reps, th);
        std::cerr << "  read pass (" << b << " factors), " << th
                  << " thread(s): " << bench::fixed(stream[{b, th}].median_ms, 1) << " ms\n";
      }
    for (Row& r : rows)
      if (r.model == name) {
        const StreamTiming& st = stream[{r.bound, r.threads}];
        r.stream_gbs = st.bytes / (st.median_ms * 1e6);
        r.stream_ms = st.median_ms;
      }

    std::cout << "\n## " << name << "\n\n";
    std::cout << "- cage: " << cage.num_vertices() << " vertices, " << cage.num_faces() << " faces, " << E
              << " edges, #V+#F = " << n << "; load_model " << bench::fixed(ms_load, 0) << " ms\n";
    std::cout << "- voxels: |I| = " << N << " (target " << opt.voxels << "), side "
              << bench::sci(sampling.side, 6) << "; sample_voxels " << bench::fixed(ms_sample, 0) << " ms\n";
    std::cout << "- subspace: s = " << s << " (" << sub.solver << ", " << bench::fixed(ms_sub, 0) << " ms)\n";
    std::cout << "- precomputation (per cage, " << thread_counts.back() << " threads): OctreeCertifier(cage, "
              << "sampling, &Xi) " << bench::fixed(ms_build, 0)
              << " ms (precompute_seconds() = " << bench::fixed(cert.precompute_seconds(), 3)
              << " s); first certify_reduced per bound, which also builds "
              << "that bound's |I| x #E factor matrix: first " << bench::fixed(ms_first["first"], 0)
              << " ms, third " << bench::fixed(ms_first["third"], 0) << " ms\n";
    std::cout << "- stored element size (resident-set growth): reduced matrices "
              << bench::fixed(elem_gh_meas, 2) << " bytes per entry of 9|I|s -> " << elem_gh
              << "-byte; factors first " << bench::fixed(elem_f_meas["first"], 2) << ", third "
              << bench::fixed(elem_f_meas["third"], 2) << " bytes per entry of |I|#E -> " << elem_f["first"]
              << "/" << elem_f["third"] << "-byte";
    if (header_float != (elem_gh == 4)) std::cout << " (WARNING: header suggests the other storage type)";
    std::cout << "\n";
    std::cout << "- bytes streamed per certification: reduced matrices 9 x " << N << " x " << s << " x "
              << elem_gh << " = " << bench::fixed(9.0 * N * s * elem_gh / 1e6, 1) << " MB; factors " << N
              << " x " << E << " x " << elem_f["third"] << " = "
              << bench::fixed(double(N) * E * elem_f["third"] / 1e6, 1)
              << " MB (as doubles: " << bench::fixed((9.0 * N * s + double(N) * E) * 8 / 1e6, 1)
              << " MB in all)\n";
    std::cout << "- deformed map: yr = Xi^T y_id + c D, D(k, k mod 3) = w_k |y_id|_max for k = 4..11, "
              << "w = (1, -0.8, 0.6, -0.5, 0.4, -0.3, 0.25, -0.2); c = " << bench::sci(scale, 6)
              << " (bisection for base min sigma3 = " << opt.sigma_target << "): base min sigma3 "
              << bench::fixed(smin_base, 4) << "\n";
    std::cout << "- validation: " << validation << "\n";
  }

  std::cout << "\n- load average at end (/proc/loadavg): " << bench::load_average()
            << "; CPU pressure (/proc/pressure/cpu): " << bench::cpu_pressure() << "\n\n";
  std::cout << "| model | map | bound | refinement | threads | verdict | min σ3 | refined | leaves | total "
               "ms (median / "
               "min) | jacobian ms | sigma ms | bound ms | refine ms | µs per child | wall ms | CPU ms | MB "
               "read | GB/s (jac+bound) | "
               "GFlop/s (jac) | read-pass ms | read-pass GB/s |\n";
  std::cout
      << "|---|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|-"
         "--:|---:|\n";
  for (const Row& r : rows) {
    const double jb = bench::median(r.st.jac) + bench::median(r.st.bnd);
    // Each subdivided node has 8 children, all evaluated unless a budget runs out (then fewer: an upper
    // bound).
    const double us_child = r.r.refined > 0 ? 1000.0 * bench::median(r.st.ref) / (8.0 * r.r.refined) : 0.0;
    std::cout << "| " << r.model << " | " << r.map << " | " << r.bound << " | " << r.refine << " | "
              << r.threads << " | " << (r.r.certified ? "certified" : "NOT certified") << " | "
              << bench::fixed(r.r.min_sigma3, 4) << " | " << r.r.refined << " | " << r.r.leaves << " | "
              << bench::fixed(bench::median(r.st.tot), 1) << " / "
              << bench::fixed(bench::minimum(r.st.tot), 1) << " | "
              << bench::fixed(bench::median(r.st.jac), 1) << " | " << bench::fixed(bench::median(r.st.sig), 1)
              << " | " << bench::fixed(bench::median(r.st.bnd), 1) << " | "
              << bench::fixed(bench::median(r.st.ref), 1) << " | "
              << (r.r.refined > 0 ? bench::fixed(us_child, 1) : "-") << " | "
              << bench::fixed(bench::median(r.st.wall), 1) << " | "
              << bench::fixed(bench::median(r.st.cpu), 1) << " | " << bench::fixed(r.bytes / 1e6, 0) << " | "
              << bench::fixed(r.bytes / (jb * 1e6), 2) << " | "
              << bench::fixed(r.flops / (bench::median(r.st.jac) * 1e6), 2) << " | "
              << bench::fixed(r.stream_ms, 1) << " | " << bench::fixed(r.stream_gbs, 2) << " |\n";
  }
  std::cout
      << "\nStage columns: medians of Certificate::ms_jacobian / ms_sigma / ms_bound / ms_refine; total = "
         "ms_total (median / min); µs per child = refine ms / (8 x refined), with refined = nodes subdivided "
         "(each evaluates 8 children), at the given thread count; refinement = CertifyParams::refinement: "
         "per-face (HarmonicBasis::differential_jet), per-edge (EdgeJet::evaluate, one child at a time) or "
         "batched (EdgeJet::evaluate_lanes, 8 children in SIMD lanes), same map and run; wall = wall clock "
         "around certify_reduced (includes y = Xi yr); CPU = "
         "process CPU time of the call (all threads). MB read = 9|I|s + |I|#E entries at the stored "
         "element sizes; GB/s = MB read / (jacobian + bound ms); GFlop/s = 2 * 9|I| * s * 3 / jacobian ms; "
         "read-pass ms / GB/s = the same bytes read once by a plain OpenMP reduction (median over the same "
         "number of repetitions), same thread count: the memory-bandwidth floor of the jacobian + bound "
         "stages.\n";
  for (const std::string& n : notes) std::cout << "\n- " << n;
  std::cout << "\n";
  return 0;
}
