#include "pick.h"

#include "lidef/mesh_fields.h"
#include "lidef/number_format.h"
#include "lidef/signed_svd.h"

namespace lidef::studio {

const CertLeaf* leaf_at(const Certificate& c, const Vec3& p) {
  const CertLeaf* best = nullptr;
  for (const CertLeaf& l : c.leaves) {
    const double h = 0.5 * l.side * (1 + 1e-6);
    if ((p - l.center).cwiseAbs().maxCoeff() > h) continue;
    if (!best || l.depth > best->depth) best = &l;
  }
  return best;
}

PickedValues picked_values(const SessionFrame& f, const Vec3& p, const std::string& where) {
  PickedValues v;
  if (!f.model || f.coefficients.rows() == 0) return v;
  const HarmonicBasis basis(f.model->cage);
  const MapJet jet = basis.map_jet(f.coefficients, p, 1);  // as lidef eval
  const Vec3 s = signed_singular_values(jet.J);
  v.valid = true;
  v.where = where;
  v.rest = p;
  v.image = jet.f;
  v.sigma1 = s(0);
  v.sigma3 = s(2);
  v.det_j = jet.J.determinant();
  v.e_iso = mesh_fields(basis, f.coefficients, p.transpose()).e_iso(0);  // the mesh view's E_iso − 6
  if (f.leaves) {
    if (const CertLeaf* l = leaf_at(*f.leaves, p)) {
      v.has_leaf = true;
      v.leaf = *l;
    }
  }
  return v;
}

std::string to_text(const PickedValues& v) {
  if (!v.valid) return "nothing picked (hover, Ctrl+click in the mesh view, click in the other views)";
  auto xyz = [](const Vec3& x) {
    return "(" + format_g(x(0), 5) + ", " + format_g(x(1), 5) + ", " + format_g(x(2), 5) + ")";
  };
  std::string t = v.where + "\np = " + xyz(v.rest) + "\nf(p) = " + xyz(v.image) +
                  "\nsigma1 = " + format_g(v.sigma1, 6) + "\nsigma3 = " + format_g(v.sigma3, 6) +
                  "\ndet J = " + format_g(v.det_j, 6) + "\nE_iso - 6 = " + format_g(v.e_iso, 6);
  if (v.has_leaf)
    t += "\nleaf: depth " + std::to_string(v.leaf.depth) + ", L = " + format_g(v.leaf.L, 5) +
         ", margin sigma3 - rL = " + format_g(v.leaf.margin, 5) + ", " +
         (v.leaf.certified ? "certified" : "NOT certified");
  return t;
}

}  // namespace lidef::studio
