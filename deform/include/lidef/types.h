// Common array types. Shapes are documented at every use ("#V by 3").
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace lidef {
using MatX3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;  // one point per row
using MatX3i = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;     // one triangle per row
using MatXd = Eigen::MatrixXd;
using MatXdR = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MatXfR = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using VecXd = Eigen::VectorXd;
using VecXi = Eigen::VectorXi;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using MatS3 = Eigen::Matrix<double, Eigen::Dynamic, 3>;  // s by 3 reduced coefficients (column-major)
using MatJT = Eigen::Matrix<double, Eigen::Dynamic, 3>;  // 3|I| by 3 stacked transposed Jacobians
}  // namespace lidef
