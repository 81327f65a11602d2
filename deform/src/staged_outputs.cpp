#include "lidef/staged_outputs.h"

#include <stdlib.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <system_error>

#include "lidef/atomic_file.h"
#include "lidef/errors.h"

namespace lidef {
namespace fs = std::filesystem;
namespace {

constexpr const char* kJournalHeader = "lidef-commit 1";

bool describes_others(const std::string& name) {
  return std::find_if(std::begin(kDescribingOutputs), std::end(kDescribingOutputs),
                      [&](const char* d) { return name == d; }) != std::end(kDescribingOutputs);
}

// A journal's content: the staging folder (a name inside DIR), the files to move from it into DIR (in the
// order they are moved: the describing outputs last) and the files of DIR to remove.
struct Journal {
  std::string staging;
  std::vector<std::string> moves, removals;
};

// A plain file name: what a journal line may hold (no separator, no line break, not "." or "..").
bool plain_name(const std::string& n) {
  return !n.empty() && n != "." && n != ".." && n.find_first_of("/\n\r") == std::string::npos;
}

std::string journal_text(const Journal& j) {
  std::string s = std::string(kJournalHeader) + "\nstaging " + j.staging + "\n";
  for (const std::string& n : j.moves) s += "move " + n + "\n";
  for (const std::string& n : j.removals) s += "remove " + n + "\n";
  return s;
}

Journal read_journal(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot read the journal of an interrupted commit");
  auto bad = [&](const std::string& why) {
    return InputError(path,
                      "not a valid journal of an interrupted commit (" + why +
                          "); the folder may mix two runs' files — remove the journal to accept it as it is");
  };
  std::string line;
  if (!std::getline(in, line) || line != kJournalHeader) throw bad("unknown first line");
  Journal j;
  while (std::getline(in, line)) {
    const size_t space = line.find(' ');
    const std::string key = line.substr(0, space);
    const std::string name = space == std::string::npos ? "" : line.substr(space + 1);
    if (!plain_name(name)) throw bad("line \"" + line + "\"");
    if (key == "staging" && j.staging.empty() && name.rfind(".lidef-staging-", 0) == 0)
      j.staging = name;
    else if (key == "move")
      j.moves.push_back(name);
    else if (key == "remove")
      j.removals.push_back(name);
    else
      throw bad("line \"" + line + "\"");
  }
  if (j.staging.empty()) throw bad("no staging folder");
  return j;
}

// Moves a staged file into DIR. Unlike commit_temp_file, a failure keeps the staged file: the journal still
// lists it, and a later attempt (or the user) can finish the commit without losing it.
void move_in(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  fs::rename(from, to, ec);
  if (ec) throw InputError(to.string(), "cannot move the staged file into place: " + ec.message());
}

// Removes DIR/name when it is there; throws InputError naming it when it stays.
void remove_in(const fs::path& dir, const std::string& name) {
  std::error_code ec;
  fs::remove(dir / name, ec);
  if (ec) throw InputError((dir / name).string(), "cannot remove: " + ec.message());
}

}  // namespace

bool is_write_leftover(const std::string& name) {
  return name.rfind(".lidef-staging-", 0) == 0 || name.find(".tmp.") != std::string::npos;
}

bool holds_only_leftovers(const std::string& dir) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (!is_write_leftover(e.path().filename().string())) return false;
  return !ec;
}

