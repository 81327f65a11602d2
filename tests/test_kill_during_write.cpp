// Killed runs leave no partial file a later run would trust: `lidef deform` killed
// (SIGKILL) at several moments while it writes into a folder that holds a previous result, its commit stopped
// after every one of its file operations, the subspace cache killed while it is first filled or corrupted by
// hand, and `lidef cage --out` killed mid-run.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "lidef/analysis/certificate_report.h"
#include "lidef/staged_outputs.h"
#include "test_cli_outputs.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;
using lidef::test::dir_entries;
using lidef::test::read_text;
using lidef::test::run_lidef_cli;
using lidef::test::shell_quote;
using lidef::test::TempDir;
using lidef::test::write_text;
using Files = std::map<std::string, std::string>;

// What a killed run may leave behind under a name no reader opens (deform/include/lidef/staged_outputs.h,
// lidef/atomic_file.h).
bool is_leftover(const std::string& name) {
  return name.rfind(".lidef-staging-", 0) == 0 || name.find(".tmp.") != std::string::npos;
}

// The files of `dir` at final names (not leftovers, not the journal of an interrupted commit), name -> bytes.
Files final_files(const std::string& dir) {
  Files f;
  for (const std::string& n : dir_entries(dir))
    if (!is_leftover(n) && n != lidef::kCommitJournal) f[n] = read_text((fs::path(dir) / n).string());
  return f;
}
bool commit_interrupted(const std::string& dir) {
  return fs::exists(fs::path(dir) / lidef::kCommitJournal);
}
std::vector<std::string> leftovers(const std::string& dir) {
  std::vector<std::string> l;
  for (const std::string& n : dir_entries(dir))
    if (is_leftover(n)) l.push_back(n);
  return l;
}

// Starts `lidef ARGS` (output to /dev/null). Once `when()` holds (polled every millisecond) it waits `after`
// seconds and sends SIGKILL, unless the process ended before; `when` that never holds lets it finish.
// Returns true when it was killed, false when it had exited by itself.
bool run_and_kill(const std::vector<std::string>& args, const std::function<bool()>& when, double after = 0) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 1);
    ::dup2(null, 2);
    std::vector<char*> argv;
    const std::string cli = lidef::test::cli();
    argv.push_back(const_cast<char*>(cli.c_str()));
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(cli.c_str(), argv.data());
    ::_exit(127);
  }
  EXPECT_GT(pid, 0);
  using Clock = std::chrono::steady_clock;
  const auto give_up = Clock::now() + std::chrono::seconds(60);
  std::optional<Clock::time_point> kill_at;
  int status = 0;
  while (!kill_at || Clock::now() < *kill_at) {
    if (::waitpid(pid, &status, WNOHANG) == pid) return false;
    if (!kill_at && when())
      kill_at =
          Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(after));
    if (Clock::now() > give_up) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  return WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
}
// `when` for run_and_kill: `seconds` after now.
std::function<bool()> elapsed(double seconds) {
  const auto end =
      std::chrono::steady_clock::now() +
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
  return [end] { return std::chrono::steady_clock::now() >= end; };
}
// `when` for run_and_kill: a staging folder has appeared in `dir` (the run is writing its outputs).
std::function<bool()> staging_in(const std::string& dir) {
  return [dir] {
    for (const std::string& n : dir_entries(dir))
      if (n.rfind(".lidef-staging-", 0) == 0) return true;
    return false;
  };
}
// `when` for run_and_kill: `path` exists.
std::function<bool()> exists(const std::string& path) {
  return [path] { return fs::exists(path); };
}

std::string beam_bend() {
  return lidef::test::project_data() + "/scenarios/beam_bend.json";
}

