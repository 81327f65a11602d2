// The σ3 explorer (paper Fig. 2, App. D; docs/explorer.md): interior local minima of the smallest signed
// singular value σ3 of harmonic maps on a ball, their certification, and the sub/superharmonicity experiment.
//
// Maps: the closed-form harmonic polynomials of harmonic_polynomials.h, or a cage map (any model and
// coefficients), both behind ExplorerMap. Everything here is deterministic for a fixed seed, whatever the
// thread count.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/green_coordinates.h"
#include "lidef/explorer/harmonic_polynomials.h"
#include "lidef/singular_value_derivatives.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

// The closed ball the map is studied on.
struct Ball {
  Vec3 center = Vec3::Zero();
  double radius = 1;
  bool contains(const Vec3& p) const { return (p - center).norm() <= radius; }
};

// A map with f, J, H and third derivatives T at a point (PolyJet layout).
class ExplorerMap {
 public:
  virtual ~ExplorerMap() = default;
  virtual PolyJet jet(const Vec3& p) const = 0;
  virtual Vec3 value(const Vec3& p) const { return jet(p).f; }
  // J alone (cheaper for cage maps).
  virtual Mat3 jacobian(const Vec3& p) const { return jet(p).J; }
  // True when T is exact (polynomials); false when it comes from finite differences (cage maps).
  virtual bool exact_third_derivatives() const = 0;
  virtual std::string description() const = 0;
};

class PolynomialExplorerMap : public ExplorerMap {
 public:
  explicit PolynomialExplorerMap(HarmonicPolynomialMap map) : map_(std::move(map)) {}
  PolyJet jet(const Vec3& p) const override { return map_.jet(p, 3); }
  Vec3 value(const Vec3& p) const override { return map_.value(p); }
  bool exact_third_derivatives() const override { return true; }
  std::string description() const override;
  const HarmonicPolynomialMap& map() const { return map_; }

 private:
  HarmonicPolynomialMap map_;
};

// A cage map f = Σ y_i basis_i (green_coordinates.h). f, J, H are the closed forms; T is the central
// difference of the closed-form H with step `fd_step` (relative error ~1e-7 at the distances the ball keeps
// from the cage).
class CageExplorerMap : public ExplorerMap {
 public:
  // y: #V+#F by 3. Keeps its own copy of the cage and y.
  CageExplorerMap(const Cage& cage, const MatX3d& y, std::string name, double fd_step = 1e-4);
  PolyJet jet(const Vec3& p) const override;
  Vec3 value(const Vec3& p) const override;
  Mat3 jacobian(const Vec3& p) const override;
  bool exact_third_derivatives() const override { return false; }
  std::string description() const override { return name_; }
  const Cage& cage() const { return cage_; }
  const MatX3d& coefficients() const { return y_; }
  const HarmonicBasis& basis() const { return basis_; }

 private:
  Cage cage_;
  MatX3d y_;
  HarmonicBasis basis_;
  std::string name_;
  double h_;
};

// σ's of the map at p with gradients and (with_hessian) Hessians and Laplacians
// (singular_value_derivatives.h).
SigmaDerivatives map_sigma_derivatives(const ExplorerMap& map, const Vec3& p, bool with_hessian = true);

// ---------------------------------------------------------------------------------------------------------------
// Interior minima of σ3.
struct Sigma3Minimum {
  Vec3 position = Vec3::Zero();
  double sigma3 = 0;
  double gradient_norm = 0;
  Vec3 hessian_eigenvalues = Vec3::Zero();  // ascending
  double sphere_radius = 0;                 // radius of the small sphere around the point that was sampled
  double sphere_min_sigma3 = 0;             // min of σ3 over that sphere's sample points
  double gap = 0;                           // gap of σ3 (σ3 simple and σ3 + σj ≠ 0 when > 0)
  bool strict = false;  // Hessian eigenvalues > 1e-8 (1 + σ1), sphere_min_sigma3 > sigma3 + 1e-12 (1 + σ1)
  int starts = 0;       // starts that converged to this point
};

struct MinimaSearchParams {
  int starts = 24;  // the ball's center plus (starts − 1) random points in the ball
  std::uint64_t seed = 1;
  int max_iterations = 200;          // per start
  double interior_margin = 1e-3;     // a minimum must satisfy |x − c| < R (1 − margin)
  double gradient_tolerance = 1e-9;  // relative to 1 + σ1 at the point
  int sphere_points = 200;           // Fibonacci points on the small confirmation sphere
};

