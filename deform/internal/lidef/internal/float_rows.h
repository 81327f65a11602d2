// Stored float rows of basis derivatives times the map's coefficients (the local certificate's base centers,
// the global check's mesh vertices): docs/certificate.md, Step 5, bounds the float storage's error.
#pragma once

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

// out[a] = Σ_k g[k] · cols[a · m + k] for the 3 contiguous coefficient columns `cols` (m entries each), the
// float row g widened to double; one pass over g for all three columns.
inline void float_row_times_columns(const float* g, const double* cols, long m, double out[3]) {
  const double* y0 = cols;
  const double* y1 = y0 + m;
  const double* y2 = y1 + m;
  double a0 = 0, a1 = 0, a2 = 0;
#pragma omp simd reduction(+ : a0, a1, a2)
  for (long k = 0; k < m; ++k) {
    const double gk = g[k];
    a0 += gk * y0[k];
    a1 += gk * y1[k];
    a2 += gk * y2[k];
  }
  out[0] = a0;
  out[1] = a1;
  out[2] = a2;
}

}  // namespace lidef
