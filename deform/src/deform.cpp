#include "lidef/deform.h"

#include <chrono>

#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_fields.h"
#include "lidef/normalization.h"

namespace lidef {

DeformResult deform_result(const DeformationSolver& solver, const TriMesh& mesh, const SolveResult& solve,
                           const PathSolveReport& path) {
  const auto t0 = Clock::now();
  DeformResult r;
  r.solve = solve;
  r.path = path;
  r.coefficients = solver.coefficients();
  r.certificate = solver.certify_current(true);
  if (const GlobalInjectivity* g = solver.held_global_injectivity()) {
    r.global = *g;
    r.global->ms = 0;
  }
  if (!r.certificate.certified)
    throw NumericalError("internal: the final map is not certified although every accepted step was (" +
                         r.certificate.reason + ")");
  // Evaluated in the solver's normalized frame (a model far from the origin would otherwise lose the
  // Jacobian's digits to the cancellation of large vertex coefficients), positions mapped back.
  const Frame& frame = solver.frame();
  MeshFields mf =
      mesh_fields(solver.normalized_basis(), solver.subspace().basis * solver.reduced_coefficients(),
                  frame.points_to_normalized(mesh.V), {/*sigma3=*/true});
  r.deformed_vertices = frame.points_from_normalized(mf.V);
  r.e_iso = std::move(mf.e_iso);
  r.det_j = std::move(mf.det_j);
  r.sigma3 = std::move(mf.sigma3);
  r.sigma1 = std::move(mf.sigma1);
  r.distortion = std::move(mf.distortion);
  r.handle_errors = solver.handle_errors();
  r.max_handle_error = r.handle_errors.size() ? r.handle_errors.maxCoeff() : 0.0;
  // handle_tolerance is relative to the model's size (deform_params.h).
  r.handle_tolerance = solver.params().handle_tolerance * frame.scale;
  r.handles_reached = r.max_handle_error <= r.handle_tolerance;
  r.history = solver.history();
  r.iterations = static_cast<int>(r.history.size());
  r.energy = solver.energy();
  r.weights = solver.weights();
  r.frame = frame;
  r.sampling = solver.sampling();
  r.sampling_params = solver.sampling_params();
  r.certify_params = solver.certify_params(false, true);
  r.backend = solver.backend().name();
  r.dof = 3 * solver.subspace().size();
  r.hessian_samples = static_cast<int>(solver.sampling().hessian_subset.size());
  r.preprocess_seconds = solver.preprocess_seconds();
  r.finish_seconds = seconds_since(t0);
  return r;
}

DeformResult deform(const Model& model, const MatX3d& sources, const MatX3d& targets,
                    const DeformParams& params, const DeformOptions& options) {
  // --- Parameters and inputs: everything a user can get wrong is refused before the precomputation.
  validate_params(params, "parameters");
  PrecomputeSetup setup;
  setup.cache_dir = options.cache_dir;
  setup.cache_max_bytes = options.cache_max_bytes;
  setup.log = options.log;
  setup.progress = options.progress;
  setup.cancel = options.stop;
  setup.mesh = &model.mesh;  // the certified domain (params.domain "mesh": its triangles and solid)
  // --- The solver (the precomputation, cached on disk) and the handles.
  DeformationSolver solver(model.cage, params, setup, options.backend);
  solver.set_handles(sources, targets, options.handles_source);
  if (options.initial_map.size() > 0) solver.set_initial_map(options.initial_map, options.initial_map_source);
  // --- Solve (continuation as needed), then the certified result with its leaves.
  PathSolveReport path;
  const SolveResult res = solve_to_targets(solver, options.waypoints, targets, options.groups,
                                           options.on_iteration, options.stop, options.on_stage, &path);
  return deform_result(solver, model.mesh, res, path);
}

}  // namespace lidef
