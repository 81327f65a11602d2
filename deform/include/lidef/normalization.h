// The normalized frame of a model: the core (sampling, subspace, basis, energy, solver, certificate) works on
// the cage translated to its bounding-box center and scaled to unit size, so that nothing a user sees depends
// on where the model sits or on its units (the harmonic map is affine-covariant). docs/solver.md, section
// "Normalized frame", gives the rule for every quantity; in short:
//
//   points, cage vertices, voxel centers, handle sources and targets:   p_n = (p − center) / scale
//   coefficients: vertex rows like points; face rows y_t unchanged (y_t = A n_t is dimensionless)
//   lengths (voxel sides, handle errors, distances):                     ℓ_n = ℓ / scale
//   Jacobians, σ's, det J, E_dis, E_smooth, r·L, certificate margins:    unchanged
//   ‖H‖, Lipschitz constants L (1 / length):                              L_n = L · scale
//
// center = the cage's bounding-box center, scale = half the largest bounding-box extent: the normalized
// cage spans [−1, 1] along its longest axis. Why this scale and not the diagonal: the paper's models already
// come in these units (bar exactly: center 0, scale 1, so its runs are bit-identical to the unnormalized
// ones; spot 0.95, animal 1.07), so the paper's absolute parameters (λ1 = 1e5 on squared distances) keep
// their meaning on them. The bounding box (not the volume centroid) because it is computed exactly from the
// vertex coordinates, with no rounding of integrals, and it is what the sampling grid is aligned to.
#pragma once
#include "lidef/cage.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

struct Frame {
  Vec3 center = Vec3::Zero();
  double scale = 1;  // > 0

  // The frame of a cage (bounding-box center, half the largest extent). Throws InputError when the extent is
  // zero or not finite.
  static Frame of(const Cage& cage);
  bool is_identity() const { return scale == 1 && center.isZero(0); }

  Vec3 to_normalized(const Vec3& p) const { return (p - center) / scale; }
  Vec3 from_normalized(const Vec3& q) const { return scale * q + center; }
  MatX3d points_to_normalized(const MatX3d& P) const;    // #P by 3
  MatX3d points_from_normalized(const MatX3d& Q) const;  // #P by 3
  double length_to_normalized(double l) const { return l / scale; }
  double length_from_normalized(double l) const { return l * scale; }

  // Coefficients #V+#F by 3 (vertex rows first, `num_vertices` of them): vertex rows map like points, face
  // rows are unchanged. f(p) = scale · f_n((p − center)/scale) + center.
  MatX3d coefficients_to_normalized(const MatX3d& y, int num_vertices) const;
  MatX3d coefficients_from_normalized(const MatX3d& yn, int num_vertices) const;

  // The cage in this frame (normals, areas, edges recomputed from the mapped vertices; source kept).
  Cage normalized(const Cage& cage) const;
  // Voxels: centers and origin like points, side like a length; grid indices, H and counts unchanged.
  VoxelSampling to_normalized(const VoxelSampling& s) const;
  VoxelSampling from_normalized(const VoxelSampling& s) const;
  // A certificate computed in this frame, in model units: leaf centers and sides, L (÷ scale), the base
  // voxel side. σ3, margins, lower bounds and the verdict are invariant.
  Certificate from_normalized(Certificate c) const;
};

// The octree certificate (octree_certifier.h) of maps of `cage`, computed in the cage's normalized frame and
// spoken in model units: certify() takes full coefficients y (#V+#F by 3, model units) and returns leaf
// centers, sides and L in model units. `lidef certify` uses it, and DeformationSolver certifies its iterates
// in the same frame, so `lidef certify` on a coefficients.txt reproduces the run's certificate.json.
class NormalizedCertifier {
 public:
  // `sampling` in model units (sample_voxels(cage, ...)).
  NormalizedCertifier(const Cage& cage, const VoxelSampling& sampling);
  NormalizedCertifier(const NormalizedCertifier&) = delete;  // the certifier keeps a reference to ncage_
  NormalizedCertifier& operator=(const NormalizedCertifier&) = delete;

  void set_backend(const ComputeBackend& backend) { certifier_.set_backend(backend); }
  Certificate certify(const MatX3d& y, const CertifyParams& params = {}) const;
  double precompute_seconds() const { return certifier_.precompute_seconds(); }
  const Frame& frame() const { return frame_; }

 private:
  Frame frame_;
  Cage ncage_;
  OctreeCertifier certifier_;
};

}  // namespace lidef
