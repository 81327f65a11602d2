#include "lidef/explorer/laplacian_experiment.h"

#include "explorer_rng.h"
#include "lidef/errors.h"
#include "lidef/explorer/explorer_map.h"
#include "lidef/explorer/random_search.h"
#include "lidef/signed_svd.h"

namespace lidef {

std::vector<LaplacianSample> laplacian_experiment(int degree, int maps, int points_per_map,
                                                  std::uint64_t seed, double max_amplitude) {
  if (maps < 1 || points_per_map < 1)
    throw InputError("", "the Laplacian experiment needs maps ≥ 1 and points ≥ 1");
  std::vector<LaplacianSample> out(static_cast<size_t>(maps) * points_per_map);
  const Ball ball;
#pragma omp parallel for schedule(dynamic)
  for (int m = 0; m < maps; ++m) {
    const std::uint64_t s = trial_seed(seed, m);
    const PolynomialExplorerMap map(random_harmonic_map(degree, s, max_amplitude));
    explorer_detail::Rng rng(explorer_detail::splitmix64(s) + 1);
    for (int i = 0; i < points_per_map; ++i) {
      LaplacianSample& o = out[static_cast<size_t>(m) * points_per_map + i];
      o.map = m;
      o.p = rng.in_ball(ball);
      const SigmaDerivatives d = map_sigma_derivatives(map, o.p, true);
      o.sigma = d.sigma;
      o.lap_sigma1 = d.laplacian(0);
      o.lap_sigma3 = d.laplacian(2);
      o.lap_sigma3_sym = d.laplacian_symmetric(2);
      o.lap_sigma3_anti = d.laplacian_antisymmetric(2);
      o.gap = std::min(d.gap(0), d.gap(2));
      const double h = 1e-3;
      Vec3 sum = -6 * d.sigma;
      for (int k = 0; k < 3; ++k) {
        Vec3 e = Vec3::Zero();
        e(k) = h;
        sum += signed_singular_values(map.jet(o.p + e).J) + signed_singular_values(map.jet(o.p - e).J);
      }
      o.lap_sigma1_fd = sum(0) / (h * h);
      o.lap_sigma3_fd = sum(2) / (h * h);
    }
  }
  return out;
}

}  // namespace lidef
