#include "lidef/explorer/explorer_map.h"

#include <array>

#include "lidef/errors.h"

namespace lidef {
namespace {

// dJ[k](a,b) = ∂²f_a/∂x_b∂x_k and d2J[k][l](a,b) = ∂³f_a/∂x_b∂x_k∂x_l from a jet.
void jacobian_derivatives(const PolyJet& j, std::array<Mat3, 3>& dJ,
                          std::array<std::array<Mat3, 3>, 3>& d2J) {
  for (int k = 0; k < 3; ++k)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        dJ[k](a, b) = j.H[a](b, k);
        for (int l = 0; l < 3; ++l) d2J[k][l](a, b) = j.T[a][b](k, l);
      }
}

}  // namespace

std::string PolynomialExplorerMap::description() const {
  return "harmonic polynomial map of degree " + std::to_string(map_.degree());
}

CageExplorerMap::CageExplorerMap(const Cage& cage, const MatX3d& y, std::string name, double fd_step)
    : cage_(cage), y_(y), basis_(cage_), name_(std::move(name)), h_(fd_step) {
  if (y.rows() != cage.num_coeffs()) throw InputError(name_, "coefficient rows do not match the cage");
}

Vec3 CageExplorerMap::value(const Vec3& p) const {
  return basis_.map_jet(y_, p, 0).f;
}

Mat3 CageExplorerMap::jacobian(const Vec3& p) const {
  return basis_.map_jet(y_, p, 1).J;
}

PolyJet CageExplorerMap::jet(const Vec3& p) const {
  const MapJet m = basis_.map_jet(y_, p, 2);
  PolyJet j;
  j.f = m.f;
  j.J = m.J;
  j.H = m.H;
  // T[a][b](c,d) = ∂_d H[a](b,c): central differences of the closed-form Hessian along each axis d.
  for (int d = 0; d < 3; ++d) {
    Vec3 e = Vec3::Zero();
    e(d) = h_;
    const MapJet mp = basis_.map_jet(y_, p + e, 2), mm = basis_.map_jet(y_, p - e, 2);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int c = 0; c < 3; ++c) j.T[a][b](c, d) = (mp.H[a](b, c) - mm.H[a](b, c)) / (2 * h_);
  }
  // Symmetrize over (b, c, d): the exact tensor is symmetric; this averages the difference errors.
  for (int a = 0; a < 3; ++a) {
    std::array<std::array<std::array<double, 3>, 3>, 3> s{};
    for (int b = 0; b < 3; ++b)
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d)
          s[b][c][d] = (j.T[a][b](c, d) + j.T[a][b](d, c) + j.T[a][c](b, d) + j.T[a][c](d, b) +
                        j.T[a][d](b, c) + j.T[a][d](c, b)) /
                       6;
    for (int b = 0; b < 3; ++b)
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d) j.T[a][b](c, d) = s[b][c][d];
  }
  return j;
}

SigmaDerivatives map_sigma_derivatives(const ExplorerMap& map, const Vec3& p, bool with_hessian) {
  const PolyJet j = map.jet(p);
  std::array<Mat3, 3> dJ;
  std::array<std::array<Mat3, 3>, 3> d2J;
  jacobian_derivatives(j, dJ, d2J);
  return sigma_derivatives(j.J, dJ, with_hessian ? &d2J : nullptr);
}

}  // namespace lidef
