// log and atan2 as plain arithmetic, for loops over SIMD lanes: a call to the C library's scalar log/atan2
// stops GCC's vectorizer, these inline into a `#pragma omp simd` loop and vectorize (the harmonic basis
// kernel, green_coordinates.cpp). Both are within 2 ulp of the correctly rounded result; the tests measure it
// against std::log/std::atan2 (tests/test_green_coordinates.cpp, LaneMath.*). Branch-free: every lane runs
// the same instructions, so a value does not depend on the lane (or the batch) it is computed in. GCC
// vectorizes them with -fno-trapping-math (deform/CMakeLists.txt says why that changes no value).
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace lidef {

// Natural logarithm. x > 0 (subnormals included); 0 → −∞, +∞ → +∞, x < 0 or NaN → NaN, as std::log.
// x = 2^e m with m in [√½, √2), log m = 2 atanh(s), s = (m − 1)/(m + 1), |s| ≤ 0.1716: the series to s²³
// leaves a remainder below 1e-19 relative; e·ln 2 is added in two parts (the high part has 21 trailing zero
// bits, so e·hi is exact).
inline double lane_log(double x) {
  constexpr double kMinNormal = 2.2250738585072014e-308, kTwo54 = 18014398509481984.0;
  constexpr double kLn2Hi = 6.93147180369123816490e-01, kLn2Lo = 1.90821492927058770002e-10;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Every value is computed on every lane and then selected: a conditional operation would be control flow
  // (GCC does not speculate a floating-point operation that may trap) and stop the vectorizer.
  const bool tiny = x < kMinNormal;
  const double x_scaled = x * kTwo54;
  const double xs = tiny ? x_scaled : x;
  std::uint64_t bits;
  std::memcpy(&bits, &xs, sizeof bits);
  // The biased exponent as a double without an int64 → double conversion (AVX2 has none): placed in the
  // mantissa of 2⁵², then 2⁵² + 1023 subtracted.
  const std::uint64_t ebits = (bits >> 52) | 0x4330000000000000ULL;
  const std::uint64_t mbits = (bits & 0x000FFFFFFFFFFFFFULL) | 0x3FF0000000000000ULL;
  double e, m;
  std::memcpy(&e, &ebits, sizeof e);
  std::memcpy(&m, &mbits, sizeof m);
  const bool big = m > 1.4142135623730951;
  const double m_half = 0.5 * m;
  m = big ? m_half : m;
  e = (e - 4503599627371519.0) + (big ? 1.0 : 0.0) - (tiny ? 54.0 : 0.0);  // 2⁵² + 1023
  const double f = m - 1.0;                                                // exact (Sterbenz)
  const double s = f / (2.0 + f);
  const double z = s * s;
  double r = 2.0 / 23;
  r = r * z + 2.0 / 21;
  r = r * z + 2.0 / 19;
  r = r * z + 2.0 / 17;
  r = r * z + 2.0 / 15;
  r = r * z + 2.0 / 13;
  r = r * z + 2.0 / 11;
  r = r * z + 2.0 / 9;
  r = r * z + 2.0 / 7;
  r = r * z + 2.0 / 5;
  r = r * z + 2.0 / 3;
  const double log_m = 2.0 * s + s * (z * r);
  const double res = e * kLn2Hi + (log_m + e * kLn2Lo);
  const double special = x == 0 ? -kInf : (x == kInf ? kInf : std::numeric_limits<double>::quiet_NaN());
  return (x > 0 && x < kInf) ? res : special;
}

// atan2(y, x) for finite y, x (0 when both are 0). The ratio t = min(|x|,|y|)/max(|x|,|y|) in [0, 1] (above
// 0.66 reduced by atan t = π/4 + atan((t−1)/(t+1)), formed as (min − max)/(min + max)), Cephes' rational
// approximation atan u = u + u³ P(u²)/Q(u²) on |u| ≤ 0.66 (peak relative error 2.6e-18), then the quadrant.
// The signs of zero are not distinguished (atan2(±0, −1) = +π).
inline double lane_atan2(double y, double x) {
  constexpr double kPi = 3.141592653589793116, kPi2 = 1.5707963267948966192, kPi4 = 0.78539816339744830962;
  constexpr double kMoreBits = 6.123233995736765886130e-17;  // π/2 − double(π/2)
  const double ax = std::abs(x), ay = std::abs(y);
  const bool steep = ay > ax;
  const double mx = steep ? ay : ax, mn = steep ? ax : ay;
  const bool mid = mn > 0.66 * mx;
  const double num = mid ? mn - mx : mn, den = mid ? mn + mx : mx;
  const double ratio = num / den;
  const double u = den > 0 ? ratio : 0.0;
  const double z = u * u;
  double p = -8.750608600031904122785e-1;
  p = p * z - 1.615753718733365076637e1;
  p = p * z - 7.500855792314704667340e1;
  p = p * z - 1.228866684490136173410e2;
  p = p * z - 6.485021904942025371773e1;
  double q = z + 2.485846490142306297962e1;
  q = q * z + 1.650270098316988542046e2;
  q = q * z + 4.328810604912902668951e2;
  q = q * z + 4.853903996359136964868e2;
  q = q * z + 1.945506571482613964425e2;
  const double at = u + u * (z * p / q);
  const double a_mid = kPi4 + (at + 0.5 * kMoreBits);
  double a = mid ? a_mid : at;  // atan(mn / mx) in [0, π/4]
  const double a_steep = kPi2 + (kMoreBits - a);
  a = steep ? a_steep : a;  // atan(|y| / |x|) in [0, π/2]
  const double a_left = kPi + (2 * kMoreBits - a);
  a = x < 0 ? a_left : a;
  return y < 0 ? -a : a;
}

}  // namespace lidef
