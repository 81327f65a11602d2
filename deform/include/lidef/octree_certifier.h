// The local-injectivity certificate (paper Sec. 3.3, 4, 5, 7.2; docs/certificate.md).
//
// A map f is certified on the union of the voxels when every leaf voxel (center c, circumradius r)
// satisfies   σ3(c) − r·L > τ,   where L is a Lipschitz constant of σ3 on the voxel's ball:
//   first order  (17): L = Σ_e ‖δ_A^e‖_F Γ_e,  Γ_e = max_ball sqrt(|α_e|²+|β_e|²)
//   third order  (21): L = ‖H(c)‖ + r Σ_e ‖δ_A^e‖_F Θ_e,  Θ_e = max_ball sqrt(‖∇α_e‖²+‖∇β_e‖²)
//   ((20),(66),(67))
//   combined (Step 3b): L = min(first order, ‖H(c)‖_op + ½ r Σ_e ‖δ_A^e‖_F Θ_e)
// (sums over undirected edges; the paper's ½ Σ over directed edges counts each edge twice), and τ is a
// floating-point allowance (see Tolerance below). Failing voxels are split into 8 children, each with its
// own exact σ3 and ‖H‖ at its center and the smaller of the parent's and its own third-order bound.
// Depth exhausted, σ3 ≤ 0 at any center, or a center where the sign of det J is not resolved in double
// precision (signed_svd.h) means NOT certified.
#pragma once
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/compute_backend.h"
#include "lidef/deform_params.h"
#include "lidef/distortion_targets.h"
#include "lidef/green_coordinates.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// The defaults of the parameters that also are rows of the parameter table come from DeformParams (declared
// once, there).
struct CertifyParams {
  LipschitzBound bound = DeformParams().bound;
  int max_depth = DeformParams().max_depth;  // subdivision levels below the base voxels
  // Budget of child voxels evaluated in all; exhausted = not certified.
  long max_refined_voxels = DeformParams().max_refined;
  long max_children_per_voxel =
      4096;                      // budget per base voxel (a full depth-4 subtree); exhausted = not certified
  bool stop_on_failure = false;  // return as soon as the verdict is "not certified" (line search)
  bool keep_leaves = true;       // fill Certificate::leaves (reports); the verdict never depends on it
  RefinementEval refinement = DeformParams().refinement;  // CPU evaluation of octree children
  // Far field: a face is "near" a subdivided node of radius r when its bounding sphere comes within
  // far_field_reach · r of the node's center (docs/certificate.md, Step 4d). Larger: more faces evaluated
  // exactly, a smaller remainder.
  double far_field_reach = 4.0;
  int max_failing_reported = 20;
  // With distortion targets and third-order sums: also bound σ1, σ3 and σ1/σ3 per leaf by their first-order
  // Taylor change (docs/certificate.md, Step 3d), the better of each pair kept. false: the Lipschitz bounds
  // alone (what the OpenCL kernels compute; for comparisons).
  bool taylor_bounds = true;
  // Above 0 (a fraction, 0.1 = 10%): once the map is certified, keep refining the leaves whose bound is
  // loosest until min_lower_bound ≥ (1 − bound_tolerance) · min_sigma3_center, so the lower bound says how
  // small σ3 really is, not merely that it is positive. Never changes the verdict; uses what is left of
  // max_refined_voxels and max_depth (docs/certificate.md, "Tight lower bound").
  double bound_tolerance = DeformParams().bound_tolerance;
  // With stop_on_failure: base voxels (indices into the sampling, any order) whose refinement runs first, to
  // completion, before the other failing voxels are refined — the line search passes the voxels that failed
  // its previous trial, so that a trial failing at the same place is rejected without refining the rest.
  // Never changes the verdict: without a budget running out the same nodes are evaluated (docs/solver.md,
  // "One Newton iteration").
  std::vector<long> priority_voxels;
  // Certifying by perturbation (docs/certificate.md, Step 4e; certify_reduced only): a map ỹ₀ (s by 3)
  // certified earlier by this certifier, and that certificate's Certificate::base_lower. A base voxel i with
  // base_lower[i] > Γ_i ‖ỹ − ỹ₀‖_F is certified without evaluating it (Γ_i bounds the reduced basis
  // gradients' norm on the voxel). Both null: every voxel is evaluated.
  const Eigen::Matrix<double, Eigen::Dynamic, 3>* previous_y = nullptr;
  const std::vector<double>* previous_lower = nullptr;
  // A voxel is taken over only when its new bound exceeds this floor: then every bound below the floor is
  // that of an evaluated voxel, and a test "min_lower_bound < floor" decides as it would without the previous
  // map (the solver passes its dynamic weighting's epsilon, condition (36)).
  double perturbation_floor = 0;
  // Optional, with previous_y (Step 4e, "the center term from a direction"): ỹ = ỹ₀ + t d up to rounding
  // (t = direction_step, d = *direction, s by 3) and D = *direction_jacobians (3N by 3, the layout of
  // DeformationEnergy::jacobians), G_i d at every base center from the same stored float rows, with
  // ‖D_i − G_i d‖_F ≤ 2⁻³⁰ ‖G_i‖_F · direction_scale (direction_scale ≥ ‖d‖_F; for a combination Σ_k α_k p_k
  // whose Jacobians were combined likewise, Σ_k |α_k| ‖p_k‖_F). Replaces the center term ‖G_i‖₂ ‖ỹ − ỹ₀‖_F by
  // t ‖D_i‖₂ plus the rounding terms where that is smaller. Ignored unless the sizes match.
  const Eigen::Matrix<double, Eigen::Dynamic, 3>* direction = nullptr;
  const Eigen::Matrix<double, Eigen::Dynamic, 3>* direction_jacobians = nullptr;
  double direction_step = 0;
  double direction_scale = 0;
  // Bounded distortion (docs/certificate.md, "Bounded distortion"): above 0, a certified map must also have
  // every leaf's upper bound of K = σ1/σ3 at most this; leaves above it are split (depth and
  // max_refined_voxels permitting) and a bound still above it makes the map not certified ("distortion bound
  // K not proven at
  // ..."). 0: off (the bounds are still computed and reported). max_sigma1 and min_sigma3 (0: off) bound σ1
  // from above and σ3 from below the same way ("distortion bound sigma1 <= S not proven at ...").
  double max_distortion = DeformParams().max_distortion;
  double max_sigma1 = DeformParams().max_sigma1;
  double min_sigma3 = DeformParams().min_sigma3;
  DistortionTargets targets() const { return {max_distortion, max_sigma1, min_sigma3}; }
  // With previous_y/previous_lower: that certificate's Certificate::base_upper (per base voxel an upper bound
  // of σ1). A voxel taken over gets σ1 ≤ base_upper[i] + Γ_i ‖ỹ − ỹ₀‖_F; without it a taken-over voxel has no
  // finite σ1 bound, and with a K or σ1 target no voxel is taken over.
  const std::vector<double>* previous_upper = nullptr;
  // With a distortion target and stop_on_failure (the line search): points, in the frame of y, where a
  // previous trial's distortion bound failed. σ1 and σ3 are evaluated there first, and where a target is
  // certainly violated (σ1/σ3 above max_distortion, σ1 above max_sigma1, σ3 below min_sigma3) the map is
  // refused at once with the verdict the full certificate would reach: the leaf whose cell holds the point
  // bounds σ1 and σ3 on a ball containing it. Points outside the voxels are skipped. Never changes a verdict;
  // saves the full evaluation of trials that fail where the last one did.
  std::vector<Vec3> distortion_probes;
  // With the third-order bound, stored derivatives and no distortion target: a base voxel that the
  // third-order bound leaves unproven takes the spectral bound's loss where that proves it
  // (docs/certificate.md, Step 4f; Steps 3b and 3c are the argument), before it would be refined. Each bound
  // is a lower bound of σ3 on the voxel, so such a voxel needs no subdivision; but a refined voxel's leaves
  // often carry higher bounds than the spectral one of the whole voxel, so the certificates written keep the
  // third-order bound alone (false). The solver's line searches set it
  // (DeformParams::line_search_spectral_fallback).
  bool base_spectral_fallback = false;
};

