// All-or-nothing output of a command that writes several files into one folder: every file is first written
// into a private staging folder inside the target (DIR/.lidef-staging-XXXXXX), and commit() moves them into
// DIR (renames within one file system). If the command fails before commit(), the destructor removes the
// staging folder — and DIR (with any parents) when this object created it and it is still empty — so nothing
// new is left behind.
//
// A commit is a list of renames, and a process can be killed between two of them. So commit() first writes a
// journal, DIR/.lidef-commit (atomically), naming the staging folder and every move and removal, and removes
// it after the last one; a folder holding a journal holds an interrupted commit, which
// finish_interrupted_commit() completes (every lidef command that writes into the folder, reads a certificate
// from it or loads it as a model does so first). Meanwhile the files that describe the others
// (kDescribingOutputs: certificate.json, summary.json, model.json) are withdrawn before the first move and
// moved in after the last: whenever DIR holds one of them, the other outputs of its run are in place beside
// it.
#pragma once
#include <string>
#include <vector>

namespace lidef {

// The journal of an interrupted commit in an output folder.
inline constexpr const char* kCommitJournal = ".lidef-commit";

// Outputs that describe the other files of their folder (a certificate names the coefficients it certifies; a
// summary names the run; model.json the model's files): withdrawn first and published last by a commit.
inline constexpr const char* kDescribingOutputs[] = {"certificate.json", "summary.json", "model.json"};

// Whether `name` (a folder entry) is what a killed run may leave behind and no reader opens: a staging folder
// (".lidef-staging-XXXXXX") or an atomic write's temporary ("NAME.tmp.PID.N"). The commit journal is not one:
// it stands for files still to be moved in.
bool is_write_leftover(const std::string& name);

// Whether the folder `dir` holds nothing but the leftovers of killed runs (is_write_leftover).
bool holds_only_leftovers(const std::string& dir);

// Completes the commit a killed process left unfinished in `dir` (DIR/.lidef-commit): the staged files still
// in the staging folder are moved in, the stale files removed, then the journal and the staging folder. Safe
// to repeat and to interrupt again. Returns whether there was one. Throws InputError naming the journal when
// it cannot be read or its staging folder is gone while files remain to be moved (the folder may then mix two
// runs; removing the journal by hand accepts that).
// `max_operations` >= 0 stops after that many file operations (moves and removals), as a kill would: the
// kill points a test walks through.
bool finish_interrupted_commit(const std::string& dir, int max_operations = -1);

class StagedOutputs {
 public:
  // Creates DIR (and parents) when missing and the staging folder in it; completes an interrupted commit
  // already in DIR first. Throws InputError(DIR, ...) when DIR is not a writable folder.
  explicit StagedOutputs(const std::string& dir);
  StagedOutputs(const StagedOutputs&) = delete;
  StagedOutputs& operator=(const StagedOutputs&) = delete;
  ~StagedOutputs();

  // Where to write the output `name` now (inside the staging folder); it is moved to DIR/name by commit().
  std::string path(const std::string& name);
  const std::string& staging_dir() const { return staging_; }
  // Final location of `name`.
  std::string final_path(const std::string& name) const;

  // Moves every staged file that exists into DIR (replacing older versions), and removes the files listed in
  // `stale` from DIR (outputs of an earlier run that this run did not produce, which would no longer match).
  // = write_journal(stale) followed by finish_interrupted_commit(DIR).
  void commit(const std::vector<std::string>& stale = {});
  // The first half of commit(): the journal only (for tests of the kill points between the two halves).
  void write_journal(const std::vector<std::string>& stale = {});

 private:
  void remove_created_dir();
  std::string dir_, staging_;
  std::vector<std::string> names_;
  std::vector<std::string> created_;
  bool committed_ = false;
};

}  // namespace lidef
