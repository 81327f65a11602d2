// Map quantities (σ1, σ3, det J, E_iso) sampled on a regular grid over the cage's bounding box, for reports,
// the studio's σ3 view and the ParaView export (vtk_export.h). VTK-free.
#pragma once
#include <vector>

#include "lidef/cage.h"
#include "lidef/green_coordinates.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// Map quantities sampled on a regular grid over the cage's bounding box.
struct FieldGrid {
  int dims[3] = {0, 0, 0};     // points per axis (x fastest in the arrays below)
  Vec3 origin = Vec3::Zero();  // = cage bounding-box minimum
  double spacing = 0;          // same on every axis
  // One value per point; NaN where the point is outside the cage (winding number < 1/2), where the map is not
  // the deformation. e_iso is also NaN where det J <= 0 (the energy is +inf there; NaN shows as ParaView's
  // NaN colour instead of wrecking the colour range).
  std::vector<float> sigma1, sigma3, det_j, e_iso;
  std::vector<unsigned char> inside_cage;     // winding number >= 1/2
  std::vector<unsigned char> inside_sampled;  // in the union of the voxels (closed cubes; containing_voxel)
  long points() const { return static_cast<long>(dims[0]) * dims[1] * dims[2]; }
  long count_inside_cage() const;
  long count_inside_sampled() const;
};

// Samples the map with coefficients y (#V+#F by 3) on a grid with `resolution` points along the longest axis
// of the cage's bounding box (>= 2) and the same spacing on the other axes (at least 2 points each), in
// parallel (OpenMP). sigma1 >= |sigma3| are signed singular values (sigma3 < 0 iff det J < 0); E_iso = Σ_i
// σ_i² + σ_i⁻² (the symmetric Dirichlet energy density, 6 at a rotation). Throws InputError when resolution <
// 2 or y has the wrong shape.
FieldGrid compute_field_grid(const Cage& cage, const HarmonicBasis& basis, const MatX3d& y,
                             const VoxelSampling& sampling, int resolution = 64);

}  // namespace lidef
