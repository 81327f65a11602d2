#include "lidef/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "lidef/errors.h"

namespace lidef {

std::string temp_path_beside(const std::string& path, const std::string& ext) {
  static std::atomic<unsigned long> counter{0};
  return path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++) + ext;
}

void commit_temp_file(const std::string& tmp, const std::string& path) {
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw InputError(path, "cannot move the temporary file into place: " + ec.message());
  }
}

void write_file_atomic(const std::string& path, const std::function<void(std::ostream&)>& writer) {
  write_file_atomic_via_path(path, "", [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw InputError(path, "cannot open for writing (does the folder exist?)");
    writer(out);
    out.flush();
    if (!out) throw InputError(path, "write failed (disk full?)");
  });
}

void write_file_atomic_via_path(const std::string& path, const std::string& ext,
                                const std::function<void(const std::string& tmp)>& write) {
  const std::string tmp = temp_path_beside(path, ext);
  std::error_code ec;
  try {
    write(tmp);
    if (!std::filesystem::exists(tmp, ec)) throw InputError(path, "write failed");
  } catch (...) {
    std::filesystem::remove(tmp, ec);
    throw;
  }
  commit_temp_file(tmp, path);
}

void ensure_directory(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) throw InputError(dir, "cannot create output directory");
}

}  // namespace lidef
