// Handle scenarios: the JSON that `lidef deform` reads and the studio saves.
//
//   {"name": "...", "model": "bar", "description": "...",
//    "handles": [{"source": [x,y,z], "target": [x,y,z]}, ...],
//               optional per handle: "path": [[x,y,z], ...] waypoints visited in order before the target
//               (every handle the same number), "group": n (the rigid part it moves with; every handle or
//               none) — docs/solver.md, "Continuation"
//    "parameters": {"lambda_p2p": 1e5, ...},           // optional; keys from deform_params.h
//    "studio": {"camera": {...}, ...}}                 // optional; lidef-studio's session settings
//
// `model` names a model folder. It resolves, in this order: <models_dir>/<model> when a models directory is
// given; <model> itself when it is an absolute path; <scenario dir>/<model>; <scenario dir>/../models/<model>
// (the layout of ../shared/data and of the project's data/). A mesh file (.obj/.off/.ply/.stl) found there is
// accepted too: the CLI turns it into an automatic cage's model folder (lidef/cage/auto_cage.h). Unknown
// top-level keys are errors (a typo such as "handels" must not silently run a scenario without handles).
#pragma once
#include <string>
#include <vector>

#include "lidef/deform_params.h"
#include "lidef/types.h"

namespace lidef {

struct Scenario {
  std::string path;  // the file it was read from ("" when built in memory)
  std::string name;  // "name", else the file's stem
  std::string description;
  std::string model;                      // as written in the file
  std::string model_dir;                  // resolved folder or mesh file (exists; not yet validated)
  MatX3d sources;                         // #handles by 3
  MatX3d targets;                         // #handles by 3
  std::vector<MatX3d> waypoints;          // each #handles by 3, visited in order before the targets
  std::vector<int> groups;                // #handles rigid-part ids, or empty (grouped by proximity)
  DeformParams params;                    // defaults overridden by "parameters"
  std::vector<std::string> params_given;  // names set by the file, in file order
  std::string studio;  // the "studio" object as JSON text ("" if none): camera and views of a saved studio
                       // session; kept verbatim, ignored by `lidef deform`
  int num_handles() const { return static_cast<int>(sources.rows()); }
};

// Reads and checks a scenario: JSON syntax (with the line), required keys, types, finite coordinates, at
// least one handle, known parameters in range, the model folder found. Throws InputError naming the file.
// Handle positions are checked against the cage later (check_handles), when the model is loaded.
Scenario read_scenario(const std::string& path, const std::string& models_dir = "");

// Writes a scenario (atomically) with all parameters that differ from the defaults.
void write_scenario(const std::string& path, const Scenario& s);

}  // namespace lidef
