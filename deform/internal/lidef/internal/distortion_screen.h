// The solver's screen of a line-search trial against a distortion target (DeformParams::max_distortion): the
// sample whose Jacobian has the largest σ1/σ3, found from the Jacobians the energy has already computed,
// becomes the certifier's first probe. A guess only — the certifier's exact evaluation at the probe decides
// (docs/certificate.md, "Bounded distortion", "Probes").
#pragma once
#include "lidef/types.h"

namespace lidef {

// J0, dJ: 3|I| by 3 (JT layout: the transposed Jacobian of sample i in rows 3i..3i+2). The sample i whose
// J0_i + t dJ_i has the largest σ1/σ3 (from the eigenvalues of JᵀJ in closed form; samples with det ≤ 0 or
// a non-positive smallest eigenvalue are skipped) and that ratio in *k; −1 (and *k = 0) when there is none.
// The same index for any thread count: ties go to the smaller index.
long largest_distortion_sample(const MatJT& J0, const MatJT& dJ, double t, double* k);

}  // namespace lidef
