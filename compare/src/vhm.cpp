#include "lidef/compare/vhm.h"

#include <chrono>
#include <cmath>

#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/local_global.h"

namespace lidef {

// Energies below this (E is 0 at the rest shape) count as converged: relative decreases of rounding noise.
constexpr double kEnergyFloor = 1e-14;

VhmSolver::VhmSolver(const Cage& cage, const HarmonicBasis& basis, const MatX3d& anchors,
                     const MatX3d& boundary, const VhmParams& params, const std::string& where)
    : cage_(cage), basis_(basis), params_(params) {
  if (anchors.rows() < 1) throw InputError(where, "VHM needs at least one anchor");
  for (Eigen::Index i = 0; i < anchors.rows(); ++i)
    if (!anchors.row(i).allFinite() || cage.winding_number(anchors.row(i).transpose()) < 0.5)
      throw InputError(where, "VHM anchor " + std::to_string(i) + " lies outside the cage");
  if (boundary.rows() < 1) throw InputError(where, "VHM needs at least one boundary sample");
  for (Eigen::Index i = 0; i < boundary.rows(); ++i)
    if (!boundary.row(i).allFinite() || cage.winding_number(boundary.row(i).transpose()) < 0.5)
      throw InputError(where, "VHM boundary sample " + std::to_string(i) + " lies outside the cage");
  G_ = basis.gradient_matrix(anchors);
  Hs_ = basis.hessian_matrix(boundary);
  for (Eigen::Index i = 0; i < boundary.rows(); ++i)
    for (int k : {1, 2, 4}) Hs_.row(6 * i + k) *= std::sqrt(2.0);  // xy, xz, yz appear twice in the tensor
  const double diag = (cage.bbox_max - cage.bbox_min).norm();
  ws_ = params_.smooth_weight * diag * diag;
  y_ = cage.identity_coefficients();
  R_.assign(anchors.rows(), Mat3::Identity());
}

void VhmSolver::set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where) {
  if (sources.rows() < 1 || sources.rows() != targets.rows())
    throw InputError(where, "VHM: need at least one handle and as many targets as sources");
  for (Eigen::Index h = 0; h < sources.rows(); ++h)
    if (!sources.row(h).allFinite() || !targets.row(h).allFinite() ||
        cage_.winding_number(sources.row(h).transpose()) < 0.5)
      throw InputError(where, "VHM: handle " + std::to_string(h) + " lies outside the cage or is not finite");
  D_ = basis_.value_matrix(sources);
  targets_ = targets;
  y_ = cage_.identity_coefficients();
  R_.assign(R_.size(), Mat3::Identity());
  history_.clear();
  factor();
}

void VhmSolver::factor() {
  const double na = static_cast<double>(num_anchors());
  A_ = (G_.transpose() * G_) / na;
  A_.noalias() += (ws_ / static_cast<double>(Hs_.rows() / 6)) * (Hs_.transpose() * Hs_);
  A_.noalias() += params_.lambda_p2p * (D_.transpose() * D_);
  rho_ = params_.proximal * A_.trace() / static_cast<double>(A_.rows());
  MatXd Ap = A_;
  Ap.diagonal().array() += rho_;
  llt_.compute(Ap);
  if (llt_.info() != Eigen::Success) throw NumericalError("VHM: the system matrix is not positive definite");
}

std::vector<Mat3> VhmSolver::best_rotations(const MatX3d& y) const {
  const MatX3d GY = G_ * y;  // row 3i+b, column c: J_i(c, b)
  std::vector<Mat3> R(num_anchors());
  for (int i = 0; i < num_anchors(); ++i) R[i] = closest_rotation(GY.middleRows<3>(3 * i).transpose());
  return R;
}

double VhmSolver::energy(const MatX3d& y, const std::vector<Mat3>& R, VhmIteration* terms) const {
  const double na = static_cast<double>(num_anchors());
  const MatX3d GY = G_ * y;
  double rigid = 0;
  for (int i = 0; i < num_anchors(); ++i) rigid += (GY.middleRows<3>(3 * i).transpose() - R[i]).squaredNorm();
  rigid /= na;
  const double smooth = (Hs_ * y).squaredNorm() / static_cast<double>(Hs_.rows() / 6);
  const double p2p = D_.rows() ? (D_ * y - targets_).squaredNorm() : 0.0;
  if (terms) {
    terms->e_rigid = rigid;
    terms->e_smooth = smooth;
    terms->e_p2p = p2p;
  }
  return rigid + ws_ * smooth + params_.lambda_p2p * p2p;
}

VecXd VhmSolver::handle_errors() const {
  return (D_ * y_ - targets_).rowwise().norm();
}

VhmIteration VhmSolver::step() {
  const auto t0 = Clock::now();
  if (D_.rows() == 0) throw InputError("handles", "VHM: no handles set");
  R_ = best_rotations(y_);  // local step
  // Global step: (A + ρI) y = (1/n_a) Gᵀ T + λ1 Dᵀ Q + ρ y_prev, T = stacked R_iᵀ (rows 3i+b: R_i(:, b)ᵀ).
  MatX3d T(3 * num_anchors(), 3);
  for (int i = 0; i < num_anchors(); ++i) T.middleRows<3>(3 * i) = R_[i].transpose();
  MatXd rhs = (G_.transpose() * T) / static_cast<double>(num_anchors());
  rhs.noalias() += params_.lambda_p2p * (D_.transpose() * targets_);
  rhs += rho_ * y_;
  y_ = llt_.solve(rhs);
  VhmIteration rec;
  rec.iteration = static_cast<int>(history_.size()) + 1;
  rec.energy = energy(y_, R_, &rec);
  rec.max_handle_error = handle_errors().maxCoeff();
  rec.ms = ms_since(t0);
  history_.push_back(rec);
  return rec;
}

VhmResult VhmSolver::solve(const std::function<bool(const VhmIteration&)>& on_iteration) {
  const auto t0 = Clock::now();
  VhmResult res;
  res.message = "iteration limit";
  double prev = energy(y_, best_rotations(y_));
  for (int it = 0; it < params_.max_iterations; ++it) {
    const VhmIteration r = step();
    ++res.iterations;
    if (on_iteration && !on_iteration(r)) {
      res.message = "interrupted";
      break;
    }
    if (prev - r.energy <= params_.energy_tolerance * std::abs(prev) + kEnergyFloor) {
      res.converged = true;
      res.message = "relative energy decrease below tolerance";
      break;
    }
    prev = r.energy;
  }
  res.seconds = seconds_since(t0);
  return res;
}

}  // namespace lidef
