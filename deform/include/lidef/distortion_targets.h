// Bounds on the distortion that a certified map must meet besides σ3 > 0 (docs/certificate.md, "Bounded
// distortion"): the conformal distortion K = σ1/σ3 from above, and — the isometric bounds of Chen and Weber
// (2015) in 3D — the largest singular value σ1 from above and the smallest σ3 from below. Each is proven per
// leaf of the certificate from the leaf's bounds σ1 ≤ σ1_upper, σ3 ≥ σ3_lower (its margin) and σ1/σ3 ≤
// distortion_upper; 0 switches a target off.
#pragma once
#include <string>

#include "lidef/types.h"

namespace lidef {

enum class DistortionTarget { kNone, kDistortion, kSigma1, kSigma3 };

struct DistortionTargets {
  double max_distortion = 0;  // K: σ1/σ3 ≤ K on every leaf (≥ 1 when on)
  double max_sigma1 = 0;      // σ1 ≤ this on every leaf (≥ 1 when on: the rest state has σ1 = 1)
  double min_sigma3 = 0;      // σ3 ≥ this on every leaf (≤ 1 when on)

  bool any() const { return max_distortion > 0 || max_sigma1 > 0 || min_sigma3 > 0; }

  // The first target (in the order above) that the leaf bounds do not prove; kNone when all are proven.
  // Plain comparisons of the bounds with the targets: this is the proof, no rounding happens here.
  DistortionTarget unproven(double sigma1_upper, double sigma3_lower, double distortion_upper) const;

  // The first target that values known at a point contradict: σ1 ≥ sigma1_lower and σ3 ≤ sigma3_upper there
  // prove σ1/σ3 > K (sigma3_upper > 0), σ1 > max_sigma1 or σ3 < min_sigma3, each beyond a relative `slack`
  // that covers the rounding of the comparison's product; kNone when none is contradicted.
  DistortionTarget violated(double sigma1_lower, double sigma3_upper, double slack) const;

  // How far a leaf's bounds are from the targets, as the largest of distortion_upper / K, sigma1_upper /
  // max_sigma1 and min_sigma3 / sigma3_lower (+∞ when that lower bound is not positive) over the targets
  // that are on; 0 when none is. Only for ranking (which child set is tighter, which sample to probe
  // first): whether a target is met is decided by unproven(), never by comparing this with 1.
  double excess(double sigma1_upper, double sigma3_lower, double distortion_upper) const;

  // "distortion bound K not proven at (x, y, z)", "distortion bound sigma1 <= S not proven at ...",
  // "distortion bound sigma3 >= s not proven at ..." for the target `which` (not kNone).
  std::string reason(DistortionTarget which, const Vec3& where) const;

  // The targets that are on, for messages: "max_distortion 1.3, min_sigma3 0.5".
  std::string describe() const;
};

}  // namespace lidef
