// FNV-1a 64: the one content hash of lidef (cache keys, the cage and coefficient hashes of certificate.json,
// the OpenCL kernel cache). Not cryptographic: it detects accidental change, not forgery.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>

namespace lidef {

// The FNV-1a 64 offset basis (the standard's: fnv1a64("") = cbf29ce484222325, fnv1a64("a") = af63dc4c8601ec8c).
constexpr std::uint64_t kFnv1a64Offset = 14695981039346656037ull;

// Continues the hash `h` over `bytes` bytes at `data`.
inline std::uint64_t fnv1a64(const void* data, std::size_t bytes, std::uint64_t h = kFnv1a64Offset) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) {
    h ^= p[i];
    h *= 1099511628211ull;
  }
  return h;
}
inline std::uint64_t fnv1a64(const std::string& data, std::uint64_t h = kFnv1a64Offset) {
  return fnv1a64(data.data(), data.size(), h);
}

// "%016x" of a hash, as certificate.json and cache file names write it.
std::string hex64(std::uint64_t h);

}  // namespace lidef
