#include "lidef/symmetric_dirichlet.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "lidef/signed_svd.h"

namespace lidef {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// q = vec(U M Vᵀ) (column-major) for M = (e_i e_jᵀ + s e_j e_iᵀ)/√2, i.e. (u_i v_jᵀ + s u_j v_iᵀ)/√2.
Vec9 lifted_pair(const SignedSvd& d, int i, int j, double s) {
  const Mat3 M =
      (d.U.col(i) * d.V.col(j).transpose() + s * d.U.col(j) * d.V.col(i).transpose()) * std::sqrt(0.5);
  return Eigen::Map<const Vec9>(M.data());
}

// Σ_k f(λ_k) q_k q_kᵀ over the 9 analytic eigenpairs (see the header), f = identity or max(·, 0).
Mat9 hessian_from_eigensystem(const Mat3& J, bool clamp) {
  if (!(J.determinant() > 0)) return Mat9::Constant(kNaN);
  const SignedSvd d = signed_svd(J);
  const Vec3& s = d.sigma;  // all > 0 here (det > 0)
  auto keep = [clamp](double lambda) { return clamp ? std::max(lambda, 0.0) : lambda; };

  Mat9 H = Mat9::Zero();
  // Scaling modes: ∂²E/∂σ_i∂σ_j is diagonal for SD (E separates in σ), eigenvectors vec(u_i v_iᵀ).
  for (int i = 0; i < 3; ++i) {
    const double lambda = keep(2.0 + 6.0 / (s(i) * s(i) * s(i) * s(i)));
    const Mat3 M = d.U.col(i) * d.V.col(i).transpose();
    const Vec9 q = Eigen::Map<const Vec9>(M.data());
    H.noalias() += lambda * q * q.transpose();
  }
  // Twist and flip modes of each pair.
  const int pairs[3][2] = {{0, 1}, {1, 2}, {0, 2}};
  for (const auto& p : pairs) {
    const double a = s(p[0]), b = s(p[1]);
    const double c = a * a * a * b * b * b;
    const double twist = 2.0 - 2.0 * (a * a - a * b + b * b) / c;
    const double flip = 2.0 + 2.0 * (a * a + a * b + b * b) / c;
    const double lt = keep(twist), lf = keep(flip);
    const Vec9 qt = lifted_pair(d, p[0], p[1], -1.0);
    const Vec9 qf = lifted_pair(d, p[0], p[1], +1.0);
    H.noalias() += lt * qt * qt.transpose();
    H.noalias() += lf * qf * qf.transpose();
  }
  // Exact symmetry (the rank-one sums are symmetric up to rounding of the products).
  return 0.5 * (H + H.transpose());
}

}  // namespace

double sd_energy(const Mat3& J) {
  const double det = J.determinant();
  if (!(det > 0)) return kInf;
  const double e = J.squaredNorm() + J.inverse().squaredNorm();
  return std::isfinite(e) ? e : kInf;
}

Mat3 sd_gradient(const Mat3& J) {
  if (!(J.determinant() > 0)) return Mat3::Constant(kNaN);
  const Mat3 Jinv = J.inverse();
  const Mat3 JinvT = Jinv.transpose();
  return 2.0 * J - 2.0 * JinvT * Jinv * JinvT;
}

Mat3 sd_hessian_times(const Mat3& J, const Mat3& dJ) {
  if (!(J.determinant() > 0)) return Mat3::Constant(kNaN);
  // ∇E = 2J − 2 Aᵀ A Aᵀ with A = J⁻¹ and dA = −A dJ A, so d(Aᵀ A Aᵀ) = −(B X B Bᵀ B + B Bᵀ dJ Bᵀ B + B Bᵀ B X
  // B) with B = Aᵀ, X = dJᵀ.
  const Mat3 B = J.inverse().transpose();
  const Mat3 BBt = B * B.transpose(), BtB = B.transpose() * B;
  const Mat3 XB = dJ.transpose() * B;
  return 2.0 * dJ + 2.0 * (B * XB * B.transpose() * B + BBt * dJ * BtB + BBt * B * XB);
}

Mat9 sd_hessian(const Mat3& J) {
  return hessian_from_eigensystem(J, false);
}

Mat9 sd_hessian_psd(const Mat3& J) {
  return hessian_from_eigensystem(J, true);
}

}  // namespace lidef
