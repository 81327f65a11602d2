#include "lidef/cage.h"

#include <algorithm>
#include <map>

#include "lidef/errors.h"
#include "lidef/geometry.h"

namespace lidef {

Cage::Cage(const TriMesh& mesh) : V(mesh.V), F(mesh.F), source(mesh.source) {
  const int nv = num_vertices(), nf = num_faces();
  if (nv < 4 || nf < 4) throw InputError(source, "cage needs at least 4 vertices and 4 faces");
  N.resize(nf, 3);
  area.resize(nf);
  for (int t = 0; t < nf; ++t) {
    for (int k = 0; k < 3; ++k)
      if (F(t, k) < 0 || F(t, k) >= nv)
        throw InputError(source, "face " + std::to_string(t + 1) + " has a vertex index out of range");
    const Vec3 a = V.row(F(t, 0)), b = V.row(F(t, 1)), c = V.row(F(t, 2));
    const Vec3 n2 = (b - a).cross(c - a);
    const double len = n2.norm();
    if (!(len > 0)) throw InputError(source, "face " + std::to_string(t + 1) + " is degenerate (zero area)");
    N.row(t) = n2 / len;
    area(t) = 0.5 * len;
  }
  volume = signed_volume(V, F);
  // Directed edge (a,b) -> (face, local index of the opposite vertex).
  std::map<std::pair<int, int>, std::pair<int, int>> directed;
  for (int t = 0; t < nf; ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = F(t, (k + 1) % 3), b = F(t, (k + 2) % 3);
      if (!directed.emplace(std::make_pair(a, b), std::make_pair(t, k)).second)
        throw InputError(source, "directed edge " + std::to_string(a + 1) + "->" + std::to_string(b + 1) +
                                     " is used twice (non-manifold or inconsistently oriented)");
    }
  for (const auto& [ab, fk] : directed) {
    const auto [a, b] = ab;
    if (a > b) continue;
    auto it = directed.find({b, a});
    if (it == directed.end())
      throw InputError(source, "edge " + std::to_string(a + 1) + "-" + std::to_string(b + 1) +
                                   " has only one face (cage is not closed)");
    edges.push_back({a, b, fk.first, it->second.first, fk.second, it->second.second});
  }
  for (const auto& [ab, fk] : directed)
    if (ab.first > ab.second && !directed.count({ab.second, ab.first}))
      throw InputError(source, "edge " + std::to_string(ab.first + 1) + "-" + std::to_string(ab.second + 1) +
                                   " has only one face (cage is not closed)");
  bbox_min = V.colwise().minCoeff().transpose();
  bbox_max = V.colwise().maxCoeff().transpose();
}

double Cage::winding_number(const Vec3& p) const {
  double w = 0;
  for (int t = 0; t < num_faces(); ++t)
    w += solid_angle_fraction(V.row(F(t, 0)), V.row(F(t, 1)), V.row(F(t, 2)), p);
  return w;
}

MatX3d Cage::identity_coefficients() const {
  return affine_coefficients(Mat3::Identity(), Vec3::Zero());
}

MatX3d Cage::affine_coefficients(const Mat3& A, const Vec3& b) const {
  MatX3d y(num_coeffs(), 3);
  for (int v = 0; v < num_vertices(); ++v) y.row(v) = (A * V.row(v).transpose() + b).transpose();
  for (int t = 0; t < num_faces(); ++t) y.row(num_vertices() + t) = (A * N.row(t).transpose()).transpose();
  return y;
}

double Cage::distance(const Vec3& p) const {
  double d2 = std::numeric_limits<double>::infinity();
  for (int t = 0; t < num_faces(); ++t)
    d2 = std::min(d2, point_triangle_dist2(p, V.row(F(t, 0)), V.row(F(t, 1)), V.row(F(t, 2))));
  return std::sqrt(d2);
}

}  // namespace lidef
