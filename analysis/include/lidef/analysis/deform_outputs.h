// The files of a deformation (`lidef deform --out DIR`, the Python module's DeformResult.write): the map, the
// deformed mesh, its certificate with leaves, the iteration log, the scenario as run and summary.json. All of
// them appear together or none (staged_outputs.h). docs/outputs.md describes them.
#pragma once
#include <string>
#include <vector>

#include "lidef/deform.h"
#include "lidef/global_injectivity.h"
#include "lidef/model_check.h"
#include "lidef/scenario.h"

namespace lidef {

struct DeformOutputOptions {
  int grid = 0;               // > 0: also field.vti with this many points along the longest axis
  double total_seconds = -1;  // summary.json's time_s.total (< 0: preprocess + solve + finish)
};

// Writes into `dir` (created if missing): coefficients.txt, cage.obj (the cage the coefficients belong to),
// deformed.obj, deformed.vtp (E_iso_minus_6, detJ, sigma3), certificate.json + voxels.csv + leaves.vtu,
// iterations.csv, summary.json, scenario.json (`scenario` with the parameters used), field.vti when
// options.grid > 0, and deformed.ply when the model comes from a PLY file whose vertices are the model's mesh
// vertices (a point cloud, Gaussian splats, a PLY mesh without unused vertices; point_cloud_io.h,
// gaussian_splats.h). A field.vti or deformed.ply of an earlier run that this one does not write is removed.
// `scenario.model_dir` names the model in the certificate. Throws InputError naming `dir` when it cannot be a
// folder.
struct DeformOutputs {
  std::string dir;
  std::vector<std::string> files;  // the names written, in the order above
  double mesh_coverage = 0;        // fraction of mesh vertices inside the certified voxels
  double volume_ratio = 0;         // signed volume of the deformed mesh over the rest mesh's
  GlobalInjectivity global;        // the global injectivity verdict written to the reports
};
DeformOutputs write_deform_outputs(const std::string& dir, const Model& model, const Scenario& scenario,
                                   const DeformResult& result, const DeformOutputOptions& options = {});

// The point file the model was made from (.ply or .xyz; deformed.ply's or deformed.xyz's source, the studio's
// point colours): the scenario's model when it is such a file, else the input named by the model folder's
// model.json (an automatic cage); "" when the model comes from neither.
std::string source_points_file(const Model& model, const Scenario& scenario);

// The CSV header and a row of iterations.csv (one column per field of IterationRecord; docs/outputs.md).
std::string iterations_header();
std::string iteration_row(const IterationRecord& r);

}  // namespace lidef
