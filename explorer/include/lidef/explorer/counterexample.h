// The verdict "verified counterexample" (docs/explorer.md, "Why verified means a bijection with an interior
// minimum"): a bijective harmonic map of the ball whose σ3 is smallest at an interior point. Decided here
// only; `lidef explore show` and `lidef explore search` run the checks and call counterexample_verdict.
#pragma once
#include <string>
#include <vector>

#include "lidef/explorer/ball_certificate.h"
#include "lidef/explorer/boundary_injectivity.h"
#include "lidef/explorer/sigma_minima.h"

namespace lidef {

// The results of the five checks, each null when it was not run (a missing check fails the verdict).
struct CounterexampleChecks {
  const Sigma3Minimum* minimum = nullptr;                     // 1. the lowest strict interior minimum x*
  const BallCertificate* local_injectivity = nullptr;         // 2. σ3 > 0 certified on the ball
  const BallCertificate* boundary_above_minimum = nullptr;    // 3. σ3 > σ3(x*) certified on the sphere
  const BoundaryInjectivity* boundary_injectivity = nullptr;  // 4. f injective on the sphere, certified
  const BoundaryEmbedding* boundary_embedding = nullptr;      // 5. triangulated boundary image embedded
};

struct CounterexampleVerdict {
  bool verified = false;
  std::vector<std::string> reasons;  // why not, one per failed check in the order above (empty if verified)
};

// Verified when: x* is strict with σ3(x*) > 0; the ball certificate covers the ball with threshold ≥ 0; the
// sphere certificate has threshold ≥ σ3(x*); the boundary is certified injective; the image is embedded.
CounterexampleVerdict counterexample_verdict(const CounterexampleChecks& checks);

// The σ3 threshold check 4 is certified with: half the smallest σ3 seen, over the centers of the ball
// certificate (check 2) and at x* when σ3(x*) > 0.
double boundary_injectivity_threshold(const BallCertificate& local_injectivity, const Sigma3Minimum* minimum);

}  // namespace lidef
