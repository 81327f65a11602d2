// Laplacians of σ1 and σ3 at random points of random harmonic maps (paper App. D: Δσ1 ≥ 0; Δσ3 has no sign;
// docs/explorer.md).
#pragma once
#include <cstdint>
#include <vector>

#include "lidef/types.h"

namespace lidef {

struct LaplacianSample {
  int map = 0;
  Vec3 p = Vec3::Zero();
  Vec3 sigma = Vec3::Zero();
  double lap_sigma1 = 0, lap_sigma3 = 0;        // exact (Hessian traces)
  double lap_sigma1_fd = 0, lap_sigma3_fd = 0;  // 7-point finite-difference Laplacians (step 1e-3)
  double lap_sigma3_sym = 0,
         lap_sigma3_anti = 0;  // the ≤ 0 and ≥ 0 parts of Δσ3 (singular_value_derivatives.h)
  double gap = 0;              // min gap of σ1 and σ3 (formulas need it > 0)
};

// `maps` random maps (random_harmonic_map, trial_seed(seed, m)) × `points_per_map` points uniform in the unit
// ball; maps × points_per_map samples, map-major.
std::vector<LaplacianSample> laplacian_experiment(int degree, int maps, int points_per_map,
                                                  std::uint64_t seed, double max_amplitude = 0.6);

}  // namespace lidef
