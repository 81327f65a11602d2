#include "lidef/continuation.h"

#include <algorithm>
#include <cmath>

#include "lidef/internal/stopwatch.h"
#include "lidef/internal/target_path.h"
#include "lidef/local_global.h"
#include "lidef/number_format.h"

namespace lidef {

namespace {

// Handles closer than this fraction of the cage diagonal move as one rigid body unless the scenario groups
// them: the ends of a bar, a head, a leg are separate parts at this distance on the published models.
constexpr double kGroupLink = 0.25;
// A stage that misses its targets is retried with half the step, down to 1/64 of a planned stage.
constexpr int kMaxStageHalvings = 6;
// A stage counts as reached when its handles are within this fraction of its largest handle move (or within
// handle_tolerance): the next stage starts close to where this one was meant to end.
constexpr double kStageSlack = 0.1;

constexpr double kPi = 3.14159265358979323846;
// The local/global warm start: iterations per solve, and blends t = 1/2, 1/4, ... 1/2^kMaxBlendHalvings of a
// local/global map that is not certified whole.
constexpr int kLocalGlobalIterations = 500;
constexpr int kMaxBlendHalvings = 6;
// Rounds of (local/global map, certified blend, Newton) while the handle error keeps dropping.
constexpr int kLocalGlobalRounds = 4;

// Runs the solver against target sets while counting the iterations of all of them against max_iterations.
struct Runner {
  DeformationSolver& solver;
  const std::function<bool(const IterationRecord&)>& on_iteration;
  const std::atomic<bool>* stop;
  const std::function<void(const std::string&)>& on_stage;
  PathSolveReport& report;
  int used = 0;        // iterations of all strategies
  int phase_used = 0;  // iterations of the current strategy: each gets max_iterations
  double seconds = 0;

  int budget() const { return std::max(0, solver.params().max_iterations - phase_used); }
  void say(const std::string& s) const {
    if (on_stage) on_stage(s);
  }
  double max_error() const {
    const VecXd e = solver.handle_errors();
    return e.size() ? e.maxCoeff() : 0.0;
  }
  // handle_tolerance is a fraction of the model size (deform_params.h); the errors are in model units.
  double tolerance() const { return solver.params().handle_tolerance * solver.frame().scale; }
  bool reached() const { return max_error() <= tolerance(); }

  // One solve against `targets` with at most `max_iterations` iterations (and what is left of the budget).
  // With `done_within` >= 0 the solve ends after the first accepted iteration that brings every handle within
  // that distance of its target (an intermediate stage needs the handles there, not a polished energy).
  // `user_stopped` tells an early end of ours from the caller's callback or stop flag.
  // With `until_rejected` the solve also ends at the first iteration that accepts no step (the local/global
  // polish: another iteration from the same map costs as many certificates and gains nothing).
  SolveResult run(const MatX3d& targets, int max_iterations, double done_within = -1,
                  bool until_rejected = false) {
    DeformParams p = solver.params();
    const int saved = p.max_iterations;
    p.max_iterations = std::min(max_iterations, budget());
    solver.set_params(p);
    solver.set_targets(targets, "continuation targets");
    solver.reset_weights();
    bool user_stopped = false, rejected = false;
    auto callback = [&](const IterationRecord& rec) {
      if (on_iteration && !on_iteration(rec)) {
        user_stopped = true;
        return false;
      }
      if (until_rejected && !rec.accepted) {
        rejected = true;
        return false;
      }
      return !(done_within >= 0 && rec.accepted && rec.max_handle_error <= done_within);
    };
    SolveResult r;
    try {
      r = solver.solve(callback, stop);
    } catch (...) {
      p.max_iterations = saved;
      solver.set_params(p);
      throw;
    }
    p.max_iterations = saved;
    solver.set_params(p);
    used += r.iterations;
    phase_used += r.iterations;
    seconds += r.seconds;
    if (r.reason == StopReason::kMaxIterations)  // the solver names the stage's share; say the real limit
      r.message = "iteration limit (" + std::to_string(saved) + " per strategy) reached";
    if (r.reason == StopReason::kInterrupted && rejected && !user_stopped && !(stop && stop->load())) {
      r.reason = StopReason::kBlocked;
      r.message = "no certified Newton step from this map";
    } else if (r.reason == StopReason::kInterrupted && !user_stopped && !(stop && stop->load())) {
      r.reason = StopReason::kConverged;
      r.message = "stage targets reached";
    }
    return r;
  }

