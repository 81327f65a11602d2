// The cage: a closed, edge-manifold, outward-oriented triangle mesh bounding the domain Ω.
// Holds the per-cage constants every other stage needs (normals, areas, undirected edges).
#pragma once
#include <vector>

#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

// An undirected cage edge with its two incident faces. f0 traverses the edge as v0 -> v1,
// f1 as v1 -> v0 (consistent orientation). lv0/lv1 is the local index (0..2) of the vertex
// *opposite* to the edge in f0/f1.
struct CageEdge {
  int v0, v1;
  int f0, f1;
  int lv0, lv1;
};

class Cage {
 public:
  // Builds the cage constants. Throws InputError if the mesh is not closed and edge-manifold or has
  // a degenerate face (full validation with all warnings lives in model_check.h).
  explicit Cage(const TriMesh& mesh);

  int num_vertices() const { return static_cast<int>(V.rows()); }
  int num_faces() const { return static_cast<int>(F.rows()); }
  int num_edges() const { return static_cast<int>(edges.size()); }
  // Number of harmonic basis functions = rows of the coefficient matrix y.
  int num_coeffs() const { return num_vertices() + num_faces(); }

  // Winding number Σ_t ω_t of the cage around p (1 inside, 0 outside, 2 in self-intersection pockets).
  double winding_number(const Vec3& p) const;

  // Coefficients reproducing the identity map: #V+#F by 3, rows y_v = v then y_t = n_t.
  MatX3d identity_coefficients() const;

  // Coefficients reproducing the affine map p -> A p + b: y_v = A v + b, y_t = A n_t.
  MatX3d affine_coefficients(const Mat3& A, const Vec3& b) const;

  // Unsigned distance from p to the cage surface (brute force over faces).
  double distance(const Vec3& p) const;

  MatX3d V;                     // #V by 3
  MatX3i F;                     // #F by 3
  MatX3d N;                     // #F by 3 unit outward normals
  VecXd area;                   // #F face areas
  std::vector<CageEdge> edges;  // #E undirected edges (any genus: #E counted, not assumed)
  double volume = 0;            // signed enclosed volume (> 0 for outward orientation)
  Vec3 bbox_min, bbox_max;
  std::string source;
};

}  // namespace lidef
