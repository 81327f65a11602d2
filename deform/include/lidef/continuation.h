// Reaching targets that one Newton solve cannot reach from where the map is (docs/solver.md, "Continuation"):
// the targets move along a rotation-aware path (target_path.h) and the solver follows them stage by stage,
// as a person dragging would, then solves to the user's targets. Every stage runs the same certified solver,
// so every accepted iterate — intermediate or final — is certified; the solver's map stays the last
// certified one whatever happens.
//
// Strategy, in order:
//   1. direct      — no waypoints and no handle group rotating by more than `continuation_angle`: one solve.
//   2. planned     — otherwise: ceil(angle / continuation_angle) stages per path segment, each until its
//                    handles are within the stage tolerance below, at most
//                    `continuation_stage_iterations` Newton iterations, then the final solve.
//   3. fallback    — a direct solve that stops with the handles not reached (blocked, no certified step,
//                    converged short of them, iteration limit) is followed by stages from where it stopped.
//   4. local/global — after 2 or 3 ended with the handles not reached: local/global (ARAP-like) maps toward
//                    the targets (local_global.h) from the current and the starting map, accepted only if the
//                    solver's certificate certifies them (else the largest certified blend toward one), then
//                    a short Newton polish; up to 4 rounds while the handle error drops.
// A stage whose targets are not reached (max handle error above max(handle_tolerance, 10% of the stage's
// largest handle move)) is retried with half the step along the path (a reached one doubles it again, up to
// the planned step); below 1/64 of a planned stage the path is given up (then strategy 4; if it fails too,
// the result says "blocked by the certificate", with the strategies tried). `continuation = false` keeps
// strategy 1 only (waypoints are still visited, one full solve each). Before any of them,
// prove_targets_unreachable (unreachable_targets.h) checks whether the handles pin the subspace to maps that
// cannot be certified: when that is proven, only a direct solve toward the targets runs (the closest
// certified map it finds is the result) and the result says so — "blocked_by_certificate" when every reaching
// map folds, "targets_unreachable" when no map of the subspace reaches them at all.
#pragma once
#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "lidef/projected_newton.h"
#include "lidef/types.h"
#include "lidef/unreachable_targets.h"

namespace lidef {

struct PathSolveReport {
  std::vector<std::string> strategies;  // tried, in order: "direct", "planned continuation", "continuation
                                        // after the direct solve stopped short", "local/global warm start
                                        // after the continuation stopped short"
  int stages = 0;                       // intermediate target sets solved (the final solve not counted)
  int stage_retries = 0;                // stages shortened because their targets were not reached
  double max_angle_deg = 0;             // largest rotation of a handle group along the path
  double path_reached = 0;              // how far along the path the handles got, in segments (0..K)
  int segments = 0;                     // K: path segments (waypoints + 1)
  UnreachabilityProof unreachable;      // of the final targets, checked before the strategies ran
  // Strategy 4's local/global solves and the certificates of their maps and blends (its Newton polish not
  // counted): part of the solve's time.
  double local_global_seconds = 0;
};

// Solves from the solver's current map to `targets` (#h by 3) through `waypoints` (each #h by 3, in order).
// `groups` (#h ids, or empty for group_handles of the sources with link distance 1/4 of the cage diagonal)
// says which handles move as one rigid body. `on_iteration` and `stop` as in DeformationSolver::solve;
// `on_stage` (optional) hears one line per stage. Each strategy (the direct solve, then the continuation)
// may use max_iterations iterations; every stage starts from the user's weights (reset_weights). Afterwards
// the solver's targets are `targets`, whichever stage the run stopped in. The result's `seconds` is the wall
// time of the whole call: every strategy, the unreachability check and the local/global maps included.
SolveResult solve_to_targets(DeformationSolver& solver, const std::vector<MatX3d>& waypoints,
                             const MatX3d& targets, const std::vector<int>& groups,
                             const std::function<bool(const IterationRecord&)>& on_iteration = {},
                             const std::atomic<bool>* stop = nullptr,
                             const std::function<void(const std::string&)>& on_stage = {},
                             PathSolveReport* report = nullptr);

}  // namespace lidef
