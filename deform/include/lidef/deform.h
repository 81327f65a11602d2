// One call from a model and its handles to the last certified map: the one-shot beside DeformationSolver
// (projected_newton.h), as certify_map sits beside OctreeCertifier. It builds the solver, runs
// solve_to_targets (continuation.h), certifies the resulting map again with its leaves and evaluates it at
// the mesh's vertices — what `lidef deform`, the Python module's lidef.deform and an embedding program run.
// Code that keeps a solver across calls (the studio, lidef.Session) makes a DeformationSolver itself and
// finishes each solve with deform_result().
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lidef/compute_backend.h"
#include "lidef/continuation.h"
#include "lidef/deform_params.h"
#include "lidef/global_injectivity.h"
#include "lidef/model_check.h"
#include "lidef/octree_certifier.h"
#include "lidef/projected_newton.h"
#include "lidef/sampling.h"
#include "lidef/types.h"

namespace lidef {

// How deform() runs; the defaults run quietly on the CPU with the on-disk precomputation cache.
struct DeformOptions {
  std::string cache_dir = default_cache_dir();  // "" = no cache
  std::uint64_t cache_max_bytes = default_cache_max_bytes();
  std::function<void(const std::string&)> log;               // one line per preprocessing stage
  std::function<void(const std::string&, double)> progress;  // PrecomputeSetup::progress
  std::function<bool(const IterationRecord&)> on_iteration;  // false stops (kInterrupted)
  std::function<void(const std::string&)> on_stage;          // one line per continuation stage
  // Set from anywhere to stop: during preprocessing deform() throws Cancelled, during the solve it returns
  // the last certified map with reason kInterrupted.
  const std::atomic<bool>* stop = nullptr;
  std::shared_ptr<const ComputeBackend> backend;  // nullptr = cpu_backend()
  std::vector<MatX3d> waypoints;                  // each #h by 3, visited in order before the targets
  std::vector<int> groups;                        // #h rigid-part ids, or empty (grouped by proximity)
  std::string handles_source = "sources";         // names the handles in errors (a scenario's file)
  MatX3d initial_map;  // #V+#F by 3 certified coefficients to start from (empty: the identity)
  std::string initial_map_source = "initial map";  // names initial_map in errors
};

// The last certified map and what a user looks at. Model units throughout.
struct DeformResult {
  SolveResult solve;        // why the solve stopped (reason, message, seconds)
  PathSolveReport path;     // strategies, stages, the unreachability check
  MatX3d coefficients;      // #V+#F by 3: the map (coefficients.txt)
  Certificate certificate;  // of `coefficients`, with leaves (certified: always, see deform())
  // The solver's global injectivity verdict of `coefficients` where it holds one (global mode; its `ms` set
  // to 0: not computed again), else empty and the report computes it.
  std::optional<GlobalInjectivity> global;
  MatX3d deformed_vertices;    // #Vm by 3: the mesh's vertices mapped
  VecXd e_iso, det_j, sigma3;  // #Vm each: E_iso − 6 (NaN where det J ≤ 0), det J, σ3 at the mesh vertices
  VecXd sigma1, distortion;    // #Vm each: σ1 and σ1/σ3 (NaN where σ3 ≤ 0) at the mesh vertices
  VecXd handle_errors;         // #h: |f(source) − target|
  double max_handle_error = 0;
  double handle_tolerance = 0;   // params.handle_tolerance in model units (of the model's size)
  bool handles_reached = false;  // max_handle_error <= handle_tolerance
  int iterations = 0;            // Newton iterations of the solver's history
  // What reports and output files need (write_deform_outputs, deform_outputs.h).
  std::vector<IterationRecord> history;
  EnergyTerms energy;
  EnergyWeights weights;
  Frame frame;
  VoxelSampling sampling;  // the certified voxels (model units)
  SamplingParams sampling_params;
  CertifyParams certify_params;
  std::string backend;  // ComputeBackend::name()
  int dof = 0;          // 3 × the subspace's size
  int hessian_samples = 0;
  double preprocess_seconds = 0;
  double finish_seconds = 0;  // the final certificate and the mesh's fields
  bool targets_met() const { return solve.targets_met(); }
};

// Certifies the solver's current map again with its leaves and evaluates it at `mesh`'s vertices (#V by 3):
// the result of a solve that ended with `solve` and `path`. Throws NumericalError if the map is not certified
// (the solver holds certified maps only, so that is a defect, not an outcome).
DeformResult deform_result(const DeformationSolver& solver, const TriMesh& mesh, const SolveResult& solve,
                           const PathSolveReport& path);

// Deforms `model` so that the handles at `sources` (#h by 3, inside the cage) move to `targets` (#h by 3):
// a DeformationSolver with `params` (validated; InputError names the parameter), solve_to_targets, then
// deform_result. Throws InputError for a source outside the cage or bad parameters, Cancelled when
// options.stop is set during the preprocessing.
DeformResult deform(const Model& model, const MatX3d& sources, const MatX3d& targets,
                    const DeformParams& params = {}, const DeformOptions& options = {});

}  // namespace lidef
