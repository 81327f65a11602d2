#include "lidef/number_format.h"

#include <charconv>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "lidef/hash.h"

namespace lidef {

std::string format_double(double x) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, x);
  return std::string(buf, res.ptr);
}

std::string format_g(double x, int digits) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*g", digits, x);
  return buf;
}

std::string format_bound(double x, bool upper, int digits) {
  std::string s = format_g(x, digits);
  if (!std::isfinite(x)) return s;
  const auto holds = [&](const std::string& t) {
    const double v = std::strtod(t.c_str(), nullptr);
    return upper ? v >= x : v <= x;
  };
  if (holds(s)) return s;
  // One unit of the last printed digit away from x (twice at most: the step itself is rounded).
  const double v = std::strtod(s.c_str(), nullptr);
  const double unit = std::pow(10.0, std::floor(std::log10(std::abs(v))) - (digits - 1));
  for (int k = 1; k <= 2; ++k) {
    s = format_g(upper ? v + k * unit : v - k * unit, digits);
    if (holds(s)) return s;
  }
  return format_double(x);  // exact
}

std::string format_fixed(double x, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, x);
  return buf;
}

std::string hex64(std::uint64_t h) {
  char buf[20];
  std::snprintf(buf, sizeof buf, "%016" PRIx64, h);
  return buf;
}

}  // namespace lidef
