// Proof that a certificate's leaves cover what the certificate claims (`lidef verify --interval`;
// docs/certificate.md, "Interval re-proof", step C). Proving every certified leaf proves σ3 > 0 on the union
// of the leaves that were handed in; it says nothing about a domain the leaves do not cover (a voxels.csv cut
// to a few rows would re-prove them all). This proof uses only the certificate's grid (origin, base side),
// the model's mesh and the leaf table, never the certifier's sampling:
//   1. every leaf is a cell of the grid's octree: side h₀ 2^−k and center origin + (idx + ½) h₀ 2^−k, up to a
//      rounding tolerance δ (the leaves are written in model units from the normalized frame); the leaf balls
//      that the interval re-proof proves are widened by `radius_slack` ≥ the distance from the written cube
//      to that cell, so the proven balls contain the cells themselves;
//   2. no two leaves are the same cell, and none is inside another; domain "voxels": the level-0 cells they
//   lie
//      in are as many as the certificate's base voxels;
//   3. domain "mesh": every grid cell that meets D (the input's points, its triangles and the solid bounded by
//      its closed components, MeshDomain; the exact test of cubes_meeting_mesh_domain) is a certified leaf, or its children that meet D are covered in
//      turn — so D lies in the union of the certified leaves; domain "voxels": every base voxel is tiled by
//      certified leaves.
// A leaf that is not certified, a cell that meets D with no leaf, or a leaf off the grid fails the proof.
#pragma once
#include <string>

#include "lidef/analysis/certificate_report.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

struct LeafCoverage {
  bool proven = false;
  std::string reason;       // what was proven, or the first gap found
  long cells_checked = 0;   // grid cells (all levels) tested against the domain
  long base_cells = 0;      // distinct level-0 cells the leaves lie in (domain "voxels": its base voxels)
  double radius_slack = 0;  // added to every leaf's ball radius by the interval re-proof (model units)
  Vec3 gap = Vec3::Zero();  // a point of D (a cell center) not covered, when not proven
};

// `mesh`: the model's mesh in model units (the certificate's frame). Deterministic; OpenMP threads do not
// change the result.
LeafCoverage prove_leaf_coverage(const CertificateReport& certificate, const TriMesh& mesh);

}  // namespace lidef
