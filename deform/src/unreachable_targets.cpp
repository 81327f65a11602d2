#include "lidef/unreachable_targets.h"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <vector>

#include "lidef/number_format.h"
#include "lidef/projected_newton.h"
#include "lidef/signed_svd.h"

namespace lidef {

namespace {

// The handle matrix must be this well conditioned for its computed pseudo-inverse to stand for the exact one
// (relative errors ~ cond · 1e-16 stay far below the factor-2 margin).
constexpr double kMaxCondition = 1e8;
// Every quantity of the proof is computed in double precision; the proof asks for twice the margin it needs.
constexpr double kMargin = 2;
// Voxel centers whose exact ratio is screened (from the energy's float gradients), and those of them
// evaluated again in double precision from the basis for the proof.
constexpr int kScreened = 256;
constexpr int kCandidates = 8;
// Unit roundoff of double precision, and γ_n = n u / (1 − n u): the relative error bound of a sum or dot
// product of n terms computed in double precision (Higham, "Accuracy and Stability of Numerical Algorithms",
// Lemma 3.1 and Eq. 3.5).
constexpr double kUnitRoundoff = 0x1p-53;
double gamma_n(double n) {
  const double nu = n * kUnitRoundoff;
  return nu / (1 - nu);
}
// Backward error of the computed SVD, as a multiple of u ‖D̃‖₂ per unit of max(#h, s): the computed singular
// values are those of D̃ + ΔD̃ with ‖ΔD̃‖₂ ≤ p(#h, s) u ‖D̃‖₂ for a modest p (Golub and Van Loan, Sec. 8.6.3);
// p = 64 max(#h, s) is generous for one-sided Jacobi, bidiagonal QR and divide and conquer alike.
constexpr double kSvdBackwardPerRow = 64;

struct Candidate {
  int sample = -1;
  double ratio = 0;  // σ_min(J₀) / (‖G_x D̃⁺‖₂ ε)
  double sigma_min = 0, bound = 0;
};

// σ_min(J₀) / (‖M‖₂ ε) at a point with reduced gradients Gx (3 by s) and M = Gx W (W = V Σ⁻¹); ratio 0
// when J₀ is not orientation-reversing (with a proven sign) there.
Candidate evaluate_point(const MatXd& Gx, const MatXd& M, const MatS3& y0, double eps) {
  Candidate c;
  const Mat3 J = (Gx * y0).transpose();
  bool resolved = false;
  const Vec3 sv = signed_singular_values(J, &resolved);
  if (!resolved || !(sv(2) < 0)) return c;
  // J(x) − J₀(x) = (M Uᵀ D̃ (ỹ − ỹ₀))ᵀ, so its norm is at most ‖M‖₂ ε.
  const Mat3 MMt = M * M.transpose();
  const double norm_m = std::sqrt(
      std::max(0.0, Eigen::SelfAdjointEigenSolver<Mat3>(MMt, Eigen::EigenvaluesOnly).eigenvalues()(2)));
  c.sigma_min = -sv(2);
  c.bound = norm_m * eps;
  c.ratio = c.bound > 0 ? c.sigma_min / c.bound : INFINITY;
  return c;
}

// Bounds of the residuals of step 3 (docs/certificate.md, "Targets no certified map reaches"), with every
// rounding of the double-precision computation accounted for:
//   upper ≥ ‖D̃ ỹ₀ − Q‖_F   (the exact residual of the computed ỹ₀; the radius of step 4 needs an upper bound)
//   lower ≤ ρ* = min over all ỹ of ‖D̃ ỹ − Q‖_F   (the exact least-squares residual; step 3 needs a lower
//   bound)
// r = D̃ ỹ₀ − Q splits into its part in the range of D̃ and the rest; the rest is the exact least-squares
// residual, so ρ*² = ‖r‖² − ‖P r‖² with ‖P r‖_F = ‖Uᵀ r‖_F = ‖Σ⁻¹ Vᵀ D̃ᵀ r‖_F ≤ ‖D̃ᵀ r‖_F / σ_min(D̃). The
// computed r̂ differs from r by at most γ_{s+1} (|D̃| |ỹ₀| + |Q|) entrywise, D̃ᵀ r̂ from its computed value by
// γ_{#h} |D̃ᵀ| |r̂|, and every Frobenius norm by a relative γ of its length.
struct ResidualBounds {
  double computed = 0;  // ‖r̂‖_F as computed
  double upper = 0;
  double lower = 0;
  double rounding = 0;  // bound of ‖r̂ − r‖_F: how finely a map's handle errors can be evaluated at all
};
ResidualBounds residual_bounds(const MatXd& D, const MatX3d& Q, const MatS3& y0, double sigma_min_lo,
                               double sigma_max_hi) {
  const double h = static_cast<double>(D.rows()), s = static_cast<double>(D.cols());
  const double g_norm = gamma_n(3 * h + 2);  // a Frobenius norm of 3 #h entries, its square root included
  const MatX3d r = D * y0 - Q;
  ResidualBounds b;
  b.computed = r.norm();
  // Sums of non-negative terms: computed ≥ (1 − γ) exact, so exact ≤ computed (1 + 2γ) while γ < ½.
  const MatX3d magnitude = D.cwiseAbs() * y0.cwiseAbs() + Q.cwiseAbs();
  const double e_r = gamma_n(s + 1) * magnitude.norm() * (1 + 2 * gamma_n(s + 1)) * (1 + 2 * g_norm);
  b.rounding = e_r;
  b.upper = b.computed * (1 + g_norm) + e_r;
  const MatS3 g = D.transpose() * r;
  const MatS3 g_rounding = D.transpose().cwiseAbs() * r.cwiseAbs();
  const double g_hi = g.norm() * (1 + gamma_n(3 * s + 2)) +
                      gamma_n(h) * g_rounding.norm() * (1 + 2 * gamma_n(h)) * (1 + 2 * gamma_n(3 * s + 2)) +
                      sigma_max_hi * e_r;
  const double r_lo = std::max(0.0, b.computed * (1 - g_norm) - e_r);
  const double p_hi = sigma_min_lo > 0 ? g_hi / sigma_min_lo : INFINITY;
  // Rounding of this last step: a relative 4u on each square and on the square root, taken off.
  b.lower = r_lo > p_hi ? std::sqrt((r_lo - p_hi) * (r_lo + p_hi)) * (1 - 8 * kUnitRoundoff) : 0.0;
  return b;
}

}  // namespace

UnreachabilityProof prove_targets_unreachable(const DeformationSolver& solver) {
  const DeformationEnergy& energy = solver.energy_function();
  const MatXd& D = energy.handle_matrix();
  const MatX3d& Q = energy.targets();
  UnreachabilityProof p;
  p.handles = static_cast<int>(D.rows());
  p.reduced_size = static_cast<int>(D.cols());
  p.tolerance = solver.params().handle_tolerance;
  const int h = p.handles, s = p.reduced_size;
  if (h < s) {
    p.reason =
        "not proven: the " + std::to_string(h) + " handles fix at most " + std::to_string(h) + " of the " +
        std::to_string(s) +
        " reduced coefficients per coordinate, so maps that reach the targets may differ in directions "
        "the handles do not see";
    return p;
  }

  // --- The least-squares map ỹ₀ = D̃⁺ Q and the radius ε of the reaching maps around it (in D̃'s norm).
  const Eigen::BDCSVD<MatXd> svd(D, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const VecXd& sv = svd.singularValues();
  const double smax = sv(0), smin = sv(s - 1);
  p.condition = smin > 0 ? smax / smin : INFINITY;
  if (!(smin > 0) || !(p.condition <= kMaxCondition)) {
    p.reason = "not proven: the handle matrix is too close to rank-deficient (condition number " +
               format_g(p.condition, 3) + " > " + format_g(kMaxCondition, 2) +
               "), so the handles barely see some directions of the subspace";
    return p;
  }
  const MatXd W = svd.matrixV() * sv.cwiseInverse().asDiagonal();  // s by s: D̃⁺ = W Uᵀ
  p.least_squares = W * (svd.matrixU().transpose() * Q);
  const double svd_error = kSvdBackwardPerRow * std::max(h, s) * kUnitRoundoff * smax;
  const ResidualBounds rb = residual_bounds(D, Q, p.least_squares, smin - svd_error, smax + svd_error);
  p.residual = rb.computed;
  p.residual_upper = rb.upper;
  p.residual_lower = rb.lower;
  p.rounding_floor = rb.rounding;
  const double reach = std::sqrt(static_cast<double>(h)) * p.tolerance;  // ‖D̃ỹ − Q‖_F of a reaching map
  p.radius = reach + p.residual_upper;
  // Below the rounding of evaluating D̃ ỹ − Q, "reached" and "missed" cannot be told apart in double
  // precision: the proof never claims a residual smaller than that, whatever the tolerance (even 0).
  const double needed = kMargin * std::max(reach, p.rounding_floor);
  if (p.residual_lower >= needed) {
    p.proven = true;
    p.kind = "residual";
    p.reason = "no map of the subspace reaches the targets: the least-squares residual is at least " +
               format_bound(p.residual_lower, false, 4) + " (computed " + format_g(p.residual, 4) +
               ", less its rounding), at least " + format_g(kMargin, 2) +
               " x max(sqrt(#handles) x tolerance, rounding floor) = " + format_g(needed, 4) +
               " (normalized frame)";
    return p;
  }

  // --- Screen every voxel center with the energy's stored (float) gradients, best margins first.
  const MatXfR& G = energy.gradient_matrix();
  const int n = static_cast<int>(G.rows() / 3);
  // First a cheap rank of the folding centers by a lower bound of their ratio, ‖G_x W‖₂ ≤ ‖G_x‖_F / σ_min(D̃),
  // then the exact ‖G_x W‖₂ for the best kScreened only (any voxel center serves the proof).
  std::vector<std::pair<double, int>> folding;  // (σ_min(J₀) / ‖G_x‖_F, voxel), where ỹ₀ folds (float screen)
  for (int i = 0; i < n; ++i) {
    const MatXd Gx = G.middleRows(3 * i, 3).cast<double>();
    const Mat3 J = (Gx * p.least_squares).transpose();
    if (!(J.determinant() < 0)) continue;
    const double sigma = -signed_singular_values(J)(2);
    if (sigma > 0) folding.emplace_back(sigma / Gx.norm(), i);
  }
  const size_t screened = std::min<size_t>(folding.size(), kScreened);
  std::partial_sort(folding.begin(), folding.begin() + screened, folding.end(),
                    [](const auto& a, const auto& b) {
                      return a.first > b.first || (a.first == b.first && a.second < b.second);
                    });
  folding.resize(screened);
  std::vector<Candidate> found;
  const int m = static_cast<int>(screened);
  MatXd Gc(3 * m, s);
  for (int j = 0; j < m; ++j) Gc.middleRows(3 * j, 3) = G.middleRows(3 * folding[j].second, 3).cast<double>();
  const MatXd Mc = Gc * W;  // ‖G_x W‖₂ of all screened centers with one product
  for (int j = 0; j < m; ++j) {
    Candidate c = evaluate_point(Gc.middleRows(3 * j, 3), Mc.middleRows(3 * j, 3), p.least_squares, p.radius);
    c.sample = folding[j].second;
    if (c.ratio > 0) found.push_back(c);
  }
  if (found.empty()) {
    p.reason =
        "not proven: the least-squares map of the targets is orientation-preserving at every voxel center, "
        "so "
        "nothing rules out a certified map that reaches them";
    return p;
  }
  std::sort(found.begin(), found.end(), [](const Candidate& a, const Candidate& b) {
    return a.ratio > b.ratio || (a.ratio == b.ratio && a.sample < b.sample);
  });
  found.resize(std::min<size_t>(found.size(), kCandidates));

  // --- The proof itself: the best candidates again in double precision from the basis.
  Candidate best;
  const MatX3d centers = solver.normalized_sampling().centers;
  for (const Candidate& f : found) {
    const MatXd Gx =
        solver.normalized_basis().gradient_matrix(centers.row(f.sample)) * solver.subspace().basis;
    Candidate c = evaluate_point(Gx, Gx * W, p.least_squares, p.radius);
    c.sample = f.sample;
    if (c.ratio > best.ratio) best = c;
  }
  if (best.sample >= 0) {
    p.point = solver.sampling().centers.row(best.sample).transpose();
    p.sigma_min = best.sigma_min;
    p.jacobian_bound = best.bound;
  }
  const std::string where = best.sample >= 0
                                ? "(" + format_g(p.point.x(), 5) + ", " + format_g(p.point.y(), 5) + ", " +
                                      format_g(p.point.z(), 5) + ")"
                                : "";
  if (best.sample >= 0 && best.ratio >= kMargin) {
    p.proven = true;
    p.kind = "orientation";
    p.reason = "every map of the subspace that reaches the targets folds: det J < 0 at the voxel center " +
               where + " (the least-squares map has sigma_min " + format_g(p.sigma_min, 4) +
               " there with det J < 0, and no map within the tolerance moves its Jacobian by more than " +
               format_g(p.jacobian_bound, 4) + ")";
  } else {
    p.reason = "not proven: the least-squares map folds, but at best by " + format_g(best.ratio, 3) +
               " x the largest change the tolerance allows " + where + " (" + format_g(kMargin, 2) +
               " needed)";
  }
  return p;
}

}  // namespace lidef
