// Stored float rows of basis derivatives times the map's coefficients (the energy's samples, the local
// certificate's base centers, the global check's mesh vertices) and the transposed products (the energy's
// gradient and Hessian products): docs/certificate.md, Step 5, bounds the float storage's error.
#pragma once

#include <cstring>
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace lidef {

// An allocator whose resize leaves new elements uninitialized (default-initialized), so that a large buffer
// filled right after by a parallel loop is written once, its pages first touched by the threads that fill
// them, instead of being zeroed first by one thread.
template <class T, class Base = std::allocator<T>>
struct DefaultInitAllocator : Base {
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U, typename std::allocator_traits<Base>::template rebind_alloc<U>>;
  };
  using Base::Base;
  template <class U>
  void construct(U* p) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    std::allocator_traits<Base>::construct(static_cast<Base&>(*this), p, std::forward<Args>(args)...);
  }
};
// Float rows kept for later checks, filled after each resize.
using FloatRows = std::vector<float, DefaultInitAllocator<float>>;

// Σ_k a[k] · b[k] for two float rows of m entries, widened to double, summed in SIMD lanes (the order of the
// sum is the compiler's: callers bound its rounding by (m − 1) u Σ_k |a[k] b[k]|, which holds for any order).
inline double float_dot(const float* a, const float* b, long m) {
  double acc = 0;
#pragma omp simd reduction(+ : acc)
  for (long k = 0; k < m; ++k) acc += static_cast<double>(a[k]) * b[k];
  return acc;
}

// Σ_k w[k] · f[k] for m double weights and a float row (each float widened, each product rounded once),
// summed in SIMD lanes like float_dot: the certificate's bound-factor row sums Σ_e w_e Θ_e (callers bound the
// rounding by (m + 1) u Σ_k |w[k] f[k]|, docs/certificate.md).
inline double weighted_float_sum(const double* w, const float* f, long m) {
  double acc = 0;
#pragma omp simd reduction(+ : acc)
  for (long k = 0; k < m; ++k) acc += w[k] * static_cast<double>(f[k]);
  return acc;
}

