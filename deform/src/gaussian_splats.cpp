#include "lidef/gaussian_splats.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>

#include "lidef/errors.h"

namespace lidef {
namespace {

const char* const kScales[] = {"scale_0", "scale_1", "scale_2"};
const char* const kRotations[] = {"rot_0", "rot_1", "rot_2", "rot_3"};

// Fixed, well-spread sample directions (a Fibonacci sphere) for fitting the SH rotation blocks.
std::vector<Vec3> sample_directions(int n) {
  std::vector<Vec3> d(static_cast<std::size_t>(n));
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n, r = std::sqrt(1.0 - z * z), t = golden * i;
    d[static_cast<std::size_t>(i)] = Vec3(r * std::cos(t), r * std::sin(t), z);
  }
  return d;
}

}  // namespace

bool is_gaussian_splat_cloud(const PlyCloud& cloud) {
  return cloud.column("scale_0") >= 0 && cloud.column("rot_0") >= 0;
}

PlyCloud read_gaussian_splats(const std::string& path) {
  PlyCloud cloud = read_ply_cloud(path);
  for (const char* s : kScales)
    if (cloud.column(s) < 0)
      throw InputError(path, std::string("splat PLY without scales (no property '") + s + "')");
  for (const char* s : kRotations)
    if (cloud.column(s) < 0)
      throw InputError(path, std::string("splat PLY without rotations (no property '") + s + "')");
  for (Eigen::Index i = 0; i < cloud.values.rows(); ++i) {
    double q2 = 0;
    for (const char* s : kRotations) q2 += std::pow(cloud.values(i, cloud.column(s)), 2);
    if (!(q2 > 0) || !std::isfinite(q2))
      throw InputError(path,
                       "splat " + std::to_string(i + 1) + ": rotation quaternion is zero or not finite");
    for (const char* s : kScales)
      if (!std::isfinite(cloud.values(i, cloud.column(s))))
        throw InputError(path, "splat " + std::to_string(i + 1) + ": " + s + " is NaN or infinite");
  }
  return cloud;
}

Mat3 splat_covariance(const Vec3& log_scale, const Eigen::Vector4d& q) {
  const Mat3 R = Eigen::Quaterniond(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
  const Vec3 s2 = (2.0 * log_scale).array().exp();
  return R * s2.asDiagonal() * R.transpose();
}

void splat_scale_rotation(const Mat3& sigma, Vec3* log_scale, Eigen::Vector4d* q) {
  const Eigen::SelfAdjointEigenSolver<Mat3> es(0.5 * (sigma + sigma.transpose()));
  Mat3 U = es.eigenvectors();  // eigenvalues ascending
  if (U.determinant() < 0) U.col(2) = -U.col(2);
  *log_scale = 0.5 * es.eigenvalues().array().log();
  Eigen::Quaterniond qq(U);
  qq.normalize();
  if (qq.w() < 0) qq.coeffs() = -qq.coeffs();
  *q = Eigen::Vector4d(qq.w(), qq.x(), qq.y(), qq.z());
}

Eigen::Matrix<double, 15, 1> sh_basis_degree1to3(const Vec3& d) {
  const double x = d(0), y = d(1), z = d(2), xx = x * x, yy = y * y, zz = z * z;
  const double C1 = 0.4886025119029199;
  const double C2[] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                       0.5462742152960396};
  const double C3[] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
                       -0.4570457994644658, 1.445305721320277, -0.5900435899266435};
  Eigen::Matrix<double, 15, 1> Y;
  Y << -C1 * y, C1 * z, -C1 * x,                                                                   //
      C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * zz - xx - yy), C2[3] * x * z, C2[4] * (xx - yy),  //
      C3[0] * y * (3 * xx - yy), C3[1] * x * y * z, C3[2] * y * (4 * zz - xx - yy),
      C3[3] * z * (2 * zz - 3 * xx - 3 * yy), C3[4] * x * (4 * zz - xx - yy), C3[5] * z * (xx - yy),
      C3[6] * x * (xx - 3 * yy);
  return Y;
}

