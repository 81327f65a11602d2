// Sub-commands of the `lidef` CLI. Each lives in its own cmd_*.cpp and registers itself here; the
// CLI itself is a thin try/catch around the library (see main.cpp).
#pragma once
#include <CLI/CLI.hpp>
#include <functional>

namespace lidef::cli {

// Exit codes shared by every sub-command.
enum ExitCode : int {
  kOk = 0,
  kNotCertified = 1,  // certify/verify: the map could not be certified (not an error)
  kStoppedEarly = 1,  // deform: stopped before convergence; the output is still the last certified map
  kError = 2,         // bad input or a failure; nothing was written
};

// A sub-command sets `action` in its parse callback; main() runs it inside its try/catch.
using Action = std::function<int()>;

void add_cage_command(CLI::App& app, Action& action);
void add_certify_command(CLI::App& app, Action& action);
void add_check_command(CLI::App& app, Action& action);
void add_deform_command(CLI::App& app, Action& action);
void add_devices_command(CLI::App& app, Action& action);
void add_eval_command(CLI::App& app, Action& action);
void add_explore_command(CLI::App& app, Action& action);
void add_make_model_command(CLI::App& app, Action& action);
void add_reproduce_command(CLI::App& app, Action& action);
void add_verify_command(CLI::App& app, Action& action);
// lidef-compare's options on its top-level app (compare_main.cpp).
void add_compare_options(CLI::App& app, Action& action);

}  // namespace lidef::cli
