#include "lidef/analysis/certificate_verification.h"

#include <limits>
#include <random>

#include "lidef/signed_svd.h"

namespace lidef {

VerificationResult verify_certificate(const HarmonicBasis& basis, const MatX3d& y,
                                      const std::vector<CertLeaf>& leaves, int samples_per_voxel,
                                      unsigned seed) {
  VerificationResult res;
  const long nl = static_cast<long>(leaves.size());
  res.voxels.resize(nl);
  std::vector<std::vector<BoundViolation>> viol(nl);
  std::vector<long> nonpos(nl, 0);
  const int n = basis.size();
#pragma omp parallel
  {
    std::vector<double> gb(3 * n);
    // Signed singular values (σ1, σ2, σ3) at p.
    auto sigmas_at = [&](const Vec3& p) {
      basis.evaluate(p, 1, nullptr, gb.data(), nullptr);
      Mat3 J = Mat3::Zero();
      for (int k = 0; k < n; ++k)
        J.noalias() += y.row(k).transpose() * Eigen::Map<const Eigen::RowVector3d>(&gb[3 * k]);
      return Vec3(signed_singular_values(J));
    };
#pragma omp for schedule(dynamic, 16)
    for (long li = 0; li < nl; ++li) {
      const CertLeaf& lf = leaves[li];
      std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + static_cast<unsigned long long>(li));
      std::uniform_real_distribution<double> U(-0.5, 0.5);
      const double s3c = sigmas_at(lf.center)(2);
      VoxelVerification v{li, s3c, s3c, 0.0, lf.L, 0.0, 0};
      const int total = 8 + samples_per_voxel;
      for (int k = 0; k < total; ++k) {
        Vec3 off;
        if (k < 8)
          off = Vec3(k & 1 ? 0.5 : -0.5, k & 2 ? 0.5 : -0.5, k & 4 ? 0.5 : -0.5);
        else
          off = Vec3(U(rng), U(rng), U(rng));
        const Vec3 p = lf.center + lf.side * off;
        const Vec3 sv = sigmas_at(p);
        const double s3 = sv(2);
        // The distortion bounds, beyond the rounding of the SVD (relative 1e-10).
        const double K = s3 > 0 ? sv(0) / s3 : std::numeric_limits<double>::infinity();
        v.max_sigma1 = std::max(v.max_sigma1, sv(0));
        if (s3 > 0) v.max_distortion = std::max(v.max_distortion, K);
        if (sv(0) > lf.sigma1_upper * (1 + 1e-10) || K > lf.distortion_upper * (1 + 1e-10))
          ++v.distortion_violations;
        const double dist = (p - lf.center).norm();
        v.min_sigma3 = std::min(v.min_sigma3, s3);
        v.max_quotient = std::max(v.max_quotient, std::abs(s3 - s3c) / dist);
        const double bound = s3c - dist * lf.L;
        // A violation beyond rounding of the two σ3 evaluations.
        if (s3 < bound - 1e-10 * (1 + std::abs(s3c))) {
          ++v.violations;
          if (viol[li].size() < 10) viol[li].push_back({li, p, s3, bound});
        }
        if (lf.certified && s3 <= 0) ++nonpos[li];
      }
      v.tightness = lf.L > 0 ? v.max_quotient / lf.L : 0.0;
      res.voxels[li] = v;
    }
  }
  res.min_sigma3 = std::numeric_limits<double>::infinity();
  for (long li = 0; li < nl; ++li) {
    res.points += 9 + samples_per_voxel;
    if (leaves[li].certified) res.min_sigma3 = std::min(res.min_sigma3, res.voxels[li].min_sigma3);
    res.violations += res.voxels[li].violations;
    res.distortion_violations += res.voxels[li].distortion_violations;
    if (leaves[li].certified) {
      res.max_sigma1 = std::max(res.max_sigma1, res.voxels[li].max_sigma1);
      res.max_distortion = std::max(res.max_distortion, res.voxels[li].max_distortion);
    }
    res.nonpositive_in_certified += nonpos[li];
    for (const auto& bv : viol[li])
      if (res.violation_list.size() < 100) res.violation_list.push_back(bv);
  }
  return res;
}

}  // namespace lidef
