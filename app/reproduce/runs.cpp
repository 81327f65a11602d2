// Solver runs shared by the figures: load a scenario's model, solve from the identity, keep what the figures
// report. The solver is lidef's (DeformationSolver, as `lidef deform` runs it), on the CPU backend.
#include <chrono>
#include <stdexcept>

#include "lidef/cage/auto_cage.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/number_format.h"
#include "reproduce.h"

namespace lidef::cli::reproduce {

Model load_scenario_model(const Context& ctx, const Scenario& sc) {
  return load_model(resolve_model_path(
      sc.model_dir, [&](const std::string& m) { ctx.progress(m); }, ctx.cache_dir));
}

EnergyTerms energy_at_user_weights(const DeformationSolver& solver, const DeformParams& params) {
  EnergyWeights w;
  w.p2p = params.lambda_p2p;
  w.smooth = params.lambda_smooth;
  return solver.energy_function().evaluate(solver.reduced_coefficients(), w);
}

SolveRun solve_scenario(const Context& ctx, const Model& model, const Scenario& sc,
                        const DeformParams& params, const std::string& label,
                        std::unique_ptr<DeformationSolver>* keep_solver) {
  // DeformationSolver::solve is one Newton solve; the continuation is not run here, so a figure that asks for
  // it would report a solve that did not happen.
  if (params.continuation)
    throw std::logic_error("solve_scenario runs one direct solve: " + label + " asks for the continuation");
  SolveRun r;
  r.label = label;
  r.params = params;
  const auto t0 = Clock::now();
  auto solver = std::make_unique<DeformationSolver>(
      model.cage, params, ctx.cache_dir, [&](const std::string& m) { ctx.progress(label + ": " + m); });
  r.preprocess_s = seconds_since(t0);
  solver->set_handles(sc.sources, sc.targets, sc.path);
  const auto t1 = Clock::now();
  r.result = solver->solve([&](const IterationRecord& it) {
    ctx.progress(label + ": iteration " + std::to_string(it.iteration) + ", energy " +
                 format_g(it.terms.total) + ", handle error " + format_g(it.max_handle_error) +
                 (it.certified ? "" : ", NOT certified"));
    return true;
  });
  r.solve_s = seconds_since(t1);
  r.history = solver->history();
  r.y = solver->coefficients();
  r.energy = energy_at_user_weights(*solver, params);
  const VecXd err = solver->handle_errors();
  r.max_handle_error = err.size() ? err.maxCoeff() : 0.0;
  r.certified = solver->certificate().certified;
  r.min_lower_bound = solver->certificate().min_lower_bound;
  r.samples = static_cast<long>(solver->sampling().size());
  ctx.progress(label + ": " + to_string(r.result.reason) + " after " + std::to_string(r.result.iterations) +
               " iterations, handle error " + format_g(r.max_handle_error) +
               (r.certified ? ", certified" : ", NOT certified"));
  if (keep_solver) *keep_solver = std::move(solver);
  return r;
}

}  // namespace lidef::cli::reproduce
