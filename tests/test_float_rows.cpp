// The stored-float-row kernels (lidef/internal/float_rows.h) that the energy's passes, the certificate's
// centers and the global check's vertices share: against a long-double reference within the rounding bound
// their callers assume (γ_n of the summed magnitudes), for every row count and row length around the vector
// widths (the tails), and a row's values independent of the rows beside it.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "lidef/internal/float_rows.h"

using namespace lidef;

namespace {

constexpr double kU = 0x1p-53;

// Row lengths around the kernels' vector widths (4 and 8 entries) and the reduced size 300.
const long kLengths[] = {1, 2, 3, 4, 5, 7, 8, 9, 12, 13, 16, 17, 299, 300, 301};

// n values in ±[2^-spread, 2^spread), in an exactly sized buffer (a read past it is an error under ASan).
template <class T>
std::vector<T> random_values(long n, std::mt19937& rng, int spread) {
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<T> v(n);
  for (T& x : v) x = static_cast<T>(std::ldexp(U(rng), static_cast<int>(U(rng) * spread)));
  return v;
}

// A sum in long double with the sum of its terms' magnitudes.
struct ReferenceSum {
  long double value = 0, magnitude = 0;
  void add(long double p) {
    value += p;
    magnitude += std::fabs(p);
  }
  // |got − exact| ≤ γ_n of the magnitudes (n roundings in double) plus the reference's own rounding.
  bool holds(double got, long n) const {
    const double bound = (n * kU / (1 - n * kU) + n * 0x1p-63) * static_cast<double>(magnitude) + 1e-300;
    return std::fabs(got - static_cast<double>(value)) <= bound;
  }
};

}  // namespace

TEST(FloatRows, ProductsWithThreeColumnsAreWithinTheRoundingBoundAndIndependentOfTheOtherRows) {
  std::mt19937 rng(7);
  for (long m : kLengths) {
    for (long rows : {1L, 2L, 3L, 4L, 5L, 9L}) {
      const std::vector<float> g = random_values<float>(rows * m, rng, 8);
      const std::vector<double> cols = random_values<double>(3 * m, rng, 8);
      std::vector<double> out(3 * rows, std::nan(""));
      float_rows_times_columns(g.data(), rows, cols.data(), m, reinterpret_cast<double(*)[3]>(out.data()));
      for (long r = 0; r < rows; ++r) {
        double alone[1][3];
        float_rows_times_columns(g.data() + r * m, 1, cols.data(), m, alone);
        for (int a = 0; a < 3; ++a) {
          ReferenceSum ref;
          for (long k = 0; k < m; ++k) ref.add(static_cast<long double>(g[r * m + k]) * cols[a * m + k]);
          const double got = out[3 * r + a];
          EXPECT_TRUE(ref.holds(got, m)) << "m " << m << " rows " << rows << " row " << r;
          EXPECT_EQ(got, alone[0][a]) << "a row's value depends on its company: m " << m << " row " << r;
        }
      }
    }
  }
}

TEST(FloatRows, TransposedProductsAccumulateWithinTheRoundingBound) {
  std::mt19937 rng(11);
  for (long m : kLengths) {
    for (long rows : {1L, 3L, 4L, 5L, 8L, 11L}) {
      const std::vector<float> g = random_values<float>(rows * m, rng, 0);
      const std::vector<double> P = random_values<double>(3 * rows, rng, 0);  // (r, a) at P[a * rows + r]
      const std::vector<double> start = random_values<double>(3 * m, rng, 0);
      std::vector<double> acc = start;
      float_rows_transpose_times(
          g.data(), rows, m, [&](long r, int a) { return P[a * rows + r]; }, acc.data());
      for (int a = 0; a < 3; ++a)
        for (long j = 0; j < m; ++j) {
          ReferenceSum ref;
          ref.add(start[a * m + j]);
          for (long r = 0; r < rows; ++r) ref.add(static_cast<long double>(g[r * m + j]) * P[a * rows + r]);
          // rows products and rows additions reach the entry: γ_{2·rows} covers any grouping.
          EXPECT_TRUE(ref.holds(acc[a * m + j], 2 * rows))
              << "m " << m << " rows " << rows << " entry " << j << " column " << a;
        }
    }
  }
}
