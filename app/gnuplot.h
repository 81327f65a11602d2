// Drawing PNGs with gnuplot (no X server needed: pngcairo), shared by the sub-commands that make pictures.
#pragma once
#include <string>

namespace lidef::cli {

// Single-quotes `s` for /bin/sh.
std::string shell_quote(const std::string& s);

// The gnuplot executable: $LIDEF_GNUPLOT (a path; "none" disables plotting), else `gnuplot` on $PATH.
// Empty when there is none.
std::string find_gnuplot();

// Runs `gnuplot script` inside `dir`. Returns true when gnuplot exited 0; `log` receives its output.
bool run_gnuplot(const std::string& gnuplot, const std::string& dir, const std::string& script,
                 std::string* log);

}  // namespace lidef::cli
