// Helpers shared by the test files: where data lives, temp dirs, running the CLI.
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "lidef/errors.h"

namespace lidef::test {

// ../shared/data (or $LIDEF_SHARED_DATA). Empty string when absent. (test_paths.cpp)
std::string shared_data();
inline std::string shared_model(const std::string& name) { return shared_data() + "/models/" + name; }
std::string project_data();  // the repository's data/
std::string cli();           // the lidef executable of this build

// Whole file as bytes ("" when unreadable).
inline std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}
// The message of the lidef::InputError thrown by f; a test failure when nothing (or something else) is thrown.
template <class F>
std::string input_error_message(F&& f) {
  try {
    f();
  } catch (const ::lidef::InputError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected InputError, nothing thrown";
  return "";
}
// Writes `text` to `path` (a gtest failure if that fails).
inline void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  ASSERT_TRUE(out.good()) << path;
}

// Skips the current test with a clear message when ../shared/data is missing.
#define LIDEF_REQUIRE_SHARED()                                                              \
  do {                                                                                      \
    if (::lidef::test::shared_data().empty())                                               \
      GTEST_SKIP() << "shared data not found (set LIDEF_SHARED_DATA or place ../shared)"; \
  } while (0)

// A fresh empty directory under the system temp dir, removed by the destructor.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    path = std::filesystem::temp_directory_path() /
           ("lidef_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            std::to_string(reinterpret_cast<uintptr_t>(this)) + "_" + std::to_string(std::rand()));
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string str() const { return path.string(); }
  std::string operator/(const std::string& f) const { return (path / f).string(); }
};

// Runs a shell command, returns its exit code; stdout+stderr go to `output`.
inline int run_command(const std::string& cmd, std::string* output = nullptr) {
  const std::string tmp = std::filesystem::temp_directory_path() / ("lidef_cmd_" + std::to_string(::getpid()) + "_" + std::to_string(std::rand()));
  const int status = std::system((cmd + " > " + tmp + " 2>&1").c_str());
  if (output) {
    FILE* f = std::fopen(tmp.c_str(), "rb");
    output->clear();
    if (f) {
      char buf[4096];
      size_t n;
      while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) output->append(buf, n);
      std::fclose(f);
    }
  }
  std::filesystem::remove(tmp);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace lidef::test
