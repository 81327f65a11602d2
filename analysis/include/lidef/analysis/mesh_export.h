// Deformed surface meshes for ParaView: VTK XML PolyData (.vtp) with per-vertex arrays (e.g. σ3 or the
// displacement length at each mesh vertex). This header is VTK-free; VTK is linked privately by
// lidef_analysis.
//
// Like vtk_export.h: appended raw binary, zlib-compressed; written to `path.tmp.<pid>.vtp` and renamed over
// `path`, so a failed write leaves `path` untouched and no temporary behind.
#pragma once
#include <string>
#include <vector>

#include "lidef/types.h"

namespace lidef {

// One scalar per mesh vertex, written as Float64 point data named `name`.
struct PointArray {
  std::string name;
  VecXd values;  // #V
};

// Writes the triangles F (#F by 3, 0-based) over the vertices V (#V by 3) with the given point arrays; the
// first array becomes the active scalars. Throws InputError(path, ...) when an array does not hold #V values,
// array names are empty or repeated (VTK would keep only one of two equal names), a face index is out of
// range, or the file cannot be written.
void write_mesh_vtp(const std::string& path, const MatX3d& V, const MatX3i& F,
                    const std::vector<PointArray>& point_data);

}  // namespace lidef
