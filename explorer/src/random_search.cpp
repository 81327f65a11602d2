#include "lidef/explorer/random_search.h"

#include <array>
#include <cmath>
#include <string>

#include "explorer_rng.h"
#include "lidef/errors.h"

namespace lidef {

using explorer_detail::Rng;
using explorer_detail::splitmix64;

std::uint64_t trial_seed(std::uint64_t seed, std::uint64_t trial) {
  return splitmix64(splitmix64(seed) ^ (trial * 0xd1b54a32d192ed03ULL + 1));
}

HarmonicPolynomialMap random_harmonic_map(int degree, std::uint64_t seed, double max_amplitude) {
  if (degree < 2 || degree > kMaxHarmonicDegree)
    throw InputError("", "random maps need a degree in 2.." + std::to_string(kMaxHarmonicDegree) + " (got " +
                             std::to_string(degree) + ")");
  Rng rng(seed);
  const Mat3 R1 = rng.rotation(), R2 = rng.rotation();
  Vec3 s;
  for (int i = 0; i < 3; ++i) s(i) = std::exp(0.35 * rng.normal());
  const Mat3 A = R1 * s.asDiagonal() * R2.transpose();
  Eigen::Matrix<double, 3, Eigen::Dynamic> C =
      HarmonicPolynomialMap::affine_coefficients(degree, A, Vec3::Zero());
  const double amp = max_amplitude * rng.uniform();
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  for (int j = 0; j < B.size(); ++j)
    if (B.degree_of[j] >= 2)
      for (int a = 0; a < 3; ++a) C(a, j) = amp / B.degree_of[j] * rng.normal();
  return HarmonicPolynomialMap(degree, C);
}

HarmonicPolynomialMap twist_example(const Vec3& s, double c, double d, int degree) {
  if (degree < 3 || degree > kMaxHarmonicDegree)
    throw InputError("", "the twist example needs degree 3 or 4");
  std::array<Polynomial, 3> f;
  auto set = [&](Polynomial& p, int a, int b, int cc, double v) { p.c[monomial_index(a, b, cc)] += v; };
  set(f[0], 1, 0, 0, s(0));
  set(f[0], 1, 0, 1, c);
  set(f[1], 0, 1, 0, s(1));
  set(f[1], 0, 1, 1, -c);
  set(f[2], 0, 0, 1, s(2));
  set(f[2], 0, 2, 0, c / 2);
  set(f[2], 2, 0, 0, -c / 2);
  set(f[2], 0, 0, 3, d);
  set(f[2], 2, 0, 1, -1.5 * d);
  set(f[2], 0, 2, 1, -1.5 * d);
  return HarmonicPolynomialMap::from_components(degree, f);
}

HarmonicPolynomialMap random_twist_map(int degree, std::uint64_t seed, double max_amplitude) {
  if (degree < 3 || degree > kMaxHarmonicDegree)
    throw InputError("", "the twist family needs a degree in 3.." + std::to_string(kMaxHarmonicDegree) +
                             " (got " + std::to_string(degree) + ")");
  Rng rng(seed);
  Vec3 s;
  s(2) = 0.3 + 0.5 * rng.uniform();
  s(1) = s(2) + 0.3 + 0.9 * rng.uniform();
  s(0) = s(1) + 0.1 + 0.5 * rng.uniform();
  const double c = 1.2 * (s(1) - s(2)) * rng.uniform(), d = 0.1 * rng.uniform();
  Eigen::Matrix<double, 3, Eigen::Dynamic> C = twist_example(s, c, d, degree).coefficients();
  const double amp = max_amplitude * rng.uniform();
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  for (int j = 0; j < B.size(); ++j)
    if (B.degree_of[j] >= 1)
      for (int a = 0; a < 3; ++a) C(a, j) += amp / B.degree_of[j] * rng.normal();
  return HarmonicPolynomialMap(degree, C);
}

std::vector<SearchTrial> search_sigma3_minima(const SearchParams& params,
                                              const std::function<void(int)>& progress) {
  if (params.trials < 1) throw InputError("--trials", "must be at least 1");
  std::vector<SearchTrial> out(params.trials);
  int done = 0;
  const Ball ball;
#pragma omp parallel for schedule(dynamic)
  for (int t = 0; t < params.trials; ++t) {
    SearchTrial& tr = out[t];
    tr.trial = t;
    tr.seed = trial_seed(params.seed, t);
    tr.map = params.family == SearchFamily::kTwist
                 ? random_twist_map(params.degree, tr.seed, params.max_amplitude)
                 : random_harmonic_map(params.degree, tr.seed, params.max_amplitude);
    const PolynomialExplorerMap m(tr.map);
    MinimaSearchParams mp = params.minima;
    mp.seed = splitmix64(tr.seed);
    tr.minima = find_sigma3_minima(m, ball, mp);
    tr.sphere_min_sigma3 = sampled_sphere_min_sigma3(m, ball).first;
    for (const Sigma3Minimum& mn : tr.minima) {
      tr.strict_minima += mn.strict;
      if (!tr.candidate && mn.strict && mn.sigma3 > 0 && mn.sigma3 < tr.sphere_min_sigma3) {
        tr.candidate = true;
        tr.candidate_gap = (tr.sphere_min_sigma3 - mn.sigma3) / mn.sigma3;
      }
    }
    // A lower strict minimum that is not positive disqualifies the map (it is not locally injective).
    if (tr.candidate)
      for (const Sigma3Minimum& mn : tr.minima)
        if (mn.sigma3 <= 0) tr.candidate = false;
    if (progress) {
#pragma omp critical(lidef_search_progress)
      progress(++done);
    }
  }
  return out;
}

}  // namespace lidef
