// Helpers shared by the benchmark programs: the command line, timing loops and their statistics, table cells,
// and a description of the machine and the build for the headers of their reports.
#pragma once
#include <time.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "lidef/internal/median.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/number_format.h"
#include "nlohmann/json.hpp"

namespace lidef::bench {

// ---- Command line.

// Parses the command line with CLI11. Returns -1 to go on, else the exit code: 0 after --help, 2 after a bad
// flag or value (CLI11's message on stderr), the benchmarks' code for bad input.
inline int parse_command_line(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  return -1;
}

// The options of every benchmark over the shared data: the data folder (positional), --threads, --cache-dir.
inline void add_data_options(CLI::App& app, std::string& data_dir, int& threads, std::string& cache_dir) {
  app.add_option("DATA_DIR", data_dir, "shared data folder (default: $LIDEF_SHARED_DATA, else the build's)");
  app.add_option("--threads", threads,
                 "OpenMP threads; OpenBLAS runs one per calling thread (0: the default)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--cache-dir", cache_dir, "subspace (and OpenCL kernel) cache folder");
}

// The shared data folder when none is given: $LIDEF_SHARED_DATA when set, else `fallback` (the build's).
inline std::string default_data_dir(const std::string& fallback) {
  const char* env = std::getenv("LIDEF_SHARED_DATA");
  return env && *env ? std::string(env) : fallback;
}

// "a,b,,c" -> {a, b, c}: the comma-separated lists of model and scenario names.
inline std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  for (std::string m; std::getline(ss, m, ',');)
    if (!m.empty()) v.push_back(m);
  return v;
}

// ---- Timing.

// Process CPU time in ms (user + system, all threads).
inline double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

// Median (lidef/internal/median.h) and minimum; NaN for no values.
using lidef::median;
inline double minimum(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : *std::min_element(v.begin(), v.end());
}

// The timed repetitions of one piece of work.
struct Timing {
  std::vector<double> ms;     // wall clock per timed run
  std::vector<double> cpu;    // process CPU ms per timed run
  double checksum = 0;        // what the warm-up returned (work returning a double)
  bool checksum_same = true;  // every timed run returned it (to 1e-9 relative): the work was really done
  double med() const { return median(ms); }
  double min() const { return minimum(ms); }
  double med_cpu() const { return median(cpu); }
};

// Runs `work` once untimed (warm-up: page faults, caches, lazily built data), then `reps` times timed. When
// `work` returns a double (a checksum, so that the work cannot be skipped), every timed run must return the
// warm-up's value (Timing::checksum_same).
template <class F>
Timing time_reps(int reps, F&& work) {
  constexpr bool checked = std::is_same_v<std::invoke_result_t<F&>, double>;
  Timing t;
  if constexpr (checked)
    t.checksum = work();
  else
    work();
  for (int r = 0; r < reps; ++r) {
    const double c0 = cpu_ms();
    const auto t0 = Clock::now();
    if constexpr (checked) {
      const double c = work();
      t.ms.push_back(ms_since(t0));
      if (std::abs(c - t.checksum) > 1e-9 * std::max(1.0, std::abs(t.checksum))) t.checksum_same = false;
    } else {
      work();
      t.ms.push_back(ms_since(t0));
    }
    t.cpu.push_back(cpu_ms() - c0);
  }
  return t;
}

// ---- Table cells: "%.<prec>f" / "%.<prec>g" (lidef/number_format.h), "n/a" for NaN and "inf" for
// infinities.

inline std::string fixed(double v, int prec) {
  if (!std::isfinite(v)) return std::isnan(v) ? "n/a" : (v > 0 ? "inf" : "-inf");
  return format_fixed(v, prec);
}
inline std::string sci(double v, int prec = 3) {
  if (!std::isfinite(v)) return std::isnan(v) ? "n/a" : (v > 0 ? "inf" : "-inf");
  return format_g(v, prec);
}

// ---- The machine and the build.

// The first line of a file ("" when it cannot be read).
inline std::string first_line(const std::string& path) {
  std::ifstream in(path);
  std::string s;
  std::getline(in, s);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\r')) s.pop_back();
  return s;
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
  const std::string s = first_line("/proc/loadavg");
  return s.empty() ? "unknown" : s;
}

// First line of /proc/pressure/cpu ("some avg10=.. avg60=.. ..."): the share of time a runnable task waited
// for a CPU, i.e. how much other load competed with the benchmark.
inline std::string cpu_pressure() {
  std::string s = first_line("/proc/pressure/cpu");
  const auto t = s.find(" total=");
  if (t != std::string::npos) s.resize(t);
  return s.empty() ? "unavailable" : s;
}

// MemTotal of /proc/meminfo in GiB ("15.6 GiB").
inline std::string mem_total() {
  std::ifstream in("/proc/meminfo");
  std::string key, unit;
  double kb = 0;
  while (in >> key >> kb >> unit)
    if (key == "MemTotal:") return fixed(kb / (1024.0 * 1024.0), 1) + " GiB";
  return "unknown";
}

// A time point of the system clock as "YYYY-MM-DD hh:mm:ss UTC".
inline std::string utc_text(std::time_t t) {
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S UTC", std::gmtime(&t));
  return buf;
}
inline std::string utc_now() {
  return utc_text(std::time(nullptr));
}

// Output of a shell command, trailing newlines removed (the git state of the measured source).
inline std::string command_output(const std::string& cmd) {
  std::string out;
  if (FILE* p = popen(cmd.c_str(), "r")) {
    char buf[512];
    while (fgets(buf, sizeof buf, p)) out += buf;
    pclose(p);
  }
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

// The optimization, target and language flags a source file was compiled with (its path ends with
// `file_suffix`, e.g. "/deform/src/octree_certifier.cpp"), read from the build's compile_commands.json
// (CMAKE_EXPORT_COMPILE_COMMANDS), so that a report shows what the measured code really used.
inline std::string compile_flags(const std::string& build_dir, const std::string& file_suffix) {
  const std::string path = build_dir + "/compile_commands.json";
  std::ifstream in(path);
  if (!in) return "unknown (" + path + " not found)";
  nlohmann::json db;
  try {
    in >> db;
  } catch (const std::exception&) {
    return "unknown (" + path + " unreadable)";
  }
  for (const auto& entry : db) {
    const std::string file = entry.value("file", "");
    if (file.size() < file_suffix.size() ||
        file.compare(file.size() - file_suffix.size(), file_suffix.size(), file_suffix) != 0)
      continue;
    std::istringstream cmd(entry.value("command", ""));
    std::string tok, flags;
    while (cmd >> tok)
      if (tok.rfind("-O", 0) == 0 || tok.rfind("-m", 0) == 0 || tok.rfind("-f", 0) == 0 ||
          tok.rfind("-std", 0) == 0 || tok == "-DNDEBUG" || tok.rfind("-g", 0) == 0)
        flags += (flags.empty() ? "" : " ") + tok;
    return flags;
  }
  return "unknown (" + std::filesystem::path(file_suffix).filename().string() + " not in " + path + ")";
}

}  // namespace lidef::bench
