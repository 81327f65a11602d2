#include "lidef/local_global.h"

#include <Eigen/QR>
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

namespace {
// Anderson acceleration of the fixed-point map x → g(x) = global_step(rotation_targets(x)) (type II, as in
// Peng et al., "Anderson Acceleration for Geometry Optimization and Physics Simulation", 2018): the next
// iterate combines the last kAndersonDepth + 1 images g so that the matching combination of residuals
// f = g(x) − x is smallest in the least-squares sense. Local/global iterations converge linearly and slowly
// (hundreds of iterations on the shared scenarios); the combination costs a (3s) by kAndersonDepth
// least-squares problem per iteration, nothing beside the two passes over G. The solve safeguards it by
// the energy (an accelerated iterate that does not lower E_LG is replaced by the plain one).
constexpr int kAndersonDepth = 5;

class Anderson {
 public:
  explicit Anderson(Eigen::Index n) : dF_(n, kAndersonDepth), dG_(n, kAndersonDepth) {}
  // The next iterate after g = g(x) (both flattened s by 3 coefficients); *accelerated says whether it is a
  // combination (false: g itself, before two pairs are known or when the least-squares weights are not
  // finite).
  VecXd next(const VecXd& x, const VecXd& g, bool* accelerated) {
    *accelerated = false;
    const VecXd f = g - x;
    if (have_prev_) {
      const int c = static_cast<int>(count_ % kAndersonDepth);
      dF_.col(c) = f - f_prev_;
      dG_.col(c) = g - g_prev_;
      ++count_;
    }
    f_prev_ = f;
    g_prev_ = g;
    have_prev_ = true;
    const int m = static_cast<int>(std::min<long>(count_, kAndersonDepth));
    if (m == 0) return g;
    // θ = argmin ‖f − ΔF θ‖ by QR with column pivoting (nearly dependent differences near convergence).
    const VecXd theta = dF_.leftCols(m).colPivHouseholderQr().solve(f);
    if (!theta.allFinite()) return g;
    *accelerated = true;
    return g - dG_.leftCols(m) * theta;
  }
  // Forgets the differences (after a rejected iterate); the last pair (x, g(x)) stays, as it is exact.
  void reset() { count_ = 0; }

 private:
  MatXd dF_, dG_;
  VecXd f_prev_, g_prev_;
  bool have_prev_ = false;
  long count_ = 0;
};

VecXd flat(const MatS3& y) {
  return Eigen::Map<const VecXd>(y.data(), y.size());
}
MatS3 unflat(const VecXd& v, Eigen::Index rows) {
  return Eigen::Map<const MatS3>(v.data(), rows, 3);
}
}  // namespace

LocalGlobalResult LocalGlobalSolver::solve(const MatS3& y0, const MatX3d& Q, int max_iterations,
                                           double tolerance, const std::atomic<bool>* stop) const {
  if (y0.rows() != energy_.reduced_size() || Q.rows() != energy_.num_handles())
    throw Error("LocalGlobalSolver::solve: y0 must be s by 3 and Q #h by 3");
  LocalGlobalResult r;
  r.y = y0;
  const Eigen::Index s = y0.rows();
  const MatJT zero = MatJT::Zero(3 * static_cast<Eigen::Index>(energy_.num_samples()), 3);
  // The local step at y: its rotation targets and E_LG(y, R(y)).
  const auto local = [&](const MatS3& y, MatJT& T) {
    double rigid = 0;
    T = rigidity_ > 0 ? rotation_targets(y, &rigid) : zero;
    return rigid + rest_energy(y, Q);
  };
  MatJT T;
  r.energy = local(r.y, T);
  Anderson anderson(y0.size());
  const auto small_decrease = [&](double before, double after) {
    return before - after <= tolerance * std::abs(before) + kEnergyFloor;
  };
  for (int it = 0; it < max_iterations; ++it) {
    if (stop && stop->load()) {
      r.interrupted = true;
      break;
    }
    // Global step: g = g(y). A plain iteration moves to g, which lowers E_LG (a minimization over ỹ, then
    // over R; up to rounding).
    const MatS3 g = global_step(T, Q);
    ++r.iterations;
    bool accelerated = false;
    MatS3 y = unflat(anderson.next(flat(r.y), flat(g), &accelerated), s);
    MatJT Ty;
    double e = local(y, Ty);
    // The safeguard: an accelerated iterate must lower E_LG, and a small decrease by one is confirmed by the
    // plain step (an accelerated step can stall where the plain one still makes progress); otherwise the
    // plain iterate is taken, whose E_LG is no higher than before up to rounding.
    const bool raised = !(e < r.energy);
    if (accelerated && (raised || small_decrease(r.energy, e))) {
      MatJT Tg;
      const double eg = local(g, Tg);
      if (raised || !(e < eg)) {
        y = g;
        Ty = std::move(Tg);
        e = eg;
        anderson.reset();
      }
    }
    const bool done = small_decrease(r.energy, e);
    r.y = std::move(y);
    T = std::move(Ty);
    r.energy = e;
    if (done) {
      r.converged = true;
      break;
    }
  }
  return r;
}

}  // namespace lidef
