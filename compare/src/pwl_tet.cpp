#include "lidef/compare/pwl_tet.h"

#include <Eigen/CholmodSupport>
#include <chrono>
#include <cmath>
#include <limits>

#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/symmetric_dirichlet.h"

namespace lidef {

using SpMat = Eigen::SparseMatrix<double>;
// Below this many tets the loops run serially: a parallel region costs more than the work (and much more when
// the cores are shared).
constexpr int kParallelTets = 4096;
using Mat9x12 = Eigen::Matrix<double, 9, 12>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

struct PwlTetSolver::Impl {
  SpMat H;                     // 3#V square, full symmetric pattern (tets + handles + diagonal)
  std::vector<int> tet_slot;   // #T * 144: index into H.valuePtr() of local entry (r, c), r*12 + c
  std::vector<int> diag_slot;  // 3#V
  std::vector<std::pair<int, double>> handle_slots;  // (value index, coefficient) of 2λ WᵀW ⊗ I₃
  Eigen::CholmodSupernodalLLT<SpMat, Eigen::Lower> chol;
  bool analyzed = false;
};

Eigen::Matrix<double, 9, 12> PwlTetSolver::jacobian_derivative(const Mat3& Bm) {
  // J(a, b) = Σ_k D_s(a, k) Bm(k, b), D_s(a, k) = x_{k+1,a} − x_{0,a}:
  // ∂J(a,b)/∂x_{j,a} = g_j(b) with g_j = Bm.row(j−1) (j ≥ 1) and g_0 = −Σ_k Bm.row(k).
  Mat9x12 F = Mat9x12::Zero();
  Eigen::Matrix<double, 4, 3> g;
  g.row(0) = -Bm.colwise().sum();
  g.bottomRows<3>() = Bm;
  for (int j = 0; j < 4; ++j)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) F(a + 3 * b, 3 * j + a) = g(j, b);
  return F;
}

PwlTetSolver::PwlTetSolver(const TetMesh& mesh, const PwlTetParams& params)
    : mesh_(mesh), params_(params), impl_(std::make_unique<Impl>()) {
  const int nt = mesh_.num_tets(), nv = mesh_.num_vertices();
  if (nt == 0 || nv == 0) throw InputError(mesh_.source, "PWL(Tet): the tet mesh is empty");
  Bm_.resize(nt);
  w_.resize(nt);
  for (int t = 0; t < nt; ++t) {
    Mat3 D;
    for (int k = 0; k < 3; ++k)
      D.col(k) = (mesh_.V.row(mesh_.T(t, k + 1)) - mesh_.V.row(mesh_.T(t, 0))).transpose();
    const double v = D.determinant() / 6;
    if (!(v > 0))
      throw InputError(mesh_.source,
                       "PWL(Tet): tetrahedron " + std::to_string(t) + " has non-positive volume");
    Bm_[t] = D.inverse();
    w_(t) = v;
  }
  w_ /= w_.sum();
  X_ = mesh_.V;
}

PwlTetSolver::~PwlTetSolver() = default;

void PwlTetSolver::set_handles(const MatX3d& sources, const MatX3d& targets, const std::string& where) {
  if (sources.rows() < 1 || sources.rows() != targets.rows())
    throw InputError(where, "PWL(Tet): need at least one handle and as many targets as sources");
  if (!sources.allFinite() || !targets.allFinite())
    throw InputError(where, "PWL(Tet): non-finite handle coordinate");
  const TetEmbedding e = embed_points(mesh_, sources, where + ": PWL(Tet) handle");
  W_ = e.weights();
  targets_ = targets;
  analyze();  // the pattern of WᵀW changed; the symbolic factorization is preprocessing, not solve time
}

void PwlTetSolver::set_positions(const MatX3d& X) {
  if (X.rows() != mesh_.num_vertices()) throw InputError("positions", "PWL(Tet): wrong number of rows");
  if (inverted_count(X) > 0) throw InputError("positions", "PWL(Tet): the positions invert a tet");
  X_ = X;
}

Mat3 PwlTetSolver::jacobian(const MatX3d& X, int t) const {
  Mat3 Ds;
  for (int k = 0; k < 3; ++k) Ds.col(k) = (X.row(mesh_.T(t, k + 1)) - X.row(mesh_.T(t, 0))).transpose();
  return Ds * Bm_[t];
}

int PwlTetSolver::inverted_count(const MatX3d& X) const {
  int n = 0;
#pragma omp parallel for reduction(+ : n) if (mesh_.num_tets() > kParallelTets)
  for (int t = 0; t < mesh_.num_tets(); ++t) n += jacobian(X, t).determinant() <= 0 ? 1 : 0;
  return n;
}

double PwlTetSolver::energy(const MatX3d& X, double* dis_out, double* p2p_out) const {
  double dis = 0;
  bool inverted = false;
#pragma omp parallel for reduction(+ : dis) reduction(|| : inverted) if (mesh_.num_tets() > kParallelTets)
  for (int t = 0; t < mesh_.num_tets(); ++t) {
    const double e = sd_energy(jacobian(X, t));
    if (!std::isfinite(e))
      inverted = true;
    else
      dis += w_(t) * (e - 6);
  }
  if (inverted) dis = std::numeric_limits<double>::infinity();
  double p2p = 0;
  if (W_.rows() > 0) p2p = (W_ * X - targets_).squaredNorm();
  if (dis_out) *dis_out = dis;
  if (p2p_out) *p2p_out = p2p;
  return dis + params_.lambda_p2p * p2p;
}

