// Helpers shared by the benchmark programs: a description of the machine for the headers of their reports.
#pragma once
#include <fstream>
#include <string>

namespace lidef::bench {

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

}  // namespace lidef::bench
