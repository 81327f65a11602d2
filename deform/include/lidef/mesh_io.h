// Reading and writing triangle meshes and point lists in plain text formats.
//
// Accepted formats (chosen by the file extension, case-insensitive):
//   .obj  `v x y z [extra numbers ignored]` and `f a b c` lines. Face corners may be written `a`, `a/t`,
//         `a//n` or `a/t/n`; only the vertex index is used. Indices are 1-based; negative indices count back
//         from the last vertex defined so far (-1 = previous vertex). Faces with more than 3 corners are
//         rejected rather than triangulated: the choice of diagonal changes a non-planar cage's geometry, and
//         keeping one triangle per `f` line keeps face numbers in messages equal to the file's `f` order.
//         vt/vn/vp/g/o/s/l/p/usemtl/mtllib lines and `#` comments are ignored; any other statement is an
//         error.
//   .off  `[C|N|ST...]OFF` header, `nv nf ne`, nv vertex lines (extra numbers such as colors ignored) and nf
//         face lines `3 a b c [color]` with 0-based indices; `#` comments.
// Every failure throws InputError(file, message, line) naming the file and, where it applies, the line.
#pragma once
#include <ostream>
#include <string>
#include <vector>

#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

// 1-based line numbers of the records a mesh was read from, so validators can point at the right line.
struct MeshLines {
  std::vector<long> vertex;  // #V: line of each `v` record
  std::vector<long> face;    // #F: line of each `f` record
};

// Reads a triangle mesh (.obj or .off). Returns V (#V by 3), F (#F by 3, 0-based) and source = path.
// Checks syntax, finite coordinates, index range and face arity; at least one vertex and one face.
// Does no topological or geometric validation (see model_check.h). `lines`, when given, receives the
// line of every vertex and face.
TriMesh read_mesh(const std::string& path, MeshLines* lines = nullptr);

// read_mesh, except that an OBJ file without `f` lines is read as a point set (F is 0 by 3): a model's mesh
// may be a point cloud (its certified domain is then the points, domain_sampling.h).
TriMesh read_mesh_or_points(const std::string& path, MeshLines* lines = nullptr);

// An ASCII .off file with faces of any size (the automatic cage's reader, cage/auto_cage.h): V (#V by 3) and
// each face's 0-based vertex indices. The same syntax checks as read_mesh (line-based: one vertex or face per
// line; extra numbers on a line — normals, colours — must be numbers and are ignored), but no arity check.
struct PolygonSoupMesh {
  MatX3d V;
  std::vector<std::vector<std::size_t>> polygons;
};
PolygonSoupMesh read_off_polygons(const std::string& path);

// Writes V (#V by 3) and F (#F by 3, 0-based) as OBJ with 1-based `f` lines. Coordinates use the shortest
// decimal form that reads back to the identical double (std::to_chars), so write/read round-trips exactly
// and the output is deterministic. `comment`, when non-empty, is written first as `# ...` lines.
void write_obj(std::ostream& out, const MatX3d& V, const MatX3i& F, const std::string& comment = "");

// Reads a point list: one `x y z` per line, or `x y z nx ny nz` (a point and its normal) on every line;
// blank lines and `#` comments are skipped. Returns #P by 3; normals (optional) gets #P by 3 normals, or 0
// rows when the file has 3 columns. Throws InputError for a missing/empty/binary file, a line whose count of
// numbers is not that of the first point (3 or 6), or a non-finite value.
MatX3d read_points_xyz(const std::string& path, MatX3d* normals = nullptr);
// Writes points (and normals, when it has #P rows) in that format, numbers in the shortest form that reads
// back to the same double.
void write_points_xyz(std::ostream& out, const MatX3d& P, const MatX3d& normals = MatX3d());

// The extension of a path with its dot, in lower case (".ply" for "a/B.PLY"; "" when there is none).
std::string lowercase_extension(const std::string& path);

}  // namespace lidef
