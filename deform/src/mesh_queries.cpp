#include "lidef/internal/mesh_queries.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <string>
#include <utility>

#include "lidef/geometry.h"

namespace lidef {

namespace {

// Pairs (bucket, triangle) sorted into CSR arrays (start: #buckets + 1, items).
void to_csr(std::vector<std::pair<long, int>>& pairs, long buckets, std::vector<int>* start,
            std::vector<int>* items) {
  std::sort(pairs.begin(), pairs.end());
  start->assign(buckets + 1, 0);
  for (const auto& p : pairs) ++(*start)[p.first + 1];
  std::partial_sum(start->begin(), start->end(), start->begin());
  items->resize(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) (*items)[i] = pairs[i].second;
}

}  // namespace

TriangleGrid::TriangleGrid(const MatX3d& V, const MatX3i& F, double cell) : V_(V), F_(F), cell_(cell) {
  const Vec3 lo = V.colwise().minCoeff().transpose(), hi = V.colwise().maxCoeff().transpose();
  origin_ = lo - Vec3::Constant(cell);
  for (int a = 0; a < 3; ++a) dims_[a] = static_cast<int>(std::ceil((hi(a) - origin_(a)) / cell)) + 1;
  std::vector<std::pair<long, int>> pairs;
  for (int t = 0; t < F.rows(); ++t) {
    const Vec3 a = V.row(F(t, 0)), b = V.row(F(t, 1)), c = V.row(F(t, 2));
    const Vec3 tl = a.cwiseMin(b).cwiseMin(c), th = a.cwiseMax(b).cwiseMax(c);
    int l[3], h[3];
    for (int k = 0; k < 3; ++k) {
      l[k] = clampi(static_cast<int>(std::floor((tl(k) - origin_(k)) / cell)), k);
      h[k] = clampi(static_cast<int>(std::floor((th(k) - origin_(k)) / cell)), k);
    }
    for (int z = l[2]; z <= h[2]; ++z)
      for (int y = l[1]; y <= h[1]; ++y)
        for (int x = l[0]; x <= h[0]; ++x) pairs.emplace_back(index(x, y, z), t);
  }
  to_csr(pairs, static_cast<long>(dims_[0]) * dims_[1] * dims_[2], &start_, &tris_);
}

bool TriangleGrid::any_within(const Vec3& p, double R) const {
  int l[3], h[3];
  for (int k = 0; k < 3; ++k) {
    l[k] = clampi(static_cast<int>(std::floor((p(k) - R - origin_(k)) / cell_)), k);
    h[k] = clampi(static_cast<int>(std::floor((p(k) + R - origin_(k)) / cell_)), k);
  }
  const double R2 = R * R;
  for (int z = l[2]; z <= h[2]; ++z)
    for (int y = l[1]; y <= h[1]; ++y)
      for (int x = l[0]; x <= h[0]; ++x) {
        const long c = index(x, y, z);
        for (int i = start_[c]; i < start_[c + 1]; ++i) {
          const int t = tris_[i];
          if (point_triangle_dist2(p, V_.row(F_(t, 0)), V_.row(F_(t, 1)), V_.row(F_(t, 2))) < R2) return true;
        }
      }
  return false;
}

void TriangleGrid::candidates(const Vec3& lo, const Vec3& hi, std::vector<int>* out) const {
  int l[3], h[3];
  for (int k = 0; k < 3; ++k) {
    l[k] = clampi(static_cast<int>(std::floor((lo(k) - origin_(k)) / cell_)), k);
    h[k] = clampi(static_cast<int>(std::floor((hi(k) - origin_(k)) / cell_)), k);
  }
  const size_t first = out->size();
  for (int z = l[2]; z <= h[2]; ++z)
    for (int y = l[1]; y <= h[1]; ++y)
      for (int x = l[0]; x <= h[0]; ++x) {
        const long c = index(x, y, z);
        out->insert(out->end(), tris_.begin() + start_[c], tris_.begin() + start_[c + 1]);
      }
  std::sort(out->begin() + static_cast<long>(first), out->end());
  out->erase(std::unique(out->begin() + static_cast<long>(first), out->end()), out->end());
}

bool triangle_box_overlap(const Vec3& center, double half, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 v[3] = {a - center, b - center, c - center};
  const double scale =
      half + std::max({v[0].cwiseAbs().maxCoeff(), v[1].cwiseAbs().maxCoeff(), v[2].cwiseAbs().maxCoeff()});
  const double eps = 1e-12 * scale;
  // Separated along axis n when the triangle's projection misses the box's [−r, r] by more than eps·|n|.
  auto separated = [&](const Vec3& n) {
    const double p0 = n.dot(v[0]), p1 = n.dot(v[1]), p2 = n.dot(v[2]);
    const double r = half * n.cwiseAbs().sum();
    const double slack = eps * (n.cwiseAbs().sum() + 1e-300);
    return std::min({p0, p1, p2}) > r + slack || std::max({p0, p1, p2}) < -r - slack;
  };
  for (int k = 0; k < 3; ++k) {
    if (std::min({v[0](k), v[1](k), v[2](k)}) > half + eps) return false;
    if (std::max({v[0](k), v[1](k), v[2](k)}) < -half - eps) return false;
  }
  const Vec3 e[3] = {v[1] - v[0], v[2] - v[1], v[0] - v[2]};
  if (separated(e[0].cross(e[1]))) return false;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      const Vec3 n = Vec3::Unit(k).cross(e[i]);
      if (n.squaredNorm() > 0 && separated(n)) return false;
    }
  return true;
}

