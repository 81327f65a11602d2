#include "lidef/domain_sampling.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "lidef/errors.h"
#include "lidef/internal/mesh_queries.h"
#include "lidef/normalization.h"

namespace lidef {

namespace {

// Union-find over vertices (path halving).
int find_root(std::vector<int>& parent, int v) {
  while (parent[v] != v) v = parent[v] = parent[parent[v]];
  return v;
}

}  // namespace

MeshDomain mesh_domain_of(const MatX3d& V, const MatX3i& F) {
  const int nv = static_cast<int>(V.rows()), nf = static_cast<int>(F.rows());
  std::vector<int> parent(nv);
  for (int v = 0; v < nv; ++v) parent[v] = v;
  std::vector<char> used(nv, 0);
  for (int t = 0; t < nf; ++t)
    for (int k = 0; k < 3; ++k) {
      used[F(t, k)] = 1;
      const int a = find_root(parent, F(t, k)), b = find_root(parent, F(t, (k + 1) % 3));
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  // Per component (keyed by its root vertex): the signed count of every undirected edge's directions.
  std::map<int, std::map<std::pair<int, int>, int>> balance;
  for (int t = 0; t < nf; ++t) {
    auto& b = balance[find_root(parent, F(t, 0))];
    for (int k = 0; k < 3; ++k) {
      const int u = F(t, k), w = F(t, (k + 1) % 3);
      b[{std::min(u, w), std::max(u, w)}] += u < w ? 1 : -1;
    }
  }
  std::map<int, bool> closed;
  MeshDomain d;
  for (const auto& [root, edges] : balance) {
    bool c = true;
    for (const auto& kv : edges) c = c && kv.second == 0;
    closed[root] = c;
    (c ? d.closed_components : d.open_components) += 1;
  }
  for (int v = 0; v < nv; ++v) d.isolated_points += !used[v];
  d.elements.resize(nf + d.isolated_points, 3);
  d.elements.topRows(nf) = F;
  int e = nf;
  for (int v = 0; v < nv; ++v)
    if (!used[v]) d.elements.row(e++) = Eigen::RowVector3i(v, v, v);
  int ns = 0;
  for (int t = 0; t < nf; ++t) ns += closed[find_root(parent, F(t, 0))];
  d.solid.resize(ns, 3);
  ns = 0;
  for (int t = 0; t < nf; ++t)
    if (closed[find_root(parent, F(t, 0))]) d.solid.row(ns++) = F.row(t);
  return d;
}

std::string MeshDomain::description() const {
  if (open_components == 0 && isolated_points == 0) return "mesh and its solid";
  if (closed_components == 0) return "points and surface, no solid";
  return "points, surface and the solid of " + std::to_string(closed_components) + " closed components";
}

std::string MeshDomain::definition() const {
  if (open_components == 0 && isolated_points == 0)
    return "every point of the mesh triangles and of the solid they bound (winding number >= 1/2)";
  std::string s = "every input point (" + std::to_string(isolated_points) +
                  " not on a triangle) and every point of the mesh triangles";
  if (closed_components == 0) return s + "; no solid (no closed component)";
  return s + ", and the solid bounded by the " + std::to_string(closed_components) +
         " closed components (their winding number >= 1/2); the " + std::to_string(open_components) +
         " open components bound no solid";
}

namespace {

// One leaf of a base cell's refinement.
struct Leaf {
  Vec3 c;
  int level;
  bool clear;
};

// The domain D and the cage, ready for cell queries (everything in the cage's normalized frame).
class DomainScan {
 public:
  DomainScan(const Cage& cage, const MatX3d& mesh_V, const MatX3i& mesh_F, const SamplingParams& p)
      : cage_(cage),
        V_(mesh_V),
        dom_(mesh_domain_of(mesh_V, mesh_F)),
        F_(dom_.elements),
        p_(p),
        mesh_wn_(V_, dom_.solid),
        cage_wn_(cage.V, cage.F),
        cage_grid_(cage.V, cage.F, (cage.bbox_max - cage.bbox_min).norm() / 128.0) {}

  // The base grid of side h: cells (i,j,k) over the cage's bounding box (as GridScan lays them out).
  void set_side(double h) {
    h_ = h;
    const Vec3 ext = cage_.bbox_max - cage_.bbox_min;
    double total = 1;
    for (int a = 0; a < 3; ++a) total *= dims_[a] = static_cast<int>(std::max(1.0, std::ceil(ext(a) / h)));
    if (!(h > 0) || !(total <= 4e9))
      throw InputError(cage_.source, "voxel side " + std::to_string(h) + " is too small for this cage");
    mesh_grid_ = std::make_unique<TriangleGrid>(V_, F_, h);
  }
  long num_cells() const { return static_cast<long>(dims_[0]) * dims_[1] * dims_[2]; }
  Vec3 center(long cell) const {
    const long i = cell % dims_[0], j = (cell / dims_[0]) % dims_[1],
               k = cell / (static_cast<long>(dims_[0]) * dims_[1]);
    return cage_.bbox_min + (Vec3(i, j, k) + Vec3::Constant(0.5)) * h_;
  }
  Eigen::RowVector3i index(long cell) const {
    return {static_cast<int>(cell % dims_[0]), static_cast<int>((cell / dims_[0]) % dims_[1]),
            static_cast<int>(cell / (static_cast<long>(dims_[0]) * dims_[1]))};
  }

  // The leaves of base cell `cell` (empty when it does not meet D), depth-first, children in octant order.
  void leaves(long cell, std::vector<Leaf>* out) const {
    out->clear();
    const Vec3 c = center(cell);
    std::vector<int> tris;
    mesh_grid_->candidates(c - Vec3::Constant(0.5 * h_), c + Vec3::Constant(0.5 * h_), &tris);
    std::vector<int> meeting;
    crossing(c, 0.5 * h_, tris, &meeting);
    if (meeting.empty() && !inside(c)) return;
    refine(c, 0, meeting, out);
  }

 private:
  bool inside(const Vec3& p) const { return mesh_wn_.at(p) >= 0.5; }
  // The elements of `from` that meet the closed cube c ± half.
  void crossing(const Vec3& c, double half, const std::vector<int>& from, std::vector<int>* out) const {
    out->clear();
    for (int t : from)
      if (triangle_box_overlap(c, half, V_.row(F_(t, 0)), V_.row(F_(t, 1)), V_.row(F_(t, 2))))
        out->push_back(t);
  }
  // Ball B(c, r) clear of the cage by the sampler's margin: distance > safety·r and winding number 1 (an
  // integer for the closed cage, counted exactly by WindingNumber).
  bool clear(const Vec3& c, int level) const {
    const double r = 0.5 * std::sqrt(3.0) * std::ldexp(h_, -level);
    return !cage_grid_.any_within(c, p_.safety * r) && std::abs(cage_wn_.at(c) - 1.0) < 1e-6;
  }
  // Depth-first: a cell meeting D (with the triangles that cross it) becomes a leaf when clear, at the
  // maximum level, or when the cell's leaf budget is spent; else its children that meet D are refined. A
  // child that no triangle crosses lies on one side of the mesh: inside when its parent had no crossing
  // triangle either (the parent met D), else decided at its center.
  void refine(const Vec3& c, int level, const std::vector<int>& tris, std::vector<Leaf>* out) const {
    const bool ok = clear(c, level);
    if (ok || level >= p_.max_domain_level || static_cast<long>(out->size()) >= p_.max_leaves_per_cell) {
      out->push_back({c, level, ok});
      return;
    }
    const double q = 0.25 * std::ldexp(h_, -level);
    std::vector<int> sub;
    for (int k = 0; k < 8; ++k) {
      const Vec3 cc = c + Vec3(k & 1 ? q : -q, k & 2 ? q : -q, k & 4 ? q : -q);
      crossing(cc, q, tris, &sub);
      if (sub.empty() && !tris.empty() && !inside(cc)) continue;
      refine(cc, level + 1, sub, out);
    }
  }

  const Cage& cage_;
  const MatX3d& V_;
  const MeshDomain dom_;
  const MatX3i& F_;  // dom_.elements: triangles and isolated points
  const SamplingParams& p_;
  WindingNumber mesh_wn_, cage_wn_;
  TriangleGrid cage_grid_;
  std::unique_ptr<TriangleGrid> mesh_grid_;
  double h_ = 0;
  int dims_[3] = {1, 1, 1};
};

// Leaves of every base cell, in grid order (cells in parallel, concatenated in order: deterministic).
std::vector<std::vector<Leaf>> scan(const DomainScan& ds) {
  const long n = ds.num_cells();
  std::vector<std::vector<Leaf>> out(n);
#pragma omp parallel for schedule(dynamic, 64)
  for (long cell = 0; cell < n; ++cell) ds.leaves(cell, &out[cell]);
  return out;
}

long leaf_count(const std::vector<std::vector<Leaf>>& cells) {
  long n = 0;
  for (const auto& v : cells) n += static_cast<long>(v.size());
  return n;
}

VoxelSampling collect(const DomainScan& ds, const std::vector<std::vector<Leaf>>& cells, double h) {
  VoxelSampling s;
  const long n = leaf_count(cells);
  s.centers.resize(n, 3);
  s.grid_index.resize(n, 3);
  s.level.resize(n);
  long r = 0;
  for (long cell = 0; cell < static_cast<long>(cells.size()); ++cell)
    for (const Leaf& l : cells[cell]) {
      s.centers.row(r) = l.c.transpose();
      s.grid_index.row(r) = ds.index(cell);
      s.level[r] = l.level;
      s.uncleared += !l.clear;
      ++r;
    }
  s.side = h;
  s.domain = "mesh";
  return s;
}

}  // namespace

VoxelSampling sample_domain(const Cage& cage, const MatX3d& mesh_V, const MatX3i& mesh_F,
                            const SamplingParams& p) {
  check_sampling_params(cage, p);
  if (mesh_V.rows() == 0) throw InputError(cage.source, "mesh domain: the mesh has no vertices");
  if (p.max_domain_level < 0 || p.max_domain_level > 30)
    throw InputError(cage.source, "mesh domain: max_domain_level must lie in [0, 30]");
  if (mesh_F.rows() > 0 && (mesh_F.minCoeff() < 0 || mesh_F.maxCoeff() >= mesh_V.rows()))
    throw InputError(cage.source, "mesh domain: a mesh face index is out of range");
  // Laid out in the normalized frame (as sample_voxels), returned in model units.
  const Frame f = Frame::of(cage);
  const Cage ncage = f.normalized(cage);
  const MatX3d nV = f.points_to_normalized(mesh_V);
  DomainScan ds(ncage, nV, mesh_F, p);
  VoxelSampling out;
  if (p.voxel_side > 0) {
    const double h = f.length_to_normalized(p.voxel_side);
    ds.set_side(h);
    out = collect(ds, scan(ds), h);
    out.search_iterations = 1;
  } else {
    // Start from the side at which the mesh's bounding box would hold the target: the count search
    // (search_voxel_side) corrects for the part of the box outside D and for the refinement. Sides above
    // 4 h0 are not considered (they count as empty, so the search turns back): the leaf count is not
    // monotonic there — a few huge base cells refined deep toward the cage can have fewer leaves than a grid,
    // and a model whose surface runs close to its cage needs a minimum number of small leaves along it
    // whatever the base side, so a target below that minimum would otherwise send the search to one cell.
    // At most 12 evaluations (each is a full scan).
    const Vec3 ext = nV.colwise().maxCoeff() - nV.colwise().minCoeff();
    const double box = std::max(ext.prod(), 1e-3 * std::pow(ext.maxCoeff(), 3));
    const double h0 = std::cbrt(box / p.target_count), h_max = 4 * h0;
    // Below h_min the mesh's bounding box holds 64 x the target in cells. A solid or a surface has far more
    // than the target leaves there, so the search never goes below it; a point cloud with fewer points than
    // the target has at most 8 leaves per point whatever the side, so its count stops growing and the search
    // would shrink the side without end — below h_min it is told "too many" and turns back, ending at the
    // cloud's largest count.
    const double h_min = std::cbrt(box / (64.0 * p.target_count));
    SamplingParams sp = p;
    sp.max_search_iterations = std::min(p.max_search_iterations, 12);
    const SideSearch ss = search_voxel_side(sp, h0, [&](double h) -> long {
      if (h > h_max) return 0;
      if (h < h_min) return std::numeric_limits<long>::max() / 2;
      ds.set_side(h);
      return leaf_count(scan(ds));
    });
    ds.set_side(ss.side);
    out = collect(ds, scan(ds), ss.side);
    out.search_iterations = ss.iterations;
    out.target_met =
        std::abs(out.size() - static_cast<double>(p.target_count)) <= p.count_tolerance * p.target_count;
  }
  out.safety = p.safety;
  out.hessian_subset = select_hessian_subset(out, p.hessian_fraction);
  out = f.from_normalized(out);
  out.origin = cage.bbox_min;  // of the base grid
  return out;
}

std::vector<char> cubes_meeting_mesh_domain(const MatX3d& V, const MatX3i& mesh_F, const MatX3d& centers,
                                            const VecXd& sides) {
  std::vector<char> out(centers.rows(), 0);
  if (centers.rows() == 0 || V.rows() == 0) return out;
  const MeshDomain dom = mesh_domain_of(V, mesh_F);
  const MatX3i& F = dom.elements;
  const Vec3 ext = V.colwise().maxCoeff() - V.colwise().minCoeff();
  const TriangleGrid grid(V, F, std::max(ext.maxCoeff() / 64, 1e-300));
  const WindingNumber wn(V, dom.solid);
#pragma omp parallel for schedule(dynamic, 64)
  for (Eigen::Index i = 0; i < centers.rows(); ++i) {
    const Vec3 c = centers.row(i);
    const double half = 0.5 * sides(i);
    std::vector<int> tris;
    grid.candidates(c - Vec3::Constant(half), c + Vec3::Constant(half), &tris);
    bool meets = false;
    for (int t : tris)
      if (triangle_box_overlap(c, half, V.row(F(t, 0)), V.row(F(t, 1)), V.row(F(t, 2)))) {
        meets = true;
        break;
      }
    out[i] = meets || wn.at(c) >= 0.5;
  }
  return out;
}

VoxelSampling sample_for_domain(const std::string& domain, const Cage& cage, const MatX3d& mesh_V,
                                const MatX3i& mesh_F, const SamplingParams& params) {
  if (domain == "mesh") return sample_domain(cage, mesh_V, mesh_F, params);
  if (domain == "voxels") return sample_voxels(cage, params);
  throw InputError(cage.source, "unknown domain '" + domain + "' (expected mesh or voxels)");
}

}  // namespace lidef
