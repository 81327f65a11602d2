// The mesh domain: the voxels that cover D = every input point, every point of the mesh's triangles, and the
// solid bounded by its closed components (winding number ≥ ½), refined toward the cage until every leaf's
// ball is clear of it. docs/sampling-and-subspace.md and docs/certificate.md explain the construction and why
// it suffices.
#pragma once
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// What D is for a mesh V (#V by 3), F (#F by 3; may be empty: a point cloud). `elements` (#E by 3) are the
// pieces whose every point D contains: the triangles of F, then one degenerate triangle (v, v, v) per vertex
// no face uses (triangle_box_overlap of such a triangle is the point-in-closed-box test). `solid` (#S by 3)
// are the faces of the closed components — connected through shared vertices, closed when the directed edge
// counts balance on every undirected edge, so their winding number is an integer off the surface — and D
// contains the points where their winding number is ≥ ½. Open components and isolated points bound nothing:
// no solid for them.
struct MeshDomain {
  MatX3i elements;
  MatX3i solid;
  int isolated_points = 0;    // vertices no face uses
  int closed_components = 0;  // components whose solid is in D
  int open_components = 0;    // components with a boundary: only their triangles are in D
  // "mesh and its solid" (every component closed, no isolated point), "points and surface, no solid" (no
  // closed component), or "points, surface and the solid of N closed components" (mixed).
  std::string description() const;
  // The sentence certificate.json and summary.json give for D.
  std::string definition() const;
};
MeshDomain mesh_domain_of(const MatX3d& V, const MatX3i& F);

// Base = the regular grid of sample_voxels (aligned with the cage's bounding-box minimum, laid out in the
// cage's normalized frame); every base cell that meets D is kept. "Meets" is decided exactly: an element
// (a triangle or an isolated point, MeshDomain) overlaps the closed cell (triangle_box_overlap), or none does
// and the cell's center is inside the solid (winding number of MeshDomain::solid ≥ ½; the whole cell then
// is). A kept cell whose ball is not clear of the
// cage (center distance ≤ safety · r, or cage winding number ≠ 1 at the center) is split into 8 and the
// children meeting D are tested again, down to params.max_domain_level. A leaf still not clear there is kept
// and counted in `uncleared` (the mesh touches or crosses the cage: the certifier refuses such a leaf, so no
// map is certified); a base cell whose refinement passes max_leaves_per_cell stops refining (its remaining
// cells are kept as uncleared leaves).
// `samples` (params.target_count) = the number of leaves |I| (the voxels the energy and the certificate
// evaluate): the base side is searched until the leaf count is within count_tolerance of it, like
// sample_voxels. params.voxel_side > 0 fixes the base side instead.
// Output: centers, level (per leaf), grid_index (its base cell), domain = "mesh", in model units.
// Deterministic whatever the thread count. Throws InputError on bad parameters or a mesh without
// vertices.
VoxelSampling sample_domain(const Cage& cage, const MatX3d& mesh_V, const MatX3i& mesh_F,
                            const SamplingParams& params = SamplingParams());

// "mesh" → sample_domain, "voxels" → sample_voxels (the paper's grid); anything else throws InputError.
VoxelSampling sample_for_domain(const std::string& domain, const Cage& cage, const MatX3d& mesh_V,
                                const MatX3i& mesh_F, const SamplingParams& params = SamplingParams());

// For each closed cube (centers: #B by 3, sides: #B), whether it meets D (the same exact test as
// sample_domain: an element overlaps it, or none does and its center is inside the solid). Reports count the
// certificate's leaves that meet D with it.
std::vector<char> cubes_meeting_mesh_domain(const MatX3d& mesh_V, const MatX3i& mesh_F, const MatX3d& centers,
                                            const VecXd& sides);

}  // namespace lidef
