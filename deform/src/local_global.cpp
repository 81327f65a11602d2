#include "lidef/local_global.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "lidef/errors.h"

namespace lidef {

namespace {
// Samples per block converted from float to double for the products with G (the energy stores G in float).
constexpr int kBlock = 512;
// E_LG below this counts as converged (rounding noise of a map that meets everything exactly).
constexpr double kEnergyFloor = 1e-14;
}  // namespace

Mat3 closest_rotation(const Mat3& M) {
  Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  const Mat3 V = svd.matrixV();
  if ((U * V.transpose()).determinant() < 0) U.col(2) *= -1;
  return U * V.transpose();
}

LocalGlobalSolver::LocalGlobalSolver(const DeformationEnergy& energy, const EnergyWeights& w, double rigidity)
    : energy_(energy), w_(w), rigidity_(rigidity) {
  const int s = energy.reduced_size();
  const int n = energy.num_samples();
  const VecXd& sw = energy.sample_weights();
  MatXd A = MatXd::Zero(s, s);
  if (rigidity_ > 0) {
    const MatXfR& G = energy.gradient_matrix();
    for (int i0 = 0; i0 < n; i0 += kBlock) {
      const int m = std::min(kBlock, n - i0);
      MatXd Gb = G.middleRows(3 * static_cast<Eigen::Index>(i0), 3 * m).cast<double>();
      MatXd WGb = Gb;
      if (sw.size())
        for (int k = 0; k < m; ++k) WGb.middleRows(3 * k, 3) *= sw(i0 + k);
      A.noalias() += Gb.transpose() * WGb;
    }
    A *= rigidity_ / n;
  }
  const MatXd& D = energy.handle_matrix();
  if (D.rows() == 0) throw Error("LocalGlobalSolver: the energy has no handles");
  A.noalias() += w_.p2p * (D.transpose() * D);
  A.diagonal() += (w_.smooth / energy.num_edges()) * energy.smooth_eigenvalues();
  llt_.compute(A);
  if (llt_.info() != Eigen::Success)
    throw NumericalError("local/global: the normal matrix is not positive definite");
}

MatJT LocalGlobalSolver::rotation_targets(const MatS3& y, double* rigid) const {
  const MatJT JT = energy_.jacobians(y);
  MatJT T(JT.rows(), 3);
  const int n = energy_.num_samples();
  VecXd e(n);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const Mat3 Jt = JT.middleRows<3>(3 * i);
    T.middleRows<3>(3 * i) = closest_rotation(Jt.transpose()).transpose();
    e(i) = (Jt - T.middleRows<3>(3 * i)).squaredNorm();
  }
  if (rigid) {
    const VecXd& sw = energy_.sample_weights();
    double sum = 0;  // in sample order: deterministic
    for (int i = 0; i < n; ++i) sum += (sw.size() ? sw(i) : 1.0) * e(i);
    *rigid = rigidity_ * sum / n;
  }
  return T;
}

MatS3 LocalGlobalSolver::global_step(const MatJT& T, const MatX3d& Q) const {
  const int s = energy_.reduced_size();
  const int n = energy_.num_samples();
  const VecXd& sw = energy_.sample_weights();
  MatS3 rhs = MatS3::Zero(s, 3);
  if (rigidity_ > 0) {
    const MatXfR& G = energy_.gradient_matrix();
    for (int i0 = 0; i0 < n; i0 += kBlock) {
      const int m = std::min(kBlock, n - i0);
      MatJT Tb = T.middleRows(3 * static_cast<Eigen::Index>(i0), 3 * m);
      if (sw.size())
        for (int k = 0; k < m; ++k) Tb.middleRows<3>(3 * k) *= sw(i0 + k);
      rhs.noalias() += G.middleRows(3 * static_cast<Eigen::Index>(i0), 3 * m).cast<double>().transpose() * Tb;
    }
    rhs *= rigidity_ / n;
  }
  rhs.noalias() += w_.p2p * (energy_.handle_matrix().transpose() * Q);
  return llt_.solve(rhs);
}

double LocalGlobalSolver::energy(const MatS3& y, const MatX3d& Q) const {
  double rigid = 0;
  if (rigidity_ > 0) rotation_targets(y, &rigid);
  return rigid + rest_energy(y, Q);
}

double LocalGlobalSolver::rest_energy(const MatS3& y, const MatX3d& Q) const {
  const double p2p = (energy_.handle_matrix() * y - Q).squaredNorm();
  double smooth = 0;
  const VecXd& mu = energy_.smooth_eigenvalues();
  for (int j = 0; j < y.rows(); ++j) smooth += mu(j) * y.row(j).squaredNorm();
  return w_.p2p * p2p + (w_.smooth / energy_.num_edges()) * smooth;
}

LocalGlobalResult LocalGlobalSolver::solve(const MatS3& y0, const MatX3d& Q, int max_iterations,
                                           double tolerance) const {
  if (y0.rows() != energy_.reduced_size() || Q.rows() != energy_.num_handles())
    throw Error("LocalGlobalSolver::solve: y0 must be s by 3 and Q #h by 3");
  LocalGlobalResult r;
  r.y = y0;
  const MatJT zero = MatJT::Zero(3 * static_cast<Eigen::Index>(energy_.num_samples()), 3);
  double rigid = 0;
  MatJT T = rigidity_ > 0 ? rotation_targets(r.y, &rigid) : zero;
  double prev = rigid + rest_energy(r.y, Q);
  r.energy = prev;
  for (int it = 0; it < max_iterations; ++it) {
    r.y = global_step(T, Q);
    ++r.iterations;
    if (rigidity_ > 0) T = rotation_targets(r.y, &rigid);
    r.energy = rigid + rest_energy(r.y, Q);
    // Each step minimizes over ỹ then over R: E_LG never increases (up to rounding).
    if (prev - r.energy <= tolerance * std::abs(prev) + kEnergyFloor) {
      r.converged = true;
      break;
    }
    prev = r.energy;
  }
  return r;
}

}  // namespace lidef
