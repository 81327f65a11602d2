// Sound lower bounds of σ3 on a ball (docs/explorer.md, items 2 and 3 of "verified"): for harmonic
// polynomial maps of degree ≤ 4 with the explorer's own cell bound, for cage maps with the project's
// certificate (octree_certifier.h).
#pragma once
#include <string>

#include "lidef/explorer/explorer_map.h"
#include "lidef/explorer/harmonic_polynomials.h"
#include "lidef/types.h"

namespace lidef {

// Polynomial maps: the cube [c − R, c + R]³ is cut into base_cells³ cells; the cells meeting the closed ball
// (or, with sphere_only, the sphere) must satisfy σ3(q) − r L − τ > threshold at their center q
// (r = circumradius, L = cell_lipschitz_bound, τ a rounding allowance; docs/explorer.md). Failing cells are
// split into 8 up to max_depth; a cell still failing there, σ3(q) ≤ threshold at a center, or an exhausted
// budget means "not certified".
struct BallCertifyParams {
  int base_cells = 8;  // per axis
  int max_depth = 8;
  long max_cells = 4000000;  // evaluated cells in all
  double threshold = 0;      // certify σ3 > threshold
  bool sphere_only = false;  // only the cells meeting the sphere |x − c| = R
};

struct BallCertificate {
  bool certified = false;
  std::string reason;  // why not (empty when certified)
  double threshold = 0;
  bool sphere_only = false;
  long cells_evaluated = 0;
  long leaves = 0;
  int max_depth_used = 0;
  double min_lower_bound = 0;        // over the leaves: a lower bound of σ3 on the region
  double min_sigma3_center = 0;      // over the evaluated centers
  Vec3 worst_center = Vec3::Zero();  // leaf with the smallest lower bound (polynomial maps)
  // Polynomial maps, over the accepted leaves (when certified they cover the region): max of L ≥ ‖H‖
  // (27-entry Frobenius) and of ‖J(q)‖_F + r L ≥ ‖J‖_F on each leaf's ball.
  double max_hessian_bound = 0;
  double max_jacobian_bound = 0;
};

// L = ‖H(q)‖ + r (‖T(q)‖ + r ‖F‖) from the jet at the center q (order 3), the constant fourth-derivative norm
// ‖F‖ and the radius r: ‖H(x)‖ ≤ L for |x − q| ≤ r (degree ≤ 4).
double cell_lipschitz_bound(const PolyJet& jet_at_center, double fourth_norm, double r);

BallCertificate certify_sigma3_on_ball(const HarmonicPolynomialMap& map, const Ball& ball,
                                       const BallCertifyParams& params = {});

// Cage maps: σ3 > 0 on the ball with the project's certificate (OctreeCertifier, third-order bound): the
// cubes of side h covering the ball (those meeting it) are the base voxels, h chosen so that every cube's
// circumscribed ball stays inside the cage, at least half the ball-to-cage clearance away from it. max_depth:
// refinement levels. Not certified when the domain ball is too close to the cage for at most `max_cells`
// base cubes.
BallCertificate certify_cage_map_on_ball(const CageExplorerMap& map, const Ball& ball, int max_depth = 6,
                                         long max_cells = 400000);

}  // namespace lidef
