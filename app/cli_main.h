// The one try/catch of lidef's command-line programs (lidef, lidef-compare): parse, run the chosen action, map
// exceptions to one message line and exit code 2.
#pragma once
#include <iostream>

#include "commands.h"
#include "lidef/errors.h"

namespace lidef::cli {

inline int run_cli(CLI::App& app, const Action& action, int argc, char** argv, const char* program) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? kOk : kError;
  }
  try {
    return action ? action() : kError;
  } catch (const lidef::Error& e) {  // InputError and the other errors of the library
    std::cerr << program << ": error: " << e.what() << "\n";
  } catch (const std::exception& e) {
    std::cerr << program << ": internal error: " << e.what() << "\n";
  }
  return kError;
}

}  // namespace lidef::cli
