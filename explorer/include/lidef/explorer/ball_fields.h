// σ's of an explorer map sampled on a regular grid over the ball's bounding cube (fields.vti of
// `lidef explore show`, the studio's ranges).
#pragma once
#include <vector>

#include "lidef/explorer/explorer_map.h"
#include "lidef/types.h"

namespace lidef {

// n³ points, x fastest: point (i, j, k) = origin + spacing (i, j, k); NaN (and inside = 0) outside the ball.
struct BallFieldGrid {
  int n = 0;
  Vec3 origin = Vec3::Zero();
  double spacing = 0;
  std::vector<float> sigma1, sigma2, sigma3, det_j;  // n³ each
  std::vector<unsigned char> inside;                 // n³
};
// resolution: points per axis (2..1024).
BallFieldGrid compute_ball_fields(const ExplorerMap& map, const Ball& ball, int resolution);

}  // namespace lidef
