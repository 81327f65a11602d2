// Deterministic random numbers of the explorer (private to lidef_explorer): own transforms, so that results
// do not depend on the standard library.
#pragma once
#include <cmath>
#include <cstdint>

#include "lidef/explorer/explorer_map.h"

namespace lidef::explorer_detail {

inline std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : s_(splitmix64(seed)) {}
  std::uint64_t next() { return s_ = splitmix64(s_); }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double normal() {                                                           // Box-Muller
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2 * M_PI * u2);
  }
  // Uniform in the ball (rejection from the bounding cube).
  Vec3 in_ball(const Ball& b) {
    for (;;) {
      const Vec3 v(2 * uniform() - 1, 2 * uniform() - 1, 2 * uniform() - 1);
      if (v.squaredNorm() <= 1) return b.center + b.radius * v;
    }
  }
  Mat3 rotation() {
    Eigen::Quaterniond q(normal(), normal(), normal(), normal());
    q.normalize();
    return q.toRotationMatrix();
  }

 private:
  std::uint64_t s_;
};

}  // namespace lidef::explorer_detail
