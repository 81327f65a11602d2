#include "lidef/blas_kernel.h"

#include <cblas.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <iterator>
#include <mutex>
#include <type_traits>

#include "lidef/errors.h"

extern "C" char* openblas_get_corename(void);
extern "C" void openblas_set_num_threads(int);
extern "C" int openblas_get_num_threads(void);
// OpenBLAS's kernel selection (driver/others/dynamic.c), exported by DYNAMIC_ARCH builds only: weak, so that
// lidef links against any OpenBLAS and simply cannot select a core where these are missing. quit forgets the
// selection; init selects again (OPENBLAS_CORETYPE if set, else the CPU model) and initializes the chosen
// kernel table's blocking parameters.
extern "C" void gotoblas_dynamic_init(void) __attribute__((weak));
extern "C" void gotoblas_dynamic_quit(void) __attribute__((weak));

namespace lidef {

namespace {

// The kernels OpenBLAS 0.3.21 has for what this CPU supports (its own names, as OPENBLAS_CORETYPE takes
// them). Measured on the 2-core Xeon (model 207) on bar_bend, ms per Newton iteration: Prescott 312, Haswell
// 164, SkylakeX 170, Cooperlake 151.
std::string core_for_cpu_features() {
  __builtin_cpu_init();
  const bool avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
                      __builtin_cpu_supports("avx512cd");
  if (avx512 && __builtin_cpu_supports("avx512bf16")) return "Cooperlake";
  if (avx512) return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
  return "";
}

std::mutex& selection_mutex() {
  static std::mutex m;
  return m;
}
std::string& replaced_core() {  // guarded by selection_mutex()
  static std::string s;
  return s;
}

std::string current_core() {
  const char* name = openblas_get_corename();
  return name ? name : "";
}

}  // namespace

bool select_blas_core(const std::string& core) {
  // OpenBLAS 0.3.21's x86-64 kernel tables (its corename[] spelling). A name it does not know would make it
  // fall back to its own choice, so such a name is refused before OpenBLAS is touched.
  static const char* const kCores[] = {
      "Prescott",  "Core2",      "Penryn",  "Dunnington",  "Nehalem",   "Opteron", "Barcelona", "Sandybridge",
      "Bulldozer", "Piledriver", "Haswell", "Steamroller", "Excavator", "Zen",     "SkylakeX",  "Cooperlake"};
  if (std::find(std::begin(kCores), std::end(kCores), core) == std::end(kCores)) return false;
  if (!gotoblas_dynamic_init || !gotoblas_dynamic_quit) return false;
  std::lock_guard<std::mutex> lock(selection_mutex());
  const char* user = std::getenv("OPENBLAS_CORETYPE");
  const std::string saved = user ? user : "";
  const bool had = user != nullptr;
  setenv("OPENBLAS_CORETYPE", core.c_str(), 1);
  gotoblas_dynamic_quit();
  gotoblas_dynamic_init();
  if (had)
    setenv("OPENBLAS_CORETYPE", saved.c_str(), 1);
  else
    unsetenv("OPENBLAS_CORETYPE");
  return current_core() == core;
}

void fix_blas_kernel() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (std::getenv("OPENBLAS_CORETYPE")) return;  // the user's choice stands
    const std::string before = current_core();
    if (before != "Prescott") return;
    const std::string better = core_for_cpu_features();
    if (!better.empty() && select_blas_core(better)) {
      std::lock_guard<std::mutex> lock(selection_mutex());
      replaced_core() = before;
    }
  });
}

namespace {
// When lidef_core is loaded (before main(), or when the Python module is imported): OpenBLAS, a library this
// one depends on, is initialized by then, and no thread of this library runs BLAS yet.
[[maybe_unused]] const bool kBlasKernelFixedAtLoad = (fix_blas_kernel(), true);
}  // namespace

BlasKernelInfo blas_kernel_info() {
  fix_blas_kernel();
  BlasKernelInfo info;
  info.core = current_core();
  info.forced = std::getenv("OPENBLAS_CORETYPE") != nullptr;
  {
    std::lock_guard<std::mutex> lock(selection_mutex());
    info.replaced = replaced_core();
  }
  // "Prescott" is what 0.3.21 picks for an Intel model it does not know; on a CPU that really is that old
  // there is nothing better (core_for_cpu_features() is then empty).
  if (info.core == "Prescott") info.recommended = core_for_cpu_features();
  return info;
}

std::vector<std::pair<std::string, std::string>> blas_environment() {
  if (std::getenv("OPENBLAS_CORETYPE")) return {};  // the user's (or our earlier) choice stands
  const BlasKernelInfo info = blas_kernel_info();
  if (info.recommended.empty()) return {};
  return {{"OPENBLAS_CORETYPE", info.recommended}};
}

std::vector<std::pair<std::string, std::string>> process_environment() {
  auto env = blas_environment();
  // Huge pages for large blocks; blocks up to 32 MiB (the solver's per-iteration matrices and per-sample
  // arrays, 2-7 MB each) from the heap, whose freed memory is kept up to 1 GiB, so that the next iteration's
  // arrays reuse it instead of faulting fresh pages in (32 MiB is glibc's largest mmap threshold).
  env.emplace_back(
      "GLIBC_TUNABLES",
      "glibc.malloc.hugetlb=1:glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=1073741824");
  return env;
}

