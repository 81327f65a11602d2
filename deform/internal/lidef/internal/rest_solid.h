// The boundary of the solid of a closed triangle mesh that intersects itself, computed exactly
// (docs/certificate.md, Step G1, "A rest mesh that intersects itself").
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "lidef/types.h"

namespace lidef {

struct RestSolidBoundary {
  std::string problem;  // "" when the boundary was computed; otherwise why it was not
  // The triangles of ∂D, D = closure{x : w(mesh, x) ≥ 1}: #B by 3, indices into num_points distinct exact
  // points (pieces of the mesh triangles, their corners identified by their exact coordinates), oriented like
  // the mesh triangles they lie in, i.e. facing out of D.
  MatX3i F;
  int num_points = 0;
  MatX3d points;   // num_points by 3: the exact points rounded to double (for tests and pictures only)
  int pieces = 0;  // pieces of the split mesh, in ∂D or not
  int split_triangles = 0;  // mesh triangles that the intersection curves split into pieces
};

// mesh: (V #V by 3, F #F by 3), one closed, consistently oriented manifold surface; intersecting: its pairs
// of intersecting triangles (find_self_intersections). The mesh is split along its intersection curves with
// CGAL's exact autorefinement; the split is verified independently (each triangle's pieces lie in it, face
// its way and cover it; the pieces meet only in common corners and edges), the winding number on the outer
// side of every piece is counted exactly, and the pieces with 0 outside (and hence 1 inside) are returned.
RestSolidBoundary rest_solid_boundary(const MatX3d& V, const MatX3i& F,
                                      const std::vector<std::pair<int, int>>& intersecting);

}  // namespace lidef