// GCC's vector extensions, 4 doubles per operation: the loops below are vectorized by construction, not by
// the compiler's judgement in each translation unit that inlines them (an `omp simd` reduction of the same
// loop was vectorized in one caller and left scalar, 5x slower, in another).
using V4d = double __attribute__((vector_size(32)));
using V4f = float __attribute__((vector_size(16)));
inline V4d widen4(const float* g) {
  V4f f;
  std::memcpy(&f, g, sizeof f);
  return __builtin_convertvector(f, V4d);
}
inline V4d load4(const double* p) {
  V4d v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store4(double* p, V4d v) {
  std::memcpy(p, &v, sizeof v);
}
inline double sum4(V4d v) {
  return (v[0] + v[1]) + (v[2] + v[3]);
}

// Rows [0, rows) of a row-major float matrix (m entries per row, row r at g + r·m) times 3 contiguous double
// columns (column a at cols + a·m): emit(r, c0, c1, c2) with c_a = Σ_k g_r[k] cols_a[k] for every row, each
// float widened to double, every product and sum in double. One row at a time, two 4-lane sums per column
// (entries 8j..8j+3 and 8j+4..8j+7), added lane-wise, lanes added pairwise, then the m mod 4 tail in order.
// Measured against four rows at a time with twelve vector sums (which share the column loads but spill
// registers): 10.8 against 18.1 ms on the certificate's 9 rows per center, 3.7 against 3.8–4.9 ms on the
// energy's 3|I| rows (30,000 centers, 300 columns, 2 threads; the project's 2-core AMD EPYC, 2026-11-30). A
// row's values do not depend on the other rows, the range or the thread count. Callers bound the rounding by
// γ_m = m·u/(1 − m·u) of Σ_k |g_r[k] cols_a[k]|, which holds for any order, with or without fused
// multiply-adds.
template <class Emit>
inline void float_rows_times_columns(const float* g, long rows, const double* cols, long m, Emit&& emit) {
  const double* y0 = cols;
  const double* y1 = y0 + m;
  const double* y2 = y1 + m;
  for (long r = 0; r < rows; ++r) {
    const float* gr = g + r * m;
    V4d a[2][3] = {};
    long j = 0;
    for (; j + 8 <= m; j += 8)
      for (int h = 0; h < 2; ++h) {
        const long k = j + 4 * h;
        const V4d gk = widen4(gr + k);
        a[h][0] += gk * load4(y0 + k);
        a[h][1] += gk * load4(y1 + k);
        a[h][2] += gk * load4(y2 + k);
      }
    for (; j + 4 <= m; j += 4) {
      const V4d gk = widen4(gr + j);
      a[0][0] += gk * load4(y0 + j);
      a[0][1] += gk * load4(y1 + j);
      a[0][2] += gk * load4(y2 + j);
    }
    double c[3];
    for (int q = 0; q < 3; ++q) c[q] = sum4(a[0][q] + a[1][q]);
    for (; j < m; ++j) {
      const double gj = gr[j];
      c[0] += gj * y0[j];
      c[1] += gj * y1[j];
      c[2] += gj * y2[j];
    }
    emit(r, c[0], c[1], c[2]);
  }
}

// term(0) + … + term(K − 1) added pairwise, ((t0 + t1) + (t2 + t3)) for K = 4: independent additions instead
// of a chain of dependent ones (K ≤ 4, written out so that the terms stay in registers).
template <int K, class Term>
inline auto pairwise_sum(const Term& term) {
  static_assert(K >= 1 && K <= 4, "pairwise_sum: 1 to 4 terms");
  if constexpr (K == 1) return term(0);
  if constexpr (K == 2) return term(0) + term(1);
  if constexpr (K == 3) return (term(0) + term(1)) + term(2);
  if constexpr (K == 4) return (term(0) + term(1)) + (term(2) + term(3));
}

// acc_a[j] += Σ_r g_r[j] · q[r][a] for K rows g_r = g + r·m of a row-major float matrix (m entries per row),
// their coefficients q (K by 3) and 3 contiguous double columns acc_a = acc + a·m; each float widened to
// double, every product and sum in double, the K terms of an entry added pairwise before the entry.
// Several rows per pass over acc: one load and store of it per K rows. `next`: the rows the caller sums next
// (K·m floats; nullptr: none), prefetched meanwhile.
template <int K>
inline void float_rows_transpose_times_group(const float* g, const double (*q)[3], long m, double* acc,
                                             const float* next = nullptr) {
  const float* gr[K];
  V4d qv[K][3];
  for (int k = 0; k < K; ++k) {
    gr[k] = g + k * m;
    for (int a = 0; a < 3; ++a) qv[k][a] = V4d{q[k][a], q[k][a], q[k][a], q[k][a]};
  }
  double* c[3] = {acc, acc + m, acc + 2 * m};
  long j = 0;
  for (; j + 4 <= m; j += 4) {
    // The next group's K rows (K·m contiguous floats) front to back, K·4 floats per step: the whole group
    // in order while this one is summed. With two of the K rows prefetched column by column the pass took
    // 1.5–2.8x a plain read of its bytes (docs/benchmarks.md, "The transposed pass's prefetch").
    if (next) __builtin_prefetch(next + K * j);
    V4d x[K];
    for (int k = 0; k < K; ++k) x[k] = widen4(gr[k] + j);
    for (int a = 0; a < 3; ++a) {
      store4(c[a] + j, load4(c[a] + j) + pairwise_sum<K>([&](int k) { return x[k] * qv[k][a]; }));
    }
  }
  for (; j < m; ++j)
    for (int a = 0; a < 3; ++a) {
      c[a][j] += pairwise_sum<K>([&](int k) { return double(gr[k][j]) * q[k][a]; });
    }
}

// The same for rows [0, rows) with coefficients coef(r, a): four rows at a time, then the remaining ones
// alone. The order of the sums is fixed by the code and the rows' grouping, which depends only on `rows`: the
// same bits for every thread count when the caller's ranges do not depend on it.
template <class Coef>
inline void float_rows_transpose_times(const float* g, long rows, long m, const Coef& coef, double* acc) {
  long r = 0;
  double q[4][3];
  for (; r + 4 <= rows; r += 4) {
    for (int k = 0; k < 4; ++k)
      for (int a = 0; a < 3; ++a) q[k][a] = coef(r + k, a);
    float_rows_transpose_times_group<4>(g + r * m, q, m, acc, r + 8 <= rows ? g + (r + 4) * m : nullptr);
  }
  for (; r < rows; ++r) {
    for (int a = 0; a < 3; ++a) q[0][a] = coef(r, a);
    float_rows_transpose_times_group<1>(g + r * m, q, m, acc);
  }
}

// The same into out[r][a] (rows by 3).
inline void float_rows_times_columns(const float* g, long rows, const double* cols, long m,
                                     double (*out)[3]) {
  float_rows_times_columns(g, rows, cols, m, [out](long r, double c0, double c1, double c2) {
    out[r][0] = c0;
    out[r][1] = c1;
    out[r][2] = c2;
  });
}

}  // namespace lidef