Eigen::Matrix<double, 15, 15> sh_rotation(const Mat3& R) {
  static const std::vector<Vec3> dirs = sample_directions(32);
  const int n = static_cast<int>(dirs.size());
  Eigen::MatrixXd A(n, 15), B(n, 15);  // rows: Y(d)ᵀ and Y(Rᵀd)ᵀ
  for (int i = 0; i < n; ++i) {
    A.row(i) = sh_basis_degree1to3(dirs[static_cast<std::size_t>(i)]).transpose();
    B.row(i) = sh_basis_degree1to3(R.transpose() * dirs[static_cast<std::size_t>(i)]).transpose();
  }
  Eigen::Matrix<double, 15, 15> M = Eigen::Matrix<double, 15, 15>::Zero();
  const int start[] = {0, 3, 8}, size[] = {3, 5, 7};
  for (int band = 0; band < 3; ++band) {
    // Y_b(Rᵀd)ᵀ = Y_b(d)ᵀ M_bᵀ for every sample: A_b M_bᵀ = B_b.
    const Eigen::MatrixXd Ab = A.middleCols(start[band], size[band]),
                          Bb = B.middleCols(start[band], size[band]);
    const Eigen::MatrixXd MbT = Ab.colPivHouseholderQr().solve(Bb);
    M.block(start[band], start[band], size[band], size[band]) = MbT.transpose();
  }
  return M;
}

Mat3 polar_rotation(const Mat3& J) {
  const Eigen::JacobiSVD<Mat3> svd(J, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  const Mat3 V = svd.matrixV();
  if ((U * V.transpose()).determinant() < 0) U.col(2) = -U.col(2);
  return U * V.transpose();
}

void map_gaussian_splats(PlyCloud& cloud, const MatX3d& mapped, const MatXd& JT) {
  const Eigen::Index n = cloud.values.rows();
  if (mapped.rows() != n || JT.rows() != 3 * n)
    throw InputError("", "map_gaussian_splats: " + std::to_string(n) + " splats, " +
                             std::to_string(mapped.rows()) + " mapped points");
  int sc[3], rc[4];
  for (int k = 0; k < 3; ++k) sc[k] = cloud.column(kScales[k]);
  for (int k = 0; k < 4; ++k) rc[k] = cloud.column(kRotations[k]);
  int rest[45];
  bool has_rest = true;
  for (int k = 0; k < 45; ++k)
    has_rest = has_rest && (rest[k] = cloud.column("f_rest_" + std::to_string(k))) >= 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Mat3 J = JT.block<3, 3>(3 * i, 0).transpose();
    if (!(J.determinant() > 0))
      throw InputError("", "splat " + std::to_string(i + 1) + ": the map's Jacobian has det <= 0 there");
    auto row = cloud.values.row(i);
    const Vec3 s(row(sc[0]), row(sc[1]), row(sc[2]));
    const Eigen::Vector4d q(row(rc[0]), row(rc[1]), row(rc[2]), row(rc[3]));
    Vec3 s_new;
    Eigen::Vector4d q_new;
    splat_scale_rotation(J * splat_covariance(s, q) * J.transpose(), &s_new, &q_new);
    for (int k = 0; k < 3; ++k) row(sc[k]) = s_new(k);
    for (int k = 0; k < 4; ++k) row(rc[k]) = q_new(k);
    if (!has_rest) continue;
    const Eigen::Matrix<double, 15, 15> MT = sh_rotation(polar_rotation(J)).transpose();
    for (int c = 0; c < 3; ++c) {
      Eigen::Matrix<double, 15, 1> coeff;
      for (int k = 0; k < 15; ++k) coeff(k) = row(rest[c * 15 + k]);
      const Eigen::Matrix<double, 15, 1> rotated = MT * coeff;
      for (int k = 0; k < 15; ++k) row(rest[c * 15 + k]) = rotated(k);
    }
  }
  map_point_cloud(cloud, mapped, JT);
}

}  // namespace lidef
