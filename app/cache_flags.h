// The command-line face of the precomputation cache (lidef/precompute_cache.h): --cache-dir, --no-cache and
// --cache-max-mb, the same on every command that precomputes (docs/parameters.md, "Cache").
#pragma once
#include <cstdint>
#include <string>

#include "commands.h"
#include "lidef/precompute_cache.h"
#include "lidef/subspace.h"

namespace lidef::cli {

struct CacheFlags {
  std::string dir = "<default>";
  bool off = false;
  double max_mb = -1;  // < 0: $LIDEF_CACHE_MAX_MB or the default

  // The folder to use ("" = no cache).
  std::string folder() const { return off ? "" : dir == "<default>" ? default_cache_dir() : dir; }
  std::uint64_t max_bytes() const {
    return max_mb >= 0 ? static_cast<std::uint64_t>(max_mb * 1048576.0) : default_cache_max_bytes();
  }
};

inline void add_cache_flags(CLI::App* sub, CacheFlags* f) {
  sub->add_option(
      "--cache-dir", f->dir,
      "Precomputation cache folder (subspace, sampling, basis derivatives; '' = no cache; default "
      "$LIDEF_CACHE_DIR, else $XDG_CACHE_HOME/lidef, else ~/.cache/lidef)");
  sub->add_flag("--no-cache", f->off, "Neither read nor write the precomputation cache");
  sub->add_option("--cache-max-mb", f->max_mb,
                  "Size limit of the cache folder in MiB; the least recently used files are evicted (default "
                  "$LIDEF_CACHE_MAX_MB, else 4096)")
      ->check(CLI::Range(0.0, 1e12));
}

}  // namespace lidef::cli
