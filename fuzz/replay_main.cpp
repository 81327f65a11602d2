// A main() for the fuzz targets without libFuzzer: replays every file named on the command line (folders are
// walked, sorted) through LLVMFuzzerTestOneInput once; -v prints each reader's verdict. The normal build runs
// it on fuzz/regressions/<target>/ and fuzz/corpus/<target>/ in `make test`, so every finding stays fixed
// with any compiler; under `make check-sanitize` the same replays run with ASan + UBSan.
//
// --mutate N [--seed S]: after the replay, N mutants spread over the inputs (round robin), each input's bytes
// changed by 1–4 random edits of the kinds that found this project's bugs (bit flips, "interesting" bytes and
// numbers such as 1e999 or 4294967295, deleted, duplicated and truncated ranges). The generator is seeded
// from S and the input's file name only, so a run is reproducible: the same inputs and N give the same
// mutants on every machine and compiler (no coverage feedback, unlike libFuzzer). This is the deterministic
// fuzzing that CI runs under ASan + UBSan (`make check-sanitize-ci`). Each mutant is written to
// DIR/replay-crash-<name> (--keep DIR, default "."; --name, default "replay") before it runs and removed at the
// end, so a crash or hang leaves the failing input behind, to be kept under fuzz/regressions/. A mutant that
// takes longer than --max-seconds (default 5) fails the run the same way.
#include <algorithm>
#include <chrono>
#include <cctype>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

using Bytes = std::vector<char>;

// FNV-1a of the file name: the per-input part of the mutation seed (not of the path, so a clone elsewhere
// gets the same mutants).
std::uint64_t name_hash(const std::string& s) {
  std::uint64_t h = 1469598103934665603ULL;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ULL;
  return h;
}

// One mutant of `in`: 1–4 edits.
Bytes mutate(const Bytes& in, std::mt19937_64& rng) {
  static const char* const kTokens[] = {"1e999", "-1",   "nan", "inf",     "4294967295", "99999999999999999999",
                                        "0",     "-0.0", "\n",  " ",       "#",          "\"",
                                        ",",     "{",    "}",   "[",       "]",          "1e-320",
                                        "f",     "v",    "3",   "end_header\n", "null", "2147483648"};
  static const char kBytes[] = {'\0', '\n', ' ', '-', '.', 'e', '9', '\xff', '\x80', '/', ':', '"'};
  Bytes b = in;
  auto pick = [&](std::size_t n) { return n ? static_cast<std::size_t>(rng() % n) : 0; };
  const int edits = 1 + static_cast<int>(rng() % 4);
  for (int e = 0; e < edits; ++e) {
    switch (rng() % 7) {
      case 0:  // flip one bit
        if (!b.empty()) b[pick(b.size())] ^= static_cast<char>(1u << (rng() % 8));
        break;
      case 1:  // an interesting byte
        if (!b.empty()) b[pick(b.size())] = kBytes[pick(sizeof kBytes)];
        break;
      case 2: {  // insert a token
        const std::string t = kTokens[pick(sizeof kTokens / sizeof kTokens[0])];
        b.insert(b.begin() + static_cast<long>(pick(b.size() + 1)), t.begin(), t.end());
        break;
      }
      case 3: {  // replace a number-like run by a token
        if (b.empty()) break;
        std::size_t i = pick(b.size()), j = i;
        while (j < b.size() && (std::isdigit(static_cast<unsigned char>(b[j])) || b[j] == '.' || b[j] == '-')) ++j;
        const std::string t = kTokens[pick(6)];
        b.erase(b.begin() + static_cast<long>(i), b.begin() + static_cast<long>(j));
        b.insert(b.begin() + static_cast<long>(i), t.begin(), t.end());
        break;
      }
      case 4: {  // delete a range
        if (b.empty()) break;
        const std::size_t i = pick(b.size()), n = 1 + pick(std::min<std::size_t>(64, b.size() - i));
        b.erase(b.begin() + static_cast<long>(i), b.begin() + static_cast<long>(std::min(b.size(), i + n)));
        break;
      }
      case 5: {  // duplicate a range
        if (b.empty() || b.size() > (1u << 20)) break;
        const std::size_t i = pick(b.size()), n = 1 + pick(std::min<std::size_t>(256, b.size() - i));
        const Bytes chunk(b.begin() + static_cast<long>(i), b.begin() + static_cast<long>(i + n));
        b.insert(b.begin() + static_cast<long>(pick(b.size() + 1)), chunk.begin(), chunk.end());
        break;
      }
      default:  // truncate
        b.resize(pick(b.size() + 1));
    }
  }
  return b;
}

void run(const Bytes& bytes) {
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
}

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  long mutants = 0;
  std::uint64_t seed = 1;
  fs::path keep = ".";
  std::string target = "replay";
  double max_seconds = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-v") {
      lidef_fuzz::verbose = true;
    } else if ((a == "--mutate" || a == "--seed" || a == "--keep" || a == "--name" || a == "--max-seconds") && i + 1 < argc) {
      const std::string v = argv[++i];
      if (a == "--mutate") mutants = std::stol(v);
      if (a == "--seed") seed = std::stoull(v);
      if (a == "--keep") keep = v;
      if (a == "--name") target = v;
      if (a == "--max-seconds") max_seconds = std::stod(v);
    } else if (fs::is_directory(a)) {
      for (const auto& e : fs::recursive_directory_iterator(a))
        if (e.is_regular_file()) files.push_back(e.path());
    } else if (fs::is_regular_file(a)) {
      files.push_back(a);
    } else {
      std::fprintf(stderr, "replay: %s: no such file or folder\n", argv[i]);
      return 2;
    }
  }
  std::sort(files.begin(), files.end());
  std::vector<Bytes> inputs;
  for (const fs::path& f : files) {
    std::ifstream in(f, std::ios::binary);
    Bytes bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in.eof() && in.fail()) {
      std::fprintf(stderr, "replay: cannot read %s\n", f.c_str());
      return 2;
    }
    std::fprintf(stderr, "replay: %s (%zu bytes)\n", f.c_str(), bytes.size());
    run(bytes);
    inputs.push_back(std::move(bytes));
  }
  std::printf("replay: %zu inputs, no finding\n", files.size());
  if (mutants > 0 && !inputs.empty()) {
    std::vector<std::mt19937_64> rngs;
    for (const fs::path& f : files) rngs.emplace_back(seed ^ name_hash(f.filename().string()));
    // The mutant about to run is written first: a crash leaves it behind (removed when it passes).
    const fs::path pending = keep / ("replay-crash-" + target);
    for (long k = 0; k < mutants; ++k) {
      const std::size_t i = static_cast<std::size_t>(k) % inputs.size();
      const Bytes m = mutate(inputs[i], rngs[i]);
      {
        std::ofstream out(pending, std::ios::binary | std::ios::trunc);
        out.write(m.data(), static_cast<std::streamsize>(m.size()));
      }
      const auto t0 = std::chrono::steady_clock::now();
      run(m);
      const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (sec > max_seconds) {  // as `make fuzz` judges: an input this slow is a finding (left in `pending`)
        std::fprintf(stderr, "replay: mutant %ld of %s took %.1f s (limit %.1f s): kept as %s\n", k,
                     files[i].c_str(), sec, max_seconds, pending.c_str());
        return 1;
      }
    }
    std::error_code ec;
    fs::remove(pending, ec);
    std::printf("replay: %ld mutants (seed %llu), no finding\n", mutants, static_cast<unsigned long long>(seed));
  }
  return 0;
}
