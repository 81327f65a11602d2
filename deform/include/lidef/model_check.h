// Validation of a model (a cage and the mesh inside it) and loading of model folders.
// Every check, its message and its severity are listed in docs/models.md.
#pragma once
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "lidef/cage.h"
#include "lidef/mesh_io.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

// One finding. Element numbers are 1-based as in the file (face k = k-th `f` line, vertex k = k-th `v` line;
// an edge is named by its two 1-based vertex numbers).
struct Issue {
  std::string file;     // file the element belongs to (the model folder for folder-level problems)
  std::string element;  // "face 12", "vertex 7", "edge 3-9", "faces 128 and 914"; empty: the whole file
  long line = 0;        // 1-based line in `file`; 0 if unknown
  std::string message;
  std::string str() const;  // "file:line: element: message"
};

// Result of validating a model. Summary fields keep their defaults when the check computing them could not
// run (e.g. no distance when the cage is broken).
struct ValidationReport {
  std::vector<Issue> errors;    // the model cannot be used
  std::vector<Issue> warnings;  // usable, but worth knowing

  std::string cage_file, mesh_file;
  int cage_vertices = 0, cage_faces = 0, cage_edges = 0;
  int cage_components = 0;       // connected components (through shared edges)
  int euler_characteristic = 0;  // V - E + F over the vertices used by faces
  int genus = -1;                // sum over components; -1 unless closed, edge-manifold and orientable
  double cage_volume = 0;        // signed; > 0 for an outward-oriented cage
  Vec3 cage_bbox_min = Vec3::Zero(), cage_bbox_max = Vec3::Zero();
  std::vector<std::pair<int, int>> self_intersections;  // 0-based face pairs (i < j)

  int mesh_vertices = 0, mesh_faces = 0;
  Vec3 mesh_bbox_min = Vec3::Zero(), mesh_bbox_max = Vec3::Zero();
  bool inside_checked = false;  // whether the mesh-in-cage test ran (it needs a valid cage)
  int mesh_vertices_outside = 0, mesh_vertices_on_cage = 0;
  double min_distance = std::numeric_limits<double>::quiet_NaN();  // min over mesh vertices of dist to cage
  int min_distance_vertex = -1;                                    // 0-based vertex attaining it

  double seconds = 0;  // wall time of the check

  bool usable() const { return errors.empty(); }
};

// Tolerances (relative, so that they do not depend on the model's units).
struct CheckTolerances {
  // A face is degenerate when 2*area <= degenerate * (longest edge)^2 (a sliver: its height is below this
  // fraction of its length, so its normal is round-off) or its longest edge <= tiny_edge * cage diagonal.
  double degenerate = 1e-10;
  double tiny_edge = 1e-12;
  // A mesh vertex closer than on_cage * (cage bounding-box diagonal) to the cage lies on it: the Green
  // coordinates are singular there.
  double on_cage = 1e-9;
};

// Validates a cage and a mesh held in memory. Never throws for problems of the input: they become errors
// or warnings. `cage_lines`/`mesh_lines` (from read_mesh) add line numbers to messages.
ValidationReport validate_model(const TriMesh& cage, const TriMesh& mesh,
                                const MeshLines* cage_lines = nullptr, const MeshLines* mesh_lines = nullptr,
                                const CheckTolerances& tol = {});

// Reads DIR/cage.obj|cage.off and DIR/mesh.obj|mesh.off and validates them. Read errors (missing file,
// syntax, NaN, ...) become errors in the report, so a broken folder reports every file's problem at once.
// `cage`/`mesh`, when given, receive what was read.
ValidationReport check_model_dir(const std::string& dir, TriMesh* cage = nullptr, TriMesh* mesh = nullptr);

// A validated model, ready for the deformation pipeline.
struct Model {
  Cage cage;
  TriMesh mesh;
  std::string dir;  // folder it was loaded from; empty for a generated model
  ValidationReport report;
};

// check_model_dir, then builds the Cage. Throws InputError naming the folder and listing every error when the
// model cannot be used; warnings are kept in Model::report.
Model load_model(const std::string& dir);

// The report as JSON (element numbers 1-based, as in the messages).
std::string report_to_json(const ValidationReport& report);

}  // namespace lidef