WindingNumber::WindingNumber(const MatX3d& V, const MatX3i& F) : V_(V), F_(F) {
  // Closed: the directed edge counts balance on every undirected edge.
  std::map<std::pair<int, int>, int> balance;
  for (int t = 0; t < F.rows(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int u = F(t, k), w = F(t, (k + 1) % 3);
      balance[{std::min(u, w), std::max(u, w)}] += u < w ? 1 : -1;
    }
  closed_ = F.rows() > 0;
  for (const auto& kv : balance) closed_ = closed_ && kv.second == 0;
  if (!closed_) return;
  const Vec3 lo = V.colwise().minCoeff().transpose(), hi = V.colwise().maxCoeff().transpose();
  const Vec3 ext = hi - lo;
  tol_ = 1e-9 * ext.norm();
  lo_ = lo;
  // About √#F buckets per axis of the (y,z) projection.
  const int n = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(F.rows()))));
  cell_ = std::max({ext(1), ext(2), 1e-300}) / n;
  for (int a = 0; a < 2; ++a) dims_[a] = static_cast<int>(std::floor(ext(a + 1) / cell_)) + 1;
  std::vector<std::pair<long, int>> pairs;
  for (int t = 0; t < F.rows(); ++t) {
    int l[2], h[2];
    for (int a = 0; a < 2; ++a) {
      double mn = V(F(t, 0), a + 1), mx = mn;
      for (int k = 1; k < 3; ++k) mn = std::min(mn, V(F(t, k), a + 1)), mx = std::max(mx, V(F(t, k), a + 1));
      l[a] = std::max(0, static_cast<int>(std::floor((mn - tol_ - lo_(a + 1)) / cell_)));
      h[a] = std::min(dims_[a] - 1, static_cast<int>(std::floor((mx + tol_ - lo_(a + 1)) / cell_)));
    }
    for (int z = l[1]; z <= h[1]; ++z)
      for (int y = l[0]; y <= h[0]; ++y) pairs.emplace_back(static_cast<long>(z) * dims_[0] + y, t);
  }
  to_csr(pairs, static_cast<long>(dims_[0]) * dims_[1], &start_, &tris_);
}

double WindingNumber::solid_angle_sum(const Vec3& p) const {
  double w = 0;
  for (int t = 0; t < F_.rows(); ++t)
    w += solid_angle_fraction(V_.row(F_(t, 0)), V_.row(F_(t, 1)), V_.row(F_(t, 2)), p);
  return w;
}

double WindingNumber::at(const Vec3& p) const {
  if (!closed_) return solid_angle_sum(p);
  const int y = static_cast<int>(std::floor((p(1) - lo_(1)) / cell_)),
            z = static_cast<int>(std::floor((p(2) - lo_(2)) / cell_));
  if (y < 0 || z < 0 || y >= dims_[0] || z >= dims_[1]) return 0.0;  // outside the projected bounding box
  const long b = static_cast<long>(z) * dims_[0] + y;
  const double tol2 = tol_ * tol_;
  int w = 0;
  for (int s = start_[b]; s < start_[b + 1]; ++s) {
    const int t = tris_[s];
    const Vec3 A = V_.row(F_(t, 0)), B = V_.row(F_(t, 1)), C = V_.row(F_(t, 2));
    if (seg_dist2_2d(p(1), p(2), A(1), A(2), B(1), B(2)) < tol2 ||
        seg_dist2_2d(p(1), p(2), B(1), B(2), C(1), C(2)) < tol2 ||
        seg_dist2_2d(p(1), p(2), C(1), C(2), A(1), A(2)) < tol2)
      return solid_angle_sum(p);  // the ray grazes a projected edge: count by solid angles
    const double area2 = cross2(B(1) - A(1), B(2) - A(2), C(1) - A(1), C(2) - A(2));
    if (area2 == 0) continue;
    const double eab = cross2(B(1) - A(1), B(2) - A(2), p(1) - A(1), p(2) - A(2));
    const double ebc = cross2(C(1) - B(1), C(2) - B(2), p(1) - B(1), p(2) - B(2));
    const double eca = cross2(A(1) - C(1), A(2) - C(2), p(1) - C(1), p(2) - C(2));
    if (!((eab > 0 && ebc > 0 && eca > 0) || (eab < 0 && ebc < 0 && eca < 0))) continue;
    const double x = (ebc * A(0) + eca * B(0) + eab * C(0)) / area2;
    if (std::abs(x - p(0)) <= tol_) return solid_angle_sum(p);  // p on (or at rounding distance of) the mesh
    if (x > p(0)) w += area2 > 0 ? 1 : -1;                      // n_x > 0: the +x ray leaves the inside here
  }
  return w;
}