std::vector<std::string> deform_args(const std::string& out, const std::string& cache,
                                     const std::vector<std::string>& extra = {}) {
  std::vector<std::string> a = {"deform",    beam_bend(), "--out",         out, "--cache-dir", cache,
                                "--samples", "4000",      "--reduced-dof", "60"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}
std::string joined(const std::vector<std::string>& args) {
  std::string s;
  for (const std::string& a : args) s += shell_quote(a) + " ";
  return s;
}

TEST(KillDuringWrite, DeformLeavesThePreviousOrTheNewResultNeverAMixture) {
  TempDir tmp;
  const std::string cache = tmp / "cache";
  std::string output;
  // The previous result (2 iterations: every file differs from the full run's).
  const std::string previous = tmp / "previous";
  ASSERT_EQ(run_lidef_cli(joined(deform_args(previous, cache, {"--max-iterations", "2"})), &output), 1)
      << output;
  // cage.obj is the model's cage, the same bytes in every run: it cannot tell an old result from a new one,
  // so the comparisons below leave it out (its presence is checked).
  auto without_cage = [](Files f) {
    EXPECT_EQ(f.erase("cage.obj"), 1u);
    return f;
  };
  const Files old = without_cage(final_files(previous));
  ASSERT_EQ(old.size(), 9u);
  Files ref;  // the full run's result, from the first case (not killed)

  struct Kill {
    std::string label;
    std::function<std::function<bool()>(const std::string& out)> when;
    double after;
  };
  const std::vector<Kill> kills = {
      {"not killed", [](const std::string&) { return [] { return false; }; }, 0},
      {"after 0.2 s (preprocessing)", [](const std::string&) { return elapsed(0.2); }, 0},
      {"after 0.5 s (solving)", [](const std::string&) { return elapsed(0.5); }, 0},
      {"as soon as the staging folder appears", staging_in, 0},
      {"5 ms after the staging folder appears", staging_in, 0.005},
      {"20 ms after the staging folder appears", staging_in, 0.02},
      {"60 ms after the staging folder appears", staging_in, 0.06},
  };
  std::string rerun_in;
  int i = 0;
  for (const Kill& k : kills) {
    SCOPED_TRACE(k.label);
    const std::string out = tmp / ("out_" + std::to_string(i++));
    fs::copy(previous, out);
    const bool killed = run_and_kill(deform_args(out, cache, {"--quiet"}), k.when(out), k.after);
    // Killed between two of the commit's renames: the journal is there, and finishing it gives the new set
    // (every kill point of a commit is walked through below).
    const bool interrupted = commit_interrupted(out);
    if (interrupted) {
      EXPECT_TRUE(lidef::finish_interrupted_commit(out));
    }
    const Files now = without_cage(final_files(out));
    if (ref.empty()) {
      ASSERT_FALSE(killed);
      ref = now;
      for (const auto& [name, bytes] : old) ASSERT_NE(bytes, ref[name]) << name;
    }
    ASSERT_EQ(now.size(), old.size());
    int same_as_old = 0;
    for (const auto& [name, bytes] : now) {
      ASSERT_TRUE(old.count(name)) << "unexpected file " << name;
      same_as_old += bytes == old.at(name);
    }
    // All previous files intact, or the new complete set: never a mixture.
    EXPECT_TRUE(same_as_old == 0 || same_as_old == static_cast<int>(old.size()))
        << same_as_old << " files old";
    if (same_as_old == 0) {  // the new set (summary.json holds timings; the map is deterministic)
      EXPECT_EQ(now.at("coefficients.txt"), ref.at("coefficients.txt"));
      EXPECT_EQ(now.at("certificate.json"), ref.at("certificate.json"));
    }
    if (!killed) {
      EXPECT_EQ(same_as_old, 0) << "the run finished but its result is not there";
    }
    std::printf("  deform %s: %s, %zu leftover(s)\n", k.label.c_str(),
                !killed            ? "had finished, new result"
                : interrupted      ? "commit interrupted, finished: new result"
                : same_as_old == 0 ? "new result"
                                   : "previous result intact",
                leftovers(out).size());
    if (rerun_in.empty() && !leftovers(out).empty()) rerun_in = out;
  }
  // A rerun into a folder with leftovers succeeds, writes the new result and leaves no leftover of its own.
  if (rerun_in.empty()) rerun_in = tmp / "out_3";
  const std::vector<std::string> before = leftovers(rerun_in);
  ASSERT_EQ(run_lidef_cli(joined(deform_args(rerun_in, cache, {"--quiet"})), &output), 0) << output;
  EXPECT_EQ(final_files(rerun_in).at("coefficients.txt"), ref.at("coefficients.txt"));
  for (const std::string& l : leftovers(rerun_in))
    EXPECT_NE(std::find(before.begin(), before.end(), l), before.end()) << "the rerun left " << l;

  // Every kill point of a commit, without timing: the full run's files staged over the previous result, the
  // journal written, then the commit stopped after 0, 1, 2, ... of its file operations (a copy of the folder
  // per point, made while the staging object is alive, as a kill leaves it).
  const Files old_all = final_files(previous), new_all = final_files(tmp / "out_0");
  const std::string prepared = tmp / "prepared";
  fs::copy(previous, prepared);
  std::vector<std::string> points;
  {
    lidef::StagedOutputs staged(prepared);
    for (const auto& [name, bytes] : new_all) write_text(staged.path(name), bytes);
    staged.write_journal({"field.vti"});
    for (int k = 0; k < 20; ++k) {
      points.push_back(tmp / ("point_" + std::to_string(k)));
      fs::copy(prepared, points.back(), fs::copy_options::recursive);
    }
  }
  int complete_at = -1;
  for (int k = 0; k < static_cast<int>(points.size()) && complete_at < 0; ++k) {
    SCOPED_TRACE("commit stopped after " + std::to_string(k) + " file operations");
    const std::string dir = points[k];
    EXPECT_TRUE(lidef::finish_interrupted_commit(dir, k));
    if (!commit_interrupted(dir)) complete_at = k;
    // A describing output present vouches for its run: every other file is of the same run.
    const Files now = final_files(dir);
    for (const char* d : lidef::kDescribingOutputs) {
      if (!now.count(d)) continue;
      const Files& run = now.at(d) == new_all.at(d) ? new_all : old_all;
      EXPECT_TRUE(now.at(d) == run.at(d)) << d << " of neither run";
      for (const auto& [name, bytes] : now) EXPECT_EQ(bytes, run.at(name)) << name << " beside " << d;
    }
    // Finished by a reader of its certificate, a writer into the folder, or directly.
    if (k % 3 == 0) {
      EXPECT_NO_THROW(lidef::read_certificate_json(dir + "/certificate.json"));
    } else if (k % 3 == 1) {
      const lidef::StagedOutputs next(dir);
    } else {
      lidef::finish_interrupted_commit(dir);
    }
    EXPECT_FALSE(commit_interrupted(dir));
    EXPECT_TRUE(final_files(dir) == new_all) << "not the new result after finishing";
    EXPECT_TRUE(leftovers(dir).empty()) << ::testing::PrintToString(leftovers(dir));
  }
  // 2 withdrawals, 8 moves, 2 publications, then the journal's removal: the 13th operation completes it.
  EXPECT_EQ(complete_at, 13);
}

TEST(KillDuringWrite, AJournalThatCannotBeFinishedIsAnErrorNamingIt) {
  TempDir tmp;
  auto expect_error = [](const std::string& dir, const std::string& what) {
    try {
      lidef::finish_interrupted_commit(dir);
      ADD_FAILURE() << "no error for " << what;
    } catch (const lidef::InputError& e) {
      EXPECT_EQ(e.file(), dir + "/" + lidef::kCommitJournal) << what;
      EXPECT_NE(e.message().find(what), std::string::npos) << e.message();
    }
    EXPECT_THROW(lidef::StagedOutputs next(dir), lidef::InputError);
    EXPECT_TRUE(commit_interrupted(dir)) << "the journal must stay";
  };
  const std::string garbled = tmp / "garbled";
  fs::create_directories(garbled);
  write_text(garbled + "/" + lidef::kCommitJournal, "lidef-commit 1\nstaging .lidef-staging-x\nmove ../a\n");
  expect_error(garbled, "not a valid journal");
  const std::string gone = tmp / "gone";
  fs::create_directories(gone);
  write_text(gone + "/coefficients.txt", "old");
  write_text(gone + "/" + lidef::kCommitJournal,
             "lidef-commit 1\nstaging .lidef-staging-x\nmove coefficients.txt\n");
  expect_error(gone, "is gone");
  // Without a journal there is nothing to finish.
  EXPECT_FALSE(lidef::finish_interrupted_commit(tmp / "garbled_not"));

  // A move that fails (a folder in the way) is an error naming the target; the staged file and the journal
  // stay, so the commit finishes once the obstacle is gone.
  const std::string blocked = tmp / "blocked";
  fs::create_directories(blocked + "/coefficients.txt/inside");
  {
    lidef::StagedOutputs staged(blocked);
    write_text(staged.path("coefficients.txt"), "new");
    staged.write_journal();
    try {
      lidef::finish_interrupted_commit(blocked);
      ADD_FAILURE() << "no error for a folder in the way";
    } catch (const lidef::InputError& e) {
      EXPECT_EQ(e.file(), blocked + "/coefficients.txt");
    }
    EXPECT_TRUE(fs::exists(staged.staging_dir() + "/coefficients.txt")) << "the staged file was lost";
    EXPECT_TRUE(commit_interrupted(blocked));
    fs::remove_all(blocked + "/coefficients.txt");
    EXPECT_TRUE(lidef::finish_interrupted_commit(blocked));
  }
  EXPECT_EQ(read_text(blocked + "/coefficients.txt"), "new");
  EXPECT_FALSE(commit_interrupted(blocked));
  EXPECT_TRUE(leftovers(blocked).empty());
}

// The subspace line of a deform log says where the subspace came from: "(cache, ..." or "(dense, ...".
bool subspace_from_cache(const std::string& log) {
  const size_t p = log.find("subspace:");
  EXPECT_NE(p, std::string::npos) << log;
  return p != std::string::npos && log.substr(p, log.find('\n', p) - p).find("(cache,") != std::string::npos;
}

TEST(KillDuringWrite, SubspaceCacheIsValidOrRebuiltNeverTrustedWhenCorrupt) {
  TempDir tmp;
  std::string output;
  const std::vector<std::string> one = {"--max-iterations", "1"};
  // The reference cache file.
  const std::string ref_cache = tmp / "ref_cache";
  ASSERT_NE(run_lidef_cli(joined(deform_args(tmp / "o_ref", ref_cache, one)), &output), 2) << output;
  const Files ref = final_files(ref_cache);
  // The subspace and the solver's precomputation entry (precompute_cache.h); the corruptions below are of the
  // subspace file (the entry's own are in test_precompute_cache.cpp).
  ASSERT_EQ(ref.size(), 2u);
  std::string name;
  for (const auto& [n, b] : ref)
    if (n.rfind("subspace-", 0) == 0) name = n;
  ASSERT_FALSE(name.empty());
  const std::string bytes = ref.at(name);

  // Killed while the cache is first filled (empty --cache-dir), then rerun.
  for (const double t : {0.05, 0.15, 0.4}) {
    SCOPED_TRACE("killed after " + std::to_string(t) + " s");
    const std::string cache = tmp / ("cache_" + std::to_string(static_cast<int>(t * 100)));
    fs::create_directories(cache);
    run_and_kill(deform_args(tmp / "o_killed", cache, one), elapsed(t));
    const Files now = final_files(cache);
    for (const auto& [n, b] : now) {
      ASSERT_EQ(ref.count(n), 1u) << n;
      EXPECT_EQ(b, ref.at(n)) << "a partial cache file at the final name";
    }
    ASSERT_NE(
        run_lidef_cli(joined(deform_args(tmp / ("o_rerun" + cache.substr(cache.size() - 2)), cache, one)),
                      &output),
        2)
        << output;
    EXPECT_EQ(subspace_from_cache(output), now.count(name) > 0) << output;
    EXPECT_EQ(final_files(cache), ref);
  }

  // A corrupted cache file (written by hand) is detected and rebuilt, not trusted.
  std::string flipped_payload = bytes, flipped_header = bytes;
  flipped_payload[bytes.size() / 2] ^= 0x10;
  flipped_header[20] ^= 0x01;
  const std::vector<std::pair<std::string, std::string>> corrupt = {
      {"truncated", bytes.substr(0, bytes.size() / 2)},
      {"flipped_payload_byte", flipped_payload},
      {"flipped_header_byte", flipped_header},
  };
  for (const auto& [what, text] : corrupt) {
    SCOPED_TRACE(what);
    const std::string cache = tmp / ("corrupt_" + what);
    fs::create_directories(cache);
    write_text(cache + "/" + name, text);
    ASSERT_NE(run_lidef_cli(joined(deform_args(tmp / ("o_" + what), cache, one)), &output), 2) << output;
    EXPECT_FALSE(subspace_from_cache(output)) << output;
    EXPECT_EQ(final_files(cache), ref) << "not rebuilt";
  }
}

TEST(KillDuringWrite, CageOutNeverLeavesAHalfModelFolder) {
  TempDir tmp;
  const std::string mesh = lidef::test::project_data() + "/models/ball/mesh.obj";
  const std::vector<std::string> model = {"cage.obj", "mesh.obj", "model.json"};
  for (const double t : {0.1, 0.5, 1.5, -1.0}) {
    SCOPED_TRACE(t < 0 ? "killed when the folder appears" : "killed after " + std::to_string(t) + " s");
    const std::string out = tmp / ("model_" + std::to_string(static_cast<int>(t * 10)));
    run_and_kill({"cage", mesh, "--out", out, "--faces", "100", "--quiet"}, t < 0 ? exists(out) : elapsed(t));
    // Nothing, or the complete model (with at most a staging folder left by a kill during the move); a kill
    // between the renames left a journal, which the next reader of the model (`lidef check`) finishes.
    if (commit_interrupted(out)) {
      std::string check;
      EXPECT_EQ(run_lidef_cli("check " + shell_quote(out), &check), 0) << check;
      EXPECT_FALSE(commit_interrupted(out));
    }
    std::vector<std::string> finals;
    for (const std::string& n : dir_entries(out))
      if (!is_leftover(n)) finals.push_back(n);
    EXPECT_TRUE(finals.empty() || finals == model) << ::testing::PrintToString(dir_entries(out));
    if (finals.empty() && !dir_entries(out).empty()) {
      // A rerun into what the killed run left succeeds (no --force needed for leftovers alone).
      std::string output;
      EXPECT_EQ(run_lidef_cli(joined({"cage", mesh, "--out", out, "--faces", "100", "--quiet"}), &output), 0)
          << output;
      EXPECT_EQ(final_files(out).size(), model.size());
    }
  }
  // The leftover of a kill between creating the staging folder and the move, made by hand: a rerun without
  // --force is not refused because of it.
  const std::string out = tmp / "staged_leftover";
  fs::create_directories(out + "/.lidef-staging-AbC123");
  write_text(out + "/.lidef-staging-AbC123/cage.obj", "v 0 0");
  std::string output;
  EXPECT_EQ(run_lidef_cli(joined({"cage", mesh, "--out", out, "--faces", "100", "--quiet"}), &output), 0)
      << output;
  EXPECT_EQ(final_files(out).size(), model.size());
  std::string check;
  EXPECT_EQ(run_lidef_cli("check " + shell_quote(out), &check), 0) << check;
}

}  // namespace
