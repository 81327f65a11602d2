#include "lidef/internal/distortion_screen.h"

#include <omp.h>

#include <Eigen/Eigenvalues>
#include <cmath>

namespace lidef {

namespace {

// The excess of one Jacobian (≤ 0: skipped, det ≤ 0 or a non-positive smallest eigenvalue of JᵀJ), and its
// singular values σ1, σ3 where s1, s3 are given.
double excess_of(const Mat3& J, const DistortionTargets& targets, double* s1 = nullptr,
                 double* s3 = nullptr) {
  if (!(J.determinant() > 0)) return -1;
  Eigen::SelfAdjointEigenSolver<Mat3> es;
  es.computeDirect(J.transpose() * J, Eigen::EigenvaluesOnly);
  const double lo = es.eigenvalues()(0), hi = es.eigenvalues()(2);
  if (!(lo > 0)) return -1;
  if (s1) *s1 = std::sqrt(hi);
  if (s3) *s3 = std::sqrt(lo);
  return targets.excess(std::sqrt(hi), std::sqrt(lo), std::sqrt(hi / lo));
}

// The sample of largest excess among those `consider` admits (ties to the smaller index, the same for any
// thread count).
template <class Consider>
long largest_excess(const MatJT& J0, const MatJT& dJ, double t, const DistortionTargets& targets,
                    const Consider& consider, double* excess) {
  const long n = J0.rows() / 3;
  long best = -1;
  double best_k = 0;
#pragma omp parallel
  {
    long b = -1;
    double bk = 0;
#pragma omp for schedule(static) nowait
    for (long i = 0; i < n; ++i) {
      if (!consider(i)) continue;
      const double k = excess_of(J0.middleRows<3>(3 * i) + t * dJ.middleRows<3>(3 * i), targets);
      if (k > bk) bk = k, b = i;  // the first of equal excesses within this thread's ascending range
    }
#pragma omp critical
    if (b >= 0 && (bk > best_k || (bk == best_k && b < best))) best_k = bk, best = b;
  }
  *excess = best_k;
  return best;
}

}  // namespace

long largest_excess_sample(const MatJT& J0, const MatJT& dJ, double t, const DistortionTargets& targets,
                           double* excess) {
  return largest_excess(
      J0, dJ, t, targets, [](long) { return true; }, excess);
}

DistortionScreen::DistortionScreen(const MatJT& J0, const MatJT& dJ) : J0_(J0), dJ_(dJ) {
  const long n = J0.rows() / 3;
  s1_.resize(n);
  s3_.resize(n);
  dn_.resize(n);
  const DistortionTargets none{};
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i) {
    double a = -1, b = -1;  // stay −1 where excess_of skips the sample
    excess_of(J0.middleRows<3>(3 * i), none, &a, &b);
    s1_(i) = a;
    s3_(i) = b;
    dn_(i) = dJ.middleRows<3>(3 * i).norm();
  }
}

long DistortionScreen::largest_excess_sample(double t, const DistortionTargets& targets,
                                             double* excess) const {
  constexpr double kMargin = 1 - 1e-6;
  auto may_exceed = [&](long i) {
    if (!(s3_(i) > 0)) return true;
    const double m = t * dn_(i);
    const double hi = s1_(i) + m, lo = s3_(i) - m;
    if (!(lo > 0)) return true;
    return !(targets.excess(hi, lo, hi / lo) < kMargin);
  };
  return largest_excess(J0_, dJ_, t, targets, may_exceed, excess);
}

}  // namespace lidef
