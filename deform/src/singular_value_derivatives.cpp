#include "lidef/singular_value_derivatives.h"

#include <algorithm>
#include <cmath>

#include "lidef/signed_svd.h"

namespace lidef {

SigmaDerivatives sigma_derivatives(const Mat3& J, const std::array<Mat3, 3>& dJ,
                                   const std::array<std::array<Mat3, 3>, 3>* d2J) {
  const SignedSvd svd = signed_svd(J);
  SigmaDerivatives out;
  out.sigma = svd.sigma;
  std::array<Mat3, 3> M;
  for (int k = 0; k < 3; ++k) M[k] = svd.U.transpose() * dJ[k] * svd.V;
  for (int i = 0; i < 3; ++i) {
    double g = INFINITY;
    for (int j = 0; j < 3; ++j)
      if (j != i)
        g = std::min({g, std::abs(svd.sigma(i) - svd.sigma(j)), std::abs(svd.sigma(i) + svd.sigma(j))});
    out.gap(i) = g;
    for (int k = 0; k < 3; ++k) out.grad(i, k) = M[k](i, i);
  }
  if (!d2J) return out;
  for (int i = 0; i < 3; ++i) {
    Mat3& Hi = out.hess[i];
    for (int k = 0; k < 3; ++k)
      for (int l = k; l < 3; ++l) {
        double h = svd.U.col(i).dot((*d2J)[k][l] * svd.V.col(i));
        for (int j = 0; j < 3; ++j) {
          if (j == i) continue;
          const double sk = M[k](j, i) + M[k](i, j), sl = M[l](j, i) + M[l](i, j);
          const double ak = M[k](j, i) - M[k](i, j), al = M[l](j, i) - M[l](i, j);
          h += 0.5 * (sk * sl / (svd.sigma(i) - svd.sigma(j)) + ak * al / (svd.sigma(i) + svd.sigma(j)));
        }
        Hi(k, l) = Hi(l, k) = h;
      }
    out.laplacian(i) = Hi.trace();
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) {
        if (j == i) continue;
        const double sk = M[k](j, i) + M[k](i, j), ak = M[k](j, i) - M[k](i, j);
        out.laplacian_symmetric(i) += 0.5 * sk * sk / (svd.sigma(i) - svd.sigma(j));
        out.laplacian_antisymmetric(i) += 0.5 * ak * ak / (svd.sigma(i) + svd.sigma(j));
      }
  }
  return out;
}

}  // namespace lidef
