// The boundary sphere of the ball and its image (docs/explorer.md, items 4 and 5 of "verified"): the quick
// check that the triangulated image is embedded, and the sound certificate that a polynomial map is injective
// on the sphere.
#pragma once
#include <array>
#include <string>

#include "lidef/explorer/explorer_map.h"
#include "lidef/explorer/harmonic_polynomials.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

// An icosphere of the ball (`subdivisions` times subdivided) mapped vertex by vertex, checked for
// self-intersections with exact predicates (self_intersections.h): a check of the piecewise-linear image at
// this resolution, not of the smooth surface.
struct BoundaryEmbedding {
  bool embedded = false;
  int subdivisions = 0;
  long intersecting_pairs = 0;
  TriMesh source;             // the icosphere on the ball's boundary
  TriMesh image;              // its image (same faces)
  double min_image_edge = 0;  // shortest image edge (degenerate triangles would be skipped by the check)
  double signed_volume = 0;   // enclosed by the image (> 0: orientation preserved)
};
BoundaryEmbedding check_boundary_embedding(const ExplorerMap& map, const Ball& ball, int subdivisions = 5);

// Injectivity of a polynomial map on the sphere from σ3 > s > 0 certified on the ball (threshold
// `sigma3_threshold`; H ≥ max ‖H‖ and G ≥ max ‖J‖_F from that certificate, ρ = s / H): pairs closer than ρ
// by the local argument, the others on an icosphere net (`subdivisions`) whose linear images must be more
// than δ1 + δ2 apart (δ_T = G sag_T + ½ H e_T²). The argument is in docs/explorer.md.
struct BoundaryInjectivity {
  bool certified = false;
  std::string reason;
  double sigma3_lower = 0;    // s
  double hessian_bound = 0;   // H
  double jacobian_bound = 0;  // G
  double rho = 0;
  int subdivisions = 0;
  long triangles = 0;
  long pairs_measured = 0;     // pairs whose distance had to be computed
  double max_delta = 0;        // max δ_T
  double min_pair_margin = 0;  // min over measured pairs of distance − δ1 − δ2 (+inf when none)
};
BoundaryInjectivity certify_boundary_injective(const HarmonicPolynomialMap& map, const Ball& ball,
                                               double sigma3_threshold, int subdivisions = 6,
                                               int max_depth = 8);

// Distance between two triangles (3 corners each) that do not intersect: the smallest of the 6
// vertex-triangle and 9 edge-edge distances (for intersecting triangles it is not 0, so callers check
// intersections first).
double disjoint_triangle_distance(const std::array<Vec3, 3>& A, const std::array<Vec3, 3>& B);

}  // namespace lidef