// One leaf of the certification octree.
struct CertLeaf {
  Vec3 center = Vec3::Zero();
  double side = 0;
  int depth = 0;
  double sigma3 = 0;  // signed σ3 at the center
  double L = 0;       // Lipschitz constant of σ3 on the voxel's ball
  double margin = 0;  // σ3 − r L − τ (> 0: certified)
  bool certified = false;
  int base = 0;                  // index of the base voxel it refines
  bool sign_unresolved = false;  // det J's sign at the center not resolved in double precision (σ3 = 0)
  // |sigma3 − the true σ3 at the center| ≤ sigma3_error: 0 where J was evaluated exactly, the far-field
  // remainder where it was not (RefinementEval::kFarField; margin already subtracts it).
  double sigma3_error = 0;
  // Bounded distortion: σ1 at the center (NaN where not evaluated), an upper bound of σ1 on the leaf
  // (σ1(c) + sigma3_error + r·L1 + τ1, L1 a Lipschitz constant of J in the spectral norm; +∞ when none) and
  // of K = σ1/σ3 on the leaf (sigma1_upper / margin when margin > 0, else +∞).
  double sigma1 = std::numeric_limits<double>::quiet_NaN();
  double sigma1_upper = std::numeric_limits<double>::infinity();
  double distortion_upper = std::numeric_limits<double>::infinity();
};