std::vector<std::vector<int>> faces_around_vertices(const MatX3i& F, int num_vertices) {
  std::vector<std::vector<int>> out(std::max(num_vertices, 0));
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) out[F(f, k)].push_back(f);
  return out;
}

namespace {

// Union-find with path halving over 0..n-1.
struct DisjointSets {
  explicit DisjointSets(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int find(int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void join(int a, int b) { parent[find(a)] = find(b); }
  std::vector<int> parent;
};

// "" or the first vertex whose triangles form more than one fan (joined through the edges at the vertex).
// Called once every edge is known to be used by exactly two triangles.
std::string pinched_vertex_problem(const MatX3i& F, const std::vector<std::vector<int>>& vertex_faces) {
  std::vector<std::pair<int, int>> around;  // (other vertex of an edge at v, face)
  for (size_t v = 0; v < vertex_faces.size(); ++v) {
    const std::vector<int>& faces = vertex_faces[v];
    if (faces.size() < 2) continue;
    around.clear();
    for (size_t k = 0; k < faces.size(); ++k)
      for (int c = 0; c < 3; ++c)
        if (const int u = F(faces[k], c); u != static_cast<int>(v))
          around.push_back({u, static_cast<int>(k)});
    std::sort(around.begin(), around.end());
    DisjointSets fans(faces.size());
    for (size_t i = 1; i < around.size(); ++i)  // faces sharing the edge (v, u) are neighbours in the fan
      if (around[i].first == around[i - 1].first) fans.join(around[i].second, around[i - 1].second);
    int count = 0;
    for (size_t k = 0; k < faces.size(); ++k) count += fans.find(static_cast<int>(k)) == static_cast<int>(k);
    if (count > 1)
      return "the mesh surface is pinched at vertex " + std::to_string(v) + " (its triangles there form " +
             std::to_string(count) + " fans that share only the vertex: not a manifold)";
  }
  return "";
}

}  // namespace

std::string closed_manifold_problem(const MatX3i& F, const std::vector<std::vector<int>>& vertex_faces) {
  const long nf = F.rows();
  if (nf == 0) return "the mesh has no triangles";
  std::vector<std::array<int, 3>> half;  // (min, max, +1/-1)
  half.reserve(3 * nf);
  for (long f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      half.push_back({std::min(a, b), std::max(a, b), a < b ? 1 : -1});
    }
  std::sort(half.begin(), half.end());
  for (size_t i = 0; i < half.size();) {
    size_t j = i;
    while (j < half.size() && half[j][0] == half[i][0] && half[j][1] == half[i][1]) ++j;
    if (j - i != 2 || half[i][2] == half[i + 1][2])
      return "the mesh surface is not a closed manifold (edge " + std::to_string(half[i][0]) + "-" +
             std::to_string(half[i][1]) + " is used by " + std::to_string(j - i) +
             " triangles or twice in one direction)";
    i = j;
  }
  return pinched_vertex_problem(F, vertex_faces);
}

std::vector<std::vector<int>> face_components(const MatX3i& F,
                                              const std::vector<std::vector<int>>& vertex_faces) {
  const auto nf = static_cast<size_t>(F.rows());
  DisjointSets sets(nf);
  for (const auto& faces : vertex_faces)
    for (size_t k = 1; k < faces.size(); ++k) sets.join(faces[k], faces[0]);
  std::vector<int> label(nf, -1);
  std::vector<std::vector<int>> out;
  for (size_t f = 0; f < nf; ++f) {
    const int r = sets.find(static_cast<int>(f));
    if (label[r] < 0) {
      label[r] = static_cast<int>(out.size());
      out.emplace_back();
    }
    out[label[r]].push_back(static_cast<int>(f));
  }
  return out;
}

}  // namespace lidef
