// Global injectivity of a map on the certified domain D (the mesh's solid): does the deformed shape pass
// through itself? docs/certificate.md, "Global injectivity", gives the argument step by step.
//
// The local certificate proves det J > 0 on D. Then f is injective on D as soon as its restriction to the
// boundary surface ∂D is (degree argument) and, for a surface of several closed components (a cavity,
// separate solids), the components' images are nested so that no point is covered twice (exact winding
// numbers of the piecewise-linear image about points clear of the tubes below). The boundary is checked piece
// by piece: the image of a triangle piece lies within ρ = ½ L₁ diam² + ε of the affine triangle on its mapped
// corners (L₁ ≥ max ‖∇J‖ over a ball around the piece, ε the rounding of the mapped corners); two pieces are
// cleared when their affine images are farther apart than the sum of their radii, or when both lie in one
// ball on which f is injective (‖J(z) − J(c)‖ ≤ R L₁ < σ3(J(c))). Pieces that are neither are split 1-to-4.
// An overlap is reported only where it is proven: an edge of one piece pierces the other piece's affine
// image with margins larger than both radii, so the true surfaces cross there (intersection number ±1).
#pragma once
#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

struct GlobalInjectivityParams {
  int max_depth = 5;               // 1-to-4 splits of a surface triangle at most
  long max_tests_per_pair = 4096;  // piece pairs examined below one pair of surface triangles at most
  // Set (by another thread) to stop a check early: it then returns kNotDecided with reason "cancelled" (an
  // interactive caller drops that result: its map has changed).
  const std::atomic<bool>* cancel = nullptr;
  // Clear pairs of surface pieces by the margins the checker kept from the last map it proved injective,
  // where the map has moved less than they allow (docs/certificate.md, Step G6); every other pair is
  // examined as without them. false: a check of its own, which neither uses nor keeps margins.
  bool reuse_margins = true;
  // For tests: where set, every reused margin is also checked against the map itself (a ball's margin
  // against its test evaluated anew, a separation against sampled distances) and each claim found wrong
  // is counted here. Slow.
  std::atomic<long>* audit_violations = nullptr;
};

struct GlobalInjectivity {
  enum class Verdict { kInjective, kOverlap, kNotDecided };
  Verdict verdict = Verdict::kNotDecided;
  std::string reason;  // empty when injective
  // kOverlap: a point of the deformed space where two disjoint parts of the surface meet, and the rest-state
  // mesh triangles those parts belong to.
  Vec3 overlap_point = Vec3::Zero();
  int overlap_face_a = -1, overlap_face_b = -1;
  long candidate_pairs = 0;  // pairs of surface triangles whose tubes' boxes overlap
  long pair_tests = 0;       // piece pairs examined in all (subdivisions included)
  long replayed_pairs = 0;   // pairs cleared by the margins of the last map proven injective (Step G6)
  int max_depth_used = 0;
  double max_tube_radius = 0;  // over the unsplit surface triangles
  // Pairs of mesh triangles that intersect at rest. Where there are any, D = closure{w ≥ 1} and "true" needs
  // its boundary, computed exactly, to be one closed manifold (docs/certificate.md, Step G1).
  long rest_intersecting_pairs = 0;
  // Wall-clock time of the check (not part of any deterministic report), with the checker's set-up where the
  // check made it (check_global_injectivity, a solver's first check).
  double ms = 0;
};

// "true" / "false" / "null", as the reports write the verdict.
const char* to_json_literal(GlobalInjectivity::Verdict v);

// What a proven verdict (kInjective) says to a user: "the shape does not pass through itself", and where the
// rest mesh already intersects itself, that its own intersections are mapped one-to-one.
std::string no_overlap_words(const GlobalInjectivity& g);

// A verdict left open for a stated reason (the local certificate failed, the domain is not the mesh's solid).
GlobalInjectivity global_injectivity_not_decided(const std::string& reason);

// Precomputes what depends only on the cage and the mesh (basis, cage clearance queries, the mesh's
// adjacency and closedness), so that check() does only map-dependent work (the solver's line search and the
// studio call it per map). It keeps the margins of the last map it proved injective: a later check clears
// the pairs the motion since then cannot have brought together without examining them (reuse_margins).
// check() may be called from several threads.
class GlobalInjectivityChecker {
 public:
  // mesh: the rest-state surface (#V by 3, #F by 3, closed and embedded; inside the cage). cache_mb: memory
  // for what no map changes (the basis values and gradients at the mesh vertices, then the factor rows of the
  // triangles' and vertices' balls), each kept while it fits and otherwise evaluated in every check; the
  // default suits a check of one map, a solve or the studio passes DeformParams::global_cache_mb.
  static constexpr double kDefaultCacheMB = 256;
  explicit GlobalInjectivityChecker(const Cage& cage, const TriMesh& mesh, double cache_mb = kDefaultCacheMB);
  ~GlobalInjectivityChecker();
  // y: coefficients (#V+#F of the cage by 3). The verdict is about the boundary surface; a caller reports
  // kInjective as "globally injective on D" only where the local certificate covers D.
  GlobalInjectivity check(const MatX3d& y, const GlobalInjectivityParams& params = {}) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// One-shot convenience: precompute and check once (a check of its own: no margins kept or reused).
GlobalInjectivity check_global_injectivity(const Cage& cage, const TriMesh& mesh, const MatX3d& y,
                                           const GlobalInjectivityParams& params = {});

}  // namespace lidef
