// The mesh domain (issue 15): the voxels that cover D = every point of the mesh's triangles and of the solid
// they bound (generalized winding number ≥ ½), refined toward the cage until every leaf's ball is clear of
// it. docs/sampling-and-subspace.md and docs/certificate.md explain the construction and why it suffices.
#pragma once
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// Base = the regular grid of sample_voxels (aligned with the cage's bounding-box minimum, laid out in the
// cage's normalized frame); every base cell that meets D is kept. "Meets" is decided exactly: a triangle
// overlaps the closed cell (triangle_box_overlap), or no triangle does and the cell's center is inside
// (winding number ≥ ½; for a closed mesh the whole cell then is). A kept cell whose ball is not clear of the
// cage (center distance ≤ safety · r, or cage winding number ≠ 1 at the center) is split into 8 and the
// children meeting D are tested again, down to params.max_domain_level. A leaf still not clear there is kept
// and counted in `uncleared` (the mesh touches or crosses the cage: the certifier refuses such a leaf, so no
// map is certified); a base cell whose refinement passes max_leaves_per_cell stops refining (its remaining
// cells are kept as uncleared leaves).
// `samples` (params.target_count) = the number of leaves |I| (the voxels the energy and the certificate
// evaluate): the base side is searched until the leaf count is within count_tolerance of it, like
// sample_voxels. params.voxel_side > 0 fixes the base side instead.
// Output: centers, level (per leaf), grid_index (its base cell), domain = "mesh", in model units.
// Deterministic whatever the thread count. Throws InputError on bad parameters or an empty mesh.
VoxelSampling sample_domain(const Cage& cage, const MatX3d& mesh_V, const MatX3i& mesh_F,
                            const SamplingParams& params = SamplingParams());

// "mesh" → sample_domain, "voxels" → sample_voxels (the paper's grid); anything else throws InputError.
VoxelSampling sample_for_domain(const std::string& domain, const Cage& cage, const MatX3d& mesh_V,
                                const MatX3i& mesh_F, const SamplingParams& params = SamplingParams());

// For each closed cube (centers: #B by 3, sides: #B), whether it meets D (the same exact test as
// sample_domain: a triangle overlaps it, or none does and its center is inside). Reports count the
// certificate's leaves that meet D with it.
std::vector<char> cubes_meeting_mesh_domain(const MatX3d& mesh_V, const MatX3i& mesh_F, const MatX3d& centers,
                                            const VecXd& sides);

}  // namespace lidef