struct Certificate {
  bool certified = false;
  std::string reason;  // why not certified (empty when certified)
  LipschitzBound bound = LipschitzBound::kThirdOrder;
  double voxel_side = 0;
  int voxels = 0;       // base voxels
  long num_leaves = 0;  // leaf voxels (= voxels + 7 × refined when complete)
  long refined = 0;     // voxels subdivided
  int max_depth_used = 0;
  double min_sigma3_center = 0;  // over all evaluated centers (far-field leaves: within their sigma3_error)
  double min_margin = 0;         // over leaves: σ3 − r L − τ
  // A lower bound of the true σ3 on the covered region: the smallest σ3 − r L − τ over the leaves (the
  // rounding allowance τ included; −∞ when a leaf was left unevaluated). It equals min_margin; the name says
  // what it is.
  double min_lower_bound = 0;
  // Leaves whose center has a det J of unresolved sign (signed_svd.h): σ3 is reported as 0 there and the
  // leaf is not certified, but the map is not shown to fold (reason: "could not prove sigma3 > 0 ...").
  long sign_unresolved_leaves = 0;
  // The tolerance asked for (CertifyParams::bound_tolerance) and whether min_lower_bound reached it
  // (false when it was not asked for, the map is not certified, or depth/budget ran out first).
  double bound_tolerance = 0;
  bool bound_tolerance_met = false;
  // Voxels the guard refused: their ball is not clear of the cage (see OctreeCertifier). Any → not certified.
  long uncleared_voxels = 0;
  std::vector<CertLeaf> leaves;   // when keep_leaves (in base-voxel order, children depth-first)
  std::vector<CertLeaf> failing;  // first failing leaves (σ3 ≤ 0, or depth/budget exhausted)
  // Base voxels (ascending, at most 64) whose own proof failed: refused, σ3 ≤ 0 at a center, max depth or the
  // per-voxel budget reached — not the ones merely left unrefined after stop_on_failure stopped (the line
  // search's CertifyParams::priority_voxels for its next trial).
  std::vector<long> failed_voxels;
  // When certified: per base voxel the smallest lower bound of σ3 over its leaves
  // (CertifyParams::previous_lower of a later certificate); empty otherwise.
  std::vector<double> base_lower;
  // When certified: per base voxel the largest upper bound of σ1 over its leaves
  // (CertifyParams::previous_upper).
  std::vector<double> base_upper;
  // Over the leaves: the largest upper bound of σ1 and of K = σ1/σ3 (+∞ when a leaf has none, e.g. one not
  // certified). The distortion targets asked for (CertifyParams::max_distortion, max_sigma1, min_sigma3; 0:
  // off) and whether every leaf's bounds reached all of them.
  double max_sigma1_upper_bound = std::numeric_limits<double>::infinity();
  double max_distortion_upper_bound = std::numeric_limits<double>::infinity();
  double max_distortion = 0;
  double max_sigma1 = 0;
  double min_sigma3 = 0;
  DistortionTargets targets() const { return {max_distortion, max_sigma1, min_sigma3}; }
  bool distortion_met = false;
  // σ3 > 0 was proven but a distortion target was not: the target (distortion_failed_on) and the reason,
  // distortion_reason().
  bool distortion_failed = false;
  DistortionTarget distortion_failed_on = DistortionTarget::kNone;
  // With distortion_failed: above 0 when the distortion stage stopped because its next split would have
  // passed the refinement budget (CertifyParams::max_refined_voxels, this value): a larger budget may still
  // prove the target. 0 when the failing leaf could not be split (depth limit, a center beyond the target,
  // children no better).
  long distortion_budget = 0;
  // targets().reason(distortion_failed_on, failing.front().center), and when distortion_budget > 0 that the
  // refinement budget ran out.
  std::string distortion_reason() const;
  long perturbed_voxels = 0;       // base voxels certified by perturbation (σ3 and L not evaluated: NaN)
  long fallback_voxels = 0;        // base voxels proven by the spectral fallback (base_spectral_fallback)
  bool spectral_fallback = false;  // the fallback applied (CertifyParams::base_spectral_fallback, Step 4f)
  double ms_jacobian = 0, ms_sigma = 0, ms_bound = 0, ms_refine = 0, ms_total = 0;
};

