// On-disk cache of per-cage precomputation (the solver's sampling, reduced basis derivatives and certifier
// matrices; the studio's mesh matrices): opening a model a second time reads what the first opening computed.
//
// An entry is one file <dir>/<kind>-<key16hex>.lpc. The key is an FNV-1a 64 hash (hash.h) of the format
// version, the kind and everything that shapes the content (cage and mesh bytes, sampling, subspace and the
// parameters; CacheKey). A file is trusted only when its magic, format version, byte order, kind, key, length
// and payload checksum all match; anything else (truncated, corrupted, another key) is reported, removed and
// rebuilt. Files are written atomically (atomic_file.h). The directory is size-limited: after a write the
// least recently used files (.lpc entries and the subspace cache's subspace-*.bin; a read refreshes a file's
// time) are removed until the total fits the limit. docs/parameters.md (cache) says how to set dir and limit.
//
// Results never depend on the cache: an entry holds exactly the bytes the computation produced, and the key
// holds the thread counts and OpenBLAS's kernels, since the dense products' rounding depends on them.
#pragma once
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "lidef/cage.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// Bump whenever the content or meaning of any entry changes (a new stage, other numerics): older entries
// then miss instead of being trusted. 2: samplings carry level, domain, uncleared; 3: SIMD basis kernel and
// OpenBLAS products; 4: the word-wise payload checksum; 5: the solver's entry holds the perturbation
// constants; 6: and the reduced Hessian's pair blocks at rest; 7: and the first-order bound factors.
constexpr std::uint32_t kPrecomputeFormatVersion = 7;

// $LIDEF_CACHE_MAX_MB (MiB) when set, else 4096 MiB.
std::uint64_t default_cache_max_bytes();

// Accumulates the key of an entry. Every add() hashes the bytes and their length, so ("ab","c") ≠ ("a","bc").
class CacheKey {
 public:
  explicit CacheKey(const std::string& kind);
  CacheKey& add_bytes(const void* data, std::size_t bytes);
  CacheKey& add(const std::string& s) { return add_bytes(s.data(), s.size()); }
  template <class T, std::enable_if_t<std::is_arithmetic_v<T> || std::is_enum_v<T>, int> = 0>
  CacheKey& add(T v) {
    return add_bytes(&v, sizeof v);
  }
  // Shape and exact element bytes of a dense Eigen matrix.
  template <class M>
  CacheKey& add_matrix(const M& m) {
    add(static_cast<std::int64_t>(m.rows()));
    add(static_cast<std::int64_t>(m.cols()));
    return add_bytes(m.data(), sizeof(typename M::Scalar) * static_cast<std::size_t>(m.size()));
  }
  // The thread counts, OpenBLAS's kernels and the build (compiler, Eigen version): the rounding of dense
  // products depends on them.
  CacheKey& add_numerics();
  const std::string& kind() const { return kind_; }
  std::uint64_t value() const { return h_; }

 private:
  std::string kind_;
  std::uint64_t h_;
};

// The payload of an entry: a sequence of arrays and scalars, read back in the order written. The writer keeps
// pointers (no copy of large arrays): the data must outlive the store() call.
class CacheWriter {
 public:
  template <class T>
  void scalar(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    small_.emplace_back(sizeof(T));
    std::memcpy(small_.back().data(), &v, sizeof(T));
    spans_.push_back({small_.back().data(), sizeof(T), small_.size() - 1});
  }
  template <class T>
  void array(const T* data, std::size_t count) {
    scalar(static_cast<std::uint64_t>(count));
    spans_.push_back({data, sizeof(T) * count, npos});
  }
  template <class M>
  void matrix(const M& m) {
    scalar(static_cast<std::int64_t>(m.rows()));
    scalar(static_cast<std::int64_t>(m.cols()));
    array(m.data(), static_cast<std::size_t>(m.size()));
  }
  std::uint64_t bytes() const;

 private:
  friend class PrecomputeCache;
  static constexpr std::size_t npos = static_cast<std::size_t>(-1);
  struct Span {
    const void* data;
    std::size_t bytes;
    std::size_t small;  // index into small_ (its storage may move), or npos
  };
  const void* span_data(const Span& s) const { return s.small == npos ? s.data : small_[s.small].data(); }
  std::vector<std::vector<char>> small_;
  std::vector<Span> spans_;
};

