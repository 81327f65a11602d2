#include "lidef/precompute_cache.h"

#include <omp.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <system_error>

#include "lidef/atomic_file.h"
#include "lidef/blas_kernel.h"
#include "lidef/domain_sampling.h"
#include "lidef/errors.h"
#include "lidef/hash.h"
#include "lidef/internal/stopwatch.h"

namespace lidef {
namespace fs = std::filesystem;

namespace {

constexpr char kMagic[8] = {'L', 'I', 'D', 'E', 'F', 'P', 'C', '\0'};
constexpr std::uint32_t kByteOrder = 0x01020304u;
constexpr std::size_t kBlock = std::size_t(1) << 20;

#pragma pack(push, 1)
struct Header {
  char magic[8];
  std::uint32_t version;
  std::uint32_t byte_order;
  char kind[24];  // zero-padded
  std::uint64_t key;
  std::uint64_t payload_bytes;
  std::uint64_t checksum;
};
#pragma pack(pop)

Header make_header(const CacheKey& key, std::uint64_t bytes, std::uint64_t checksum) {
  Header h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.version = kPrecomputeFormatVersion;
  h.byte_order = kByteOrder;
  std::memcpy(h.kind, key.kind().data(), std::min(key.kind().size(), sizeof h.kind - 1));
  h.key = key.value();
  h.payload_bytes = bytes;
  h.checksum = checksum;
  return h;
}

// The files the limit applies to: this cache's entries and the subspace cache's files (subspace.h).
bool counted(const fs::path& p) {
  const std::string name = p.filename().string();
  const auto ends = [&](const std::string& e) {
    return name.size() > e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0;
  };
  if (name.find(".tmp.") != std::string::npos) return false;  // another writer's temporary
  return ends(".lpc") || (name.rfind("subspace-", 0) == 0 && ends(".bin"));
}

struct FileInfo {
  fs::path path;
  std::uint64_t bytes;
  fs::file_time_type time;
};

std::vector<FileInfo> list_counted(const std::string& dir) {
  std::vector<FileInfo> out;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code e2;
    if (!it->is_regular_file(e2) || !counted(it->path())) continue;
    const auto size = it->file_size(e2);
    if (e2) continue;
    const auto t = it->last_write_time(e2);
    if (e2) continue;
    out.push_back({it->path(), size, t});
  }
  return out;
}

std::string megabytes(std::uint64_t b) {
  char s[32];
  std::snprintf(s, sizeof s, "%.1f MB", static_cast<double>(b) / 1e6);
  return s;
}

}  // namespace

std::uint64_t default_cache_max_bytes() {
  if (const char* v = std::getenv("LIDEF_CACHE_MAX_MB"); v && *v) {
    char* end = nullptr;
    const double mb = std::strtod(v, &end);
    if (end && *end == '\0' && mb >= 0) return static_cast<std::uint64_t>(mb * 1048576.0);
    throw InputError("LIDEF_CACHE_MAX_MB", std::string("'") + v + "' is not a number of MiB >= 0");
  }
  return std::uint64_t(4096) << 20;
}

CacheKey::CacheKey(const std::string& kind) : kind_(kind), h_(kFnv1a64Offset) {
  add(kPrecomputeFormatVersion);
  add(kind);
}

CacheKey& CacheKey::add_bytes(const void* data, std::size_t bytes) {
  const std::uint64_t n = bytes;
  h_ = fnv1a64(&n, sizeof n, h_);
  h_ = fnv1a64(data, bytes, h_);
  return *this;
}

CacheKey& CacheKey::add_numerics() {
  add(omp_get_max_threads()).add(std::string(__VERSION__)).add(blas_numerics());
  return add(EIGEN_WORLD_VERSION).add(EIGEN_MAJOR_VERSION).add(EIGEN_MINOR_VERSION);
}

std::uint64_t CacheWriter::bytes() const {
  std::uint64_t b = 0;
  for (const Span& s : spans_) b += s.bytes;
  return b;
}

void lower_calling_thread_priority() {
  // setpriority on a thread id changes that thread only (Linux; setpriority(2), NOTES). Nice 10, not
  // SCHED_IDLE: an idle-class thread gets ~0.3% of a core when other processes keep the cores busy (ctest
  // -j2), and the solver's destructor waits for this write.
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10);
}

