// lidef cage MESH --out MODEL_DIR: an automatic cage for a user's mesh (lidef_cage, docs/cages.md).
#include <signal.h>

#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

#include "commands.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "lidef/staged_outputs.h"

namespace lidef::cli {
namespace {

struct CageCommandOptions {
  std::string mesh, out;
  CageOptions cage;
  bool force = false;
  bool quiet = false;
};

// Blocks SIGINT/SIGTERM/SIGHUP while the outputs are written and moved into place, so that Ctrl-C leaves
// either nothing or the complete folder; a signal that arrived meanwhile takes effect when the block ends.
class BlockSignals {
 public:
  BlockSignals() {
    sigemptyset(&set_);
    sigaddset(&set_, SIGINT);
    sigaddset(&set_, SIGTERM);
    sigaddset(&set_, SIGHUP);
    sigprocmask(SIG_BLOCK, &set_, &old_);
  }
  ~BlockSignals() { sigprocmask(SIG_SETMASK, &old_, nullptr); }
  BlockSignals(const BlockSignals&) = delete;
  BlockSignals& operator=(const BlockSignals&) = delete;

 private:
  sigset_t set_, old_;
};

int make_cage_command(const CageCommandOptions& o) {
  namespace fs = std::filesystem;
  auto log = [&](const std::string& s) {
    if (!o.quiet) std::cerr << "lidef cage: " << s << "\n";
  };
  check_cage_options(o.cage);
  {
    std::error_code ec;
    if (fs::exists(o.out, ec)) {
      if (!fs::is_directory(o.out, ec)) throw InputError(o.out, "exists and is not a folder");
      // A folder holding only what a killed run left behind (a staging folder) counts as empty; a killed
      // run's interrupted commit is completed first (then the folder holds its model).
      finish_interrupted_commit(o.out);
      if (!holds_only_leftovers(o.out) && !o.force)
        throw InputError(o.out,
                         "the folder exists and is not empty (use --force to replace its model files)");
    }
  }
  MeshReadInfo info;
  const TriMesh mesh = read_any_mesh(o.mesh, &info);
  log("read " + o.mesh + ": " + std::to_string(mesh.V.rows()) + " vertices, " +
      std::to_string(mesh.F.rows()) + " triangles" +
      (info.fan_triangles > 0 ? " (" + std::to_string(info.fan_triangles) + " from fan triangulation)" : "") +
      (info.dropped_faces > 0 ? ", " + std::to_string(info.dropped_faces) + " degenerate polygons dropped"
                              : "") +
      (info.dropped_vertices > 0 ? ", " + std::to_string(info.dropped_vertices) + " unused vertices dropped"
                                 : ""));
  const CageResult result = make_cage(mesh, o.cage, log);

  {
    const BlockSignals block;
    StagedOutputs out(o.out);
    write_cage_model(result, o.mesh, info, o.cage, [&](const std::string& name) { return out.path(name); });
    out.commit();
  }
  const ValidationReport& v = result.report.validation;
  std::cout << "lidef cage: wrote " << o.out << " {cage.obj, mesh.obj, model.json}: cage " << v.cage_vertices
            << " vertices / " << v.cage_faces << " faces, mesh " << v.mesh_vertices << " vertices / "
            << v.mesh_faces << " faces, min distance mesh -> cage " << format_g(v.min_distance, 4) << " ("
            << format_g(v.min_distance / result.report.diagonal, 3) << " x diagonal), retries "
            << result.report.retries() << ", " << format_g(result.report.seconds, 3) << " s\n";
  return kOk;
}

}  // namespace

void add_cage_command(CLI::App& app, Action& action) {
  auto opt = std::make_shared<CageCommandOptions>();
  auto* sub = app.add_subcommand("cage", "Make a model folder from a mesh file: an automatic cage around it");
  sub->footer(
      "Reads MESH (.obj, .off, .ply or .stl, ASCII or binary; polygons fan-triangulated), or a point\n"
      "cloud (.ply without faces, Gaussian splats included, .xyz, an .obj with vertices only), wraps it "
      "with\n"
      "CGAL's 3D alpha wrapping (alpha and offset are fractions of the bounding-box diagonal), simplifies\n"
      "the wrap by edge collapses to about --faces triangles, refusing every collapse that would bring the\n"
      "cage closer than --clearance to the mesh, and keeps the cage only when lidef's model checks pass\n"
      "(closed, manifold, outward, no self-intersection, every mesh vertex strictly inside). A failed check\n"
      "retries with 1.5 x the offset and 1.5 x the faces (at most 4000).\n"
      "Writes MODEL_DIR/cage.obj, mesh.obj (the input's vertices unchanged) and model.json, all or nothing\n"
      "(also on Ctrl-C). Deterministic: the same mesh and options give the same cage.obj.\n"
      "A mesh file also works wherever a model folder is expected (lidef deform's scenario \"model\",\n"
      "lidef certify): its cage is made once with the default options and cached.\n"
      "Exit 0: written; 2: error (nothing written). See docs/cages.md.");
  sub->add_option("MESH", opt->mesh, "Input mesh file")->required();
  sub->add_option("--out", opt->out, "Model folder to write (created if missing)")
      ->required()
      ->type_name("MODEL_DIR");
  sub->add_option("--faces", opt->cage.faces, "Target number of cage triangles (4..4000)")
      ->capture_default_str();
  sub->add_option("--clearance", opt->cage.clearance,
                  "Minimum distance cage -> mesh during simplification, x bounding-box diagonal")
      ->capture_default_str();
  sub->add_option("--offset", opt->cage.offset, "Alpha wrap offset, x bounding-box diagonal (> clearance)")
      ->capture_default_str();
  sub->add_option("--alpha", opt->cage.alpha, "Alpha wrap alpha, x bounding-box diagonal")
      ->capture_default_str();
  sub->add_option("--retries", opt->cage.max_retries, "Attempts after the first when a check fails (0..10)")
      ->capture_default_str();
  sub->add_flag("--force", opt->force, "Replace the model files of an existing, non-empty MODEL_DIR");
  sub->add_flag("--quiet", opt->quiet, "No progress lines on stderr");
  sub->callback([&action, opt] { action = [opt] { return make_cage_command(*opt); }; });
}

}  // namespace lidef::cli
