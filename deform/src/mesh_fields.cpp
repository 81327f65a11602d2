#include "lidef/mesh_fields.h"

#include <cmath>
#include <limits>

#include "lidef/signed_svd.h"
#include "lidef/symmetric_dirichlet.h"

namespace lidef {

MeshFields mesh_fields(MatX3d V, const MatXd& JT, const MeshFieldOptions& options) {
  MeshFields m;
  const Eigen::Index n = V.rows();
  m.V = std::move(V);
  m.e_iso.resize(n);
  m.det_j.resize(n);
  if (options.sigma3) {
    m.sigma3.resize(n);
    m.sigma1.resize(n);
    m.distortion.resize(n);
  }
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < n; ++i) {
    const Mat3 J = JT.middleRows(3 * i, 3).transpose();
    const double e = sd_energy(J);
    m.e_iso(i) = std::isfinite(e) ? e - 6.0 : std::numeric_limits<double>::quiet_NaN();
    m.det_j(i) = J.determinant();
    if (options.sigma3) {
      const Vec3 sv = signed_singular_values(J);
      m.sigma3(i) = sv(2);
      m.sigma1(i) = sv(0);
      m.distortion(i) = sv(2) > 0 ? sv(0) / sv(2) : std::numeric_limits<double>::quiet_NaN();
    }
  }
  return m;
}

MeshFields mesh_fields(const HarmonicBasis& basis, const MatX3d& y, const MatX3d& P,
                       const MeshFieldOptions& options) {
  MatX3d V;
  MatXd JT;
  basis.map_jets(y, P, V, JT);
  return mesh_fields(std::move(V), JT, options);
}

}  // namespace lidef