namespace {
// The checksum of one block, fed in pieces: four independent lanes over 8-byte words (one thread: 5.4 GB/s
// against 0.83 for FNV-1a's byte-serial chain, which took ~0.9 s for the animal's 781 MB of entries), the
// piece boundaries not mattering (a carry of up to 32 bytes), the lanes and the tail folded with FNV-1a 64 at
// the end.
class BlockChecksum {
 public:
  void feed(const unsigned char* p, std::size_t n) {
    bytes_ += n;
    while (n > 0 && fill_ > 0) {
      carry_[fill_++] = *p++;
      --n;
      if (fill_ == 32) {
        mix(carry_);
        fill_ = 0;
      }
    }
    for (; n >= 32; p += 32, n -= 32) mix(p);
    for (; n > 0; --n) carry_[fill_++] = *p++;
  }
  std::uint64_t finish() const {
    std::uint64_t h = fnv1a64(lane_, sizeof lane_);
    h = fnv1a64(carry_, fill_, h);
    return fnv1a64(&bytes_, sizeof bytes_, h);
  }

 private:
  void mix(const unsigned char* p) {
    for (int k = 0; k < 4; ++k) {
      std::uint64_t w;
      std::memcpy(&w, p + 8 * k, 8);
      std::uint64_t x = (lane_[k] ^ w) * 0x100000001b3ULL;  // the FNV prime
      lane_[k] = x ^ (x >> 29);  // a multiply only carries upwards: fold the high bits back down
    }
  }
  std::uint64_t lane_[4] = {kFnv1a64Offset, kFnv1a64Offset ^ 1, kFnv1a64Offset ^ 2, kFnv1a64Offset ^ 3};
  unsigned char carry_[32] = {};
  std::size_t fill_ = 0;
  std::uint64_t bytes_ = 0;
};
}  // namespace

std::uint64_t payload_checksum(const std::vector<const void*>& data, const std::vector<std::size_t>& bytes) {
  // Blocks of the concatenation, so the result does not depend on how the payload is split into arrays.
  struct Piece {
    std::size_t span, offset, bytes;
  };
  std::vector<Piece> pieces;
  std::vector<std::size_t> block_of_piece;
  std::size_t block = 0, fill = 0;
  for (std::size_t k = 0; k < data.size(); ++k)
    for (std::size_t off = 0; off < bytes[k];) {
      const std::size_t take = std::min(bytes[k] - off, kBlock - fill);
      pieces.push_back({k, off, take});
      block_of_piece.push_back(block);
      off += take;
      fill += take;
      if (fill == kBlock) {
        ++block;
        fill = 0;
      }
    }
  const std::size_t blocks = block + (fill > 0 ? 1 : 0);
  std::vector<std::uint64_t> h(blocks, 0);
  // Pieces of one block are consecutive; each thread takes whole blocks.
  std::vector<std::size_t> first(blocks + 1, pieces.size());
  for (std::size_t i = pieces.size(); i-- > 0;) first[block_of_piece[i]] = i;
#pragma omp parallel for schedule(static)
  for (long b = 0; b < static_cast<long>(blocks); ++b) {
    BlockChecksum c;
    for (std::size_t i = first[b]; i < first[b + 1]; ++i) {
      const Piece& p = pieces[i];
      c.feed(static_cast<const unsigned char*>(data[p.span]) + p.offset, p.bytes);
    }
    h[b] = c.finish();
  }
  const std::uint64_t total = std::accumulate(bytes.begin(), bytes.end(), std::uint64_t(0));
  return fnv1a64(h.data(), sizeof(std::uint64_t) * h.size(), fnv1a64(&total, sizeof total));
}

PrecomputeCache::PrecomputeCache(std::string dir, std::uint64_t max_bytes)
    : dir_(std::move(dir)), max_bytes_(max_bytes) {}

std::string PrecomputeCache::path(const CacheKey& key) const {
  return (fs::path(dir_) / (key.kind() + "-" + hex64(key.value()) + ".lpc")).string();
}

