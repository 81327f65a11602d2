// lidef check MODEL_DIR [--json FILE]: validates a model folder and prints what was found.
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include "commands.h"
#include "lidef/atomic_file.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"

namespace lidef::cli {
namespace {

struct CheckOptions {
  std::string dir;
  std::string json;
};

std::string box(const Vec3& lo, const Vec3& hi) {
  return "[" + format_g(lo.x()) + ", " + format_g(hi.x()) + "] x [" + format_g(lo.y()) + ", " +
         format_g(hi.y()) + "] x [" + format_g(lo.z()) + ", " + format_g(hi.z()) + "]";
}

void print_report(std::ostream& out, const std::string& dir, const ValidationReport& r) {
  out << "model " << dir << "\n";
  if (r.cage_vertices > 0) {
    out << "  cage   " << r.cage_file << "\n";
    out << "         " << r.cage_vertices << " vertices, " << r.cage_faces << " faces, " << r.cage_edges
        << " edges, " << r.cage_components << " component" << (r.cage_components == 1 ? "" : "s")
        << ", Euler characteristic " << r.euler_characteristic;
    if (r.genus >= 0) out << ", genus " << r.genus;
    out << "\n         bounding box " << box(r.cage_bbox_min, r.cage_bbox_max) << "\n";
    out << "         volume " << format_g(r.cage_volume) << ", " << r.self_intersections.size()
        << " self-intersecting face pair" << (r.self_intersections.size() == 1 ? "" : "s") << "\n";
  }
  if (r.mesh_vertices > 0) {
    out << "  mesh   " << r.mesh_file << "\n";
    out << "         " << r.mesh_vertices << " vertices, " << r.mesh_faces << " faces\n";
    out << "         bounding box " << box(r.mesh_bbox_min, r.mesh_bbox_max) << "\n";
    if (r.inside_checked) {
      out << "         min distance mesh -> cage " << format_g(r.min_distance) << " (vertex "
          << r.min_distance_vertex + 1 << ")\n";
      out << "         " << r.mesh_vertices - r.mesh_vertices_outside - r.mesh_vertices_on_cage << " of "
          << r.mesh_vertices << " vertices strictly inside the cage\n";
    } else {
      out << "         mesh-in-cage test skipped (the cage has errors)\n";
    }
  }
  out << "warnings: " << r.warnings.size() << "\n";
  for (const Issue& w : r.warnings) out << "  warning: " << w.str() << "\n";
  out << "errors: " << r.errors.size() << "\n";
  for (const Issue& e : r.errors) out << "  error: " << e.str() << "\n";
  out << (r.usable() ? "result: usable" : "result: NOT usable") << " (checked in "
      << format_fixed(r.seconds, 2) << " s)\n";
}

}  // namespace

void add_check_command(CLI::App& app, Action& action) {
  auto opt = std::make_shared<CheckOptions>();
  auto* sub = app.add_subcommand("check", "Validate a model folder (cage + mesh) and print a summary");
  sub->footer(
      "A model folder holds cage.obj (or cage.off) and mesh.obj (or mesh.off).\n"
      "Errors (the model cannot be used): unreadable or malformed files, NaN/Inf coordinates, indices out "
      "of\n"
      "range, degenerate or duplicate cage faces, an open, non-manifold, inconsistently oriented or "
      "inverted\n"
      "cage, mesh vertices outside or on the cage.\n"
      "Warnings (usable): cage self-intersections, several cage components, unused cage vertices, "
      "degenerate\n"
      "mesh faces, mesh vertices in self-overlapping cage regions.\n"
      "Elements are numbered from 1 as in the file (face k = k-th 'f' line).\n"
      "Exit status: 0 usable (warnings allowed), 2 not usable or bad arguments.\n"
      "See docs/models.md.");
  sub->add_option("MODEL_DIR", opt->dir, "Model folder to check")->required()->type_name("DIR");
  sub->add_option("--json", opt->json,
                  "Also write the full report as JSON to FILE ('-': JSON only, to stdout)")
      ->type_name("FILE");
  sub->callback([&action, opt] {
    action = [opt] {
      const ValidationReport r = check_model_dir(opt->dir);
      if (opt->json == "-") {
        std::cout << report_to_json(r);
      } else {
        print_report(std::cout, opt->dir, r);
        if (!opt->json.empty())
          write_file_atomic(opt->json, [&](std::ostream& out) { out << report_to_json(r); });
      }
      return r.usable() ? kOk : kError;
    };
  });
}

}  // namespace lidef::cli
