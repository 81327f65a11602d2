// Per-voxel, per-edge factors of the Lipschitz bounds on σ3 (paper Sec. 5, App. H; docs/certificate.md).
// Everything here depends only on the cage and the voxel (a ball B(p, r) containing it), never on the map.
//
// For an undirected cage edge (u, w) of length d and the ball B(p, r), with m(q) = |q−u| + |q−w|:
//   h_e   = a lower bound of m over the ball (> d is required for any finite bound),
//   first order  (16)-(17):  max_B sqrt(|α_e|² + |β_e|²) ≤ sqrt(h² + 4d²) / (2π (h² − d²)),
//   third order  (66)-(67):  max_B sqrt(‖∇α_e‖² + ‖∇β_e‖²) ≤ sqrt(bound66 + bound67),
//   sharp first order:       the smaller of (17) and d sqrt((a+b)² + 4ab) / (4π ab sqrt(h² − d²)), a, b the
//                            lower bounds of |q−u|, |q−w| (docs/certificate.md, Step 3: (17) ignores that
//                            α and β vanish with the angle at q, which is what makes m² − d² small near the
//                            edge; there the sharp form is smaller by about d / dist(q, edge)).
// All use that m/(m²−d²) and 1/(m²−d²) decrease in m > d, so the worst case is the smallest m.
// A ball that touches the edge (h ≤ d, or |p−u| ≤ r, or |p−w| ≤ r) gets +∞: never certifiable.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "lidef/types.h"