// Multi-start projected trust-region Newton descent of σ3 in the ball, with the exact gradient
// (∂σ3/∂x_k = u3ᵀ ∂J/∂x_k v3) and Hessian of σ3. Returns the distinct interior critical points that are local
// minima candidates (|∇σ3| small, inside the margin), sorted by σ3, each confirmed by the Hessian's
// eigenvalues and by sampling σ3 on a small sphere around it (radius min(R/100, distance to the boundary /
// 2)).
std::vector<Sigma3Minimum> find_sigma3_minima(const ExplorerMap& map, const Ball& ball,
                                              const MinimaSearchParams& params = {});

// Min of σ3 over the vertices of an icosphere of the ball's radius (`subdivisions` times subdivided): a
// sampled estimate of the minimum on the boundary. Returns the value and its point.
std::pair<double, Vec3> sampled_sphere_min_sigma3(const ExplorerMap& map, const Ball& ball,
                                                  int subdivisions = 4);

// ---------------------------------------------------------------------------------------------------------------
// A sound lower bound of σ3 on the ball (or on its boundary sphere) for polynomial maps of degree ≤ 4.
// Cells: the cube [c − R, c + R]³ is cut into base_cells³ cubes; the cells meeting the closed ball (or, with
// sphere_only, meeting the sphere) are checked. A cell with center q, side h, circumradius r = (√3/2) h
// passes when
//   σ3(q) − r L − τ > threshold,   L = ‖H(q)‖ + r (‖T(q)‖ + r ‖F‖)
// (full Frobenius norms: 27, 81, 243 entries). L bounds ‖H‖ on B(q, r) exactly: T is affine for degree ≤ 4 so
// ‖T‖ ≤ ‖T(q)‖ + r ‖F‖ there, and ‖H(x)‖ ≤ ‖H(q)‖ + |x − q| max ‖T‖. By Theorem 4.1 (docs/certificate.md)
// σ3 ≥ σ3(q) − r L on the cell. τ = 1e-9 (|σ3(q)| + r L + 24 max(1, ρ)⁴ Σ|monomial coefficients|), ρ =
// largest coordinate magnitude in the cube, covers rounding (a wide allowance, not interval arithmetic).
// Failing cells are split into 8 up to max_depth; a cell still failing there, σ3(q) ≤ threshold at a center,
// or an exhausted budget means "not certified".
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
  double min_lower_bound = 0;  // over the leaves: σ3(q) − r L − τ (a lower bound of σ3 on the region)
  double min_sigma3_center = 0;      // over the evaluated centers
  Vec3 worst_center = Vec3::Zero();  // leaf with the smallest lower bound
  // Over the accepted leaves (when certified they cover the region): max of L ≥ ‖H‖ (27-entry Frobenius) and
  // of ‖J(q)‖_F + r L ≥ ‖J‖_F on each leaf's ball.
  double max_hessian_bound = 0;
  double max_jacobian_bound = 0;
};

// The cell bound L above from the jet at the center q (order 3), ‖F‖ and the radius r: ‖H(x)‖ ≤ L for |x − q|
// ≤ r.
double cell_lipschitz_bound(const PolyJet& jet_at_center, double fourth_norm, double r);

BallCertificate certify_sigma3_on_ball(const HarmonicPolynomialMap& map, const Ball& ball,
                                       const BallCertifyParams& params = {});

// Local injectivity (σ3 > 0) of a cage map on the ball with the project's certificate (octree_certifier.h,
// docs/certificate.md, third-order bound): cubes of side h covering the ball (those meeting it) as base
// voxels, with h chosen so that every cube's circumscribed ball stays inside the cage, at least half the
// ball-to-cage clearance away from it (the map is harmonic, and the edge bounds finite, only there).
// max_depth: refinement levels. Not certified when the domain ball is too close to the cage for at most
// `max_cells` base cubes.
BallCertificate certify_cage_map_on_ball(const CageExplorerMap& map, const Ball& ball, int max_depth = 6,
                                         long max_cells = 400000);

