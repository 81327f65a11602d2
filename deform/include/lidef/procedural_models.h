// Models the project generates itself, so that demos and tests run without ../shared.
// Output is deterministic: the same parameters give bit-identical arrays on every run and machine.
#pragma once
#include <string>

#include "lidef/model_check.h"
#include "lidef/tri_mesh.h"

namespace lidef {

// A straight bar along x: the mesh is the surface of the box [-L/2,L/2] x [-T/2,T/2]^2 (regular grid on
// each side, alternating diagonals), the cage the same box grown by `gap * T` on every side, with a coarser
// grid. Defaults: mesh 3,170 vertices, cage 106 vertices / 208 faces (like the published `bar`).
struct BeamParams {
  double length = 2.0;
  double thickness = 0.4;
  double gap = 0.1;  // mesh-to-cage distance as a fraction of the thickness
  int mesh_segments_length = 60, mesh_segments_section = 12;
  int cage_segments_length = 12, cage_segments_section = 2;
};

// A sphere of `radius` (icosphere, `mesh_subdivisions` times subdivided) inside an icosphere cage
// (`cage_subdivisions` times subdivided) whose faces are `gap * radius` away from the sphere.
// Defaults: mesh 2,562 vertices, cage 162 vertices / 320 faces.
struct BallParams {
  double radius = 1.0;
  double gap = 0.1;
  int mesh_subdivisions = 4;
  int cage_subdivisions = 2;
};

// Validated models (Model::dir is empty). Throw lidef::Error if parameters are out of range
// (non-positive sizes, segments < 1, subdivisions outside 0..7).
Model make_beam(const BeamParams& params = {});
Model make_ball(const BallParams& params = {});

// Building blocks, outward oriented (counter-clockwise seen from outside).
// Surface of the axis-aligned box [lo, hi] with segments(d) grid cells along axis d; vertices are shared.
TriMesh box_surface(const Vec3& lo, const Vec3& hi, const Eigen::Vector3i& segments);
// Icosahedron around the origin with vertices at `radius`, each face split into 4 `subdivisions` times
// (new vertices pushed to the sphere): 10*4^s + 2 vertices, 20*4^s faces.
TriMesh icosphere(double radius, int subdivisions);

}  // namespace lidef
