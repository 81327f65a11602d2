// Voxel sampling of the cage interior (Liao et al. 2021, Sec. 3.3 and 7.1): the set I of cube centers on
// which the energy is evaluated and condition (6) is certified, and the Hessian subset H ⊂ I.
//
// A voxel is kept only if its center has winding number exactly 1 and its circumscribed ball
// B(center, r), r = (√3/2) side, stays at distance ≥ (safety − 1) r from the cage (center distance
// ≥ safety · r). The winding number is constant off the cage surface, so the whole ball then lies in the
// winding-number-1 region — never in a self-intersection pocket, where the identity coefficients give
// f = 2p — and the third-order bound (66)/(67) of the certificate, which needs ‖l‖ − r > 0 and grows without
// bound as a ball nears the cage, stays finite on every voxel.
#pragma once
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <unordered_map>
#include <vector>

#include "lidef/cage.h"
#include "lidef/deform_params.h"
#include "lidef/types.h"

namespace lidef {

// The defaults of the parameters that also are rows of the parameter table come from DeformParams (declared
// once, there).
struct SamplingParams {
  // Desired |I|; the voxel side is searched until |I| is within count_tolerance of it (relative).
  int target_count = DeformParams().samples;
  double count_tolerance = 0.03;
  // > 0: use exactly this voxel side and skip the search (target_count is then ignored).
  double voxel_side = DeformParams().voxel_side;
  // Center-to-cage distance ≥ safety · r. Must be > 1 (at 1 the ball touches the cage and the third-order
  // bound is infinite); 1.5 leaves every ball r/2 clear of the cage while losing only a thin layer.
  double safety = DeformParams().safety;
  // |H| = round(hessian_fraction · |I|) (paper: 5%), spread evenly over the volume (see
  // select_hessian_subset).
  double hessian_fraction = DeformParams().hessian_fraction;
  int max_search_iterations = 40;
  // Mesh domain (domain_sampling.h): octree levels below the base grid when refining toward the cage, and the
  // most leaves one base cell may be split into (a mesh crossing the cage would otherwise refine forever).
  int max_domain_level = 12;
  int max_leaves_per_cell = 4096;
};

struct VoxelSampling {
  MatX3d centers;         // #I by 3 voxel centers, grid order (z slowest, x fastest)
  double side = 0;        // base cube side h (a voxel of level k has side h / 2^k)
  double radius() const;  // (√3/2) h, center-to-corner of a base voxel
  // Per-voxel octree level below the base grid (#I, or empty: every voxel is a base voxel). The mesh domain
  // (domain_sampling.h) refines toward the cage; everything that uses a voxel's size asks side_of/radius_of.
  std::vector<int> level;
  double side_of(int i) const { return level.empty() ? side : std::ldexp(side, -level[i]); }
  double radius_of(int i) const;  // (√3/2) side_of(i): the radius condition (6) uses
  double weight_of(int i) const { return level.empty() ? 1.0 : std::ldexp(1.0, -3 * level[i]); }  // 8^-k
  int max_level() const;
  std::vector<int> hessian_subset;  // ascending indices into centers (the set H)
  Vec3 origin = Vec3::Zero();       // grid origin: center of cell (i,j,k) = origin + ((i,j,k) + 0.5) h
  MatX3i grid_index;          // #I by 3 cell indices (i,j,k); empty when the centers are not on one grid
  double safety = 0;          // clearance factor the centers satisfy (0 = unknown, e.g. published samples)
  int search_iterations = 0;  // voxel-side evaluations the count search used
  bool target_met = true;     // false if the search ended without reaching the count tolerance
  // What the voxels cover: "voxels" (sample_voxels: the grid cells clear of the cage) or "mesh"
  // (sample_domain: every cell meeting the mesh's triangles or solid, refined until clear of the cage).
  std::string domain = "voxels";
  long uncleared = 0;  // mesh domain: leaves meeting D still not clear of the cage at the maximum depth
  int size() const { return static_cast<int>(centers.rows()); }
};

// Samples the interior of `cage` on a regular grid aligned with the cage's bounding-box minimum.
// The grid is laid out and the side searched in the cage's normalized frame (normalization.h) and returned in
// model units (params.voxel_side is in model units too), so a translated or scaled copy of a model gets the
// same voxels up to the transform.
// Deterministic: the same cage and parameters give bit-identical output, whatever the thread count.
// When the count search cannot reach the tolerance (tiny targets), returns the closest count found with
// target_met = false. Throws InputError on bad parameters or a cage with non-positive volume.
VoxelSampling sample_voxels(const Cage& cage, const SamplingParams& params = SamplingParams());

// Throws InputError (naming the cage) on parameters no sampler accepts, or a cage of non-positive volume.
void check_sampling_params(const Cage& cage, const SamplingParams& params);

// The voxel-side search shared by the samplers: from h0, secant steps in log space on count(h) ≈ C / h³,
// safeguarded by bisection, until |count − target_count| ≤ count_tolerance · target_count or
// max_search_iterations; returns the side with the closest count and the number of evaluations.
struct SideSearch {
  double side = 0;
  int iterations = 0;
};
SideSearch search_voxel_side(const SamplingParams& params, double h0,
                             const std::function<long(double)>& count);

// The Hessian subset rule: samples ordered along a Morton (Z-order) curve of their grid indices, cut into
// |H| = round(fraction · #I) strata of consecutive ranks, one pick per stratum at a golden-ratio offset
// (stratified sampling along a space-filling curve). H is spread evenly in 3D without the aliasing of
// "every k-th in scan order", which can put all of H on one plane. Without grid indices the stored order
// is used instead of the curve.
// Returns ascending indices into sampling.centers; at least one when fraction > 0 and #I > 0.
std::vector<int> select_hessian_subset(const VoxelSampling& sampling, double fraction);

// For each point (#P by 3), the index of a voxel (closed cube of side side_of(i)) containing it, or -1.
VecXi containing_voxel(const VoxelSampling& sampling, const MatX3d& points);

// containing_voxel's lookup (buckets of the base side), built once for many queries on the same sampling
// (the line search's probes, every trial: building it is most of what a probe-refused trial cost, docs/
// benchmarks.md). Keeps a reference to the sampling, which must outlive it.
class VoxelLocator {
 public:
  explicit VoxelLocator(const VoxelSampling& sampling);
  VecXi find(const MatX3d& points) const;  // #P by 3 → the voxel index or -1, as containing_voxel

 private:
  const VoxelSampling& s_;
  Vec3 origin_ = Vec3::Zero();
  std::unordered_map<std::uint64_t, std::vector<int>> buckets_;
};

// Fraction of mesh vertices (#V by 3) inside the union of the voxels (closed cubes).
double mesh_coverage(const VoxelSampling& sampling, const MatX3d& mesh_V);

// Reads the paper's samples.xyz (one "x y z" per line; blank lines and '#' comments skipped) as cubes of
// side voxel_side (model.json: samples.voxel_side) centered at the points. grid_index is filled when the
// points lie on one grid of that spacing. Throws InputError with the line number on malformed input.
VoxelSampling load_published_samples(const std::string& samples_xyz, double voxel_side,
                                     double hessian_fraction = 0.05);

}  // namespace lidef