bool finish_interrupted_commit(const std::string& dir, int max_operations) {
  const fs::path d(dir);
  const fs::path journal_path = d / kCommitJournal;
  std::error_code ec;
  if (!fs::exists(journal_path, ec)) return false;
  const Journal j = read_journal(journal_path.string());
  const fs::path staging = d / j.staging;
  // The staging folder goes only after the journal, so a journal without it means someone removed it.
  if (!j.moves.empty() && !fs::is_directory(staging, ec))
    throw InputError(journal_path.string(),
                     "the staging folder " + j.staging +
                         " of an interrupted commit is gone; the folder may mix two runs' files — remove the "
                         "journal to accept it as it is");
  auto staged = [&](const std::string& name) { return fs::exists(staging / name, ec); };
  int done = 0;
  auto budget_left = [&] { return max_operations < 0 || done < max_operations; };
  // Every stage acts only on what is still staged, so a repeat after a kill continues where it stopped.
  // 1. Withdraw the older describing outputs that this commit replaces.
  for (const std::string& n : j.moves)
    if (describes_others(n) && staged(n) && fs::exists(d / n, ec)) {
      if (!budget_left()) return true;
      remove_in(d, n), ++done;
    }
  // 2. Move the described files, 3. remove the stale ones, 4. publish the describing outputs.
  for (const bool describing : {false, true}) {
    for (const std::string& n : j.moves)
      if (describes_others(n) == describing && staged(n)) {
        if (!budget_left()) return true;
        move_in(staging / n, d / n), ++done;
      }
    if (describing) break;
    for (const std::string& n : j.removals)
      if (fs::exists(d / n, ec)) {
        if (!budget_left()) return true;
        remove_in(d, n), ++done;
      }
  }
  // 5. The commit is complete: the journal goes, then the staging folder (a leftover no reader opens).
  if (!budget_left()) return true;
  remove_in(d, kCommitJournal), ++done;
  fs::remove_all(staging, ec);
  return true;
}

StagedOutputs::StagedOutputs(const std::string& dir) : dir_(dir) {
  std::error_code ec;
  if (fs::exists(dir_, ec) && !fs::is_directory(dir_, ec))
    throw InputError(dir_, "exists and is not a folder");
  // The folders this object creates (DIR and missing parents), deepest first, to remove again on failure.
  for (fs::path p = fs::absolute(fs::path(dir_), ec).lexically_normal(); !p.empty() && !fs::exists(p, ec);
       p = p.parent_path()) {
    created_.push_back(p.string());
    if (p == p.parent_path()) break;
  }
  ensure_directory(dir_);
  finish_interrupted_commit(dir_);
  std::string tmpl = (fs::path(dir_) / ".lidef-staging-XXXXXX").string();
  if (!::mkdtemp(tmpl.data())) {
    remove_created_dir();
    throw InputError(dir_, "cannot create a staging folder (not writable?)");
  }
  staging_ = tmpl;
}

StagedOutputs::~StagedOutputs() {
  std::error_code ec;
  if (!staging_.empty()) fs::remove_all(staging_, ec);
  if (!committed_) remove_created_dir();
}

std::string StagedOutputs::path(const std::string& name) {
  if (!plain_name(name) || name == kCommitJournal || is_write_leftover(name))
    throw Error("StagedOutputs: \"" + name + "\" is not a plain output file name");
  if (std::find(names_.begin(), names_.end(), name) == names_.end()) names_.push_back(name);
  return (fs::path(staging_) / name).string();
}

std::string StagedOutputs::final_path(const std::string& name) const {
  return (fs::path(dir_) / name).string();
}

void StagedOutputs::write_journal(const std::vector<std::string>& stale) {
  Journal j;
  j.staging = fs::path(staging_).filename().string();
  std::error_code ec;
  for (const std::string& n : names_)
    if (fs::exists(fs::path(staging_) / n, ec)) j.moves.push_back(n);
  for (const std::string& n : stale) {
    if (!plain_name(n)) throw Error("StagedOutputs: \"" + n + "\" is not a plain output file name");
    if (std::find(j.moves.begin(), j.moves.end(), n) == j.moves.end()) j.removals.push_back(n);
  }
  const std::string text = journal_text(j);
  write_file_atomic(final_path(kCommitJournal), [&](std::ostream& s) { s << text; });
}

void StagedOutputs::commit(const std::vector<std::string>& stale) {
  write_journal(stale);
  finish_interrupted_commit(dir_);
  committed_ = true;
}

void StagedOutputs::remove_created_dir() {
  for (const std::string& p : created_) {
    std::error_code ec;
    if (!fs::is_empty(p, ec) || ec) break;
    fs::remove(p, ec);
  }
}

}  // namespace lidef