void reexec_with_environment(char** argv, const std::vector<std::pair<std::string, std::string>>& env) {
  bool changed = false;
  for (const auto& [name, value] : env) {
    if (std::getenv(name.c_str())) continue;
    setenv(name.c_str(), value.c_str(), 1);
    changed = true;
  }
  // Each variable is now set, so the re-executed process finds nothing to change and runs on.
  if (changed) execv("/proc/self/exe", argv);
}

namespace {
// Checks the shapes and sizes C; false when there is nothing for dgemm to do (C empty, or zero when k = 0).
template <class MA, class MC>
bool prepare_product(const MA& A, const MatXd& B, MC& C) {
  if (A.cols() != B.rows())
    throw Error("blas_product: " + std::to_string(A.rows()) + "x" + std::to_string(A.cols()) + " times " +
                std::to_string(B.rows()) + "x" + std::to_string(B.cols()));
  C.resize(A.rows(), B.cols());
  if (A.cols() == 0) C.setZero();
  return C.size() > 0 && A.cols() > 0;
}
}  // namespace

void use_blas_in_calling_thread() {
  static std::once_flag once;
  std::call_once(once, [] {
    fix_blas_kernel();
    openblas_set_num_threads(1);
  });
}

ScopedBlasThreads::ScopedBlasThreads(int threads) : previous_(openblas_get_num_threads()) {
  openblas_set_num_threads(std::max(1, threads));
}

int ScopedBlasThreads::active() const {
  return openblas_get_num_threads();
}

ScopedBlasThreads::~ScopedBlasThreads() {
  openblas_set_num_threads(previous_);
}

namespace {
template <class T>
void gemm_one(bool ta, bool tb, int m, int n, int k, const T* A, int lda, const T* B, int ldb, T* C,
              int ldc) {
  const auto opa = ta ? CblasTrans : CblasNoTrans, opb = tb ? CblasTrans : CblasNoTrans;
  if constexpr (std::is_same_v<T, float>)
    cblas_sgemm(CblasColMajor, opa, opb, m, n, k, 1.0f, A, lda, B, ldb, 0.0f, C, ldc);
  else
    cblas_dgemm(CblasColMajor, opa, opb, m, n, k, 1.0, A, lda, B, ldb, 0.0, C, ldc);
}

// Slices of C: columns j0..j1 take B's columns (rows of Bᵀ) j0..j1; rows i0..i1 take A's rows (columns of
// Aᵀ).
template <class T>
void gemm_split(bool ta, bool tb, int m, int n, int k, const T* A, int lda, const T* B, int ldb, T* C,
                int ldc) {
  use_blas_in_calling_thread();
  if (m <= 0 || n <= 0) return;
  const int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
  const bool by_columns = n >= 2 * threads || n >= m;
  const int len = by_columns ? n : m;
  const int parts = std::max(1, std::min(threads, len / 16));
#pragma omp parallel for schedule(static) num_threads(parts) if (parts > 1)
  for (int p = 0; p < parts; ++p) {
    const int b = static_cast<int>(static_cast<long>(len) * p / parts);
    const int e = static_cast<int>(static_cast<long>(len) * (p + 1) / parts);
    if (e <= b) continue;
    if (by_columns) {
      const T* Bp = tb ? B + b : B + static_cast<long>(b) * ldb;
      gemm_one(ta, tb, m, e - b, k, A, lda, Bp, ldb, C + static_cast<long>(b) * ldc, ldc);
    } else {
      const T* Ap = ta ? A + static_cast<long>(b) * lda : A + b;
      gemm_one(ta, tb, e - b, n, k, Ap, lda, B, ldb, C + b, ldc);
    }
  }
}
}  // namespace

void gemm_parallel(bool trans_a, bool trans_b, int m, int n, int k, const float* A, int lda, const float* B,
                   int ldb, float* C, int ldc) {
  gemm_split(trans_a, trans_b, m, n, k, A, lda, B, ldb, C, ldc);
}
void gemm_parallel(bool trans_a, bool trans_b, int m, int n, int k, const double* A, int lda, const double* B,
                   int ldb, double* C, int ldc) {
  gemm_split(trans_a, trans_b, m, n, k, A, lda, B, ldb, C, ldc);
}

void blas_product(const MatXdR& A, const MatXd& B, MatXdR& C) {
  if (!prepare_product(A, B, C)) return;
  // Row-major C = A B is column-major Cᵀ = Bᵀ Aᵀ, and a column-major B is a row-major Bᵀ: so Cᵀ (n by m) is
  // the column-major product of B transposed (lda = k) and A read as the column-major Aᵀ (k by m).
  gemm_parallel(true, false, static_cast<int>(B.cols()), static_cast<int>(A.rows()),
                static_cast<int>(A.cols()), B.data(), static_cast<int>(B.rows()), A.data(),
                static_cast<int>(A.cols()), C.data(), static_cast<int>(B.cols()));
}

void blas_product(const MatXd& A, const MatXd& B, MatXd& C) {
  if (!prepare_product(A, B, C)) return;
  gemm_parallel(false, false, static_cast<int>(A.rows()), static_cast<int>(B.cols()),
                static_cast<int>(A.cols()), A.data(), static_cast<int>(A.rows()), B.data(),
                static_cast<int>(B.rows()), C.data(), static_cast<int>(C.rows()));
}

std::string blas_numerics() {
  use_blas_in_calling_thread();
  // "split": the products are split over OpenMP's threads, one BLAS thread each (entries cached by the code
  // before, with OpenBLAS's own threads, carry "<core>/<threads>" and are not taken for these).
  return blas_kernel_info().core + "/" + std::to_string(omp_get_max_threads()) + " split";
}

}  // namespace lidef