MatX3d PwlTetSolver::gradient(const MatX3d& X) const {
  MatX3d G = MatX3d::Zero(X.rows(), 3);
  for (int t = 0; t < mesh_.num_tets(); ++t) {
    const Mat3 J = jacobian(X, t);
    const Mat3 P = sd_gradient(J);
    const Eigen::Matrix<double, 12, 1> g =
        w_(t) * jacobian_derivative(Bm_[t]).transpose() * Eigen::Map<const Vec9>(P.data());
    for (int j = 0; j < 4; ++j) G.row(mesh_.T(t, j)) += g.segment<3>(3 * j).transpose();
  }
  if (W_.rows() > 0) G += 2 * params_.lambda_p2p * (W_.transpose() * (W_ * X - targets_));
  return G;
}

SpMat PwlTetSolver::projected_hessian(const MatX3d& X) const {
  const int n = 3 * mesh_.num_vertices();
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(144 * mesh_.num_tets());
  for (int t = 0; t < mesh_.num_tets(); ++t) {
    const Mat9x12 F = jacobian_derivative(Bm_[t]);
    const Mat12 h = w_(t) * F.transpose() * sd_hessian_psd(jacobian(X, t)) * F;
    for (int r = 0; r < 12; ++r)
      for (int c = 0; c < 12; ++c)
        trip.emplace_back(3 * mesh_.T(t, r / 3) + r % 3, 3 * mesh_.T(t, c / 3) + c % 3, h(r, c));
  }
  if (W_.rows() > 0) {
    const SpMat WtW = 2 * params_.lambda_p2p * SpMat(W_.transpose() * W_);
    for (int k = 0; k < WtW.outerSize(); ++k)
      for (SpMat::InnerIterator it(WtW, k); it; ++it)
        for (int a = 0; a < 3; ++a) trip.emplace_back(3 * it.row() + a, 3 * it.col() + a, it.value());
  }
  SpMat H(n, n);
  H.setFromTriplets(trip.begin(), trip.end());
  return H;
}

VecXd PwlTetSolver::handle_errors() const {
  if (W_.rows() == 0) return VecXd();
  return (W_ * X_ - targets_).rowwise().norm();
}

void PwlTetSolver::analyze() {
  const int nt = mesh_.num_tets(), n = 3 * mesh_.num_vertices();
  Impl& im = *impl_;
  {
    // The pattern: every tet's 12x12 block, 2λ WᵀW ⊗ I₃ and the diagonal; slots map local entries to values.
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(144 * nt + n);
    for (int t = 0; t < nt; ++t)
      for (int r = 0; r < 12; ++r)
        for (int c = 0; c < 12; ++c)
          trip.emplace_back(3 * mesh_.T(t, r / 3) + r % 3, 3 * mesh_.T(t, c / 3) + c % 3, 0.0);
    for (int i = 0; i < n; ++i) trip.emplace_back(i, i, 0.0);
    const SpMat WtW = SpMat(W_.transpose() * W_);
    for (int k = 0; k < WtW.outerSize(); ++k)
      for (SpMat::InnerIterator it(WtW, k); it; ++it)
        for (int a = 0; a < 3; ++a) trip.emplace_back(3 * it.row() + a, 3 * it.col() + a, 0.0);
    im.H.resize(n, n);
    im.H.setFromTriplets(trip.begin(), trip.end());
    im.H.makeCompressed();
    auto slot = [&](int r, int c) { return static_cast<int>(&im.H.coeffRef(r, c) - im.H.valuePtr()); };
    im.tet_slot.resize(144 * static_cast<size_t>(nt));
    for (int t = 0; t < nt; ++t)
      for (int r = 0; r < 12; ++r)
        for (int c = 0; c < 12; ++c)
          im.tet_slot[144 * static_cast<size_t>(t) + 12 * r + c] =
              slot(3 * mesh_.T(t, r / 3) + r % 3, 3 * mesh_.T(t, c / 3) + c % 3);
    im.diag_slot.resize(n);
    for (int i = 0; i < n; ++i) im.diag_slot[i] = slot(i, i);
    im.handle_slots.clear();
    for (int k = 0; k < WtW.outerSize(); ++k)
      for (SpMat::InnerIterator it(WtW, k); it; ++it)
        for (int a = 0; a < 3; ++a)
          im.handle_slots.emplace_back(slot(3 * it.row() + a, 3 * it.col() + a),
                                       2 * params_.lambda_p2p * it.value());
    im.chol.analyzePattern(im.H);
    if (im.chol.info() != Eigen::Success) throw NumericalError("PWL(Tet): CHOLMOD symbolic analysis failed");
    im.analyzed = true;
  }
}

