// Interior local minima of σ3 of a map on a ball (docs/explorer.md, item 1 of "verified"), and a sampled
// estimate of σ3's minimum on the boundary sphere. Deterministic for a fixed seed, whatever the thread count.
#pragma once
#include <cstdint>
#include <utility>
#include <vector>

#include "lidef/explorer/explorer_map.h"
#include "lidef/types.h"

namespace lidef {

struct Sigma3Minimum {
  Vec3 position = Vec3::Zero();
  double sigma3 = 0;
  double gradient_norm = 0;
  Vec3 hessian_eigenvalues = Vec3::Zero();  // ascending
  double sphere_radius = 0;                 // radius of the small sphere around the point that was sampled
  double sphere_min_sigma3 = 0;             // min of σ3 over that sphere's sample points
  double gap = 0;                           // gap of σ3 (σ3 simple and σ3 + σj ≠ 0 when > 0)
  bool strict = false;  // Hessian eigenvalues > 1e-8 (1 + σ1), sphere_min_sigma3 > sigma3 + 1e-12 (1 + σ1)
  int starts = 0;       // starts that converged to this point
};

struct MinimaSearchParams {
  int starts = 24;  // the ball's center plus (starts − 1) random points in the ball
  std::uint64_t seed = 1;
  int max_iterations = 200;          // per start
  double interior_margin = 1e-3;     // a minimum must satisfy |x − c| < R (1 − margin)
  double gradient_tolerance = 1e-9;  // relative to 1 + σ1 at the point
  int sphere_points = 200;           // Fibonacci points on the small confirmation sphere
};

// Multi-start projected trust-region Newton descent of σ3 in the ball, with the exact gradient and Hessian of
// σ3. Returns the distinct interior critical points that are local minima candidates (|∇σ3| small, inside the
// margin), sorted by σ3, each confirmed by the Hessian's eigenvalues and by sampling σ3 on a small sphere
// around it (radius min(R/100, distance to the boundary / 2)).
std::vector<Sigma3Minimum> find_sigma3_minima(const ExplorerMap& map, const Ball& ball,
                                              const MinimaSearchParams& params = {});

// The first strict minimum of `minima` (sorted by σ3, as find_sigma3_minima returns them), or null.
const Sigma3Minimum* lowest_strict_minimum(const std::vector<Sigma3Minimum>& minima);

// Min of σ3 over the vertices of an icosphere of the ball's radius (`subdivisions` times subdivided): a
// sampled estimate of the minimum on the boundary. Returns the value and its point.
std::pair<double, Vec3> sampled_sphere_min_sigma3(const ExplorerMap& map, const Ball& ball,
                                                  int subdivisions = 4);

}  // namespace lidef