// Per voxel i, B(center_i, radius_of(i)) must be clear of the cage: distance from the center to the cage >
// radius and winding number 1 at the center. The bounds' argument (docs/certificate.md) needs the ball inside
// the cage's interior; a voxel that is not clear is never certified (margin −∞, not refined, the reason names
// it), whoever built the sampling. The cage is closed, so the winding number is an exact crossing count.
std::vector<char> balls_clear_of_cage(const Cage& cage, const VoxelSampling& sampling);

// Precomputes everything that depends only on the cage and the voxels (per-voxel per-edge bound factors,
// basis derivatives at the centers, the clearance guard above) once; certify() then does only map-dependent
// work.
class OctreeCertifier {
 public:
  // `reduction` (#V+#F by s, optional): the subspace y = Ξ ỹ in which certify_reduced() is called; the
  // basis Jacobians/Hessians at the centers are then precomputed in that space (3|I| by s and 6|I| by s).
  // Without it, full-space matrices are precomputed when they fit in `max_matrix_bytes`, else the
  // centers are evaluated on the fly.
  // `on_chunk` (optional) is called with the fraction done after each chunk of centers; it may throw (to
  // cancel: projected_newton.h's PrecomputeSetup).
  OctreeCertifier(const Cage& cage, const VoxelSampling& sampling, const MatXd* reduction = nullptr,
                  double max_matrix_bytes = 1.5e9, const std::function<void(double)>& on_chunk = {});
  // The reduced basis derivatives at the centers (certifier with a reduction), as the constructor computes
  // them: per voxel 9 rows of m floats (3 gradient rows, 6 Hessian rows), and per voxel the sums of |value|
  // of the gradient and the Hessian rows (the rounding allowance). precompute_cache.h stores them.
  struct ReducedDerivatives {
    std::vector<float> GH;  // 9 |I| m
    long m = 0;
    VecXd scale_J, scale_H;  // |I|
  };
  // From derivatives computed earlier for the same cage, sampling and reduction (checked: shapes only).
  OctreeCertifier(const Cage& cage, const VoxelSampling& sampling, const MatXd* reduction,
                  ReducedDerivatives derivatives);
  // Those of a certifier built with a reduction (GH = nullptr otherwise), without a copy. The gradient rows
  // are float(∇basis Ξ) at each center: the solver's energy takes its G from them (deformation_energy.h
  // stores G as floats too).
  struct ReducedDerivativesRef {
    const std::vector<float>* GH = nullptr;
    long m = 0;
    const VecXd* scale_J = nullptr;
    const VecXd* scale_H = nullptr;
  };
  ReducedDerivativesRef reduced_derivatives() const;
  // A bound's per-voxel per-edge factors Θ (|I| by #E, floats rounded up; third order: built by the first
  // certification that needs them; first order: by the first that needs them, or factor_matrix(false)), and
  // per voxel whether all are finite; nullptr before. adopt_factors takes factors built earlier for the same
  // cage and sampling (shapes checked) instead of building them.
  using FactorMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const FactorMatrix* built_factors(bool third_kind, const std::vector<char>** finite) const;
  const FactorMatrix& factor_matrix(bool third_kind) const;  // built on first use
  void adopt_factors(bool third_kind, FactorMatrix factors, std::vector<char> finite);
  // The voxel groups of the rest from a direction (docs/certificate.md, Step 4e, "Voxel groups"), formed
  // with the first-order factors (built or adopted): group g holds voxels[start[g] .. start[g + 1]), and its
  // row of `factors` (#groups by #E) and its `radius` bound every member's first-order factors and radius
  // (`finite`: no member has a factor +∞). Empty before the factors exist. A copy, for tests and diagnostics.
  struct VoxelGroups {
    std::vector<long> start, voxels;
    FactorMatrix factors;
    VecXd radius;
    std::vector<char> finite;
  };
  VoxelGroups voxel_groups() const;
  // Whether certifying by perturbation should keep the first-order factors for the rest from a direction
  // (docs/certificate.md, Step 4e): reduced mode, and a factor row (#E floats) at most a third of
  // the voxel's stored Hessian rows (6 s floats), so that bounding a voxel that way costs well below
  // evaluating it. The certifier uses them whenever they are built; the solver builds them when this holds.
  bool direction_rest_pays() const;
  // Certifying by perturbation's per-voxel constants (docs/certificate.md, Step 4e; a certifier with a
  // reduction only): g2 ≥ ‖G(c_i)‖₂, rest = the H and third-order part of Γ_i, gF = ‖G̃(c_i)‖_F, each |I|.
  // They depend on the cage, the voxels and the reduction alone. perturbation_constants() builds them at its
  // first call (with the third-order factors, if those are not built yet) and throws without a reduction;
  // perturbation_constants_if_built() is nullptr before; adopt_perturbation_constants takes constants built
  // earlier for the same cage, sampling and reduction (shapes checked) instead of building them.
  struct PerturbationConstants {
    VecXd g2, rest, gF;
  };
  const PerturbationConstants& perturbation_constants() const;
  const PerturbationConstants* perturbation_constants_if_built() const;
  void adopt_perturbation_constants(PerturbationConstants constants);
  ~OctreeCertifier();

