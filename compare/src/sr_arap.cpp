#include "lidef/compare/sr_arap.h"

#include <Eigen/CholmodSupport>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>

#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/local_global.h"

namespace lidef {

// Energies below this (E is 0 at the rest shape) count as converged: relative decreases of rounding noise.
constexpr double kEnergyFloor = 1e-14;

using SpMat = Eigen::SparseMatrix<double>;

struct SrArapSolver::Impl {
  SpMat L;  // (1/A) Dᵀ W D + λ1 WhᵀWh + ρ I: the global system (#V square)
  Eigen::CholmodSupernodalLLT<SpMat, Eigen::Lower> chol;
  double rho = 0;
};

SrArapSolver::SrArapSolver(const TriMesh& mesh, const PwlTriParams& params)
    : mesh_(mesh), params_(params), impl_(std::make_unique<Impl>()) {
  const int nv = static_cast<int>(mesh_.V.rows());
  if (nv == 0 || mesh_.F.rows() == 0) throw InputError(mesh_.source, "PWL(Tri): the mesh is empty");
  if (mesh_.F.minCoeff() < 0 || mesh_.F.maxCoeff() >= nv)
    throw InputError(mesh_.source, "PWL(Tri): bad face index");
  // Cotangent weights: w_ij = ½ Σ over the faces of edge ij of the cotangent of the opposite angle.
  std::map<std::pair<int, int>, double> w;
  area_ = 0;
  for (Eigen::Index f = 0; f < mesh_.F.rows(); ++f) {
    const Vec3 p[3] = {mesh_.V.row(mesh_.F(f, 0)), mesh_.V.row(mesh_.F(f, 1)), mesh_.V.row(mesh_.F(f, 2))};
    const double a2 = (p[1] - p[0]).cross(p[2] - p[0]).norm();
    area_ += a2 / 2;
    for (int k = 0; k < 3; ++k) {
      const int i = mesh_.F(f, (k + 1) % 3), j = mesh_.F(f, (k + 2) % 3);
      const Vec3 u = p[(k + 1) % 3] - p[k], v = p[(k + 2) % 3] - p[k];
      const double cot = a2 > 0 ? u.dot(v) / a2 : 0.0;
      w[{std::min(i, j), std::max(i, j)}] += 0.5 * cot;
    }
  }
  if (!(area_ > 0)) throw InputError(mesh_.source, "PWL(Tri): the mesh has zero area");
  nbr_.assign(nv, {});
  for (const auto& [e, wij] : w) {
    const double c = std::max(wij, 0.0);
    nbr_[e.first].emplace_back(e.second, c);
    nbr_[e.second].emplace_back(e.first, c);
  }
  X_ = mesh_.V;
  R_.assign(nv, Mat3::Identity());
}

SrArapSolver::~SrArapSolver() = default;

void SrArapSolver::set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where) {
  if (sources.rows() < 1 || sources.rows() != targets.rows())
    throw InputError(where, "PWL(Tri): need at least one handle and as many targets as sources");
  const int nv = static_cast<int>(mesh_.V.rows());
  const double diag = (mesh_.V.colwise().maxCoeff() - mesh_.V.colwise().minCoeff()).norm();
  std::vector<Eigen::Triplet<double>> trip;
  for (Eigen::Index h = 0; h < sources.rows(); ++h) {
    const Vec3 p = sources.row(h);
    if (!p.allFinite() || !targets.row(h).allFinite()) throw InputError(where, "PWL(Tri): non-finite handle");
    double best = std::numeric_limits<double>::infinity();
    Eigen::Index bf = 0;
    Vec3 bb;
    for (Eigen::Index f = 0; f < mesh_.F.rows(); ++f) {
      const Vec3 a = mesh_.V.row(mesh_.F(f, 0)), b = mesh_.V.row(mesh_.F(f, 1)),
                 c = mesh_.V.row(mesh_.F(f, 2));
      const Vec3 l = closest_point_on_triangle(p, a, b, c).barycentric;
      const double d = (l(0) * a + l(1) * b + l(2) * c - p).squaredNorm();
      if (d < best) {
        best = d;
        bf = f;
        bb = l;
      }
    }
    if (std::sqrt(best) > 1e-6 * diag)
      throw InputError(where, "PWL(Tri): handle " + std::to_string(h) +
                                  " is not on the mesh surface (distance " + std::to_string(std::sqrt(best)) +
                                  ")");
    for (int k = 0; k < 3; ++k) trip.emplace_back(static_cast<int>(h), mesh_.F(bf, k), bb(k));
  }
  W_.resize(sources.rows(), nv);
  W_.setFromTriplets(trip.begin(), trip.end());
  targets_ = targets;
  X_ = mesh_.V;
  R_.assign(nv, Mat3::Identity());
  history_.clear();
  // Global matrix: (2/A) Σ_ij w_ij (rows of the Laplacian; each undirected edge counted from both ends) + λ1
  // WᵀW.
  std::vector<Eigen::Triplet<double>> lt;
  for (int i = 0; i < nv; ++i)
    for (const auto& [j, wij] : nbr_[i]) {
      const double c = 2 * wij / area_;  // directed edges (i,j) and (j,i) each add w (x_i − x_j)² terms
      lt.emplace_back(i, i, c);
      lt.emplace_back(i, j, -c);
    }
  SpMat L(nv, nv);
  L.setFromTriplets(lt.begin(), lt.end());
  const SpMat WtW = SpMat(W_.transpose() * W_);
  L += params_.lambda_p2p * WtW;
  impl_->rho = params_.proximal * L.diagonal().mean();
  SpMat I(nv, nv);
  I.setIdentity();
  impl_->L = L + impl_->rho * I;
  impl_->chol.compute(impl_->L);
  if (impl_->chol.info() != Eigen::Success) throw NumericalError("PWL(Tri): CHOLMOD factorization failed");
}

