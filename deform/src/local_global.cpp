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
// The Newton polar iteration (closest_rotation) runs on matrices with det M > kPolarMinDet ‖M‖_F³, so that
// σ3 > 1e-3 σ1 (det M ≤ σ1² σ3 and ‖M‖_F ≥ σ1) and the inverses it takes lose at most ~3 digits; the
// local/global solve's Jacobians are near rotations. It stops once a step changes X by less than kPolarStep
// (relative, Frobenius): the convergence is quadratic (error e → ~e²/2), so after a step of 1e-6 X is ~1e-12
// from the polar factor and one more step leaves it at rounding level.
constexpr double kPolarMinDet = 1e-3;
constexpr double kPolarStep = 1e-6;
constexpr int kPolarMaxSteps = 20;

// X⁻ᵀ of a 3 by 3 matrix with determinant d: the columns' cross products over d.
Mat3 inverse_transpose(const Mat3& X, double d) {
  Mat3 C;
  C.col(0) = X.col(1).cross(X.col(2));
  C.col(1) = X.col(2).cross(X.col(0));
  C.col(2) = X.col(0).cross(X.col(1));
  return C / d;
}

// The polar factor of M (det M > 0) by Higham's scaled Newton iteration X ← (γX + X⁻ᵀ/γ)/2, γ the Frobenius
// scaling (‖X⁻¹‖_F / ‖X‖_F)^½; false when it does not converge within kPolarMaxSteps.
bool polar_newton(const Mat3& M, Mat3& X) {
  X = M;
  bool small = false;
  for (int k = 0; k < kPolarMaxSteps; ++k) {
    const double d = X.determinant();
    if (!(d > 0)) return false;
    const Mat3 Y = inverse_transpose(X, d);
    // Scaling speeds up the first steps; near convergence it is 1 up to rounding and is left out.
    const double g = small ? 1.0 : std::sqrt(std::sqrt(Y.squaredNorm() / X.squaredNorm()));
    const Mat3 next = 0.5 * (g * X + Y / g);
    const double change2 = (next - X).squaredNorm();
    X = next;
    if (small) return true;
    small = change2 <= kPolarStep * kPolarStep * X.squaredNorm();
  }
  return false;
}
}  // namespace

Mat3 closest_rotation(const Mat3& M) {
  // Near rotations (the local/global solve's Jacobians, millions of calls per solve) the Newton iteration
  // costs a few 3 by 3 products; a reflection, a near-singular M or no convergence takes the SVD.
  const double f = M.norm();
  Mat3 X;
  if (M.determinant() > kPolarMinDet * f * f * f && polar_newton(M, X)) return X;
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
  MatS3 rhs = MatS3::Zero(energy_.reduced_size(), 3);
  if (rigidity_ > 0) rhs = (rigidity_ / energy_.num_samples()) * energy_.weighted_transpose_times(T);
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
                                           double tolerance, const std::atomic<bool>* stop) const {
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
    if (stop && stop->load()) {
      r.interrupted = true;
      break;
    }
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
