// Per-vertex fields of a map at the vertices of a mesh: deformed positions, E_iso − 6, det J and (optionally)
// the smallest signed singular value σ3, the largest σ1 and the distortion σ1/σ3. The one computation behind
// `lidef deform`'s deformed.vtp, the comparison driver's per-method fields and the studio's frames.
#pragma once
#include "lidef/green_coordinates.h"
#include "lidef/types.h"

namespace lidef {

struct MeshFields {
  MatX3d V;      // #V by 3: deformed positions f(v_i)
  VecXd e_iso;   // #V: E_iso − 6 = symmetric Dirichlet energy − 6; NaN where det J ≤ 0 (or the energy
                 //     is not finite), so that means over a mesh stay finite and a count of NaN says the rest
  VecXd det_j;   // #V: det J, the local volume ratio
  VecXd sigma3;  // #V: smallest signed singular value of J; empty unless MeshFieldOptions::sigma3
  VecXd sigma1;  // #V: largest singular value of J (with sigma3)
  VecXd distortion;  // #V: σ1/σ3, NaN where σ3 ≤ 0 (with sigma3)
};

struct MeshFieldOptions {
  bool sigma3 = false;  // also σ3, σ1 and σ1/σ3 (a signed SVD per vertex)
};

// Fields from given positions and Jacobians.
//   V   #V by 3: deformed positions (moved into the result)
//   JT  3#V by 3: rows 3i..3i+2 = J(v_i)ᵀ (the layout of HarmonicBasis::gradient_matrix(P) * y)
MeshFields mesh_fields(MatX3d V, const MatXd& JT, const MeshFieldOptions& options = {});

// Fields of the harmonic map f = Φ y at the points P.
//   y  #V+#F by 3: full-space coefficients of the map
//   P  #P by 3: rest-space points (the mesh vertices)
MeshFields mesh_fields(const HarmonicBasis& basis, const MatX3d& y, const MatX3d& P,
                       const MeshFieldOptions& options = {});

}  // namespace lidef