bool PrecomputeCache::load(const CacheKey& key, std::vector<char>& payload, CacheEvent* event) const {
  CacheEvent ev;
  ev.kind = key.kind();
  const auto t0 = Clock::now();
  const auto done = [&](bool ok, const std::string& outcome) {
    ev.outcome = outcome;
    ev.ms = ms_since(t0);
    if (event) *event = ev;
    return ok;
  };
  if (!enabled()) return done(false, "disabled");
  const std::string p = path(key);
  std::ifstream in(p, std::ios::binary);
  if (!in) return done(false, "miss");
  // Any way the file fails to check out: remove it so that the rebuilt entry replaces it.
  const auto bad = [&](const std::string& why) {
    in.close();
    std::error_code ec;
    fs::remove(p, ec);
    return done(false, "rebuilt (" + why + ")");
  };
  Header h{};
  if (!in.read(reinterpret_cast<char*>(&h), sizeof h)) return bad("truncated header");
  if (std::memcmp(h.magic, kMagic, sizeof kMagic) != 0) return bad("not a cache entry");
  if (h.version != kPrecomputeFormatVersion) return bad("format version " + std::to_string(h.version));
  if (h.byte_order != kByteOrder) return bad("other byte order");
  const Header want = make_header(key, h.payload_bytes, h.checksum);
  if (std::memcmp(h.kind, want.kind, sizeof h.kind) != 0 || h.key != key.value()) return bad("other key");
  std::error_code ec;
  const auto size = fs::file_size(p, ec);
  if (ec || size != sizeof(Header) + h.payload_bytes) return bad("wrong length");
  payload.resize(static_cast<std::size_t>(h.payload_bytes));
  if (!in.read(payload.data(), static_cast<std::streamsize>(payload.size()))) return bad("truncated payload");
  if (payload_checksum({payload.data()}, {payload.size()}) != h.checksum) {
    payload.clear();
    return bad("checksum mismatch");
  }
  fs::last_write_time(p, fs::file_time_type::clock::now(), ec);  // least recently *used*
  ev.bytes = payload.size();
  return done(true, "hit");
}

void PrecomputeCache::store(const CacheKey& key, const CacheWriter& w, CacheEvent* event) const {
  CacheEvent ev;
  ev.kind = key.kind();
  ev.bytes = w.bytes();
  const auto t0 = Clock::now();
  const auto done = [&](const std::string& outcome) {
    ev.outcome = outcome;
    ev.ms = ms_since(t0);
    if (event) *event = ev;
  };
  if (!enabled()) return done("disabled");
  if (sizeof(Header) + ev.bytes > max_bytes_)
    return done("not stored (" + megabytes(ev.bytes) + " is over the limit of " + megabytes(max_bytes_) +
                ")");
  try {
    ensure_directory(dir_);
    std::vector<const void*> data;
    std::vector<std::size_t> bytes;
    for (const auto& s : w.spans_) {
      data.push_back(w.span_data(s));
      bytes.push_back(s.bytes);
    }
    const Header h = make_header(key, ev.bytes, payload_checksum(data, bytes));
    const std::string p = path(key);
    write_file_atomic(p, [&](std::ostream& out) {
      out.write(reinterpret_cast<const char*>(&h), sizeof h);
      for (std::size_t k = 0; k < data.size(); ++k)
        out.write(static_cast<const char*>(data[k]), static_cast<std::streamsize>(bytes[k]));
    });
    ev.evicted = evict(p);
    done("stored");
  } catch (const std::exception& e) {
    done(std::string("not stored (") + e.what() + ")");
  }
}

CacheUsage PrecomputeCache::usage() const {
  CacheUsage u;
  u.limit = max_bytes_;
  if (!enabled()) return u;
  for (const FileInfo& f : list_counted(dir_)) {
    ++u.entries;
    u.bytes += f.bytes;
  }
  return u;
}

long PrecomputeCache::evict(const std::string& keep) const {
  if (!enabled()) return 0;
  std::vector<FileInfo> files = list_counted(dir_);
  std::uint64_t total = 0;
  for (const FileInfo& f : files) total += f.bytes;
  // Oldest first; ties by name so that eviction is reproducible.
  std::sort(files.begin(), files.end(), [](const FileInfo& a, const FileInfo& b) {
    return a.time != b.time ? a.time < b.time : a.path < b.path;
  });
  long n = 0;
  std::error_code ec;
  const fs::path kept = keep.empty() ? fs::path() : fs::path(keep);
  for (const FileInfo& f : files) {
    if (total <= max_bytes_) break;
    if (!keep.empty() && fs::equivalent(f.path, kept, ec)) continue;
    if (fs::remove(f.path, ec)) {
      total -= f.bytes;
      ++n;
    }
  }
  return n;
}

