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

// The same screen for the trials of one line search (one J0, one dJ; both must outlive it): σ1 and σ3 of
// every J0_i and ‖dJ_i‖_F are kept, and a trial evaluates only the samples that may be beyond a target at its
// step — by Weyl, σ1(J0_i + t dJ_i) ≤ σ1(J0_i) + t‖dJ_i‖ and σ3 ≥ σ3(J0_i) − t‖dJ_i‖, so a sample whose
// excess bound from these is below 1 − 1e-6 (the margin covers the closed form's rounding) cannot be the
// answer when it is above 1. largest_excess_sample(t, ...) returns what the function above returns whenever
// that excess is above 1; otherwise a sample and excess at most 1, or −1 and 0.
class DistortionScreen {
 public:
  DistortionScreen(const MatJT& J0, const MatJT& dJ);
  long largest_excess_sample(double t, const DistortionTargets& targets, double* excess) const;

 private:
  const MatJT& J0_;
  const MatJT& dJ_;
  VecXd s1_, s3_, dn_;  // per sample: σ1(J0_i), σ3(J0_i) (−1: not usable, always evaluated), ‖dJ_i‖_F
};

}  // namespace lidef