  // Certifies the map with full coefficients y (#V+#F by 3).
  Certificate certify(const MatX3d& y, const CertifyParams& params = {}) const;
  // Same map given in the reduced space (ỹ: s by 3, y = Ξ ỹ); uses the precomputed reduced matrices.
  Certificate certify_reduced(const Eigen::Matrix<double, Eigen::Dynamic, 3>& y_reduced,
                              const CertifyParams& params = {}) const;
  // Only the distortion probes of `params` (CertifyParams::distortion_probes, with stop_on_failure and a
  // target) at the map ỹ (s by 3), evaluated and judged as certify_reduced() judges them
  // (docs/certificate.md, "Probes"), without any voxel and, unless `search`, without the search near them
  // ("The search near a probe"): true, with `refusal` filled as certify_reduced() fills it, when one of them
  // proves a target violated; false decides nothing. The line search asks this with the points where earlier
  // trials failed before screening its samples for a new probe; the continuation's maps with their worst
  // sample and the search.
  bool distortion_refuted(const Eigen::Matrix<double, Eigen::Dynamic, 3>& y_reduced,
                          const CertifyParams& params, Certificate& refusal, bool search = false) const;

  // Runs the base stage and the evaluation of octree nodes on `backend` from now on (a CPU backend restores
  // the built-in code). Verdicts do not depend on the backend: every decision is taken here, on the host.
  void set_backend(const ComputeBackend& backend);

  // ‖δ_A^e‖_F for every undirected cage edge (#E): zero for affine maps.
  VecXd edge_delta_norms(const MatX3d& y) const;

  const VoxelSampling& sampling() const { return sampling_; }
  const HarmonicBasis& basis() const { return basis_; }
  double precompute_seconds() const { return precompute_seconds_; }

  // Floating-point allowance τ added to condition (6): relative to the magnitudes that enter σ3 and L.
  static constexpr double kRoundingRel = 1e-9;
  // Allowance factor for float storage of the precomputed basis derivatives: 6 · 2⁻²⁴ (see run()).
  static constexpr double kFloatStorageRel = 6.0 / 16777216.0;

 private:
  struct Impl;
  struct Run;                                // the stages of one certification (octree_certifier.cpp)
  void init_common(const MatXd* reduction);  // checks the sampling, edge endpoints
  void build_groups() const;                 // the voxel groups of the rest from a direction (Step 4e)
  VecXd delta_norms(const HarmonicBasis::FaceMatrices& fm) const;
  Certificate run(const MatX3d& y, const double* reduced_ptr, long reduced_rows,
                  const CertifyParams& p) const;
  // Ξ ỹ (#V+#F by 3) after checking ỹ (s by 3): its size, finite entries, a certifier with a reduction.
  MatX3d expand_reduced(const Eigen::Matrix<double, Eigen::Dynamic, 3>& y_reduced, const char* caller) const;

  const Cage& cage_;
  VoxelSampling sampling_;
  HarmonicBasis basis_;
  std::unique_ptr<Impl> impl_;
  double precompute_seconds_ = 0;
};

// One-shot convenience: precompute and certify once.
Certificate certify_map(const Cage& cage, const VoxelSampling& sampling, const MatX3d& y,
                        const CertifyParams& params = {});

}  // namespace lidef
