// Small procedural cages for math tests (independent of any file loader).
#pragma once
#include <map>
#include <random>

#include "lidef/cage.h"
#include "lidef/subspace.h"
#include "lidef/tri_mesh.h"

namespace lidef::test {

// A map with a bent, non-affine Jacobian (#V+#F by 3): the cage's identity coefficients plus N(0, amp²)
// perturbations of every coefficient (seeded).
inline MatX3d perturbed_map(const Cage& cage, double amp, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01;
  MatX3d y = cage.identity_coefficients();
  for (int i = 0; i < y.rows(); ++i) y.row(i) += amp * Vec3(N01(rng), N01(rng), N01(rng)).transpose();
  return y;
}

// A smooth bent map in the span of a subspace (#V+#F by 3): the cage's identity plus N(0, (amp · bbox
// diagonal)²) multiples of the low modes 4..11 (seeded).
inline MatX3d smooth_map(const Cage& cage, const SpectralSubspace& sub, double amp, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01;
  MatX3d y = cage.identity_coefficients();
  const double size = (cage.bbox_max - cage.bbox_min).norm();
  for (int k = 4; k < std::min(12, sub.size()); ++k)
    for (int a = 0; a < 3; ++a) y.col(a) += amp * size * N01(rng) * sub.basis.col(k);
  return y;
}

// perturbed_map with the output scaled by (1, 0.7, 0.45): σ1 > σ2 > σ3 with gaps, as on deformed maps (near
// the identity all three are ≈ 1 and the spectral bound, docs/certificate.md Step 3c, has no gap to use).
inline MatX3d anisotropic_perturbed_map(const Cage& cage, double amp, unsigned seed) {
  MatX3d y = perturbed_map(cage, amp, seed);
  y.col(1) *= 0.7;
  y.col(2) *= 0.45;
  return y;
}

// Icosphere of radius 1 (subdivided `levels` times), each vertex radially scaled by a factor in
// [1 − bump, 1 + bump] (seeded) so the cage is star-shaped but not convex. CCW seen from outside.
inline TriMesh icosphere(int levels, double bump = 0.0, unsigned seed = 1) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (auto& p : v) p.normalize();
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> g;
    for (auto& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      g.push_back({tri[0], a, c});
      g.push_back({tri[1], b, a});
      g.push_back({tri[2], c, b});
      g.push_back({a, b, c});
    }
    f = g;
  }
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(1.0 - bump, 1.0 + bump);
  TriMesh m;
  m.V.resize(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) m.V.row(i) = v[i] * (bump > 0 ? U(rng) : 1.0);
  m.F.resize(f.size(), 3);
  for (size_t i = 0; i < f.size(); ++i) m.F.row(i) << f[i][0], f[i][1], f[i][2];
  m.source = "icosphere";
  return m;
}

// Random points strictly inside the cage, at least `margin` away from it.
inline MatX3d interior_points(const Cage& cage, int count, double margin, unsigned seed = 7) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  MatX3d P(count, 3);
  int got = 0;
  while (got < count) {
    Vec3 p;
    for (int k = 0; k < 3; ++k) p(k) = cage.bbox_min(k) + U(rng) * (cage.bbox_max(k) - cage.bbox_min(k));
    if (std::abs(cage.winding_number(p) - 1.0) < 1e-6 && cage.distance(p) > margin) P.row(got++) = p;
  }
  return P;
}

// Minimal OBJ reader for test inputs (v and f lines only).
inline TriMesh read_obj_simple(const std::string& path) {
  std::FILE* fp = std::fopen(path.c_str(), "r");
  std::vector<Vec3> v;
  std::vector<std::array<int, 3>> f;
  char line[512];
  while (fp && std::fgets(line, sizeof line, fp)) {
    double x, y, z;
    int a, b, c;
    if (line[0] == 'v' && line[1] == ' ' && std::sscanf(line + 2, "%lf %lf %lf", &x, &y, &z) == 3)
      v.push_back({x, y, z});
    else if (line[0] == 'f' && line[1] == ' ' && std::sscanf(line + 2, "%d %d %d", &a, &b, &c) == 3)
      f.push_back({a - 1, b - 1, c - 1});
  }
  if (fp) std::fclose(fp);
  TriMesh m;
  m.V.resize(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) m.V.row(i) = v[i];
  m.F.resize(f.size(), 3);
  for (size_t i = 0; i < f.size(); ++i) m.F.row(i) << f[i][0], f[i][1], f[i][2];
  m.source = path;
  return m;
}

}  // namespace lidef::test