double SrArapSolver::energy(const MatX3d& X, const std::vector<Mat3>& R) const {
  double arap = 0, smooth = 0;
  for (size_t i = 0; i < nbr_.size(); ++i)
    for (const auto& [j, wij] : nbr_[i]) {
      const Vec3 e = (mesh_.V.row(i) - mesh_.V.row(j)).transpose(), ed = (X.row(i) - X.row(j)).transpose();
      arap += wij * (ed - R[i] * e).squaredNorm();
      smooth += wij * (R[i] - R[j]).squaredNorm();
    }
  const double p2p = W_.rows() ? (W_ * X - targets_).squaredNorm() : 0.0;
  return arap / area_ + params_.alpha * smooth + params_.lambda_p2p * p2p;
}

VecXd SrArapSolver::handle_errors() const {
  return (W_ * X_ - targets_).rowwise().norm();
}

void SrArapSolver::local_step() {
  for (size_t i = 0; i < nbr_.size(); ++i) {
    Mat3 S = Mat3::Zero();
    for (const auto& [j, wij] : nbr_[i]) {
      const Vec3 e = (mesh_.V.row(i) - mesh_.V.row(j)).transpose(), ed = (X_.row(i) - X_.row(j)).transpose();
      S += wij * e * ed.transpose() + 2 * params_.alpha * area_ * wij * R_[j].transpose();
    }
    // argmax tr(R S) over rotations = the rotation closest to Sᵀ (S = U Σ Vᵀ → R = V Uᵀ).
    R_[i] = closest_rotation(S.transpose());
  }
}

void SrArapSolver::global_step() {
  // rhs_i = (1/A) Σ_j w_ij (R_i + R_j) e_ij  + λ1 (WᵀQ)_i + ρ x_i
  const int nv = static_cast<int>(X_.rows());
  MatXd rhs(nv, 3);
  for (int i = 0; i < nv; ++i) {
    Vec3 r = Vec3::Zero();
    for (const auto& [j, wij] : nbr_[i])
      r += wij * (R_[i] + R_[j]) * (mesh_.V.row(i) - mesh_.V.row(j)).transpose();
    rhs.row(i) = (r / area_).transpose();
  }
  rhs += params_.lambda_p2p * (W_.transpose() * targets_);
  rhs += impl_->rho * X_;
  const MatXd X = impl_->chol.solve(rhs);
  if (impl_->chol.info() != Eigen::Success || !X.allFinite())
    throw NumericalError("PWL(Tri): CHOLMOD solve failed");
  X_ = X;
}

PwlTriIteration SrArapSolver::step() {
  const auto t0 = Clock::now();
  if (W_.rows() == 0) throw InputError("handles", "PWL(Tri): no handles set");
  PwlTriIteration rec;
  rec.iteration = static_cast<int>(history_.size()) + 1;
  local_step();
  rec.energy_after_local = energy(X_, R_);
  global_step();
  rec.energy = energy(X_, R_);
  rec.max_handle_error = handle_errors().maxCoeff();
  rec.ms = ms_since(t0);
  history_.push_back(rec);
  return rec;
}

PwlTriResult SrArapSolver::solve(const std::function<bool(const PwlTriIteration&)>& on_iteration) {
  const auto t0 = Clock::now();
  PwlTriResult res;
  res.message = "iteration limit";
  double prev = std::numeric_limits<double>::infinity();
  for (int it = 0; it < params_.max_iterations; ++it) {
    const PwlTriIteration r = step();
    ++res.iterations;
    if (on_iteration && !on_iteration(r)) {
      res.message = "interrupted";
      break;
    }
    if (std::isfinite(prev) && prev - r.energy <= params_.energy_tolerance * std::abs(prev) + kEnergyFloor) {
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
