// All-or-nothing output of a command that writes several files into one folder: every file is first written
// into a private staging folder inside the target (DIR/.lidef-staging-XXXXXX), and commit() moves them into
// DIR (renames within one file system). If the command fails before commit(), the destructor removes the
// staging folder — and DIR (with any parents) when this object created it and it is still empty — so nothing
// new is left behind.
#pragma once
#include <stdlib.h>

#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "lidef/atomic_file.h"
#include "lidef/errors.h"

namespace lidef {

// Whether `name` (a folder entry) is what a killed run may leave behind: a staging folder
// (".lidef-staging-XXXXXX") or an atomic write's temporary ("NAME.tmp.PID.N"). No reader opens these names.
inline bool is_write_leftover(const std::string& name) {
  return name.rfind(".lidef-staging-", 0) == 0 || name.find(".tmp.") != std::string::npos;
}

// Whether the folder `dir` holds nothing but the leftovers of killed runs (is_write_leftover).
inline bool holds_only_leftovers(const std::string& dir) {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    if (!is_write_leftover(e.path().filename().string())) return false;
  return !ec;
}

class StagedOutputs {
 public:
  explicit StagedOutputs(const std::string& dir) : dir_(dir) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::exists(dir_, ec) && !fs::is_directory(dir_, ec))
      throw InputError(dir_, "exists and is not a folder");
    // The folders this object creates (DIR and missing parents), deepest first, to remove again on failure.
    for (fs::path p = fs::absolute(fs::path(dir_), ec).lexically_normal(); !p.empty() && !fs::exists(p, ec);
         p = p.parent_path()) {
      created_.push_back(p);
      if (p == p.parent_path()) break;
    }
    ensure_directory(dir_);
    std::string tmpl = (fs::path(dir_) / ".lidef-staging-XXXXXX").string();
    if (!::mkdtemp(tmpl.data())) {
      remove_created_dir();
      throw InputError(dir_, "cannot create a staging folder (not writable?)");
    }
    staging_ = tmpl;
  }
  StagedOutputs(const StagedOutputs&) = delete;
  StagedOutputs& operator=(const StagedOutputs&) = delete;
  ~StagedOutputs() {
    std::error_code ec;
    if (!staging_.empty()) std::filesystem::remove_all(staging_, ec);
    if (!committed_) remove_created_dir();
  }

  // Where to write the output `name` now (inside the staging folder); it is moved to DIR/name by commit().
  std::string path(const std::string& name) {
    names_.push_back(name);
    return (std::filesystem::path(staging_) / name).string();
  }
  const std::string& staging_dir() const { return staging_; }
  // Final location of `name`.
  std::string final_path(const std::string& name) const {
    return (std::filesystem::path(dir_) / name).string();
  }

  // Moves every staged file that exists into DIR (replacing older versions), and removes the files listed in
  // `stale` from DIR (outputs of an earlier run that this run did not produce, which would no longer match).
  void commit(const std::vector<std::string>& stale = {}) {
    namespace fs = std::filesystem;
    for (const std::string& name : names_) {
      const fs::path from = fs::path(staging_) / name;
      std::error_code ec;
      if (!fs::exists(from, ec)) continue;
      commit_temp_file(from.string(), final_path(name));
    }
    for (const std::string& name : stale) {
      std::error_code ec;
      std::filesystem::remove(fs::path(dir_) / name, ec);
    }
    committed_ = true;
  }

 private:
  void remove_created_dir() {
    for (const std::filesystem::path& p : created_) {
      std::error_code ec;
      if (!std::filesystem::is_empty(p, ec) || ec) break;
      std::filesystem::remove(p, ec);
    }
  }
  std::string dir_, staging_;
  std::vector<std::string> names_;
  std::vector<std::filesystem::path> created_;
  bool committed_ = false;
};

}  // namespace lidef
