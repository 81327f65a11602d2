// Interval re-proof of a certificate (`lidef verify --interval`; docs/certificate.md, "Interval re-proof").
//
// For every certified leaf (center c, side h) the certificate's condition is re-proved without the rounding
// allowance τ: every quantity is enclosed in an interval with outward rounding (Boost.Interval with a
// rounding policy that rounds to nearest and then steps one ulp outward; the transcendental functions log
// and atan are widened by kTranscendentalUlps ulps because the C library does not round them correctly):
//   - J(c) and the full 3x3x3 Hessian H(c) from the closed-form Green-coordinate derivatives (solid angles
//     by an interval atan2, edge logarithms, square roots), contracted with the coefficients y;
//   - a rigorous lower bound of σ3(J(c)) (det J > 0 proven by the interval, then σ_min of Uᵀ J V with U, V
//     from a double SVD, bounded by its diagonal minus its off-diagonal norm, or |det J| / ‖cof J‖_F);
//   - the certificate's Lipschitz constant L on the leaf's ball (first order Σ_e ‖δ_e‖ Γ_e or third order
//     ‖H(c)‖ + r Σ_e ‖δ_e‖ Θ_e, whichever the certificate used), each factor's upper end;
//   - the proven margin  lower(σ3) − upper(r)·upper(L).
// A leaf is *proven* when that margin is > 0. Nothing here is a floating-point estimate called proven.
// The ball's radius covers the decimal round trip of voxels.csv: r = (√3/2)(h + ulp(h)) + ‖ulp(c)‖₂, plus the
// slack that makes it hold the exact grid cell the leaf stands for (leaf_coverage.h). That the leaves cover
// the certified domain at all is proven separately by prove_leaf_coverage; `lidef verify --interval` runs
// both.
#pragma once
#include <array>
#include <limits>
#include <memory>
#include <vector>

#include "lidef/cage.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/octree_certifier.h"
#include "lidef/types.h"

namespace lidef {

// Ulps by which the results of std::log and std::atan are widened on each side. glibc documents at most
// 1 ulp for both on x86_64 and aarch64 ("Known Maximum Errors in Math Functions"); 4 leaves room.
constexpr int kTranscendentalUlps = 4;

// An enclosure of the derivatives of the map at one point: lo ≤ true ≤ hi entrywise.
struct JetEnclosure {
  Mat3 J_lo, J_hi;                 // J(a,b) = ∂f_a/∂p_b
  std::array<Mat3, 3> H_lo, H_hi;  // H[a](b,c) = ∂²f_a/∂p_b∂p_c
  double hessian_norm_hi = 0;      // upper bound of the full 27-entry Frobenius norm of H
};

// The result for one leaf.
struct IntervalLeaf {
  bool proven = false;
  double sigma3_lo = 0;  // rigorous lower bound of the signed σ3 at the center (−∞ when none)
  double L_hi = 0;       // rigorous upper bound of the certificate's Lipschitz constant on the ball
  double radius_hi = 0;  // radius of the ball that was proven (covers the leaf and the decimal round trip)
  double margin_lo = 0;  // lower bound of σ3(c) − r L: > 0 proves σ3 > 0 on the whole ball
  // Bounded distortion (add_distortion_bound_i): upper bounds of σ1 and of σ1/σ3 on the whole ball (+∞ for
  // the latter when margin_lo ≤ 0).
  double sigma1_hi = std::numeric_limits<double>::infinity();
  double distortion_hi = std::numeric_limits<double>::infinity();
};

// A rigorous lower bound of the signed σ3 of every matrix J with lo ≤ J ≤ hi (entrywise). −∞ when no bound
// is found (e.g. an unbounded entry). Uses the interval det J for the sign, then the larger of
// σ_min(UᵀJV)/(‖U‖‖V‖) (U, V from the double SVD of the midpoint; σ_min(B) ≥ min|B_ii| − ‖offdiag B‖_F) and
// |det J| / ‖cof J‖_F (valid since ‖cof J‖_F ≥ σ1σ2 and det J = σ1σ2σ3).
double sigma3_lower_bound(const Mat3& lo, const Mat3& hi);

// Precomputes the per-face and per-edge interval constants of one cage and one map (y: #V+#F by 3, as the
// certificate describes them). Thread-safe const evaluation.
class IntervalVerifier {
 public:
  IntervalVerifier(const Cage& cage, const MatX3d& y, LipschitzBound bound);
  ~IntervalVerifier();
  IntervalVerifier(const IntervalVerifier&) = delete;
  IntervalVerifier& operator=(const IntervalVerifier&) = delete;

  // Enclosure of J and H at the exact point p.
  JetEnclosure jet(const Vec3& p) const;
  // Re-proves the leaf with center `center` and side `side` as read from voxels.csv, on its ball widened by
  // `radius_slack` (leaf_coverage.h: so that the ball holds the exact grid cell the leaf stands for).
  // claim_distortion, claim_sigma1: the certifier's bounds of σ1/σ3 and σ1 on the leaf. Where the Lipschitz
  // bounds do not re-prove them, the Taylor bounds of Step 3d are formed (with third-order sums); where that
  // re-proves the claimed σ1/σ3 exactly, distortion_hi is the claim (a root found here could differ from it
  // in the last bits). Without claims (+∞) the Lipschitz bounds alone.
  IntervalLeaf verify_leaf(const Vec3& center, double side, double radius_slack = 0,
                           double claim_distortion = std::numeric_limits<double>::infinity(),
                           double claim_sigma1 = std::numeric_limits<double>::infinity()) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct IntervalVerification {
  std::vector<long> leaf_index;       // index into the certificate's leaves (certified leaves only)
  std::vector<IntervalLeaf> results;  // one per entry of leaf_index
  long proven = 0, not_proven = 0;
  double worst_slack = 0;  // min margin_lo over the checked leaves (+∞ when there is none)
  // Bounded distortion: a checked leaf's bounds are proven when sigma1_hi ≤ its sigma1_upper and
  // distortion_hi ≤ its distortion_upper (a bound of +∞ in voxels.csv claims nothing and is proven).
  long distortion_proven = 0, distortion_not_proven = 0;
  double max_sigma1_hi = 0, max_distortion_hi = 0;  // over the checked leaves
  double seconds = 0;
};

// Re-proves every certified leaf of `leaves` (OpenMP threads; the results do not depend on their number),
// each on its ball widened by `radius_slack` (model units).
IntervalVerification verify_certificate_intervals(const Cage& cage, const MatX3d& y,
                                                  const std::vector<CertLeaf>& leaves, LipschitzBound bound,
                                                  double radius_slack = 0);

}  // namespace lidef
