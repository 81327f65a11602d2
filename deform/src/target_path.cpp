#include "lidef/internal/target_path.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace lidef {

std::vector<int> group_handles(const MatX3d& sources, double link_distance) {
  const int n = static_cast<int>(sources.rows());
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < i; ++j)
      if ((sources.row(i) - sources.row(j)).norm() <= link_distance) {
        const int a = find(i), b = find(j);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
  // Renumber roots 0, 1, ... in order of their first handle (deterministic, independent of the link order).
  std::vector<int> id(n, -1), groups(n);
  int next = 0;
  for (int i = 0; i < n; ++i) {
    const int r = find(i);
    if (id[r] < 0) id[r] = next++;
    groups[i] = id[r];
  }
  return groups;
}

namespace {

// The rotation R minimizing Σ‖R(a_i − ca) − (b_i − cb)‖² (Kabsch), as angle and axis; angle 0 when the start
// points do not determine a rotation (fewer than 3, or all on one line: the second singular value of the
// cross-covariance vanishes).
void best_rotation(const MatX3d& a, const MatX3d& b, const Vec3& ca, const Vec3& cb, double& angle,
                   Vec3& axis) {
  angle = 0;
  axis = Vec3::UnitZ();
  if (a.rows() < 3) return;
  Mat3 h = Mat3::Zero();
  double spread = 0;
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    const Vec3 p = a.row(i).transpose() - ca, q = b.row(i).transpose() - cb;
    h += p * q.transpose();
    spread = std::max(spread, p.norm());
  }
  // Rank test on the start points alone: points on a line leave the rotation about that line undetermined.
  Mat3 cov = Mat3::Zero();
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    const Vec3 p = a.row(i).transpose() - ca;
    cov += p * p.transpose();
  }
  const Eigen::JacobiSVD<Mat3> cs(cov);
  if (!(cs.singularValues()(1) > 1e-12 * cs.singularValues()(0)) || spread == 0) return;
  const Eigen::JacobiSVD<Mat3> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Mat3 u = svd.matrixU(), v = svd.matrixV();
  Mat3 d = Mat3::Identity();
  d(2, 2) = (v * u.transpose()).determinant() < 0 ? -1 : 1;
  const Mat3 r = v * d * u.transpose();
  const Eigen::AngleAxisd aa(r);
  angle = aa.angle();
  axis = aa.axis();
  if (!(angle > 0) || !axis.allFinite()) {
    angle = 0;
    axis = Vec3::UnitZ();
  }
}

}  // namespace

TargetPath::TargetPath(const std::vector<MatX3d>& keyframes, const std::vector<int>& groups) {
  if (keyframes.size() < 2) throw std::invalid_argument("TargetPath: at least two keyframes are needed");
  const Eigen::Index n = keyframes[0].rows();
  if (static_cast<Eigen::Index>(groups.size()) != n)
    throw std::invalid_argument("TargetPath: one group id per handle is needed");
  for (const MatX3d& k : keyframes)
    if (k.rows() != n) throw std::invalid_argument("TargetPath: every keyframe needs one row per handle");
  const int num_groups = n == 0 ? 0 : *std::max_element(groups.begin(), groups.end()) + 1;
  for (size_t k = 0; k + 1 < keyframes.size(); ++k) {
    Segment seg;
    seg.start = keyframes[k];
    seg.end = keyframes[k + 1];
    for (int g = 0; g < num_groups; ++g) {
      GroupMotion m;
      for (Eigen::Index i = 0; i < n; ++i)
        if (groups[i] == g) m.handles.push_back(static_cast<int>(i));
      if (m.handles.empty()) continue;
      MatX3d a(m.handles.size(), 3), b(m.handles.size(), 3);
      for (size_t j = 0; j < m.handles.size(); ++j) {
        a.row(j) = seg.start.row(m.handles[j]);
        b.row(j) = seg.end.row(m.handles[j]);
      }
      m.from_centroid = a.colwise().mean().transpose();
      m.to_centroid = b.colwise().mean().transpose();
      best_rotation(a, b, m.from_centroid, m.to_centroid, m.angle, m.axis);
      const Mat3 r = Eigen::AngleAxisd(m.angle, m.axis).toRotationMatrix();
      m.residual.resize(a.rows(), 3);
      for (Eigen::Index j = 0; j < a.rows(); ++j)
        m.residual.row(j) =
            (b.row(j).transpose() - (r * (a.row(j).transpose() - m.from_centroid) + m.to_centroid))
                .transpose();
      seg.groups.push_back(std::move(m));
    }
    segments_.push_back(std::move(seg));
  }
}

MatX3d TargetPath::at(double s) const {
  const int k = std::clamp(static_cast<int>(std::floor(s)), 0, segments() - 1);
  const Segment& seg = segments_[k];
  const double t = std::clamp(s - k, 0.0, 1.0);
  // The ends exactly, not up to the rounding of the rigid motion: the last stage's targets are the user's.
  if (t == 0) return seg.start;
  if (t == 1) return seg.end;
  MatX3d p(seg.start.rows(), 3);
  for (const GroupMotion& m : seg.groups) {
    const Mat3 r = Eigen::AngleAxisd(t * m.angle, m.axis).toRotationMatrix();
    const Vec3 c = m.from_centroid + t * (m.to_centroid - m.from_centroid);
    for (size_t j = 0; j < m.handles.size(); ++j) {
      const Vec3 a = seg.start.row(m.handles[j]).transpose();
      p.row(m.handles[j]) = (r * (a - m.from_centroid) + c + t * m.residual.row(j).transpose()).transpose();
    }
  }
  return p;
}

double TargetPath::max_angle(int k) const {
  double a = 0;
  for (const GroupMotion& m : segments_.at(k).groups) a = std::max(a, m.angle);
  return a;
}

double TargetPath::max_displacement(int k) const {
  const Segment& seg = segments_.at(k);
  return seg.start.rows() == 0 ? 0.0 : (seg.end - seg.start).rowwise().norm().maxCoeff();
}

}  // namespace lidef
