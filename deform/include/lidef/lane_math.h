// Branch-free log and atan2 that vectorize inside `#pragma omp simd` loops (the batched evaluation of octree
// children, EdgeJet::evaluate_lanes). Each is a truncated Taylor series on a reduced argument, with exact
// rational coefficients rounded once; docs/certificate.md (Step 4c) gives the error bounds step by step:
// lane_log_ratio within 6u·|log(n/d)|, lane_atan2 within 12u·|atan2(y, x)| (u = 2⁻⁵³; relative bounds).
// Their domains are stated below; callers test the `*_in_domain` predicate and fall back to std:: otherwise.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>

namespace lidef {
namespace lane_math {

inline double from_bits(std::uint64_t b) {
  double d;
  std::memcpy(&d, &b, sizeof d);
  return d;
}
inline std::uint64_t to_bits(double d) {
  std::uint64_t b;
  std::memcpy(&b, &d, sizeof b);
  return b;
}

// log(n/d) for n, d positive, normal and finite, without forming n/d. n = 2^en·fn, d = 2^ed·fd with
// fn, fd ∈ [1, 2) (bit fields; the exponent field becomes an exact double by the 2^52 trick, no int64 →
// double conversion), one of fn, fd doubled so that fn/fd ∈ [1/√2, √2] (fn − fd is then exact by
// Sterbenz), s = (fn − fd)/(fn + fd), |s| ≤ 3 − 2√2, and log(fn/fd) = 2 atanh(s) = 2 Σ_{k≥0} s^(2k+1)/(2k+1)
// truncated after k = 9 (remainder below 2.5·10⁻¹⁷ |2s|). k·ln 2 is added as k·ln2_hi (exact: ln2_hi has 33
// significant bits) plus k·ln2_lo.
inline bool log_ratio_in_domain(double n, double d) {
  // `&`, not `&&`: no branches inside SIMD loops.
  return (n >= 0x1p-1022) & (n <= 0x1.fffffffffffffp+1023) & (d >= 0x1p-1022) &
         (d <= 0x1.fffffffffffffp+1023);
}
inline double lane_log_ratio(double n, double d) {
  constexpr std::uint64_t kMant = (std::uint64_t{1} << 52) - 1, kOne = 0x3ff0000000000000ull,
                          kTwo52 = 0x4330000000000000ull;
  const std::uint64_t bn = to_bits(n), bd = to_bits(d);
  double fn = from_bits((bn & kMant) | kOne), fd = from_bits((bd & kMant) | kOne);
  // Biased exponent fields (n, d > 0: no sign bit) as 2^52 + field, exactly; their difference is exact.
  double k = from_bits((bn >> 52) | kTwo52) - from_bits((bd >> 52) | kTwo52);
  const bool hi = fn > 1.4142135623730951 * fd, lo = fd > 1.4142135623730951 * fn;
  fd = hi ? 2.0 * fd : fd;
  k = hi ? k + 1.0 : k;
  fn = lo ? 2.0 * fn : fn;
  k = lo ? k - 1.0 : k;
  const double s = (fn - fd) / (fn + fd);
  const double z = s * s;
  double q = 1.0 / 19;
  q = q * z + 1.0 / 17;
  q = q * z + 1.0 / 15;
  q = q * z + 1.0 / 13;
  q = q * z + 1.0 / 11;
  q = q * z + 1.0 / 9;
  q = q * z + 1.0 / 7;
  q = q * z + 1.0 / 5;
  q = q * z + 1.0 / 3;
  const double s2 = 2.0 * s;
  constexpr double kLn2Hi = 0x1.62e42fefp-1, kLn2Lo = 0x1.473de6af278edp-34;
  return k * kLn2Hi + (k * kLn2Lo + (s2 + s2 * z * q));
}

// atan2(y, x) for finite y, x, not both zero (the quadrant rules of std::atan2, signed zeros included).
// With a = |x|, b = |y|, mn = min(a, b), mx = max(a, b): z = mn/mx, or z = (mn − mx)/(mn + mx) with π/4
// added when mn > tan(π/8)·mx, so |z| ≤ tan(π/8) + 2u; atan z = Σ_{k≥0} (−1)^k z^(2k+1)/(2k+1) truncated
// after k = 19 (an alternating series: remainder below z⁴¹/41 ≤ 1.2·10⁻¹⁷ |z|); then π/2 − ·, π − · and the
// sign of y.
inline bool atan2_in_domain(double y, double x) {
  const double a = std::fabs(x), b = std::fabs(y);
  const double m = a > b ? a : b;
  return (m > 0) & (m <= 0x1.fffffffffffffp+1023) & (a == a) & (b == b);
}
inline double lane_atan2(double y, double x) {
  const double a = std::fabs(x), b = std::fabs(y);
  const double mx = a > b ? a : b, mn = a > b ? b : a;
  const bool big = mn > 0.41421356237309503 * mx;
  const double z = (big ? mn - mx : mn) / (big ? mn + mx : mx);
  const double w = z * z;
  // Σ_{k=1}^{19} (−1)^k w^(k−1)/(2k+1), Horner from the highest degree.
  double q = -1.0 / 39;
  q = q * w + 1.0 / 37;
  q = q * w - 1.0 / 35;
  q = q * w + 1.0 / 33;
  q = q * w - 1.0 / 31;
  q = q * w + 1.0 / 29;
  q = q * w - 1.0 / 27;
  q = q * w + 1.0 / 25;
  q = q * w - 1.0 / 23;
  q = q * w + 1.0 / 21;
  q = q * w - 1.0 / 19;
  q = q * w + 1.0 / 17;
  q = q * w - 1.0 / 15;
  q = q * w + 1.0 / 13;
  q = q * w - 1.0 / 11;
  q = q * w + 1.0 / 9;
  q = q * w - 1.0 / 7;
  q = q * w + 1.0 / 5;
  q = q * w - 1.0 / 3;
  constexpr double kPi4 = 0x1.921fb54442d18p-1, kPi2 = 0x1.921fb54442d18p+0, kPi = 0x1.921fb54442d18p+1;
  double t = z + z * w * q;                     // atan z
  t = big ? kPi4 + t : t;                       // atan(mn/mx) ∈ [0, π/4]
  t = b > a ? kPi2 - t : t;                     // atan(b/a)   ∈ [0, π/2]
  t = std::copysign(1.0, x) < 0 ? kPi - t : t;  // x < 0 or x = −0 (std::atan2's rule)
  return std::copysign(t, y);
}

}  // namespace lane_math
}  // namespace lidef