// ---------------------------------------------------------------------------------------------------------------
// The image of the boundary sphere: an icosphere of the ball (`subdivisions` times subdivided) mapped vertex
// by vertex, checked for self-intersections with exact predicates (self_intersections.h). This is a check of
// the piecewise-linear interpolant of the image surface at this resolution, not of the smooth surface itself.
struct BoundaryEmbedding {
  bool embedded = false;
  int subdivisions = 0;
  long intersecting_pairs = 0;
  TriMesh source;             // the icosphere on the ball's boundary
  TriMesh image;              // its image (same faces)
  double min_image_edge = 0;  // shortest image edge (degenerate triangles would be skipped by the check)
  double signed_volume = 0;   // enclosed by the image (> 0: orientation preserved)
};
BoundaryEmbedding check_boundary_embedding(const ExplorerMap& map, const Ball& ball, int subdivisions = 5);

// A sound certificate that a polynomial map is injective on the boundary sphere (docs/explorer.md). With σ3 >
// s > 0 certified on the ball (threshold `sigma3_threshold`), H := max ‖H‖ and G := max ‖J‖_F bounded by that
// certificate, and ρ = s / H:
//  * |p − q| < ρ: f(p) − f(q) = J(q)(p − q) + E, |E| ≤ ½ H |p − q|², so |f(p) − f(q)| ≥ |p − q| (s − ½ H |p −
//  q|) > 0
//    (the segment lies in the ball, which is convex);
//  * |p − q| ≥ ρ: p, q lie in spherical triangles T1, T2 of an icosphere (`subdivisions`) with
//    |c1 − c2| + rad1 + rad2 ≥ ρ (c the centroid, rad ≥ max |p − c| on the spherical triangle). f maps each
//    spherical triangle T to within δ_T = G sag_T + ½ H e_T² of its linear image (sag: distance from the
//    sphere to the flat triangle, e: longest edge), so it suffices that the linear images of every such pair
//    are more than δ1 + δ2 apart: pairs whose image boxes grown by δ do not overlap are, the others are
//    measured exactly (the triangle-triangle distance, after an exact check that no two linear images
//    intersect).
// Together with local injectivity this makes f a bijection of the ball onto its image (docs/explorer.md).
struct BoundaryInjectivity {
  bool certified = false;
  std::string reason;
  double sigma3_lower = 0;    // s
  double hessian_bound = 0;   // H
  double jacobian_bound = 0;  // G
  double rho = 0;
  int subdivisions = 0;
  long triangles = 0;
  long pairs_measured = 0;     // pairs whose distance had to be computed
  double max_delta = 0;        // max δ_T
  double min_pair_margin = 0;  // min over measured pairs of distance − δ1 − δ2 (+inf when none)
};
// Distance between two triangles that do not intersect: the smallest of the 6 vertex-triangle and 9 edge-edge
// distances (for intersecting triangles it is not 0, so callers check intersections first).
double disjoint_triangle_distance(const std::array<Vec3, 3>& A, const std::array<Vec3, 3>& B);

BoundaryInjectivity certify_boundary_injective(const HarmonicPolynomialMap& map, const Ball& ball,
                                               double sigma3_threshold, int subdivisions = 6,
                                               int max_depth = 8);

// ---------------------------------------------------------------------------------------------------------------
// Random maps and the search.

// A random harmonic polynomial map of degree D (2..4): linear part A = R1 diag(s) R2ᵀ (rotations, s_i =
// exp(N(0, 0.35²))), no translation, and every coefficient of degree l ≥ 2 drawn from N(0, (amplitude / l)²),
// amplitude itself uniform in [0, max_amplitude]. Deterministic for a given 64-bit seed.
HarmonicPolynomialMap random_harmonic_map(int degree, std::uint64_t seed, double max_amplitude = 0.6);

// The constructed counterexample family (docs/explorer.md): with s1 > s2 > s3 > 0, twist c and cubic weight
// d,
//   f(x, y, z) = ( s1 x + c x z,   s2 y − c y z,   s3 z + (c/2)(y² − x²) + d (z³ − (3/2) z (x² + y²)) ).
// At the origin J = diag(s1, s2, s3), ∇σ3 = 0, and the Hessian of σ3 is
//   diag(2c²/(s3 + s1) − 3d, 2c²/(s3 + s2) − 3d, 6d):
// the twist (an antisymmetric change of J in the (1,3) and (2,3) entries) raises σ3 in x and y, the cubic
// term in z. Degree 3 when d ≠ 0 (returned in the degree-`degree` basis, degree ≥ 3).
HarmonicPolynomialMap twist_example(const Vec3& s, double c, double d, int degree = 4);

