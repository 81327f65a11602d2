// The median of a list of numbers (timings, bound ratios): the mean of the two middle values for an even
// count, NaN for none.
#pragma once
#include <algorithm>
#include <cmath>
#include <vector>

namespace lidef {

inline double median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace lidef