namespace lidef {

// Which bound the certificate uses (octree_certifier.h, docs/certificate.md Steps 1-3 and 3b):
//   first     (17): loss r·Σ δ Γ
//   third     (21): loss r·(‖H(c)‖_F + r Σ δ Θ)
//   combined  (Step 3b): per leaf the smaller of the first-order loss and the Taylor form
//                        r ‖H(c)‖_op + ½ r² Σ δ Θ (Weyl + second-order Taylor of J, operator norm of H(c)).
//   spectral  (Step 3c): combined, and a third candidate per leaf: σ3(c) − ℓ + ½ r² Σ δ Θ with ℓ a
//                        lower bound of σ3 on the first-order Taylor polynomial of J over the ball
//                        (taylor_sigma3_lower_bound: the smallest eigenvalue of JᵀJ moved by the exact
//                        first-order change, minus a second-order term with the spectral gap).
enum class LipschitzBound { kFirstOrder, kThirdOrder, kCombined, kSpectral };
const char* to_string(LipschitzBound b);  // "first" / "third" / "combined" / "spectral"
LipschitzBound lipschitz_bound_from_string(const std::string& s);  // throws InputError

// How the CPU refinement evaluates octree children (docs/certificate.md, Steps 4b–4d; the benchmarks
// compare them in one run): per face (HarmonicBasis::differential_jet, the first code), per edge one child at
// a time (EdgeJet::evaluate), per edge with 8 children at once in SIMD lanes (EdgeJet::evaluate_lanes) —
// these three give the same values up to rounding, covered by the allowance τ — or far field: the 8 children
// of a node evaluated on the cage faces near them only, the other faces' part expanded to second order around
// the parent's center with a bounded remainder that the margin subtracts (third-order bound only; the others
// use "batched").
enum class RefinementEval { kPerFace, kPerEdge, kPerEdgeBatched, kFarField };
const char* to_string(RefinementEval r);  // "per-face" / "per-edge" / "batched" / "far-field"

// The per-edge factors as functions of the ball-dependent lower bounds, shared by the per-voxel factors below
// and the per-edge evaluation of octree children (edge_jet.h): h = lower bound of m over the ball (> d),
// a, b = lower bounds of |q−u|, |q−w| over the ball (> 0). Callers check h > d (and a, b > 0) first.
inline double first_order_factor(double h, double d) {
  return std::sqrt(h * h + 4 * d * d) / (2 * M_PI * (h * h - d * d));
}
// |α|² + |β|² ≤ d² ((1/a + 1/b)² + 4/(ab)) / (16π² (m² − d²)) pointwise (a = |q−u|, b = |q−w|, m = a + b;
// from m² − d² = 4ab cos²(θ/2), θ the angle at q), decreasing in a, b and m: at the lower bounds it bounds
// the ball. The smaller of it and (17).
inline double sharp_first_order_factor(double h, double d, double a, double b) {
  const double ab = a * b;
  const double near = d * std::sqrt(((a + b) * (a + b) + 4 * ab) / (h * h - d * d)) / (4 * M_PI * ab);
  return std::min(first_order_factor(h, d), near);
}
// (66) + (67) = (1 + h²d²/n²)/(π²(h²−d²)²) + 3h²d²/(2π²n²(h²−d²)²)
//             = (n² + 2.5 h²d²)/(π² n² (h²−d²)²),  n = ab.
inline double third_order_factor(double h, double d, double a, double b) {
  const double md = h * h - d * d;
  const double nn = (a * b) * (a * b);
  const double h2d2 = h * h * d * d;
  return std::sqrt((nn + 2.5 * h2d2) / (M_PI * M_PI * nn * md * md));
}

// An upper bound of the operator norm of the Hessian tensor as a map R³ → (R³ˣ³, ‖·‖_F), v ↦ Σ_k v_k H_k
// with (H_k)_ab = ∂J_ab/∂p_k = H[a](b, k): sqrt of the largest eigenvalue of the Gram matrix
// G_kl = ⟨H_k, H_l⟩_F, plus a rounding allowance, and never above the 27-entry Frobenius norm. It bounds the
// ‖·‖₂ version as well (‖M‖₂ ≤ ‖M‖_F). H[a] = ∂²f_a/∂p∂p (MapJet's layout).
double hessian_operator_norm(const std::array<Mat3, 3>& H);

// A lower bound of σ3ˢ(J + H[v]) over all |v| ≤ r, where H[v] has rows (H[a] v)ᵀ (the first-order Taylor
// polynomial of J around the center): λmin((J+H[v])ᵀ(J+H[v])) ≥ λmin(JᵀJ + F(v)), F(v) = JᵀH[v] + H[v]ᵀJ,
// bounded below through the smallest eigenvector of JᵀJ and its 2x2 reduction (docs/certificate.md, Step 3c),
// with a rounding allowance. −∞ when det J ≤ 0, J or H is not finite, or the bound is not positive.
double taylor_sigma3_lower_bound(const Mat3& J, const std::array<Mat3, 3>& H, double r);

// Step 3d of docs/certificate.md (bounded distortion): bounds of σ1 and σ3 on the first-order Taylor
// polynomial J + H[v] of the map's Jacobian that are linear in v up to a second-order remainder,
//   σ1(J + H[v]) ≤ upper1 + g1·v,   σ3ˢ(J + H[v]) ≥ lower3 + g3·v   for every |v| ≤ r,
// g1 and g3 the gradients of σ1 and σ3 at the center (from the computed singular vectors), upper1 and lower3
// the center values moved by the second-order terms of the 2x2 reductions of Step 3c (for λmax and λmin of
// JᵀJ) and by rounding allowances. Near a maximum of σ1/σ3 the gradients nearly cancel in g1 − K g3, so the
// bound of K below loses O(r²) where the per-leaf quotient of Lipschitz bounds loses O(r).
// valid = false when det J ≤ 0, J or H is not finite, or σ3's remainder is not below σ3.
struct TaylorSingularBounds {
  bool valid = false;
  double upper1 = 0, lower3 = 0;
  Vec3 g1 = Vec3::Zero(), g3 = Vec3::Zero();
};
TaylorSingularBounds taylor_singular_bounds(const Mat3& J, const std::array<Mat3, 3>& H, double r);
// With ‖J(q) − J − H[q − c]‖₂ ≤ rho on the ball (Taylor remainder, storage and rounding allowances): the
// smallest K (rounded up, verified) with upper1 + rho + r|g1 − K g3| ≤ K (lower3 − rho), so that
// σ1(J(q)) ≤ K σ3(J(q)) on the whole ball; +∞ when there is none (or t is not valid).
double taylor_distortion_bound(const TaylorSingularBounds& t, double r, double rho);
// The same ball's upper bound of σ1: upper1 + rho + r|g1| (+∞ when t is not valid).
double taylor_sigma1_upper_bound(const TaylorSingularBounds& t, double r, double rho);
// The same ball's lower bound of σ3: lower3 − rho − r|g3| (−∞ when t is not valid).
double taylor_sigma3_lower_bound(const TaylorSingularBounds& t, double r, double rho);

// Lower bound of |q−u| + |q−w| over q in the ball B(p, r): the larger of
// (|p−u| − r) + (|p−w| − r)  and  2 sqrt(ρ² + d²/4), ρ = max(0, dist(p, line uw) − r).
double edge_sum_lower_bound(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// max over B(p, r) of sqrt(|α_e|² + |β_e|²) (upper bound); +∞ when the ball nears the edge.
double first_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// The same maximum, bounded by sharp_first_order_factor (never above first_order_edge_factor).
double sharp_first_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// max over B(p, r) of sqrt(‖∇α_e‖_F² + ‖∇β_e‖_F²) (upper bound, (66)+(67)); +∞ when the ball nears the edge.
double third_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// The cage's undirected edges u → w as arrays (structure of arrays: e = w − u, d = |e|), for factor_row().
struct EdgeArrays {
  EdgeArrays(const std::vector<Vec3>& u, const std::vector<Vec3>& w);
  long size() const { return static_cast<long>(d.size()); }
  std::vector<double> ux, uy, uz, wx, wy, wz, ex, ey, ez, d;
};
// Which per-edge factor a row holds: the paper's first order (17) and third order (66)+(67) (the local
// certificate's `bound`), or the sharp first order (the global injectivity check's L₁, global_injectivity.h).
enum class EdgeFactor { kFirstOrder, kThirdOrder, kSharpFirstOrder };
// One ball's row of a factor matrix: out[e] = the factor `kind` of edge e for the ball B(p, r)
// (first_order_edge_factor, third_order_edge_factor, sharp_first_order_edge_factor), rounded up to the next
// float (an upper bound stays one), for every edge; a loop over the edges that vectorizes (the same
// arithmetic as the functions above). Returns whether every factor is finite.
bool factor_row(const EdgeArrays& edges, EdgeFactor kind, const Vec3& p, double r, float* out);

// The exact pointwise quantities the factors bound, for tests: |α|²+|β|² and ‖∇α‖²+‖∇β‖² at q,
// the latter from the closed forms (64) and (65) (with the MATH-NOTES erratum of (65)).
double alpha_beta_norm2(const Vec3& u, const Vec3& w, const Vec3& q);
double grad_alpha_norm2_closed_form(const Vec3& u, const Vec3& w, const Vec3& q);
double grad_beta_norm2_closed_form(const Vec3& u, const Vec3& w, const Vec3& q);

}  // namespace lidef
