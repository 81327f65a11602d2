#include "lidef/signed_svd.h"

#include <Eigen/SVD>

namespace lidef {

SignedSvd signed_svd(const Mat3& J) {
  Eigen::JacobiSVD<Mat3> svd(J, Eigen::ComputeFullU | Eigen::ComputeFullV);
  SignedSvd out{svd.matrixU(), svd.matrixV(), svd.singularValues()};
  // Make U and V rotations; each reflection removed flips the sign of the smallest singular value.
  if (out.U.determinant() < 0) {
    out.U.col(2) *= -1;
    out.sigma(2) *= -1;
  }
  if (out.V.determinant() < 0) {
    out.V.col(2) *= -1;
    out.sigma(2) *= -1;
  }
  return out;
}

Vec3 signed_singular_values(const Mat3& J) {
  Vec3 s = Eigen::JacobiSVD<Mat3>(J).singularValues();
  if (J.determinant() < 0) s(2) = -s(2);
  return s;
}

}  // namespace lidef
