// The scripted drag of the benchmarks that time interactive use (bench_studio in the window, bench_opencl on
// the engine alone): the pushed handles circle around their scenario targets.
#pragma once
#include <cmath>

#include "lidef/types.h"

namespace lidef::bench {

// Targets at time t (seconds) of a drag: each handle whose target differs from its source (#h by 3 each)
// moves on a circle of radius `amp` in the x-z plane, one turn every 4 s, starting at its scenario target.
inline MatX3d drag_targets(const MatX3d& S, const MatX3d& T0, double t, double amp) {
  MatX3d T = T0;
  const double w = 2 * M_PI * t / 4.0;
  for (Eigen::Index i = 0; i < T.rows(); ++i)
    if ((T0.row(i) - S.row(i)).norm() > 1e-9) {
      T(i, 0) += amp * std::sin(w);
      T(i, 2) += amp * (1 - std::cos(w));
    }
  return T;
}

}  // namespace lidef::bench