PwlTetIteration PwlTetSolver::step() {
  const auto t0 = Clock::now();
  if (W_.rows() == 0) throw InputError("handles", "PWL(Tet): no handles set");
  const int nt = mesh_.num_tets(), n = 3 * mesh_.num_vertices();
  Impl& im = *impl_;
  if (!im.analyzed) analyze();
  PwlTetIteration rec;
  rec.iteration = static_cast<int>(history_.size()) + 1;
  // Gradient and per-tet projected Hessians (parallel), then a serial scatter into the fixed pattern.
  std::vector<Mat12> local(nt);
  std::vector<Eigen::Matrix<double, 12, 1>> lg(nt);
#pragma omp parallel for schedule(static) if (nt > kParallelTets)
  for (int t = 0; t < nt; ++t) {
    const Mat3 J = jacobian(X_, t);
    const Mat9x12 F = jacobian_derivative(Bm_[t]);
    const Mat3 P = sd_gradient(J);
    lg[t] = w_(t) * F.transpose() * Eigen::Map<const Vec9>(P.data());
    local[t] = w_(t) * F.transpose() * sd_hessian_psd(J) * F;
  }
  MatX3d G = MatX3d::Zero(X_.rows(), 3);
  double* val = im.H.valuePtr();
  std::fill(val, val + im.H.nonZeros(), 0.0);
  for (int t = 0; t < nt; ++t) {
    for (int j = 0; j < 4; ++j) G.row(mesh_.T(t, j)) += lg[t].segment<3>(3 * j).transpose();
    const int* s = &im.tet_slot[144 * static_cast<size_t>(t)];
    const double* h = local[t].data();  // column-major: h[r + 12 c]
    for (int c = 0; c < 12; ++c)
      for (int r = 0; r < 12; ++r) val[s[12 * r + c]] += h[r + 12 * c];
  }
  G += 2 * params_.lambda_p2p * (W_.transpose() * (W_ * X_ - targets_));
  for (const auto& [k, v] : im.handle_slots) val[k] += v;
  double mean_diag = 0;
  for (int i = 0; i < n; ++i) mean_diag += val[im.diag_slot[i]];
  mean_diag /= n;
  for (int i = 0; i < n; ++i) val[im.diag_slot[i]] += params_.diagonal_shift * mean_diag;
  im.chol.factorize(im.H);
  if (im.chol.info() != Eigen::Success) throw NumericalError("PWL(Tet): CHOLMOD factorization failed");
  VecXd g(n);
  for (int i = 0; i < X_.rows(); ++i) g.segment<3>(3 * i) = G.row(i).transpose();
  const VecXd d = im.chol.solve(-g);
  if (im.chol.info() != Eigen::Success || !d.allFinite())
    throw NumericalError("PWL(Tet): CHOLMOD solve failed");
  MatX3d D(X_.rows(), 3);
  for (int i = 0; i < X_.rows(); ++i) D.row(i) = d.segment<3>(3 * i).transpose();

  // Line search: halving from t = 1; E = +∞ for any inverted tet, so no accepted step inverts one.
  const double e0 = energy(X_);
  const double slope = g.dot(d);
  double t = 1;
  bool accepted = false;
  MatX3d trial;
  for (int k = 0; k <= params_.max_halvings; ++k, t *= 0.5) {
    trial = X_ + t * D;
    const double e = energy(trial);
    if (std::isfinite(e) && e <= e0 + params_.armijo * t * slope) {
      accepted = true;
      break;
    }
    ++rec.halvings;
  }
  rec.newton_decrement = -slope;
  rec.direction_norm = d.norm();
  if (accepted) {
    X_ = trial;
    rec.step = t;
    rec.step_norm = t * d.norm();
  }
  rec.energy = energy(X_, &rec.e_dis, &rec.e_p2p);
  rec.max_handle_error = handle_errors().maxCoeff();
  rec.ms = ms_since(t0);
  history_.push_back(rec);
  return rec;
}

PwlTetResult PwlTetSolver::solve(const std::function<bool(const PwlTetIteration&)>& on_iteration) {
  const auto t0 = Clock::now();
  PwlTetResult res;
  res.message = "iteration limit";
  for (int it = 0; it < params_.max_iterations; ++it) {
    const double e_before = energy(X_);
    const PwlTetIteration r = step();
    ++res.iterations;
    if (on_iteration && !on_iteration(r)) {
      res.message = "interrupted";
      break;
    }
    if (r.step == 0) {
      res.message = "no decreasing step";
      break;
    }
    // Convergence is judged on the Newton direction, not on the accepted step: a line search that had to
    // shorten the step a lot (to keep every tet positive) makes t‖δ‖ and the decrease small far from a
    // minimum.
    const double scale = std::max(1.0, std::sqrt(X_.squaredNorm()));
    if (r.direction_norm <= params_.step_tolerance * scale) {
      res.converged = true;
      res.message = "Newton step below tolerance";
      break;
    }
    if (0.5 * r.newton_decrement <= params_.energy_tolerance * std::abs(e_before)) {
      res.converged = true;
      res.message = "Newton decrement below tolerance";
      break;
    }
  }
  res.seconds = seconds_since(t0);
  return res;
}

}  // namespace lidef
