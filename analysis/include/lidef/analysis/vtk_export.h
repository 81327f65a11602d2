// Files for ParaView: the certification octree as an unstructured grid (.vtu) and map fields on a regular
// grid
// (.vti). This header is VTK-free; VTK (9.1) is linked privately by lidef_analysis. Arrays and suggested
// filters: docs/outputs.md.
//
// Writes are atomic: each writer writes `path.tmp.<pid>.<ext>` and renames it over `path`; on failure the
// temporary is removed, `path` is untouched and InputError(path, ...) is thrown. Files are VTK XML, appended
// raw binary, zlib-compressed.
#pragma once
#include <string>
#include <vector>

#include "lidef/analysis/field_grid.h"
#include "lidef/cage.h"
#include "lidef/green_coordinates.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// The leaves as VTK_HEXAHEDRON cells (8 unshared points each, axis-aligned cubes) with cell data:
//   depth (Int32), side, sigma3, L, margin (Float64; sigma3 NaN and L inf for leaves left unevaluated when a
//   refinement budget ran out), status (UInt8: 1 certified, 0 not).
void write_leaves_vtu(const std::string& path, const std::vector<CertLeaf>& leaves);

// Writes a FieldGrid as .vti with point data sigma1, sigma3, detJ, E_iso (Float32), inside_cage,
// inside_sampled (UInt8).
void write_field_vti(const std::string& path, const FieldGrid& grid);

// compute_field_grid + write_field_vti. Returns the grid (for summaries).
FieldGrid write_field_vti(const std::string& path, const Cage& cage, const HarmonicBasis& basis,
                          const MatX3d& y, const VoxelSampling& sampling, int resolution = 64);

}  // namespace lidef
