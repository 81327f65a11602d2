#include "lidef/analysis/leaf_coverage.h"

#include <algorithm>
#include <cmath>
#include <tuple>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "lidef/domain_sampling.h"
#include "lidef/number_format.h"

namespace lidef {
namespace {

constexpr double kUnitRoundoff = 0x1p-53;
// Deepest octree level below the base grid that a leaf may have (the certifier's max_depth plus the mesh
// domain's own refinement stay far below it).
constexpr int kMaxLevel = 40;
// Cells tested against the domain at one level at most: a bound on the work, not a result.
constexpr long kMaxCellsPerLevel = 50'000'000;

// A cell of the grid's octree: level k below the base grid, integer index of its lower corner in units of
// h₀ 2^−k.
struct Cell {
  int level = 0;
  long i = 0, j = 0, k = 0;
  bool operator==(const Cell& o) const { return level == o.level && i == o.i && j == o.j && k == o.k; }
  Cell parent() const { return {level - 1, floor_half(i), floor_half(j), floor_half(k)}; }
  Cell child(int c) const {
    return {level + 1, 2 * i + (c & 1), 2 * j + ((c >> 1) & 1), 2 * k + ((c >> 2) & 1)};
  }
  static long floor_half(long x) { return x >= 0 ? x / 2 : -((-x + 1) / 2); }
};
struct CellHash {
  size_t operator()(const Cell& c) const {
    size_t h = static_cast<size_t>(c.level);
    for (long v : {c.i, c.j, c.k}) h = h * 1000003u ^ static_cast<size_t>(v);
    return h;
  }
};

std::string where(const Vec3& p) {
  return "(" + format_g(p.x(), 7) + ", " + format_g(p.y(), 7) + ", " + format_g(p.z(), 7) + ")";
}
std::string leaf_name(long n) {
  return "leaf " + std::to_string(n) + " (row " + std::to_string(n + 2) + " of voxels.csv)";
}

class Grid {
 public:
  Grid(const Vec3& origin, double h0) : origin_(origin), h0_(h0) {}
  double side(int level) const { return std::ldexp(h0_, -level); }
  Vec3 center(const Cell& c) const {
    const double s = side(c.level);
    return origin_ + Vec3(c.i + 0.5, c.j + 0.5, c.k + 0.5) * s;
  }

