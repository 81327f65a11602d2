// The CGAL part of lidef_cage (the only translation unit that includes CGAL; see cage/CMakeLists.txt).
#pragma once
#include <cstddef>
#include <string>
#include <vector>

#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef::cage_cgal {

// A polygon soup as the file holds it: #P by 3 points, polygons of any arity (0-based indices).
struct PolygonSoup {
  MatX3d points;
  std::vector<std::vector<std::size_t>> polygons;
};

// Reads `path` with CGAL's reader for `format` ("obj", "off", "ply", "stl"). Returns false when the reader
// fails (syntax, truncated binary data); the file is opened in binary mode.
bool read_polygon_soup(const std::string& path, const std::string& format, PolygonSoup& soup);

struct WrapResult {
  TriMesh cage;
  int wrap_faces = 0;
  int faces_within_clearance =
      0;  // cage triangles the clearance test cannot prove clear (wrap faces never collapsed)
  double seconds_wrap = 0, seconds_simplify = 0;
};

// CGAL::alpha_wrap_3 of `mesh`'s triangles, or of its points when it has no faces (absolute alpha and offset), then edge collapses (Lindstrom-Turk
// cost and placement) down to `target_faces` triangles, refusing every collapse after which a triangle around
// the new vertex would come closer than `clearance` to the mesh or flip its normal. Deterministic.
WrapResult wrap_and_simplify(const TriMesh& mesh, double alpha, double offset, double clearance,
                             int target_faces);

}  // namespace lidef::cage_cgal