// A random perturbation of the twist family: s3 ~ U[0.3, 0.8], s2 = s3 + U[0.3, 1.2], s1 = s2 + U[0.1, 0.6],
// c ~ U[0, 1.2] (s2 − s3), d ~ U[0, 0.1], plus N(0, (amplitude / max(l, 1))²) on every coefficient of degree
// l ≥ 1 (amplitude itself uniform in [0, max_amplitude]).
HarmonicPolynomialMap random_twist_map(int degree, std::uint64_t seed, double max_amplitude = 0.6);

// Per-trial seeds: splitmix64 of (seed, trial), so a trial's result does not depend on threads or on other
// trials.
std::uint64_t trial_seed(std::uint64_t seed, std::uint64_t trial);

struct SearchTrial {
  int trial = 0;
  std::uint64_t seed = 0;
  HarmonicPolynomialMap map;
  std::vector<Sigma3Minimum> minima;  // interior minima (find_sigma3_minima)
  double sphere_min_sigma3 = 0;       // sampled_sphere_min_sigma3
  int strict_minima = 0;
  // A strict interior minimum with σ3 > 0 that lies below every sampled boundary value: the Fig. 2 situation
  // (up to certification).
  bool candidate = false;
  double candidate_gap = 0;  // (sphere min − interior min) / interior min, for ranking
};

enum class SearchFamily { kRandom, kTwist };  // random_harmonic_map / random_twist_map
struct SearchParams {
  SearchFamily family = SearchFamily::kRandom;
  int degree = 4;
  int trials = 200;
  std::uint64_t seed = 1;
  double max_amplitude = 0.6;
  MinimaSearchParams minima;
};

// Runs the trials in parallel (results in trial order). `progress` (optional) is called after each finished
// trial with the number finished so far, from one thread at a time.
std::vector<SearchTrial> search_sigma3_minima(const SearchParams& params,
                                              const std::function<void(int)>& progress = nullptr);

// ---------------------------------------------------------------------------------------------------------------
// Laplacians of σ1 and σ3 at random points of random maps (App. D: Δσ1 ≥ 0; Δσ3 has no sign).
struct LaplacianSample {
  int map = 0;
  Vec3 p = Vec3::Zero();
  Vec3 sigma = Vec3::Zero();
  double lap_sigma1 = 0, lap_sigma3 = 0;        // exact (Hessian traces)
  double lap_sigma1_fd = 0, lap_sigma3_fd = 0;  // 7-point finite-difference Laplacians (step 1e-3)
  double lap_sigma3_sym = 0,
         lap_sigma3_anti = 0;  // the ≤ 0 and ≥ 0 parts of Δσ3 (singular_value_derivatives.h)
  double gap = 0;              // min gap of σ1 and σ3 (formulas need it > 0)
};
std::vector<LaplacianSample> laplacian_experiment(int degree, int maps, int points_per_map,
                                                  std::uint64_t seed, double max_amplitude = 0.6);

// ---------------------------------------------------------------------------------------------------------------
// Map files (JSON; docs/explorer.md). Throws InputError(path, ...) on any problem.
struct ExplorerExample {
  std::string kind;  // "harmonic_polynomial" or "cage"
  Ball ball;
  std::string note;
  std::shared_ptr<const ExplorerMap> map;
  std::string cage_model, cage_coefficients;  // kind == cage: the resolved paths ("identity" kept as is)
  // The polynomial map (kind == harmonic_polynomial), else null.
  const HarmonicPolynomialMap* polynomial() const;
};
ExplorerExample read_explorer_example(const std::string& path);
// The polynomial map as JSON text (format of read_explorer_example), deterministic, numbers in shortest
// round-trip form.
std::string explorer_example_json(const HarmonicPolynomialMap& map, const Ball& ball,
                                  const std::string& note);

// σ's sampled on a regular grid over the ball's bounding cube (`resolution` points per axis, x fastest), NaN
// outside the ball.
struct BallFieldGrid {
  int n = 0;
  Vec3 origin = Vec3::Zero();
  double spacing = 0;
  std::vector<float> sigma1, sigma2, sigma3, det_j;
  std::vector<unsigned char> inside;
};
BallFieldGrid compute_ball_fields(const ExplorerMap& map, const Ball& ball, int resolution);

}  // namespace lidef
