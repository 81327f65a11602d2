// Per-voxel, per-edge factors of the Lipschitz bounds on σ3 (paper Sec. 5, App. H; docs/certificate.md).
// Everything here depends only on the cage and the voxel (a ball B(p, r) containing it), never on the map.
//
// For an undirected cage edge (u, w) of length d and the ball B(p, r), with m(q) = |q−u| + |q−w|:
//   h_e   = a lower bound of m over the ball (> d is required for any finite bound),
//   first order  (16)-(17):  max_B sqrt(|α_e|² + |β_e|²) ≤ sqrt(h² + 4d²) / (2π (h² − d²)),
//   third order  (66)-(67):  max_B sqrt(‖∇α_e‖² + ‖∇β_e‖²) ≤ sqrt(bound66 + bound67).
// Both use that m/(m²−d²) and 1/(m²−d²) decrease in m > d, so the worst case is the smallest m.
// A ball that touches the edge (h ≤ d, or |p−u| ≤ r, or |p−w| ≤ r) gets +∞: never certifiable.
#pragma once
#include <string>

#include "lidef/types.h"

namespace lidef {

// Which bound the certificate uses: first order (17) or third order (21) (octree_certifier.h).
enum class LipschitzBound { kFirstOrder, kThirdOrder };
const char* to_string(LipschitzBound b);                           // "first" / "third"
LipschitzBound lipschitz_bound_from_string(const std::string& s);  // throws InputError

// Lower bound of |q−u| + |q−w| over q in the ball B(p, r): the larger of
// (|p−u| − r) + (|p−w| − r)  and  2 sqrt(ρ² + d²/4), ρ = max(0, dist(p, line uw) − r).
double edge_sum_lower_bound(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// max over B(p, r) of sqrt(|α_e|² + |β_e|²) (upper bound); +∞ when the ball nears the edge.
double first_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// max over B(p, r) of sqrt(‖∇α_e‖_F² + ‖∇β_e‖_F²) (upper bound, (66)+(67)); +∞ when the ball nears the edge.
double third_order_edge_factor(const Vec3& u, const Vec3& w, const Vec3& p, double r);

// The exact pointwise quantities the factors bound, for tests: |α|²+|β|² and ‖∇α‖²+‖∇β‖² at q,
// the latter from the closed forms (64) and (65) (with the MATH-NOTES erratum of (65)).
double alpha_beta_norm2(const Vec3& u, const Vec3& w, const Vec3& q);
double grad_alpha_norm2_closed_form(const Vec3& u, const Vec3& w, const Vec3& q);
double grad_beta_norm2_closed_form(const Vec3& u, const Vec3& w, const Vec3& q);

}  // namespace lidef
