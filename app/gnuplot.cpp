#include "gnuplot.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "lidef/staged_outputs.h"

namespace lidef::cli {

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (const char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string find_gnuplot() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("LIDEF_GNUPLOT")) {
    const std::string g = env;
    if (g == "none") return "";
    if (!g.empty()) return fs::exists(g) ? g : "";
  }
  const char* path = std::getenv("PATH");
  if (!path) return "";
  std::istringstream dirs(path);
  for (std::string d; std::getline(dirs, d, ':');) {
    if (d.empty()) continue;
    const fs::path p = fs::path(d) / "gnuplot";
    std::error_code ec;
    if (fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0) return p.string();
  }
  return "";
}

bool run_gnuplot(const std::string& gnuplot, const std::string& dir, const std::string& script,
                 std::string* log) {
  const std::string cmd =
      "cd " + shell_quote(dir) + " && " + shell_quote(gnuplot) + " " + shell_quote(script) + " 2>&1";
  std::string out;
  int rc = -1;
  if (FILE* p = ::popen(cmd.c_str(), "r")) {
    char buf[512];
    while (std::fgets(buf, sizeof buf, p)) out += buf;
    rc = ::pclose(p);
  }
  if (log) *log = out;
  return rc == 0;
}

std::string render_staged_png(StagedOutputs& out, const std::string& name, const std::string& hint) {
  namespace fs = std::filesystem;
  const std::string gnuplot = find_gnuplot();
  if (gnuplot.empty()) return "gnuplot not found" + hint + ": " + name + ".png not drawn";
  const std::string png = out.path(name + ".png");
  std::string log;
  if (!run_gnuplot(gnuplot, out.staging_dir(), name + ".gp", &log) || !fs::exists(png)) {
    std::error_code ec;
    fs::remove(png, ec);
    return "gnuplot failed (" + gnuplot + "): " + name + ".png not drawn" + (log.empty() ? "" : ": " + log);
  }
  return "";
}

}  // namespace lidef::cli
