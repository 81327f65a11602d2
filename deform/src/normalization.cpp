#include "lidef/normalization.h"

#include <cmath>

#include "lidef/compute_backend.h"
#include "lidef/errors.h"
#include "lidef/octree_certifier.h"

namespace lidef {

Frame Frame::of(const Cage& cage) {
  Frame f;
  // Exact: the half-sum of two doubles is rounded once, and it is 0 for a box symmetric about the origin.
  f.center = 0.5 * (cage.bbox_min + cage.bbox_max);
  f.scale = 0.5 * (cage.bbox_max - cage.bbox_min).maxCoeff();
  if (!(f.scale > 0) || !std::isfinite(f.scale) || !f.center.allFinite())
    throw InputError(cage.source, "the cage's bounding box has no extent (or is not finite)");
  return f;
}

MatX3d Frame::points_to_normalized(const MatX3d& P) const {
  return (P.rowwise() - center.transpose()) / scale;
}

MatX3d Frame::points_from_normalized(const MatX3d& Q) const {
  return (scale * Q).rowwise() + center.transpose();
}

MatX3d Frame::coefficients_to_normalized(const MatX3d& y, int num_vertices) const {
  MatX3d yn = y;
  yn.topRows(num_vertices) = points_to_normalized(y.topRows(num_vertices));
  return yn;
}

MatX3d Frame::coefficients_from_normalized(const MatX3d& yn, int num_vertices) const {
  MatX3d y = yn;
  y.topRows(num_vertices) = points_from_normalized(yn.topRows(num_vertices));
  return y;
}

Cage Frame::normalized(const Cage& cage) const {
  TriMesh m;
  m.V = points_to_normalized(cage.V);
  m.F = cage.F;
  m.source = cage.source;
  return Cage(m);
}

VoxelSampling Frame::to_normalized(const VoxelSampling& s) const {
  VoxelSampling n = s;
  n.centers = points_to_normalized(s.centers);
  n.side = length_to_normalized(s.side);
  n.origin = to_normalized(s.origin);
  return n;
}

VoxelSampling Frame::from_normalized(const VoxelSampling& s) const {
  VoxelSampling m = s;
  m.centers = points_from_normalized(s.centers);
  m.side = length_from_normalized(s.side);
  m.origin = from_normalized(s.origin);
  return m;
}

Certificate Frame::from_normalized(Certificate c) const {
  if (is_identity()) return c;
  c.voxel_side = length_from_normalized(c.voxel_side);
  for (auto* list : {&c.leaves, &c.failing})
    for (CertLeaf& l : *list) {
      l.center = from_normalized(l.center);
      l.side = length_from_normalized(l.side);
      l.L /= scale;  // a Lipschitz constant of σ3 (dimensionless) per unit length
    }
  // The distortion stage names its worst leaf in the certifier's frame: name it in the model's.
  if (c.distortion_failed && !c.failing.empty()) c.reason = c.distortion_reason();
  return c;
}

NormalizedCertifier::NormalizedCertifier(const Cage& cage, const VoxelSampling& sampling)
    : frame_(Frame::of(cage)),
      ncage_(frame_.normalized(cage)),
      certifier_(ncage_, frame_.to_normalized(sampling)) {}

Certificate NormalizedCertifier::certify(const MatX3d& y, const CertifyParams& params) const {
  return frame_.from_normalized(
      certifier_.certify(frame_.coefficients_to_normalized(y, ncage_.num_vertices()), params));
}

}  // namespace lidef
