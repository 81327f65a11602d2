// Which OpenBLAS kernels the process runs, and a fix for CPUs OpenBLAS does not know.
//
// Debian 12's OpenBLAS 0.3.21 (DYNAMIC_ARCH) picks its kernels from the CPU model number; a model newer than
// the library (seen: family 6 model 207, a 2-core Xeon VM) falls back to "Prescott", its SSE3 kernels,
// although the CPU has AVX-512. The reduced Hessian's sgemm then runs 2-4x slower (bar_bend: 312 instead of
// 151 ms per Newton iteration; docs/benchmarks.md, "OpenBLAS kernels"). OpenBLAS chooses when it is loaded,
// reading OPENBLAS_CORETYPE, but a DYNAMIC_ARCH build exports the choice itself (gotoblas_dynamic_quit /
// gotoblas_dynamic_init, which read OPENBLAS_CORETYPE again): lidef_core makes the choice again in-process
// when it is loaded (select_blas_core), so every program, an embedding program and the Python module run the
// CPU's kernels without re-executing themselves.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "lidef/types.h"

namespace lidef {

struct BlasKernelInfo {
  std::string core;  // openblas_get_corename() of this process, e.g. "Cooperlake", "Haswell", "Prescott"
  std::string
      recommended;      // the core this CPU's features support, when `core` is OpenBLAS's fallback; else ""
  bool forced = false;  // OPENBLAS_CORETYPE is set in this process's environment
  // OpenBLAS's own choice that lidef replaced in this process (fix_blas_kernel: "Prescott"), else "".
  std::string replaced;
};
BlasKernelInfo blas_kernel_info();

// Makes OpenBLAS run the kernels of `core` (a name OPENBLAS_CORETYPE takes: "Haswell", "SkylakeX",
// "Cooperlake", ...) in this process, without re-executing it: OpenBLAS's DYNAMIC_ARCH selection runs again
// with OPENBLAS_CORETYPE = core for its duration (the environment is restored afterwards). Returns whether
// OpenBLAS now runs `core`: false (and OpenBLAS untouched) for a name that is not one of OpenBLAS 0.3.21's
// x86-64 cores or when the OpenBLAS linked is not a DYNAMIC_ARCH build (it exports no selection). Call it
// while no other thread runs BLAS: the kernel table is swapped under the caller's feet otherwise.
bool select_blas_core(const std::string& core);

// When OpenBLAS fell back to Prescott on a CPU with AVX2/FMA (Haswell), AVX-512 (SkylakeX) or AVX-512 BF16
// (Cooperlake) and the user did not set OPENBLAS_CORETYPE: selects the core the CPU supports (once per
// process). lidef_core calls it when it is loaded (a static initializer of blas_kernel.cpp) and before its
// first product, so callers need not.
void fix_blas_kernel();

// The environment a re-executed process should have so that OpenBLAS uses the kernels the CPU supports:
// {"OPENBLAS_CORETYPE", core} when OpenBLAS still runs its Prescott fallback on a CPU with better kernels
// (fix_blas_kernel could not replace it) and the user did not set OPENBLAS_CORETYPE; else nothing.
std::vector<std::pair<std::string, std::string>> blas_environment();

// What every lidef program re-executes itself with (reexec_with_environment, first thing in main()):
// blas_environment(), and GLIBC_TUNABLES (unless the user set it) with glibc.malloc.hugetlb=1, so that malloc
// backs its large blocks with transparent huge pages, and mmap_threshold 32 MiB, trim_threshold 1 GiB, so
// that the blocks below 32 MiB come from the heap and freed ones are reused rather than returned. Why:
// touching fresh memory costs one page fault per 4 KiB, and on a virtual machine each is slow — reopening the
// animal from the cache (781 MB read into new buffers) took several times as long without huge pages, and a
// solve's per-iteration arrays faulted in anew each time (docs/benchmarks.md, "Opening a model"). It changes
// where memory comes from, never a result. A library cannot set it for its host (glibc reads it at startup):
// the Python module's users set it themselves.
std::vector<std::pair<std::string, std::string>> process_environment();

// Sets each variable of `env` that is not already set and, when one was set, re-executes /proc/self/exe with
// `argv` (returns only when there was nothing to set, or when exec failed: the program then runs as it is).
// Call first thing in main(), before any thread starts. For variables a library reads only when it is loaded
// (the studio's OMP_WAIT_POLICY, gui/src/omp_wait.h); OpenBLAS's kernels need none (fix_blas_kernel).
void reexec_with_environment(char** argv, const std::vector<std::pair<std::string, std::string>>& env);

// OpenBLAS runs in the calling thread (openblas_set_num_threads(1), set once by the first call of any
// function below); the products split their output over OpenMP's threads instead. Why: Debian's OpenBLAS is
// the pthread build, whose workers spin ~0.1 s after each call; on two cores they then take a core from the
// OpenMP stages that follow and from the studio's renderer (bench_studio at the defaults: a 900x900 Cholesky
// 8 ms alone, 63-76 ms beside the window; 3.1-3.6 -> 4.2 view updates/s, side by side; CHANGELOG.md).
// One pool, one wait policy (OMP_WAIT_POLICY, gui/src/omp_wait.h).
void use_blas_in_calling_thread();
// OpenBLAS's own thread count set to `threads` for a scope and restored after it: for code that calls BLAS
// outside lidef's kernels (CHOLMOD's supernodal factorization in the comparison methods), which would
// otherwise run in the one thread use_blas_in_calling_thread leaves for the whole process once lidef has run
// in it.
class ScopedBlasThreads {
 public:
  explicit ScopedBlasThreads(int threads);
  ~ScopedBlasThreads();
  ScopedBlasThreads(const ScopedBlasThreads&) = delete;
  ScopedBlasThreads& operator=(const ScopedBlasThreads&) = delete;
  // The thread count OpenBLAS reports in this scope (it may cap the one asked for).
  int active() const;

 private:
  int previous_;
};
// Column-major C (m by n) = op(A) op(B), op = transpose when the flag is set, as cblas_?gemm with alpha 1 and
// beta 0, the columns of C (or its rows when n < 2 × threads) split over OpenMP's threads. Each element of C
// sums over the whole k in one call, as a single call would.
void gemm_parallel(bool trans_a, bool trans_b, int m, int n, int k, const float* A, int lda, const float* B,
                   int ldb, float* C, int ldc);
void gemm_parallel(bool trans_a, bool trans_b, int m, int n, int k, const double* A, int lda, const double* B,
                   int ldb, double* C, int ldc);

// C = A B for a row-major A (m by k) and a column-major B (k by n), into a row-major C (m by n; resized, its
// memory reused when the shape is the same), with OpenBLAS's dgemm: the precomputation's products of basis
// derivatives with the subspace Ξ, about twice Eigen's product with OpenBLAS's AVX-512 kernels
// (CHANGELOG.md, 2026-11-24). Its rounding depends on OpenBLAS's kernels and thread count: blas_numerics().
void blas_product(const MatXdR& A, const MatXd& B, MatXdR& C);
// C = A B, all column-major (C resized): the studio's per-frame products of the mesh matrices (#V and 3#V by
// s) with ỹ (s by 3), 3.8 ms against Eigen's 15.3 for the bar's 94 MB (bench_studio, CHANGELOG.md).
void blas_product(const MatXd& A, const MatXd& B, MatXd& C);
// "<core>/<threads>" of OpenBLAS in this process (threads: OpenMP's, over which the products split), for the
// keys of cached results of blas_product.
std::string blas_numerics();

}  // namespace lidef
