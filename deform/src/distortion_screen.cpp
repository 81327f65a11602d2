#include "lidef/internal/distortion_screen.h"

#include <omp.h>

#include <Eigen/Eigenvalues>
#include <cmath>

namespace lidef {

long largest_excess_sample(const MatJT& J0, const MatJT& dJ, double t, const DistortionTargets& targets,
                           double* excess) {
  const long n = J0.rows() / 3;
  long best = -1;
  double best_k = 0;
#pragma omp parallel
  {
    long b = -1;
    double bk = 0;
#pragma omp for schedule(static) nowait
    for (long i = 0; i < n; ++i) {
      const Mat3 J = J0.middleRows<3>(3 * i) + t * dJ.middleRows<3>(3 * i);
      if (!(J.determinant() > 0)) continue;
      Eigen::SelfAdjointEigenSolver<Mat3> es;
      es.computeDirect(J.transpose() * J, Eigen::EigenvaluesOnly);
      const double lo = es.eigenvalues()(0), hi = es.eigenvalues()(2);
      if (!(lo > 0)) continue;
      const double k = targets.excess(std::sqrt(hi), std::sqrt(lo), std::sqrt(hi / lo));
      if (k > bk) bk = k, b = i;  // the first of equal excesses within this thread's ascending range
    }
#pragma omp critical
    if (b >= 0 && (bk > best_k || (bk == best_k && b < best))) best_k = bk, best = b;
  }
  *excess = best_k;
  return best;
}

}  // namespace lidef
