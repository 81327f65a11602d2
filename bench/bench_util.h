// Helpers shared by the benchmark programs: a description of the machine for the headers of their reports.
#pragma once
#include <cmath>
#include <fstream>
#include <string>

#include "lidef/number_format.h"

namespace lidef::bench {

// Table cells: "%.<prec>f" / "%.<prec>g" (lidef/number_format.h), "n/a" for NaN and "inf" for infinities.
inline std::string fixed(double v, int prec) {
  if (!std::isfinite(v)) return std::isnan(v) ? "n/a" : (v > 0 ? "inf" : "-inf");
  return format_fixed(v, prec);
}
inline std::string sci(double v, int prec = 3) {
  if (!std::isfinite(v)) return std::isnan(v) ? "n/a" : (v > 0 ? "inf" : "-inf");
  return format_g(v, prec);
}

// "model name" of the first CPU in /proc/cpuinfo.
inline std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      const auto c = line.find(':');
      return c == std::string::npos ? line : line.substr(c + 2);
    }
  return "unknown";
}

// The first line of /proc/loadavg (the machine's load when a benchmark ran).
inline std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string line;
  std::getline(in, line);
  return line;
}

}  // namespace lidef::bench