// Reads a payload back; any mismatch (too short, wrong shape) throws CacheReader::Bad, which the caller
// treats as a corrupted entry.
class CacheReader {
 public:
  struct Bad {};
  explicit CacheReader(std::vector<char> payload) : buf_(std::move(payload)) {}
  template <class T>
  T scalar() {
    static_assert(std::is_trivially_copyable_v<T>);
    T v;
    std::memcpy(&v, take(sizeof(T)), sizeof(T));
    return v;
  }
  template <class T>
  std::vector<T> array() {
    const auto n = scalar<std::uint64_t>();
    if (n > buf_.size()) throw Bad{};
    std::vector<T> v(static_cast<std::size_t>(n));
    copy_out(v.data(), sizeof(T) * v.size());
    return v;
  }
  // Into an existing Eigen matrix type: the stored shape must match `rows`/`cols` when they are ≥ 0.
  template <class M>
  void matrix(M& m, long rows = -1, long cols = -1) {
    const auto r = scalar<std::int64_t>(), c = scalar<std::int64_t>();
    if (r < 0 || c < 0 || (rows >= 0 && r != rows) || (cols >= 0 && c != cols)) throw Bad{};
    const auto n = scalar<std::uint64_t>();
    if (n != static_cast<std::uint64_t>(r) * static_cast<std::uint64_t>(c) || n > buf_.size()) throw Bad{};
    m.resize(r, c);
    copy_out(m.data(), sizeof(typename M::Scalar) * n);
  }
  bool at_end() const { return pos_ == buf_.size(); }

 private:
  // An empty array's data() may be null, and memcpy's pointers must not be, even for 0 bytes (UBSan's
  // nonnull-attribute check found it in `make check-sanitize`).
  void copy_out(void* dst, std::size_t bytes) {
    const char* src = take(bytes);
    if (bytes > 0) std::memcpy(dst, src, bytes);
  }
  const char* take(std::size_t bytes) {
    if (bytes > buf_.size() - pos_) throw Bad{};
    const char* p = buf_.data() + pos_;
    pos_ += bytes;
    return p;
  }
  std::vector<char> buf_;
  std::size_t pos_ = 0;
};

// What happened to one entry, and the state of the directory (the studio and the CLI print it).
struct CacheEvent {
  std::string kind;
  std::string outcome;  // "disabled", "hit", "miss", "rebuilt (<why>)", "stored", "not stored (<why>)"
  std::uint64_t bytes = 0;
  double ms = 0;     // read (hit) or write (stored) time
  long evicted = 0;  // files removed by the store to keep the limit
};
struct CacheUsage {
  long entries = 0;  // files counted against the limit
  std::uint64_t bytes = 0, limit = 0;
};

// Checksum of an entry's payload (it catches corrupted or truncated files, not tampering): of each 1 MiB
// block of the concatenated arrays (in parallel) four multiply-xor lanes over 8-byte words, folded with
// FNV-1a 64, then FNV-1a 64 of the block checksums. Deterministic whatever the thread count and however the
// payload is split into arrays.
std::uint64_t payload_checksum(const std::vector<const void*>& data, const std::vector<std::size_t>& bytes);

// Lowers the calling thread's priority (nice 10, Linux) for the rest of its life: a cache entry written in
// the background while the caller computes on all cores should take little from that computation.
void lower_calling_thread_priority();

class PrecomputeCache {
 public:
  // dir "" disables the cache (every lookup misses, nothing is written).
  explicit PrecomputeCache(std::string dir, std::uint64_t max_bytes = default_cache_max_bytes());
  bool enabled() const { return !dir_.empty(); }
  const std::string& dir() const { return dir_; }
  std::uint64_t max_bytes() const { return max_bytes_; }
  std::string path(const CacheKey& key) const;  // <dir>/<kind>-<key16hex>.lpc

  // The payload of a valid entry for `key` (and its time refreshed), or false. A file that exists but does
  // not check out is removed; `event` says which.
  bool load(const CacheKey& key, std::vector<char>& payload, CacheEvent* event = nullptr) const;
  // Writes the entry atomically, then evicts least-recently-used files beyond the limit (never this one). An
  // entry larger than the limit, or a directory that cannot be written, is not stored (the cache is an
  // optimisation: a full disk never stops a computation); `event` says so. Never throws.
  void store(const CacheKey& key, const CacheWriter& payload, CacheEvent* event = nullptr) const;

  // Files counted against the limit, and their bytes.
  CacheUsage usage() const;
  // Removes least-recently-used files until the total is ≤ limit, keeping `keep`; returns how many.
  long evict(const std::string& keep = "") const;

 private:
  std::string dir_;
  std::uint64_t max_bytes_;
};

// A sampling in an entry's payload (all of its fields, exactly).
void write_sampling(CacheWriter& w, const VoxelSampling& s);
VoxelSampling read_sampling(CacheReader& r);  // throws CacheReader::Bad

// sample_for_domain(domain, cage, mesh_V, mesh_F, params) (domain_sampling.h) through the cache (entry kind
// "sampling"; `lidef certify`): keyed by the cage, the parameters, the domain and, for "mesh", the mesh.
VoxelSampling cached_sample_for_domain(const std::string& domain, const Cage& cage, const MatX3d& mesh_V,
                                       const MatX3i& mesh_F, const SamplingParams& params,
                                       const PrecomputeCache& cache, CacheEvent* event = nullptr);

// "hit 12.3 MB in 40 ms" etc., and "cache: 3 entries, 1.2 GB of 4.0 GB" (for logs).
std::string describe(const CacheEvent& e);
std::string describe(const CacheUsage& u);

}  // namespace lidef
