// Spatial queries on a triangle mesh shared by the samplers and the certifier's clearance guard:
// "is any triangle within R of p?", "which triangles may meet this box?", the exact triangle–box overlap
// test, and the inside test (generalized winding number ≥ ½). docs/sampling-and-subspace.md explains them.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "lidef/types.h"

namespace lidef {

// Uniform bucket grid of the triangles of (V: #V by 3, F: #F by 3). A triangle is registered in every cell
// its bounding box overlaps, so the cells overlapping a box hold every triangle that can meet it.
class TriangleGrid {
 public:
  TriangleGrid(const MatX3d& V, const MatX3i& F, double cell);
  // True when some triangle is at distance < R from p.
  bool any_within(const Vec3& p, double R) const;
  // Indices of the triangles whose bounding box may overlap [lo, hi] (sorted, unique) appended to out.
  void candidates(const Vec3& lo, const Vec3& hi, std::vector<int>* out) const;

 private:
  int clampi(int v, int axis) const { return std::min(std::max(v, 0), dims_[axis] - 1); }
  long index(int x, int y, int z) const { return (static_cast<long>(z) * dims_[1] + y) * dims_[0] + x; }
  const MatX3d& V_;
  const MatX3i& F_;
  double cell_;
  Vec3 origin_;
  int dims_[3];
  std::vector<int> start_, tris_;
};

// True when the closed triangle (a,b,c) meets the closed axis-aligned box center ± half (separating axis
// test, Akenine-Möller 2001). Conservative: a pair closer than ~1e-12 of the box size counts as meeting, so
// rounding can only add boxes, never drop one.
bool triangle_box_overlap(const Vec3& center, double half, const Vec3& a, const Vec3& b, const Vec3& c);

// Winding number of a triangle mesh around points. A closed mesh (every undirected edge traversed as often
// in each direction) has an integer winding number, counted exactly as the signed crossings of the ray
// p + t e_x (t > 0), through a (y,z) bucket grid; a ray passing within rounding distance of a projected edge
// falls back to the solid-angle sum. Other meshes (holes, open boundaries) use the solid-angle sum — the
// generalized winding number (Jacobson et al. 2013) — everywhere.
class WindingNumber {
 public:
  WindingNumber(const MatX3d& V, const MatX3i& F);
  double at(const Vec3& p) const;
  bool closed() const { return closed_; }

 private:
  double solid_angle_sum(const Vec3& p) const;
  const MatX3d& V_;
  const MatX3i& F_;
  bool closed_ = false;
  double tol_ = 0;
  Vec3 lo_;
  double cell_ = 1;
  int dims_[2] = {1, 1};
  std::vector<int> start_, tris_;
};

// The structure of a triangle surface (F: #F by 3, indices into num_vertices vertices), as the degree
// argument of the global injectivity check needs it (docs/certificate.md, Step G1). The triangles around each
// vertex.
std::vector<std::vector<int>> faces_around_vertices(const MatX3i& F, int num_vertices);
// Why F is not a union of closed, consistently oriented 2-manifolds ("" when it is): an undirected edge not
// used exactly once in each direction, or a vertex whose triangles form several fans joined only by the
// vertex (two spheres touching at a point may be nested without any two triangles' images crossing).
std::string closed_manifold_problem(const MatX3i& F, const std::vector<std::vector<int>>& vertex_faces);
// The connected components of the faces through shared vertices, each listed in increasing face order and
// numbered in the order of their first face.
std::vector<std::vector<int>> face_components(const MatX3i& F,
                                              const std::vector<std::vector<int>>& vertex_faces);

}  // namespace lidef
