// lidef's one include for programs that use the method: a model (cage and mesh), its handles, one call to
// deform it (every accepted map certified locally injective), the certificate of any map, the parameter
// table and the scenario files. Link lidef::core (find_package(lidef CONFIG REQUIRED); docs/tutorial.md):
//
//   lidef::Model model = lidef::load_model("data/models/beam");
//   lidef::DeformResult r = lidef::deform(model, sources, targets);   // #h by 3 each
//   r.certificate.certified, r.coefficients (#V+#F by 3), r.deformed_vertices (#Vm by 3)
//
// The pieces underneath, for code that needs them: DeformationSolver (projected_newton.h) keeps a solver
// between solves, certify_map / NormalizedCertifier certify a map, HarmonicBasis evaluates one.
#pragma once

#include "lidef/blas_kernel.h"        // OpenBLAS's kernels (selected for the CPU when lidef is loaded)
#include "lidef/cage.h"               // the cage and the identity map's coefficients
#include "lidef/coefficients.h"       // coefficient files (#V+#F rows)
#include "lidef/continuation.h"       // solve_to_targets: large motions stage by stage
#include "lidef/deform.h"             // lidef::deform, DeformResult, DeformOptions
#include "lidef/deform_params.h"      // DeformParams and the parameter table
#include "lidef/errors.h"             // Error, InputError, NumericalError
#include "lidef/green_coordinates.h"  // HarmonicBasis: f(p) = Σ y_v φ_v(p) + Σ y_t ψ_t(p)
#include "lidef/mesh_io.h"            // reading and writing meshes and points
#include "lidef/model_check.h"        // Model, load_model, validate_model
#include "lidef/normalization.h"      // NormalizedCertifier, Frame
#include "lidef/octree_certifier.h"   // Certificate, certify_map, OctreeCertifier
#include "lidef/projected_newton.h"   // DeformationSolver
#include "lidef/sampling.h"           // VoxelSampling
#include "lidef/scenario.h"           // Scenario, read_scenario, write_scenario
#include "lidef/types.h"              // MatX3d (#n by 3 points), MatX3i (#n by 3 faces)
