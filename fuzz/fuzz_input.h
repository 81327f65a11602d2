// Shared by the fuzz targets (fuzz/README.md): the readers take a path, so each input is written to a file in
// a per-process scratch folder, on /dev/shm when it exists (a tmpfs: no disk I/O per execution) and in
// $TMPDIR or /tmp otherwise. No second parser: the target calls the same function the CLI calls, on that
// file.
#pragma once
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace lidef_fuzz {

// Set by replay_main's -v: each target then prints the reader's verdict on every input (to check what the
// seeds reach). Always false under libFuzzer.
inline bool verbose = false;

// Called by each target after the reader: "accepted" or the InputError's message.
inline void report(const char* verdict) {
  if (verbose) std::fprintf(stderr, "  -> %s\n", verdict);
}

// The scratch folder of this process (created on first use, removed at exit). The path is never destroyed:
// the atexit handler is registered before the path's construction completes, so it runs after the path's
// destructor.
inline const std::filesystem::path& scratch_dir() {
  static const std::filesystem::path* const dir = [] {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path base = fs::is_directory("/dev/shm", ec) ? fs::path("/dev/shm") : fs::temp_directory_path();
    auto* d = new fs::path(base / ("lidef-fuzz-" + std::to_string(::getpid())));
    fs::create_directories(*d);
    std::atexit([] {
      std::error_code e;
      fs::remove_all(scratch_dir(), e);
    });
    return d;
  }();
  return *dir;
}

// Writes `size` bytes to scratch_dir()/name (replacing it) and returns the file's path.
inline std::string write_input(const std::uint8_t* data, std::size_t size, const std::string& name) {
  const std::string path = (scratch_dir() / name).string();
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) std::abort();  // the harness itself failed: not a finding in the reader, but never silent
  return path;
}

}  // namespace lidef_fuzz
