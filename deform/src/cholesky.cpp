#include "lidef/internal/cholesky.h"

#include <cblas.h>

#include <algorithm>
#include <utility>
#include <vector>

#include "lidef/blas_kernel.h"

extern "C" {
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
}

namespace lidef {

namespace {

// Panel width and tile size. A panel's diagonal block is factored by one thread while the others wait, so it
// stays narrow; the trailing update's tiles are the parallel work (at n = 900: 45 tiles after the first
// panel). Chosen on the 2-core machine (docs/benchmarks.md, "Cholesky factor"): panels of 64-192 and tiles of
// 96-192 were within 30%.
constexpr int kPanel = 64;
constexpr int kTile = 96;

// Row ranges [begin, end) of [from, n) in tiles of kTile, fixed by n and `from` alone.
std::vector<std::pair<int, int>> tiles(int from, int n) {
  std::vector<std::pair<int, int>> t;
  for (int b = from; b < n; b += kTile) t.emplace_back(b, std::min(n, b + kTile));
  return t;
}

}  // namespace

bool cholesky_factor(MatXd& H) {
  const int n = static_cast<int>(H.rows());
  if (H.cols() != n) return false;
  use_blas_in_calling_thread();
  double* A = H.data();
  const auto at = [&](int i, int j) { return A + i + static_cast<long>(j) * n; };
  for (int k = 0; k < n; k += kPanel) {
    // 1. The panel's diagonal block: L11 L11ᵀ = A11.
    const int kb = std::min(kPanel, n - k);
    int info = 0;
    dpotrf_("L", &kb, at(k, k), &n, &info);
    if (info != 0) return false;
    const int rest = k + kb;
    if (rest >= n) break;
    const auto rows = tiles(rest, n);
    const int count = static_cast<int>(rows.size());
    // 2. The panel below it: L21 = A21 L11⁻ᵀ, by row tiles.
#pragma omp parallel for schedule(dynamic, 1) if (count > 1)
    for (int t = 0; t < count; ++t)
      cblas_dtrsm(CblasColMajor, CblasRight, CblasLower, CblasTrans, CblasNonUnit,
                  rows[t].second - rows[t].first, kb, 1.0, at(k, k), n, at(rows[t].first, k), n);
    // 3. The trailing matrix's lower triangle: A22 -= L21 L21ᵀ, by tiles (i, j), i ≥ j; diagonal tiles by
    // SYRK (their strict upper triangle is H's and stays untouched).
    std::vector<std::pair<int, int>> work;
    for (int j = 0; j < count; ++j)
      for (int i = j; i < count; ++i) work.emplace_back(i, j);
    const int tasks = static_cast<int>(work.size());
#pragma omp parallel for schedule(dynamic, 1) if (tasks > 1)
    for (int w = 0; w < tasks; ++w) {
      const auto [r0, r1] = rows[work[w].first];
      const auto [c0, c1] = rows[work[w].second];
      if (r0 == c0)
        cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, c1 - c0, kb, -1.0, at(c0, k), n, 1.0, at(c0, c0),
                    n);
      else
        cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, r1 - r0, c1 - c0, kb, -1.0, at(r0, k), n,
                    at(c0, k), n, 1.0, at(r0, c0), n);
    }
  }
  return true;
}

// Two triangular solves with one vector each (BLAS-2 dtrsv). LAPACK's dpotrs takes the matrix path (dtrsm)
// even for one right-hand side, 4x slower at n = 900 (0.39 against 0.10 ms; bench_cholesky,
// docs/benchmarks.md): the kept factor's preconditioner applies this at every CG step. Blocked substitutions
// spread over two threads were no faster than the single dtrsv (L is read from cache either way).
bool cholesky_solve_factored(const MatXd& L, VecXd& b) {
  const int n = static_cast<int>(L.rows());
  if (b.size() != n || L.cols() != n) return false;
  use_blas_in_calling_thread();
  cblas_dtrsv(CblasColMajor, CblasLower, CblasNoTrans, CblasNonUnit, n, L.data(), n, b.data(), 1);
  cblas_dtrsv(CblasColMajor, CblasLower, CblasTrans, CblasNonUnit, n, L.data(), n, b.data(), 1);
  return b.allFinite();
}

bool cholesky_solve(MatXd& H, VecXd& b) {
  return cholesky_factor(H) && cholesky_solve_factored(H, b);
}

}  // namespace lidef