  SolveResult finish(SolveResult r) const {
    r.iterations = used;
    r.seconds = seconds;
    // A run the distortion bound stopped says so, whichever strategy reported the stop last.
    if (!r.targets_met() && !reached() && r.reason != StopReason::kInterrupted &&
        r.message.find("distortion bound") == std::string::npos)
      r.message += solver.distortion_note();
    std::string tried;
    for (const std::string& s : report.strategies) tried += (tried.empty() ? "" : ", ") + s;
    if (report.stages > 0 || report.strategies.size() > 1)
      r.message += " [strategies: " + tried + "; " + std::to_string(report.stages) +
                   " intermediate stages, " + std::to_string(report.stage_retries) + " shortened]";
    return r;
  }

  // Strategy 4 (docs/solver.md): local/global maps toward `targets` from the current map and from `entry`
  // (the map solve_to_targets started from), each accepted only through the solver's certificate — whole, or
  // the largest certified blend y + t (y_lg − y) — then Newton from the accepted map to the targets.
  SolveResult local_global(const MatX3d& targets, const MatS3& entry) {
    const DeformParams& p = solver.params();
    const LocalGlobalSolver lg(solver.energy_function(), {p.lambda_p2p, p.lambda_smooth});
    const MatX3d Q = solver.frame().points_to_normalized(targets);
    SolveResult r;
    r.reason = StopReason::kBlocked;
    r.message =
        "blocked by the certificate: no local/global map toward the targets nor a blend of one was "
        "certified";
    for (int round = 0; round < kLocalGlobalRounds; ++round) {
      const double before = max_error();
      const auto t_maps = Clock::now();
      bool accepted = false, interrupted = false;
      std::vector<MatS3> starts{solver.reduced_coefficients()};
      if (round == 0 && (entry - solver.reduced_coefficients()).norm() > 0) starts.push_back(entry);
      for (size_t k = 0; k < starts.size() && !accepted; ++k) {
        const LocalGlobalResult c = lg.solve(starts[k], Q, kLocalGlobalIterations, 1e-8, stop);
        if (c.interrupted) {  // the map stays the last certified one; nothing of this solve is used
          interrupted = true;
          break;
        }
        const double err = (solver.energy_function().handle_matrix() * c.y - Q).rowwise().norm().maxCoeff() *
                           solver.frame().scale;
        const std::string from = k == 0 ? "the current map" : "the starting map";
        std::string why;
        if (solver.set_reduced_map(c.y, &why)) {
          accepted = true;
          say("local/global: accepted the map from " + from + " (" + std::to_string(c.iterations) +
              " iterations, max handle error " + format_g(err, 3) + "), certified");
          break;
        }
        say("local/global: the map from " + from + " (" + std::to_string(c.iterations) +
            " iterations, max handle error " + format_g(err, 3) + ") is not certified (" + why +
            "): trying blends");
        const MatS3 y0 = solver.reduced_coefficients();
        for (int h = 1; h <= kMaxBlendHalvings && !accepted && !(stop && stop->load()); ++h) {
          const double t = std::ldexp(1.0, -h);
          if (solver.set_reduced_map(y0 + t * (c.y - y0))) {
            accepted = true;
            say("local/global: accepted a blend t = " + format_g(t, 3) + " toward the map from " + from +
                " (max handle error " + format_g(max_error(), 3) + "), certified");
          }
        }
      }
      report.local_global_seconds += seconds_since(t_maps);
      if (interrupted || (!accepted && stop && stop->load())) {
        r.reason = StopReason::kInterrupted;
        r.message = "interrupted during a local/global solve";
        break;
      }
      if (!accepted) break;
      // Newton polish, briefly: a local/global map lies close to the boundary of what the line search's
      // certificate (with its refinement budget) proves, and measured on beam_pull_through every trial step
      // from it was rejected — iterations there cost many certificates and gain nothing, so the polish also
      // ends at its first iteration without an accepted step.
      const int polish = std::min(budget(), std::max(1, p.continuation_stage_iterations));
      say("local/global: Newton from the accepted map to the targets (at most " + std::to_string(polish) +
          " iterations)");
      solver.set_targets(targets, "targets");  // the errors below are against the user's targets
      const bool was_reached = reached();
      r = run(targets, polish, -1, /*until_rejected=*/true);
      if (r.reason == StopReason::kMaxIterations)
        r.message = "the " + std::to_string(polish) + " polish iterations ran (Newton did not converge)";
      if (reached() && r.reason != StopReason::kConverged && r.reason != StopReason::kInterrupted)
        r.message = "targets reached by a certified local/global map" +
                    std::string(was_reached ? "" : " and Newton") + "; Newton afterwards: " + r.message;
      if (r.reason == StopReason::kInterrupted || reached() || budget() == 0) break;
      if (max_error() > (1 - 1e-3) * before) break;  // no progress this round
    }
    report.path_reached = reached() ? report.segments : report.path_reached;
    return finish(r);
  }

