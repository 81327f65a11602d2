#include "lidef/mesh_fields.h"

#include <algorithm>
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
  // The basis values and gradients by the SIMD kernel (evaluate_rows: evaluate()'s numbers,
  // HarmonicBasis::kLanes points at a time) a block of points per task, contracted with y in map_jet's order,
  // so that f and J are map_jet's at each point at a fraction of the time.
  const Eigen::Index n = P.rows(), nb = basis.size();
  constexpr Eigen::Index kBlock = 64;
  MatX3d V(n, 3);
  MatXd JT(3 * n, 3);
#pragma omp parallel
  {
    MatXdR rows;
#pragma omp for schedule(dynamic, 1)
    for (Eigen::Index b = 0; b < (n + kBlock - 1) / kBlock; ++b) {
      const Eigen::Index i0 = b * kBlock, m = std::min(kBlock, n - i0);
      basis.evaluate_rows(P.middleRows(i0, m), true, true, false, rows);
      for (Eigen::Index i = 0; i < m; ++i) {
        Vec3 f = Vec3::Zero();
        Mat3 J = Mat3::Zero();
        for (Eigen::Index k = 0; k < nb; ++k) {
          const Vec3 yk = y.row(k).transpose();
          f += yk * rows(4 * i, k);
          J += yk * Eigen::RowVector3d(rows(4 * i + 1, k), rows(4 * i + 2, k), rows(4 * i + 3, k));
        }
        V.row(i0 + i) = f.transpose();
        JT.middleRows(3 * (i0 + i), 3) = J.transpose();
      }
    }
  }
  return mesh_fields(std::move(V), JT, options);
}

}  // namespace lidef
