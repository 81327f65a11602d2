// Random harmonic polynomial maps and the search for interior minima of σ3 (docs/explorer.md, "How often it
// happens"), and the constructed twist family. Deterministic for a given seed, whatever the thread count.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include "lidef/explorer/harmonic_polynomials.h"
#include "lidef/explorer/sigma_minima.h"
#include "lidef/types.h"

namespace lidef {

// A random harmonic polynomial map of degree D (2..4): linear part A = R1 diag(s) R2ᵀ (rotations, s_i =
// exp(N(0, 0.35²))), no translation, and every coefficient of degree l ≥ 2 drawn from N(0, (amplitude / l)²),
// amplitude itself uniform in [0, max_amplitude].
HarmonicPolynomialMap random_harmonic_map(int degree, std::uint64_t seed, double max_amplitude = 0.6);

// The twist family (s1 > s2 > s3 > 0, twist c, cubic weight d; docs/explorer.md):
//   f(x, y, z) = ( s1 x + c x z,   s2 y − c y z,   s3 z + (c/2)(y² − x²) + d (z³ − (3/2) z (x² + y²)) ),
// with ∇σ3(0) = 0 and Hess σ3(0) = diag(2c²/(s3 + s1) − 3d, 2c²/(s3 + s2) − 3d, 6d). Returned in the
// degree-`degree` basis (3 or 4).
HarmonicPolynomialMap twist_example(const Vec3& s, double c, double d, int degree = 4);

// A random perturbation of the twist family: s3 ~ U[0.3, 0.8], s2 = s3 + U[0.3, 1.2], s1 = s2 + U[0.1, 0.6],
// c ~ U[0, 1.2] (s2 − s3), d ~ U[0, 0.1], plus N(0, (amplitude / max(l, 1))²) on every coefficient of degree
// l ≥ 1 (amplitude itself uniform in [0, max_amplitude]).
HarmonicPolynomialMap random_twist_map(int degree, std::uint64_t seed, double max_amplitude = 0.6);

// Per-trial seeds: splitmix64 of (seed, trial), so a trial's result does not depend on threads or on other
// trials.
std::uint64_t trial_seed(std::uint64_t seed, std::uint64_t trial);

struct SearchTrial {
  int trial = 0;
  std::uint64_t seed = 0;
  HarmonicPolynomialMap map;
  std::vector<Sigma3Minimum> minima;  // interior minima (find_sigma3_minima)
  double sphere_min_sigma3 = 0;       // sampled_sphere_min_sigma3
  int strict_minima = 0;
  // A strict interior minimum with σ3 > 0 that lies below every sampled boundary value: the Fig. 2 situation
  // (up to certification).
  bool candidate = false;
  double candidate_gap = 0;  // (sphere min − interior min) / interior min, for ranking
};

enum class SearchFamily { kRandom, kTwist };  // random_harmonic_map / random_twist_map
struct SearchParams {
  SearchFamily family = SearchFamily::kRandom;
  int degree = 4;
  int trials = 200;
  std::uint64_t seed = 1;
  double max_amplitude = 0.6;
  MinimaSearchParams minima;
};

// Runs the trials (on the unit ball) in parallel, results in trial order. `progress` (optional) is called
// after each finished trial with the number finished so far, from one thread at a time.
std::vector<SearchTrial> search_sigma3_minima(const SearchParams& params,
                                              const std::function<void(int)>& progress = nullptr);

}  // namespace lidef
