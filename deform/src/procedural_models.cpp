#include "lidef/procedural_models.h"

#include <cmath>
#include <map>
#include <vector>

#include "lidef/errors.h"

namespace lidef {
namespace {

// i-th of n+1 evenly spaced values in [lo, hi]: exact at both ends and mirror-symmetric about the middle
// (exactly 0 there for a symmetric range). The offset is a product followed by a quotient, so no fused
// multiply-add can change its rounding: the values do not depend on -march or -ffp-contract.
double lattice(double lo, double hi, int i, int n) {
  if (i == 0) return lo;
  if (i == n) return hi;
  const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
  const double offset = half * (2 * i - n) / n;
  return mid + offset;
}

TriMesh from_vectors(const std::vector<Vec3>& V, const std::vector<Eigen::Vector3i>& F,
                     const std::string& source) {
  TriMesh m;
  m.source = source;
  m.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  m.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) m.V.row(i) = V[i].transpose();
  for (size_t i = 0; i < F.size(); ++i) m.F.row(i) = F[i].transpose();
  return m;
}

Model validated(TriMesh cage, TriMesh mesh, const char* what) {
  ValidationReport report = validate_model(cage, mesh);
  if (!report.usable() || !report.warnings.empty()) {
    std::string msg = std::string("generated ") + what + " model failed validation:";
    for (const Issue& i : report.errors) msg += "\n  error: " + i.str();
    for (const Issue& i : report.warnings) msg += "\n  warning: " + i.str();
    throw Error(msg);
  }
  return Model{Cage(cage), std::move(mesh), "", std::move(report)};
}

}  // namespace

TriMesh box_surface(const Vec3& lo, const Vec3& hi, const Eigen::Vector3i& n) {
  if ((n.array() < 1).any() || !((hi - lo).array() > 0).all())
    throw Error("box_surface: empty box or no segments");
  std::vector<Vec3> V;
  std::vector<Eigen::Vector3i> F;
  // Lattice point (i,j,k) -> vertex index, so that the six sides share their border vertices exactly.
  std::vector<int> id((n[0] + 1) * (n[1] + 1) * (n[2] + 1), -1);
  auto vertex = [&](const Eigen::Vector3i& g) {
    int& slot = id[(g[0] * (n[1] + 1) + g[1]) * (n[2] + 1) + g[2]];
    if (slot < 0) {
      slot = static_cast<int>(V.size());
      V.emplace_back(lattice(lo[0], hi[0], g[0], n[0]), lattice(lo[1], hi[1], g[1], n[1]),
                     lattice(lo[2], hi[2], g[2], n[2]));
    }
    return slot;
  };
  for (int d = 0; d < 3; ++d)
    for (int side = 0; side < 2; ++side) {
      // (d, u, v) is a cyclic permutation of (x, y, z), so e_u x e_v = e_d: corners in (u, v) order are
      // counter-clockwise seen from +d, and must be reversed on the -d side.
      const int u = (d + 1) % 3, v = (d + 2) % 3;
      for (int a = 0; a < n[u]; ++a)
        for (int b = 0; b < n[v]; ++b) {
          int q[4];
          const int du[4] = {0, 1, 1, 0}, dv[4] = {0, 0, 1, 1};
          for (int c = 0; c < 4; ++c) {
            Eigen::Vector3i g;
            g[d] = side ? n[d] : 0;
            g[u] = a + du[c];
            g[v] = b + dv[c];
            q[c] = vertex(g);
          }
          if (!side) std::swap(q[1], q[3]);
          // Alternating diagonals keep the triangulation symmetric under the box's mirror symmetries.
          if ((a + b) % 2 == 0) {
            F.emplace_back(q[0], q[1], q[2]);
            F.emplace_back(q[0], q[2], q[3]);
          } else {
            F.emplace_back(q[0], q[1], q[3]);
            F.emplace_back(q[1], q[2], q[3]);
          }
        }
    }
  return from_vectors(V, F, "");
}

TriMesh icosphere(double radius, int subdivisions) {
  if (!(radius > 0) || subdivisions < 0 || subdivisions > 7)
    throw Error("icosphere: radius <= 0 or subdivisions not in 0..7");
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> V = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& p : V) p.normalize();
  std::vector<Eigen::Vector3i> F = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      V.push_back((V[a] + V[b]).normalized());
      return mid[key] = static_cast<int>(V.size()) - 1;
    };
    std::vector<Eigen::Vector3i> next;
    next.reserve(4 * F.size());
    for (const auto& f : F) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      next.emplace_back(f[0], ab, ca);
      next.emplace_back(f[1], bc, ab);
      next.emplace_back(f[2], ca, bc);
      next.emplace_back(ab, bc, ca);
    }
    F = std::move(next);
  }
  for (Vec3& p : V) p *= radius;
  return from_vectors(V, F, "");
}

Model make_beam(const BeamParams& p) {
  if (!(p.length > 0) || !(p.thickness > 0) || !(p.gap > 0) || p.mesh_segments_length < 1 ||
      p.mesh_segments_section < 1 || p.cage_segments_length < 1 || p.cage_segments_section < 1)
    throw Error("make_beam: sizes and the gap must be > 0 and segment counts >= 1");
  const Vec3 half(p.length / 2, p.thickness / 2, p.thickness / 2);
  const Vec3 grow = Vec3::Constant(p.gap * p.thickness);
  TriMesh mesh =
      box_surface(-half, half, {p.mesh_segments_length, p.mesh_segments_section, p.mesh_segments_section});
  TriMesh cage = box_surface(-half - grow, half + grow,
                             {p.cage_segments_length, p.cage_segments_section, p.cage_segments_section});
  mesh.source = "generated beam mesh";
  cage.source = "generated beam cage";
  return validated(std::move(cage), std::move(mesh), "beam");
}

Model make_ball(const BallParams& p) {
  if (!(p.radius > 0) || !(p.gap > 0)) throw Error("make_ball: radius and gap must be > 0");
  TriMesh mesh = icosphere(p.radius, p.mesh_subdivisions);
  TriMesh cage = icosphere(1.0, p.cage_subdivisions);
  // The cage's faces are closer to the center than its vertices: scale so that the nearest face plane
  // (the inradius) is (1 + gap) * radius away, which puts every mesh vertex gap * radius inside.
  double inradius = 1.0;
  for (int f = 0; f < cage.F.rows(); ++f) {
    const Vec3 a = cage.V.row(cage.F(f, 0)), b = cage.V.row(cage.F(f, 1)), c = cage.V.row(cage.F(f, 2));
    inradius = std::min(inradius, std::abs(a.dot((b - a).cross(c - a).normalized())));
  }
  cage.V *= (1.0 + p.gap) * p.radius / inradius;
  mesh.source = "generated ball mesh";
  cage.source = "generated ball cage";
  return validated(std::move(cage), std::move(mesh), "ball");
}

}  // namespace lidef
