// The solver's screen of a line-search trial against the distortion targets (DeformParams::max_distortion,
// max_sigma1, min_sigma3): the sample whose Jacobian is farthest beyond them, found from the Jacobians the
// energy has already computed, becomes the certifier's first probe. A guess only — the certifier's exact
// evaluation at the probe decides (docs/certificate.md, "Bounded distortion", "Probes").
#pragma once
#include "lidef/distortion_targets.h"
#include "lidef/types.h"

namespace lidef {

// J0, dJ: 3|I| by 3 (JT layout: the transposed Jacobian of sample i in rows 3i..3i+2). The sample i whose
// J0_i + t dJ_i has the largest targets.excess(σ1, σ3, σ1/σ3) (singular values from the eigenvalues of JᵀJ
// in closed form; samples with det ≤ 0 or a non-positive smallest eigenvalue are skipped) and that excess in
// *excess (above 1: the sample seems beyond a target); −1 (and *excess = 0) when there is none. With only
// max_distortion = 1 the excess is σ1/σ3 itself. The same index for any thread count: ties go to the
// smaller index.
long largest_excess_sample(const MatJT& J0, const MatJT& dJ, double t, const DistortionTargets& targets,
                           double* excess);

}  // namespace lidef
