// Point clouds: PLY files (ASCII, binary little and big endian) whose vertex element holds x y z and any
// other scalar properties (normals, colours, a Gaussian splat's parameters), with an optional face element;
// XYZ files (mesh_io.h, read_points_xyz); OBJ files with `v` lines only (mesh_io.h, read_mesh_or_points).
//
// Every vertex property is kept, in file order and with its PLY type, so a deformed cloud is written back
// with every property it did not change bit for bit (a float or integer property goes through a double
// exactly). Elements other than vertex and face are skipped. Every failure throws InputError(path, ...):
// no vertex element, a vertex without x, y or z, an empty cloud, a NaN or infinite coordinate, a truncated
// binary body, a face index out of range, a malformed header.
#pragma once
#include <ostream>
#include <string>
#include <vector>

#include "lidef/types.h"

namespace lidef {

struct PlyCloud {
  // "ascii", "binary_little_endian" or "binary_big_endian".
  std::string format = "binary_little_endian";
  std::vector<std::string> names;  // the vertex element's properties, file order
  std::vector<std::string> types;  // their PLY types (char uchar short ushort int uint float double, or
                                   // the aliases int8 uint8 int16 uint16 int32 uint32 float32 float64)
  MatXdR values;                   // #P by #names, every property as a double
  // Faces of the face element (polygons fan-triangulated v0 vi vi+1), 0-based; 0 rows when there is none.
  MatX3i F;
  std::vector<std::string> comments;  // the header's comment lines, without "comment "

  int column(const std::string& name) const;  // index in names, -1 when absent
  // #P by 3: the columns x y z (or nx ny nz, ...), each of which must exist.
  MatX3d columns3(const std::string& a, const std::string& b, const std::string& c) const;
  void set_columns3(const std::string& a, const std::string& b, const std::string& c, const MatX3d& P);
  MatX3d points() const { return columns3("x", "y", "z"); }
  bool has_normals() const { return column("nx") >= 0 && column("ny") >= 0 && column("nz") >= 0; }
};

// Reads a PLY file. Checks the header, the body's length (binary) or token count (ASCII), finite
// coordinates, at least one vertex and face index ranges.
PlyCloud read_ply_cloud(const std::string& path);

// The count of the face element of a PLY file's header (0 when there is none), for telling a point cloud
// from a mesh before reading the body. Throws InputError for a missing file or a malformed header.
long ply_face_count(const std::string& path);

// Writes `cloud` as PLY in cloud.format with the same properties and types (and faces as `vertex_indices`
// lists of 3). Floating-point values are written in the shortest form that reads back to the same double
// (ASCII) or in their type (binary); integer properties are rounded to their type.
void write_ply_cloud(std::ostream& out, const PlyCloud& cloud);

// Maps a cloud's positions (mapped: #P by 3, f(p_i)) and, when present, its normals nx ny nz by the cofactor
// matrix of J (the normal transform, cof J = det J · J⁻ᵀ), normalized; every other property is kept. JT: 3#P
// by 3, rows 3i..3i+2 = J(p_i)ᵀ (mesh_fields.h's layout).
void map_point_cloud(PlyCloud& cloud, const MatX3d& mapped, const MatXd& JT);

// Points (#P by 3) of a point-cloud file by extension: .ply (its vertices), .xyz, .obj (`v` lines; faces are
// ignored). Throws InputError for other extensions and for every read error.
MatX3d read_point_cloud(const std::string& path);

}  // namespace lidef