 private:
  Vec3 origin_;
  double h0_;
};

// Cells (all of one level) meeting D, by the exact test of the mesh domain.
std::vector<char> meeting_domain(const Grid& grid, const TriMesh& mesh, const std::vector<Cell>& cells) {
  MatX3d C(cells.size(), 3);
  VecXd S(cells.size());
  for (size_t q = 0; q < cells.size(); ++q) {
    C.row(q) = grid.center(cells[q]).transpose();
    S(q) = grid.side(cells[q].level);
  }
  return cubes_meeting_mesh_domain(mesh.V, mesh.F, C, S);
}

}  // namespace

LeafCoverage prove_leaf_coverage(const CertificateReport& rep, const TriMesh& mesh) {
  LeafCoverage out;
  const std::vector<CertLeaf>& leaves = rep.cert.leaves;
  const double h0 = rep.cert.voxel_side;
  const Vec3 origin = rep.sampling_origin;
  auto fail = [&](const std::string& why) {
    out.proven = false;
    out.reason = "the leaves do not provably cover the certified domain: " + why;
    return out;
  };
  if (!(h0 > 0) || !std::isfinite(h0) || !origin.allFinite())
    return fail("the certificate's grid (voxel_side " + format_g(h0) + ", origin " + where(origin) +
                ") is not usable");
  if (leaves.empty()) return fail("the certificate has no leaves");
  const Grid grid(origin, h0);

  // --- 1. Every leaf is a cell of the grid's octree, up to the rounding of writing it in model units.
  double magnitude = origin.cwiseAbs().maxCoeff() + h0;
  for (const CertLeaf& l : leaves)
    if (l.center.allFinite() && std::isfinite(l.side))
      magnitude = std::max(magnitude, l.center.cwiseAbs().maxCoeff() + std::abs(l.side));
  // The leaves are mapped from the normalized frame (a few roundings of coordinates of this magnitude); 128 u
  // leaves room for them and for the rounding of the cell centers computed here.
  const double tol = 128 * kUnitRoundoff * magnitude;
  std::vector<Cell> cell_of(leaves.size());
  double center_dev = 0, side_dev = 0;
  for (size_t n = 0; n < leaves.size(); ++n) {
    const CertLeaf& l = leaves[n];
    if (!(l.side > 0) || !l.center.allFinite() || !std::isfinite(l.side))
      return fail(leaf_name(n) + " has no finite center and positive side");
    const long level = std::lround(std::log2(h0 / l.side));
    if (level < 0 || level > kMaxLevel)
      return fail(leaf_name(n) + ": side " + format_g(l.side) + " is not the base side " + format_g(h0) +
                  " over a power of 2 up to 2^" + std::to_string(kMaxLevel));
    const double s = grid.side(static_cast<int>(level));
    if (std::abs(l.side - s) > tol)
      return fail(leaf_name(n) + ": side " + format_g(l.side, 17) + " is not the base side over 2^" +
                  std::to_string(level) + " (" + format_g(s, 17) + ")");
    const Vec3 q = (l.center - origin) / s - Vec3::Constant(0.5);
    Cell c{static_cast<int>(level), std::lround(q.x()), std::lround(q.y()), std::lround(q.z())};
    const double dev = (l.center - grid.center(c)).cwiseAbs().maxCoeff();
    if (!(dev <= tol))
      return fail(leaf_name(n) + ": center " + where(l.center) +
                  " is not a cell center of the grid (off by " + format_g(dev) + ")");
    center_dev = std::max(center_dev, dev);
    side_dev = std::max(side_dev, std::abs(l.side - s));
    cell_of[n] = c;
  }
  // The exact cell (center and side in exact arithmetic) lies in the ball around the written center of radius
  // (√3/2)(written side + side_dev) + √3 (center_dev + the rounding of grid.center, ≤ tol).
  out.radius_slack = std::sqrt(3.0) / 2 * side_dev + std::sqrt(3.0) * (center_dev + tol);

  // --- 2. Distinct cells, none inside another.
  std::unordered_map<Cell, long, CellHash> leaf_at;
  leaf_at.reserve(2 * leaves.size());
  for (size_t n = 0; n < leaves.size(); ++n)
    if (!leaf_at.emplace(cell_of[n], static_cast<long>(n)).second)
      return fail(leaf_name(n) + " is the same cell as " + leaf_name(leaf_at[cell_of[n]]));
  std::unordered_set<Cell, CellHash> inner;  // cells that strictly contain a leaf
  std::unordered_set<Cell, CellHash> base;   // depth-0 ancestors: the certificate's base voxels
  for (size_t n = 0; n < leaves.size(); ++n) {
    Cell c = cell_of[n];
    const int base_level = c.level - leaves[n].depth;
    if (leaves[n].depth < 0 || base_level < 0)
      return fail(leaf_name(n) + ": depth " + std::to_string(leaves[n].depth) + " is deeper than its level");
    if (c.level == base_level) base.insert(c);
    while (c.level > 0) {
      c = c.parent();
      if (leaf_at.count(c)) return fail(leaf_name(n) + " lies inside " + leaf_name(leaf_at[c]));
      if (c.level == base_level) base.insert(c);
      if (!inner.insert(c).second) {
        // Its ancestors are in already; base_level may still be below.
        while (c.level > base_level) c = c.parent();
        base.insert(c);
        break;
      }
    }
  }
  out.base_cells = static_cast<long>(base.size());
  const bool mesh_domain = rep.domain == "mesh";
  // The paper's grid: the base voxels are the level-0 cells, and the certificate says how many it certified.
  // (On the mesh domain the sampling refines its own cells toward the cage and a leaf's depth counts from the
  // base grid, so its sampling voxel is not in the table; there step 3 checks D itself.)
  if (!mesh_domain && out.base_cells != rep.cert.voxels)
    return fail("the leaves refine " + std::to_string(out.base_cells) +
                " base voxels, the certificate claims " + std::to_string(rep.cert.voxels));

  // --- 3. Coverage, level by level: a cell that must be covered is a certified leaf, or it contains leaves
  // and each of its children that must be covered is covered in turn.
  if (mesh_domain && mesh.V.rows() == 0) return fail("the mesh domain needs the model's mesh");
  std::vector<Cell> frontier;
  if (mesh_domain) {
    // Every base-grid cell that the mesh's bounding box touches (D lies in that box).
    const Vec3 lo = (mesh.V.colwise().minCoeff().transpose() - origin) / h0;
    const Vec3 hi = (mesh.V.colwise().maxCoeff().transpose() - origin) / h0;
    long first[3], last[3];
    double count = 1;
    for (int a = 0; a < 3; ++a) {
      first[a] = static_cast<long>(std::floor(lo(a))) - 1;
      last[a] = static_cast<long>(std::floor(hi(a))) + 1;
      count *= static_cast<double>(last[a] - first[a] + 1);
    }
    if (count > kMaxCellsPerLevel)
      return fail("the mesh's bounding box spans " + format_g(count, 3) + " base cells (more than " +
                  std::to_string(kMaxCellsPerLevel) + " are not checked)");
    for (long k = first[2]; k <= last[2]; ++k)
      for (long j = first[1]; j <= last[1]; ++j)
        for (long i = first[0]; i <= last[0]; ++i) frontier.push_back({0, i, j, k});
  } else {
    frontier.assign(base.begin(), base.end());
    std::sort(frontier.begin(), frontier.end(), [](const Cell& a, const Cell& b) {
      return std::tie(a.level, a.k, a.j, a.i) < std::tie(b.level, b.k, b.j, b.i);
    });
  }
  long covered_leaves = 0;
  while (!frontier.empty()) {
    if (static_cast<long>(frontier.size()) > kMaxCellsPerLevel)
      return fail("more than " + std::to_string(kMaxCellsPerLevel) + " cells at one level");
    const std::vector<char> needed =
        mesh_domain ? meeting_domain(grid, mesh, frontier) : std::vector<char>(frontier.size(), 1);
    out.cells_checked += static_cast<long>(frontier.size());
    std::vector<Cell> next;
    for (size_t q = 0; q < frontier.size(); ++q) {
      if (!needed[q]) continue;
      const Cell& c = frontier[q];
      const auto it = leaf_at.find(c);
      if (it != leaf_at.end()) {
        if (!leaves[it->second].certified)
          return fail(leaf_name(it->second) + " at " + where(leaves[it->second].center) + " is " +
                      (mesh_domain ? "in the domain" : "part of a base voxel") + " and not certified");
        ++covered_leaves;
        continue;
      }
      if (inner.count(c)) {
        for (int ch = 0; ch < 8; ++ch) next.push_back(c.child(ch));
        continue;
      }
      out.gap = grid.center(c);
      return fail("the cell of side " + format_g(grid.side(c.level)) + " centered at " + where(out.gap) +
                  (mesh_domain ? " meets the domain" : " is part of a base voxel") +
                  " and no leaf covers it");
    }
    frontier.swap(next);
  }
  out.proven = true;
  out.reason =
      mesh_domain
          ? "every grid cell meeting the mesh's points, triangles or solid is covered by certified leaves (" +
                std::to_string(covered_leaves) + " leaves, " + std::to_string(out.cells_checked) +
                " cells checked)"
          : "the " + std::to_string(out.base_cells) + " base voxels are tiled by certified leaves (" +
                std::to_string(covered_leaves) + " leaves)";
  return out;
}

}  // namespace lidef