void write_sampling(CacheWriter& w, const VoxelSampling& s) {
  w.matrix(s.centers);
  w.scalar(s.side);
  w.array(s.hessian_subset.data(), s.hessian_subset.size());
  w.matrix(s.origin);
  w.matrix(s.grid_index);
  w.scalar(s.safety);
  w.scalar(s.search_iterations);
  w.scalar(static_cast<char>(s.target_met));
  w.array(s.level.data(), s.level.size());
  w.array(s.domain.data(), s.domain.size());
  w.scalar(s.uncleared);
}

VoxelSampling read_sampling(CacheReader& r) {
  VoxelSampling s;
  r.matrix(s.centers, -1, 3);
  s.side = r.scalar<double>();
  s.hessian_subset = r.array<int>();
  r.matrix(s.origin, 3, 1);
  r.matrix(s.grid_index, -1, 3);
  s.safety = r.scalar<double>();
  s.search_iterations = r.scalar<int>();
  s.target_met = r.scalar<char>() != 0;
  s.level = r.array<int>();
  const std::vector<char> domain = r.array<char>();
  s.domain.assign(domain.begin(), domain.end());
  s.uncleared = r.scalar<long>();
  if (!s.level.empty() && static_cast<long>(s.level.size()) != s.size()) throw CacheReader::Bad{};
  for (int k : s.level)
    if (k < 0 || k > 60) throw CacheReader::Bad{};
  for (int i : s.hessian_subset)
    if (i < 0 || i >= s.size()) throw CacheReader::Bad{};
  return s;
}

CacheKey sampling_key(const std::string& domain, const Cage& cage, const MatX3d& mesh_V, const MatX3i& mesh_F,
                      const SamplingParams& p) {
  CacheKey k("sampling");
  k.add_matrix(cage.V).add_matrix(cage.F);
  k.add(p.target_count).add(p.count_tolerance).add(p.voxel_side).add(p.safety);
  k.add(p.hessian_fraction).add(p.max_search_iterations);
  k.add(domain);
  if (domain == "mesh")
    k.add_matrix(mesh_V).add_matrix(mesh_F).add(p.max_domain_level).add(p.max_leaves_per_cell);
  return k.add_numerics();
}

VoxelSampling cached_sample_for_domain(const std::string& domain, const Cage& cage, const MatX3d& mesh_V,
                                       const MatX3i& mesh_F, const SamplingParams& params,
                                       const PrecomputeCache& cache, CacheEvent* event) {
  const CacheKey key = sampling_key(domain, cage, mesh_V, mesh_F, params);
  std::vector<char> payload;
  CacheEvent ev;
  if (cache.load(key, payload, &ev)) {
    try {
      CacheReader r(std::move(payload));
      VoxelSampling s = read_sampling(r);
      if (r.at_end()) {
        if (event) *event = ev;
        return s;
      }
    } catch (const CacheReader::Bad&) {
    }
    std::error_code ec;
    fs::remove(cache.path(key), ec);
    ev.outcome = "rebuilt (malformed payload)";
  }
  const VoxelSampling s = sample_for_domain(domain, cage, mesh_V, mesh_F, params);
  CacheWriter w;
  write_sampling(w, s);
  CacheEvent st;
  cache.store(key, w, &st);
  if (st.outcome != "stored" && st.outcome != "disabled") ev.outcome += "; " + st.outcome;
  if (event) *event = ev;
  return s;
}

std::string describe(const CacheEvent& e) {
  std::string s = e.kind + ": " + e.outcome;
  if (e.outcome == "hit" || e.outcome == "stored") {
    char t[64];
    std::snprintf(t, sizeof t, " %s in %.0f ms", megabytes(e.bytes).c_str(), e.ms);
    s += t;
  }
  if (e.evicted > 0) s += ", " + std::to_string(e.evicted) + " least recently used evicted";
  return s;
}

std::string describe(const CacheUsage& u) {
  return "cache: " + std::to_string(u.entries) + " files, " + megabytes(u.bytes) + " of " +
         megabytes(u.limit);
}

}  // namespace lidef
