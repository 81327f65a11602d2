#include "lidef/analysis/field_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "lidef/errors.h"
#include "lidef/signed_svd.h"

namespace lidef {

long FieldGrid::count_inside_cage() const {
  return static_cast<long>(std::count(inside_cage.begin(), inside_cage.end(), 1));
}
long FieldGrid::count_inside_sampled() const {
  return static_cast<long>(std::count(inside_sampled.begin(), inside_sampled.end(), 1));
}

FieldGrid compute_field_grid(const Cage& cage, const HarmonicBasis& basis, const MatX3d& y,
                             const VoxelSampling& sampling, int resolution) {
  if (resolution < 2)
    throw InputError("", "field grid resolution must be >= 2 (got " + std::to_string(resolution) + ")");
  if (y.rows() != basis.size())
    throw InputError("", "coefficients have " + std::to_string(y.rows()) +
                             " rows, expected #V+#F = " + std::to_string(basis.size()));
  FieldGrid g;
  const Vec3 ext = cage.bbox_max - cage.bbox_min;
  g.spacing = ext.maxCoeff() / (resolution - 1);
  if (!(g.spacing > 0)) throw InputError(cage.source, "cage bounding box is empty");
  const Vec3 center = 0.5 * (cage.bbox_min + cage.bbox_max);
  for (int k = 0; k < 3; ++k) {
    // Enough points to cover the extent, centred on the box (the longest axis gets exactly `resolution`).
    const double cells = std::ceil(ext(k) / g.spacing - 1e-9);
    g.dims[k] = std::max(2, static_cast<int>(cells) + 1);
    g.origin(k) = center(k) - 0.5 * (g.dims[k] - 1) * g.spacing;
  }
  const long np = g.points();
  MatX3d P(np, 3);
  for (long i = 0; i < np; ++i) {
    const long ix = i % g.dims[0], iy = (i / g.dims[0]) % g.dims[1],
               iz = i / (static_cast<long>(g.dims[0]) * g.dims[1]);
    P.row(i) = (g.origin + g.spacing * Vec3(ix, iy, iz)).transpose();
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  g.sigma1.assign(np, nan);
  g.sigma3.assign(np, nan);
  g.det_j.assign(np, nan);
  g.e_iso.assign(np, nan);
  g.inside_cage.assign(np, 0);
  g.inside_sampled.assign(np, 0);
  const VecXi vox = containing_voxel(sampling, P);
  const int n = basis.size();
#pragma omp parallel
  {
    std::vector<double> gb(3 * static_cast<size_t>(n));
#pragma omp for schedule(dynamic, 256)
    for (long i = 0; i < np; ++i) {
      g.inside_sampled[i] = vox(i) >= 0 ? 1 : 0;
      const Vec3 p = P.row(i).transpose();
      const double w = cage.winding_number(p);
      if (!(w >= 0.5)) continue;
      basis.evaluate(p, 1, nullptr, gb.data(), nullptr);
      // A grid point on the cage itself (its winding number is rounding there) has no finite basis: f is not
      // defined, so it is not inside.
      bool finite = true;
      for (double v : gb) finite = finite && std::isfinite(v);
      if (!finite) continue;
      g.inside_cage[i] = 1;
      Mat3 J = Mat3::Zero();
      for (int k = 0; k < n; ++k)
        J.noalias() += y.row(k).transpose() * Eigen::Map<const Eigen::RowVector3d>(&gb[3 * k]);
      const Vec3 s = signed_singular_values(J);
      const double det = J.determinant();
      g.sigma1[i] = static_cast<float>(s(0));
      g.sigma3[i] = static_cast<float>(s(2));
      g.det_j[i] = static_cast<float>(det);
      if (det > 0) {
        double e = 0;
        for (int k = 0; k < 3; ++k) e += s(k) * s(k) + 1.0 / (s(k) * s(k));
        g.e_iso[i] = static_cast<float>(e);
      }
    }
  }
  return g;
}

}  // namespace lidef
