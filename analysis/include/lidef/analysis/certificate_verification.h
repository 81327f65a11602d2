// Ground truth for the certificate (paper Fig. 5): dense sampling inside every leaf voxel.
#pragma once
#include <vector>

#include "lidef/green_coordinates.h"
#include "lidef/octree_certifier.h"
#include "lidef/types.h"

namespace lidef {

struct VoxelVerification {
  long leaf;                // index into the leaves given
  double sigma3_center;     // σ3 at the leaf center (recomputed)
  double min_sigma3;        // min σ3 over the leaf's samples (including the center and corners)
  double max_quotient;      // max |σ3(p) − σ3(c)| / |p − c| over the samples: a lower estimate of the true Lipschitz constant
  double L;                 // the certificate's Lipschitz constant
  double tightness;         // max_quotient / L (≤ 1 when the bound holds)
  long violations;          // samples with σ3(p) < σ3(c) − |p−c| L (the bound is wrong there)
  // Bounded distortion: the largest sampled σ1 and σ1/σ3 (the latter over samples with σ3 > 0), and the
  // samples above the leaf's sigma1_upper or distortion_upper (the bounds are wrong there).
  double max_sigma1 = 0;
  double max_distortion = 0;
  long distortion_violations = 0;
};

struct BoundViolation {
  long leaf;
  Vec3 p;
  double sigma3;  // σ3(p)
  double bound;   // σ3(c) − |p − c| L
};

struct VerificationResult {
  long points = 0;
  double min_sigma3 = 0;        // over all samples of certified leaves
  long nonpositive_in_certified = 0;  // samples with σ3 ≤ 0 inside leaves marked certified (must be 0)
  long violations = 0;          // bound violations over all leaves
  // Over the samples of certified leaves: the largest σ1 and σ1/σ3; and over all leaves the samples above
  // their leaf's σ1 or σ1/σ3 upper bound (must be 0).
  double max_sigma1 = 0;
  double max_distortion = 0;
  long distortion_violations = 0;
  std::vector<VoxelVerification> voxels;  // one per leaf, in leaf order
  std::vector<BoundViolation> violation_list;  // the first violations (at most 100)
};

// Samples every leaf: its 8 corners, its center and `samples_per_voxel` uniform random points (seeded by
// `seed` and the leaf index, so the result does not depend on the thread count). σ3 and σ1 from the exact
// basis; σ1 and σ1/σ3 are checked against each leaf's sigma1_upper and distortion_upper.
VerificationResult verify_certificate(const HarmonicBasis& basis, const MatX3d& y, const std::vector<CertLeaf>& leaves,
                                      int samples_per_voxel, unsigned seed = 1);

}  // namespace lidef
