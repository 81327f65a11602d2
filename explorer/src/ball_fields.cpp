#include "lidef/explorer/ball_fields.h"

#include <cmath>

#include "lidef/errors.h"
#include "lidef/signed_svd.h"

namespace lidef {

BallFieldGrid compute_ball_fields(const ExplorerMap& map, const Ball& ball, int resolution) {
  if (resolution < 2 || resolution > 1024) throw InputError("--grid", "must be in 2..1024");
  BallFieldGrid g;
  g.n = resolution;
  g.origin = ball.center - Vec3::Constant(ball.radius);
  g.spacing = 2 * ball.radius / (resolution - 1);
  const long n3 = static_cast<long>(resolution) * resolution * resolution;
  g.sigma1.assign(n3, NAN);
  g.sigma2.assign(n3, NAN);
  g.sigma3.assign(n3, NAN);
  g.det_j.assign(n3, NAN);
  g.inside.assign(n3, 0);
#pragma omp parallel for schedule(dynamic)
  for (long idx = 0; idx < n3; ++idx) {
    const long i = idx % resolution, j = (idx / resolution) % resolution, k = idx / (resolution * resolution);
    const Vec3 p = g.origin + g.spacing * Vec3(i, j, k);
    if (!ball.contains(p)) continue;
    const Mat3 J = map.jacobian(p);
    const Vec3 s = signed_singular_values(J);
    g.sigma1[idx] = static_cast<float>(s(0));
    g.sigma2[idx] = static_cast<float>(s(1));
    g.sigma3[idx] = static_cast<float>(s(2));
    g.det_j[idx] = static_cast<float>(J.determinant());
    g.inside[idx] = 1;
  }
  return g;
}

}  // namespace lidef
