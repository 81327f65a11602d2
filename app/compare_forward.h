// `lidef compare` is a separate program (lidef-compare, next to lidef) so that the comparison methods' heavy
// dependencies (TetGen, CHOLMOD) stay out of lidef: lidef execs it with the same arguments, like git's
// sub-commands. The placeholder only lists it in `lidef --help`.
#pragma once
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "commands.h"

namespace lidef::cli {

inline void add_compare_placeholder(CLI::App& app) {
  app.add_subcommand("compare",
                     "Compare lidef with PWL(Tet), VHM and SR-ARAP on one scenario (runs lidef-compare; "
                     "'lidef compare --help' for its options)");
}

// Replaces this process with <dir of this executable>/lidef-compare argv[2..]; returns only on failure.
inline int forward_to_compare(int argc, char** argv) {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string exe = (ec ? std::filesystem::path(argv[0]) : self).parent_path() / "lidef-compare";
  std::vector<char*> args;
  std::string name = "lidef-compare";
  args.push_back(name.data());
  for (int i = 2; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  ::execv(exe.c_str(), args.data());
  std::cerr << "lidef: error: " << exe << ": cannot run the comparison program (" << std::strerror(errno)
            << "); it is built next to lidef (target lidef-compare)\n";
  return kError;
}

}  // namespace lidef::cli
