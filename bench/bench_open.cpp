// Opening a model in the studio's engine: the time from open_model()
// to a resting session (solver precomputation + mesh matrices, the identity certified), per stage, three ways
// in one process: without the cache, the first time with an empty cache (computed and written), and reopened
// (read from the cache). Stage times come from the preparing frames (InteractiveSession publishes one per
// chunk of work with the stage's name), so they are the times a user watches on the progress bar. The session
// writes a computed cache entry in the background while it rests: the table says when that was done.
//
// Usage: bench_open DATA_DIR [MODEL...] [--threads T] (models default: animal; a name is looked up in
// DATA_DIR/models, a path is used as it is). Markdown on stdout.
#include <omp.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "bench_util.h"
#include "lidef/analysis/interactive_session.h"
#include "lidef/blas_kernel.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/precompute_cache.h"

using namespace lidef;

namespace {

struct Timing {
  double load_s = 0;   // open_model(): reading and checking the files (caller's thread)
  double total_s = 0;  // open_model() until resting
  std::vector<std::pair<std::string, double>> stages;  // in order, seconds
  double cpu_s = 0;  // process CPU time (all threads) of the whole opening: meaningful on a loaded machine
  bool certified = false;
  double stored_s = 0;      // resting until the background cache write was done
  double cpu_stored_s = 0;  // process CPU time until then
};

Timing open_once(const std::string& model_dir, const std::string& cache_dir, const DeformParams& p) {
  std::mutex m;
  std::vector<std::pair<std::string, Clock::time_point>> marks;
  InteractiveSession s(
      [&](std::shared_ptr<const SessionFrame> f) {
        if (f->state != SessionState::kPreparing) return;
        std::lock_guard<std::mutex> lk(m);
        if (marks.empty() || marks.back().first != f->stage) marks.emplace_back(f->stage, Clock::now());
      },
      [](const std::string& e) { std::fprintf(stderr, "bench_open: %s\n", e.c_str()); });
  s.set_cache(cache_dir);
  Timing t;
  const auto t0 = Clock::now();
  const double c0 = bench::cpu_ms();
  s.open_model(model_dir, p);
  const auto t1 = Clock::now();
  if (!s.wait_until_resting(3600)) std::fprintf(stderr, "bench_open: %s did not finish\n", model_dir.c_str());
  const auto t2 = Clock::now();
  t.cpu_s = (bench::cpu_ms() - c0) / 1e3;
  t.load_s = std::chrono::duration<double>(t1 - t0).count();
  t.total_s = std::chrono::duration<double>(t2 - t0).count();
  for (size_t i = 0; i < marks.size(); ++i) {
    const auto end = i + 1 < marks.size() ? marks[i + 1].second : t2;
    t.stages.emplace_back(marks[i].first, std::chrono::duration<double>(end - marks[i].second).count());
  }
  t.certified = s.latest_frame() && s.latest_frame()->certified;
  // The cache entry the session writes in the background while it rests: the time from resting until it is
  // written, and the CPU time of the whole opening with it.
  s.wait_for_cache_store();
  t.stored_s = seconds_since(t2);
  t.cpu_stored_s = (bench::cpu_ms() - c0) / 1e3;
  return t;
}

std::string stages_text(const Timing& t) {
  std::string s;
  for (const auto& [name, sec] : t.stages)
    if (sec >= 0.05) s += (s.empty() ? "" : ", ") + name + " " + bench::fixed(sec, 1);
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  std::string data;
  std::vector<std::string> models;
  DeformParams p;
  CLI::App app{
      "bench_open: opening a model in the studio's engine (preprocessing to a resting session) "
      "without the cache, the first time with an empty cache and reopened; a markdown table on stdout"};
  app.option_defaults()->always_capture_default();
  app.add_option("DATA_DIR", data, "shared data folder (its models/ folder)")->required();
  app.add_option("MODEL", models,
                 "model names (looked up in DATA_DIR/models) or model folders (default: animal)");
  app.add_option("--threads", p.threads, "DeformParams::threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  if (models.empty()) models = {"animal"};
  const std::string cache = (std::filesystem::temp_directory_path() / "lidef-bench-open-cache").string();
  std::printf("- machine: %s; nproc %d; OpenMP threads %d\n", bench::cpu_model().c_str(), omp_get_num_procs(),
              p.threads > 0 ? p.threads : omp_get_num_procs());
  std::printf("- load average at start: %s\n", bench::load_average().c_str());
  std::printf(
      "- parameters: defaults (%d DOF per coordinate, %d samples); cache folder %s (emptied first)\n\n",
      p.reduced_dof, p.samples, cache.c_str());
  std::printf(
      "| model | run | open (files) s | preprocessing to resting s | CPU s (all threads) | stages (wall s) | "
      "certified | background write done, s after resting | CPU s with it |\n");
  std::printf("|---|---|---:|---:|---:|---|---|---:|---:|\n");
  for (const std::string& name : models) {
    const std::string dir = std::filesystem::is_directory(name) ? name : data + "/models/" + name;
    std::filesystem::remove_all(cache);
    const std::pair<const char*, std::string> runs[] = {
        {"no cache", ""}, {"first time (empty cache)", cache}, {"reopened (cache)", cache}};
    for (const auto& [label, dir_cache] : runs) {
      const Timing t = open_once(dir, dir_cache, p);
      std::printf("| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", name.c_str(), label,
                  bench::fixed(t.load_s, 2).c_str(), bench::fixed(t.total_s - t.load_s, 1).c_str(),
                  bench::fixed(t.cpu_s, 1).c_str(), stages_text(t).c_str(), t.certified ? "yes" : "NO",
                  bench::fixed(t.stored_s, 1).c_str(), bench::fixed(t.cpu_stored_s, 1).c_str());
      std::fflush(stdout);
    }
    const CacheUsage u = PrecomputeCache(cache).usage();
    std::string files;  // per entry: which stage's data takes the space
    for (const auto& f : std::filesystem::directory_iterator(cache))
      files += (files.empty() ? "" : ", ") + f.path().filename().string().substr(0, 8) + " " +
               bench::fixed(static_cast<double>(f.file_size()) / 1e6, 1) + " MB";
    std::printf("| %s | cache size | | | | %s (%s) | | | |\n", name.c_str(), describe(u).c_str(),
                files.c_str());
  }
  std::filesystem::remove_all(cache);
  std::printf("\n- load average at end: %s\n", bench::load_average().c_str());
  return 0;
}