  // Follows `path` stage by stage (planned[k] stages in segment k), then solves to its end.
  SolveResult staged(const TargetPath& path, const std::vector<int>& planned) {
    const int K = path.segments();
    const int stage_iterations = solver.params().continuation_stage_iterations;
    double s = 0;
    for (int k = 0; k < K; ++k) {
      double ds = 1.0 / planned[k];
      const double min_ds = ds / (1 << kMaxStageHalvings);
      while (s < k + 1) {
        const double s_next = std::min<double>(k + 1, s + ds);
        if (k == K - 1 && s_next >= K) break;  // the last stage is the final solve below
        const MatX3d stage_targets = path.at(s_next);
        const double move = (stage_targets - path.at(s)).rowwise().norm().maxCoeff();
        const double within = std::max(tolerance(), kStageSlack * move);
        const SolveResult r = run(stage_targets, stage_iterations, within);
        ++report.stages;
        if (r.reason == StopReason::kInterrupted) return finish(r);
        const double err = max_error();
        if (err <= within) {
          s = s_next;
          ds = std::min(2 * ds, 1.0 / planned[k]);  // back toward the planned step after a shortened one
          report.path_reached = s;
          say("stage " + std::to_string(report.stages) + ": reached " + format_fixed(100 * s / K, 1) +
              "% of the path (max handle error " + format_g(err, 3) + ")");
        } else {
          ds /= 2;
          ++report.stage_retries;
          say("stage " + std::to_string(report.stages) + ": targets at " + format_fixed(100 * s_next / K, 1) +
              "% not reached (max handle error " + format_g(err, 3) + "), step halved");
          if (ds < min_ds * (1 - 1e-12)) {
            SolveResult b;
            b.reason = StopReason::kBlocked;
            b.message = "blocked by the certificate: the handles could not follow the path beyond " +
                        format_fixed(100 * s / K, 1) + "% of it (stage steps down to 1/" +
                        std::to_string(1 << kMaxStageHalvings) + " of a planned stage)";
            return finish(b);
          }
        }
        if (budget() == 0) {
          SolveResult b;
          b.reason = StopReason::kMaxIterations;
          b.message = "iteration limit (" + std::to_string(solver.params().max_iterations) + ") reached at " +
                      format_fixed(100 * s / K, 1) + "% of the path";
          return finish(b);
        }
      }
    }
    say("final stage: the targets");
    const SolveResult r = run(path.at(K), budget());
    report.path_reached = reached() ? K : report.path_reached;
    return finish(r);
  }
};

std::vector<int> planned_stages(const TargetPath& path, double max_angle_deg) {
  std::vector<int> m(path.segments());
  const double step = max_angle_deg * kPi / 180;
  for (int k = 0; k < path.segments(); ++k)
    m[k] = std::max(1, static_cast<int>(std::ceil(path.max_angle(k) / step - 1e-9)));
  return m;
}

}  // namespace

SolveResult solve_to_targets(DeformationSolver& solver, const std::vector<MatX3d>& waypoints,
                             const MatX3d& targets, const std::vector<int>& groups_in,
                             const std::function<bool(const IterationRecord&)>& on_iteration,
                             const std::atomic<bool>* stop,
                             const std::function<void(const std::string&)>& on_stage,
                             PathSolveReport* report_out) {
  const auto t_start = Clock::now();
  PathSolveReport report;
  Runner runner{solver, on_iteration, stop, on_stage, report};
  const DeformParams& params = solver.params();
  const double diag = (solver.cage().bbox_max - solver.cage().bbox_min).norm();
  const std::vector<int> groups =
      groups_in.empty() ? group_handles(solver.handle_sources(), kGroupLink * diag) : groups_in;

  const MatS3 entry = solver.reduced_coefficients();
  std::vector<MatX3d> keyframes{solver.handle_positions()};
  keyframes.insert(keyframes.end(), waypoints.begin(), waypoints.end());
  keyframes.push_back(targets);
  const TargetPath path(keyframes, groups);
  report.segments = path.segments();
  for (int k = 0; k < path.segments(); ++k)
    report.max_angle_deg = std::max(report.max_angle_deg, path.max_angle(k) * 180 / kPi);
  const std::vector<int> planned = planned_stages(path, params.continuation_angle);
  const bool large = std::any_of(planned.begin(), planned.end(), [](int m) { return m > 1; });

  // Targets pinned by the handles to maps that cannot be certified: no strategy can reach them, so only the
  // direct solve runs (its last certified map is the closest the solver finds) and the result says why.
  solver.set_targets(targets, "targets");
  report.unreachable = prove_targets_unreachable(solver);
  SolveResult result;
  if (report.unreachable.proven) {
    report.strategies.push_back(
        "direct (the targets are proven unreachable by a certified map: no other "
        "strategy tried)");
    runner.say("the targets are proven unreachable: " + report.unreachable.reason);
    SolveResult r = runner.run(targets, runner.budget());
    if (r.reason != StopReason::kInterrupted && !runner.reached()) {
      const bool folds = report.unreachable.kind == "orientation";
      r.message = std::string(folds ? "blocked by the certificate: " : "") + report.unreachable.reason +
                  "; the map is the last certified one of a direct solve toward them (Newton ended " +
                  to_string(r.reason) + ": " + r.message + ")";
      r.reason = folds ? StopReason::kBlocked : StopReason::kUnreachable;
    }
    result = runner.finish(r);
  } else if (!params.continuation) {
    // Waypoints are the user's: visit each with a full solve, then the targets.
    report.strategies.push_back(waypoints.empty() ? "direct" : "waypoints, one solve each");
    for (const MatX3d& w : waypoints) {
      const SolveResult r = runner.run(w, runner.budget());
      if (r.reason == StopReason::kInterrupted) {
        result = runner.finish(r);
        break;
      }
    }
    if (result.reason != StopReason::kInterrupted)
      result = runner.finish(runner.run(targets, runner.budget()));
  } else if (waypoints.empty() && !large) {
    report.strategies.push_back("direct");
    const SolveResult r = runner.run(targets, runner.budget());
    if (r.reason == StopReason::kInterrupted || runner.reached() || runner.budget() == 0) {
      report.path_reached = runner.reached() ? 1 : 0;
      result = runner.finish(r);
    } else {
      report.strategies.push_back("continuation after the direct solve stopped short (" +
                                  std::string(to_string(r.reason)) + ")");
      runner.say("the direct solve stopped short of the targets (" + r.message +
                 "): continuing through intermediate targets from there");
      runner.phase_used = 0;
      const TargetPath rest({solver.handle_positions(), targets}, groups);
      std::vector<int> m = planned_stages(rest, params.continuation_angle);
      m[0] = std::max(m[0], 2);
      result = runner.staged(rest, m);
    }
  } else {
    report.strategies.push_back("planned continuation");
    int total = 0;
    for (int m : planned) total += m;
    runner.say("planned continuation: " + std::to_string(total) + " stages over " +
               std::to_string(path.segments()) + " path segment(s), largest group rotation " +
               format_fixed(report.max_angle_deg, 1) + " degrees");
    result = runner.staged(path, planned);
  }
  // Strategy 4: where the others stopped short, a local/global map (rotation-aware, like VHM) through the
  // same certificate.
  if (params.continuation && !report.unreachable.proven && result.reason != StopReason::kInterrupted &&
      !runner.reached()) {
    report.strategies.push_back("local/global warm start after the continuation stopped short (" +
                                std::string(to_string(result.reason)) + ")");
    runner.say("the continuation stopped short of the targets (" + result.message +
               "): trying local/global maps toward them");
    runner.phase_used = 0;
    result = runner.local_global(targets, entry);
  }
  // Whatever stage the run stopped in, the solver's targets (and so its reported handle errors) are the
  // user's.
  solver.set_targets(targets, "targets");
  // The targets met with a certified map although Newton stopped before its convergence test (typically the
  // local/global map's polish finding no certified step, or its short polish budget running out): the honest
  // label is "reached", not "blocked". The user's own iteration limit stays max_iterations (more iterations
  // would still lower the energy; the caller asked for fewer).
  const bool internal_limit = result.reason == StopReason::kMaxIterations && runner.budget() > 0;
  if (runner.reached() && (result.reason == StopReason::kBlocked ||
                           result.reason == StopReason::kNoCertifiedStep || internal_limit)) {
    result.message = "max handle error " + format_g(runner.max_error(), 3) +
                     " within the tolerance; Newton ended " + std::string(to_string(result.reason)) + ": " +
                     result.message;
    result.reason = StopReason::kReached;
  }
  result.seconds = seconds_since(t_start);
  if (report_out) *report_out = report;
  return result;
}

}  // namespace lidef
