// Values at a picked point: σ1, σ3, det J and E_iso − 6 of the frame's map at a rest-space
// point — computed as `lidef eval` computes them (HarmonicBasis::map_jet, signed_singular_values) and E_iso
// as the mesh view's field (mesh_fields) — and, when the frame has the certificate's leaves, the leaf that
// holds the point (depth, L, margin, status). No Qt or VTK here.
#pragma once
#include <string>

#include "lidef/analysis/interactive_session.h"

namespace lidef::studio {

struct PickedValues {
  bool valid = false;
  std::string where;  // what was picked: "mesh surface", "leaf voxel", "sigma3 slice"
  Vec3 rest = Vec3::Zero(), image = Vec3::Zero();  // p and f(p)
  double sigma1 = 0, sigma3 = 0, det_j = 0, e_iso = 0;
  bool has_leaf = false;
  CertLeaf leaf;
};

// The values of `f`'s map at the rest-space point p. `where` is copied into the result.
PickedValues picked_values(const SessionFrame& f, const Vec3& p, const std::string& where);

// The leaf of `c` whose voxel holds p (closed box, relative slack 1e-6 of its side); the deepest such leaf
// when p lies on a shared face; nullptr when none does.
const CertLeaf* leaf_at(const Certificate& c, const Vec3& p);

// Several lines for the picked-values panel.
std::string to_text(const PickedValues& v);

}  // namespace lidef::studio
