// Automatic cages ("bring your own mesh", docs/cages.md): read a user's mesh in a common format, wrap it in a
// coarse closed cage with CGAL's 3D alpha wrapping, simplify the cage by edge collapses that never bring it
// closer than a clearance to the mesh, and accept the result only when lidef's own model checks
// (model_check.h) pass. No CGAL in this header: CGAL is confined to cage/src/auto_cage_cgal.cpp.
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "lidef/model_check.h"
#include "lidef/tri_mesh.h"

namespace lidef {

// What read_any_mesh did to the file's polygons.
struct MeshReadInfo {
  std::string format;           // "obj", "off", "ply", "stl"
  int file_vertices = 0;        // points in the file
  int file_polygons = 0;        // polygons in the file (any arity)
  int fan_triangles = 0;        // triangles added by fan-triangulating polygons with more than 3 corners
  int dropped_faces = 0;        // polygons with < 3 corners and triangles using a vertex twice
  int dropped_vertices = 0;     // points not used by any kept triangle (removed; the others keep their order)
  int degenerate_faces = 0;     // kept triangles that the validator calls degenerate (zero area)
  std::uint64_t file_hash = 0;  // fnv1a64 of the file's bytes
};

// Reads a surface mesh from PATH: .obj, .off, .ply (ASCII or binary), .stl (ASCII or binary), by extension
// (case-insensitive), through CGAL's polygon soup readers. Polygons are fan-triangulated (v0, vi, vi+1);
// polygons with fewer than 3 corners and triangles that use a vertex twice are dropped, as are points no kept
// triangle uses; the remaining coordinates are the file's, unchanged, in the file's order. Returns V (#V by
// 3), F (#F by 3, 0-based) and source = PATH. Throws InputError(PATH, ...) for a missing, empty, unreadable
// or binary-garbage file, an unsupported extension, a non-finite coordinate, no polygons, or only degenerate
// (zero-area) faces.
TriMesh read_any_mesh(const std::string& path, MeshReadInfo* info = nullptr);

// Parameters of make_cage. Lengths are fractions of the mesh's bounding-box diagonal, so they do not depend
// on the mesh's units.
struct CageOptions {
  int faces = 500;          // target number of cage triangles (simplification stops there), 4..2000
  double clearance = 0.01;  // no cage point closer than clearance * diagonal to the mesh (collapse filter)
  double offset = 0.02;     // alpha wrap offset (distance of the wrap from the mesh) * diagonal; > clearance
  // Alpha wrap alpha (about the wrap's edge length and the narrowest cavity it enters) * diagonal. alpha =
  // offset keeps the wrap's flat faces from cutting in much closer than the offset (measured: >= clearance on
  // every mesh of docs/cages.md); a larger alpha is faster but its faces chord in towards the mesh.
  double alpha = 0.02;
  // Attempts after the first: a failed model check retries with 1.5 x the offset and 1.5 x the faces; cage
  // faces closer than the clearance (uncollapsed wrap faces) with 1.5 x the offset (the last attempt is then
  // accepted as it is, recorded in CageAttempt::faces_within_clearance).
  int max_retries = 4;
};

// Throws InputError("--faces" / "--clearance" / ...) when an option is out of range.
void check_cage_options(const CageOptions& options);

// One wrap + simplify + validate attempt.
struct CageAttempt {
  double alpha = 0, offset = 0, clearance = 0;  // absolute lengths used
  int target_faces = 0;
  int wrap_faces = 0;  // triangles of the alpha wrap
  int cage_faces = 0;  // after simplification
  // Cage triangles the clearance test cannot prove to be >= clearance from the mesh: wrap faces that no
  // collapse touched (the wrap is only at the offset at its vertices; its faces may chord in closer).
  int faces_within_clearance = 0;
  double seconds_wrap = 0, seconds_simplify = 0, seconds_check = 0;
  std::string failure;  // empty when the cage passed every check
};

struct CageReport {
  double diagonal = 0;                // bounding-box diagonal of the mesh
  std::vector<CageAttempt> attempts;  // the last one succeeded
  int retries() const { return static_cast<int>(attempts.size()) - 1; }
  ValidationReport validation;  // validate_model(cage, mesh) of the returned cage
  double seconds = 0;           // wall time of make_cage
};

struct CageResult {
  TriMesh
      cage;  // closed, edge-manifold, outward-oriented, free of self-intersections, every mesh vertex inside
  TriMesh mesh;  // the input mesh (unchanged)
  CageReport report;
};

// Progress lines ("alpha wrap: 12,408 triangles in 0.8 s"); may be empty.
using CageLog = std::function<void(const std::string&)>;

// Makes a cage for `mesh` (#V by 3, #F by 3). Retries with a larger offset and more faces (at most 2000) when
// a check fails, and records each attempt; throws NumericalError when no attempt gives a cage that passes, so
// the result is always usable (load_model accepts it). Deterministic: the same input gives the same cage.
CageResult make_cage(const TriMesh& mesh, const CageOptions& options = {}, const CageLog& log = {});

// Writes the model folder's files: cage.obj, mesh.obj and model.json (input file, its hash, the options, the
// attempts, the times). `path_of(name)` says where each file goes (a staging folder, a cache entry); the
// files are written atomically (write_file_atomic).
void write_cage_model(const CageResult& result, const std::string& input_path, const MeshReadInfo& info,
                      const CageOptions& options,
                      const std::function<std::string(const std::string&)>& path_of);

// Whether `path` names a mesh file that read_any_mesh reads (a regular file with a supported extension)
// rather than a model folder.
bool is_mesh_file(const std::string& path);

// Where a mesh file stands for a model (`lidef deform`, `lidef certify`): for a folder returns `path`
// unchanged; for a mesh file returns the model folder <cache_dir>/cages/<key> made by make_cage with default
// options, making it first unless it exists (log: "reused cached cage ..."). key = hash of the file's bytes
// and the options. cache_dir "<default>" is default_cache_dir() (lidef/subspace.h); when that or cache_dir is
// "", <system temp dir>/lidef-cache. An entry is written into a private folder and renamed into place.
std::string resolve_model_path(const std::string& path, const CageLog& log = {},
                               const std::string& cache_dir = "<default>");

}  // namespace lidef
