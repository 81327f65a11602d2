// Drawing PNGs with gnuplot (no X server needed: pngcairo), shared by the sub-commands that make pictures.
#pragma once
#include <string>

namespace lidef {
class StagedOutputs;  // lidef/staged_outputs.h
}  // namespace lidef

namespace lidef::cli {

// Single-quotes `s` for /bin/sh.
std::string shell_quote(const std::string& s);

// The gnuplot executable: $LIDEF_GNUPLOT (a path; "none" disables plotting), else `gnuplot` on $PATH.
// Empty when there is none.
std::string find_gnuplot();

// Runs `gnuplot script` inside `dir`. Returns true when gnuplot exited 0; `log` receives its output.
bool run_gnuplot(const std::string& gnuplot, const std::string& dir, const std::string& script,
                 std::string* log);

// Draws NAME.png from the script NAME.gp already written into `out`'s staging folder (the PNG is staged as
// an output of `out`). Returns "" when drawn, else why not ("gnuplot not found" + hint, or gnuplot's error);
// a failed run leaves no PNG behind. The one place the commands that make pictures run gnuplot.
std::string render_staged_png(StagedOutputs& out, const std::string& name, const std::string& hint = "");

}  // namespace lidef::cli
