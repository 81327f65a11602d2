// Two families of vectorizable log/atan2 (a call to the C library's scalar log/atan2 stops GCC's vectorizer):
// - lidef::lane_log / lidef::lane_atan2: general (every finite input), within 2 ulp measured against long
//   double (LaneMath.LogAndAtan2AreWithinTwoUlpOfALongDoubleReference); the harmonic basis kernel
//   (green_coordinates.cpp, HarmonicBasis::evaluate_rows).
// - lidef::lane_math::lane_log_ratio / lane_atan2: restricted domains with a written error bound (6u, 12u
//   relative; docs/certificate.md Step 4c); the certificate's batched refinement (edge_jet.cpp).
// Two implementations of atan2 came from two branches merged the same day; making the basis kernel use the
// bounded one (or proving a bound for the other) is open (docs/certificate.md, Step 4c).
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

// Branch-free log and atan2 that vectorize inside `#pragma omp simd` loops (the batched evaluation of octree
// children, EdgeJet::evaluate_lanes). Each is a truncated Taylor series on a reduced argument, with exact
// rational coefficients rounded once; docs/certificate.md (Step 4c) gives the error bounds step by step:
// lane_log_ratio within 6u·|log(n/d)|, lane_atan2 within 12u·|atan2(y, x)| (u = 2⁻⁵³; relative bounds).
// Their domains are stated below; callers test the `*_in_domain` predicate and fall back to std:: otherwise.
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
