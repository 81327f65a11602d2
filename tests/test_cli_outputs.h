// Helpers of the failure-behaviour tests (test_malformed_inputs.cpp, test_kill_during_write.cpp): running
// lidef, listing what a folder holds.
#pragma once
#include <algorithm>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "test_support.h"

namespace lidef::test {

// `s` in single quotes, for a shell command line (the test paths hold no quote).
inline std::string shell_quote(const std::string& s) {
  return "'" + s + "'";
}
// Runs `lidef ARGS`, returns its exit code; stdout+stderr go to `output`.
inline int run_lidef_cli(const std::string& args, std::string* output = nullptr) {
  return run_command(shell_quote(cli()) + " " + args, output);
}
// The names in `dir`, sorted (empty when it does not exist).
inline std::vector<std::string> dir_entries(const std::string& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace lidef::test
