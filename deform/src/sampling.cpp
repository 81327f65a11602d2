#include "lidef/sampling.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numeric>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/mesh_io.h"
#include "lidef/normalization.h"

namespace lidef {

double VoxelSampling::radius() const {
  return 0.5 * std::sqrt(3.0) * side;
}

namespace {

// Uniform bucket grid of cage faces answering "is any face closer than R to p?" (the clearance test).
// A face is registered in every cell it can touch (cell center within the cell's half-diagonal of the face),
// so the cells overlapping the box [p − R, p + R] hold every face within R of p.
class FaceGrid {
 public:
  FaceGrid(const Cage& cage, double cell) : cage_(cage), cell_(cell) {
    origin_ = cage.bbox_min - Vec3::Constant(cell);
    for (int a = 0; a < 3; ++a)
      dims_[a] = static_cast<int>(std::ceil((cage.bbox_max(a) - origin_(a)) / cell)) + 1;
    const double reach2 = std::pow(0.5 * std::sqrt(3.0) * cell, 2) * (1 + 1e-9);
    std::vector<std::pair<long, int>> pairs;
    for (int t = 0; t < cage.num_faces(); ++t) {
      const Vec3 a = cage.V.row(cage.F(t, 0)), b = cage.V.row(cage.F(t, 1)), c = cage.V.row(cage.F(t, 2));
      const Vec3 lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
      int l[3], h[3];
      for (int k = 0; k < 3; ++k) {
        l[k] = clampi(static_cast<int>(std::floor((lo(k) - origin_(k)) / cell)), k);
        h[k] = clampi(static_cast<int>(std::floor((hi(k) - origin_(k)) / cell)), k);
      }
      for (int z = l[2]; z <= h[2]; ++z)
        for (int y = l[1]; y <= h[1]; ++y)
          for (int x = l[0]; x <= h[0]; ++x) {
            const Vec3 cc = origin_ + (Vec3(x, y, z) + Vec3::Constant(0.5)) * cell;
            if (point_triangle_dist2(cc, a, b, c) <= reach2) pairs.emplace_back(index(x, y, z), t);
          }
    }
    std::sort(pairs.begin(), pairs.end());
    start_.assign(static_cast<size_t>(dims_[0]) * dims_[1] * dims_[2] + 1, 0);
    for (const auto& p : pairs) ++start_[p.first + 1];
    std::partial_sum(start_.begin(), start_.end(), start_.begin());
    faces_.resize(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) faces_[i] = pairs[i].second;
  }

  bool any_within(const Vec3& p, double R) const {
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
            const int t = faces_[i];
            if (point_triangle_dist2(p, cage_.V.row(cage_.F(t, 0)), cage_.V.row(cage_.F(t, 1)),
                                     cage_.V.row(cage_.F(t, 2))) < R2)
              return true;
          }
        }
    return false;
  }

 private:
  int clampi(int v, int axis) const { return std::min(std::max(v, 0), dims_[axis] - 1); }
  long index(int x, int y, int z) const { return (static_cast<long>(z) * dims_[1] + y) * dims_[0] + x; }

  const Cage& cage_;
  double cell_;
  Vec3 origin_;
  int dims_[3];
  std::vector<int> start_, faces_;
};

inline double cross2(double ax, double ay, double bx, double by) {
  return ax * by - ay * bx;
}

inline double seg_dist2_2d(double px, double py, double ax, double ay, double bx, double by) {
  const double dx = bx - ax, dy = by - ay, dd = dx * dx + dy * dy;
  double t = dd > 0 ? ((px - ax) * dx + (py - ay) * dy) / dd : 0.0;
  t = std::min(1.0, std::max(0.0, t));
  const double ex = ax + t * dx - px, ey = ay + t * dy - py;
  return ex * ex + ey * ey;
}

// The grid for one voxel side h, and the scan that classifies its cells.
//
// Inside test: along each x-scanline (fixed j,k) the winding number of a point is the signed count of the
// surface crossings ahead of it (+1 where the outward normal points along +x, i.e. the ray exits, −1 where it
// enters). That is exact and O(crossings) per line instead of O(#F) per cell. A line passing within `tol_`
// of a projected triangle edge or vertex (e.g. along a box's face diagonal) is ambiguous; its cells fall back
// to the solid-angle winding number (Cage::winding_number, |w − 1| < 1e-6).
// Clearance test: FaceGrid, run only on cells that are inside.
class GridScan {
 public:
  GridScan(const Cage& cage, double h, double safety)
      : cage_(cage), h_(h), R_(safety * 0.5 * std::sqrt(3.0) * h) {
    origin_ = cage.bbox_min;
    const Vec3 ext = cage.bbox_max - cage.bbox_min;
    double d[3], total = 1;
    for (int a = 0; a < 3; ++a) total *= d[a] = std::max(1.0, std::ceil(ext(a) / h));
    if (!(h > 0) || !(total <= 4e9) || std::max({d[0], d[1], d[2]}) > (1 << 20))
      throw InputError(cage.source, "voxel side " + std::to_string(h) + " is too small for this cage (" +
                                        std::to_string(total) + " grid cells, at most 4e9)");
    for (int a = 0; a < 3; ++a) dims_[a] = static_cast<int>(d[a]);
    tol_ = 1e-9 * ext.norm();
    nlines_ = static_cast<long>(dims_[1]) * dims_[2];
    // Scanline -> faces whose projected (y,z) bounding box (grown by tol_) contains the line, as CSR.
    std::vector<std::pair<long, int>> pairs;
    for (int t = 0; t < cage.num_faces(); ++t) {
      double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
      double hi[2] = {-lo[0], -lo[1]};
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 2; ++a) {
          lo[a] = std::min(lo[a], cage.V(cage.F(t, k), a + 1));
          hi[a] = std::max(hi[a], cage.V(cage.F(t, k), a + 1));
        }
      int l[2], u[2];
      for (int a = 0; a < 2; ++a) {
        l[a] = std::max(0, static_cast<int>(std::ceil((lo[a] - tol_ - origin_(a + 1)) / h - 0.5)));
        u[a] = std::min(dims_[a + 1] - 1,
                        static_cast<int>(std::floor((hi[a] + tol_ - origin_(a + 1)) / h - 0.5)));
      }
      for (int k = l[1]; k <= u[1]; ++k)
        for (int j = l[0]; j <= u[0]; ++j) pairs.emplace_back(static_cast<long>(k) * dims_[1] + j, t);
    }
    std::sort(pairs.begin(), pairs.end());
    start_.assign(nlines_ + 1, 0);
    for (const auto& p : pairs) ++start_[p.first + 1];
    std::partial_sum(start_.begin(), start_.end(), start_.begin());
    faces_.resize(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) faces_[i] = pairs[i].second;
    // Cells of at least R keep the clearance query to ≤ 27 cells; the floor bounds the grid's size.
    grid_ = std::make_unique<FaceGrid>(cage, std::max(R_, ext.norm() / 128.0));
  }

  Vec3 center(int i, int j, int k) const { return origin_ + (Vec3(i, j, k) + Vec3::Constant(0.5)) * h_; }

  // Kept cells' i of line (j,k), ascending, appended to `out`; returns their number.
  int scan_line(long line, std::vector<int>* out) const {
    const int j = static_cast<int>(line % dims_[1]), k = static_cast<int>(line / dims_[1]);
    const double yc = origin_(1) + (j + 0.5) * h_, zc = origin_(2) + (k + 0.5) * h_;
    std::vector<std::pair<double, int>> cross;
    bool ambiguous = false;
    for (int s = start_[line]; s < start_[line + 1] && !ambiguous; ++s) {
      const int t = faces_[s];
      const Vec3 a = cage_.V.row(cage_.F(t, 0)), b = cage_.V.row(cage_.F(t, 1)),
                 c = cage_.V.row(cage_.F(t, 2));
      const double tol2 = tol_ * tol_;
      if (seg_dist2_2d(yc, zc, a(1), a(2), b(1), b(2)) < tol2 ||
          seg_dist2_2d(yc, zc, b(1), b(2), c(1), c(2)) < tol2 ||
          seg_dist2_2d(yc, zc, c(1), c(2), a(1), a(2)) < tol2) {
        ambiguous = true;
        break;
      }
      const double area2 = cross2(b(1) - a(1), b(2) - a(2), c(1) - a(1), c(2) - a(2));
      if (area2 == 0) continue;  // edge-on and not near its edges: no crossing
      const double eab = cross2(b(1) - a(1), b(2) - a(2), yc - a(1), zc - a(2));
      const double ebc = cross2(c(1) - b(1), c(2) - b(2), yc - b(1), zc - b(2));
      const double eca = cross2(a(1) - c(1), a(2) - c(2), yc - c(1), zc - c(2));
      const bool inside = (eab > 0 && ebc > 0 && eca > 0) || (eab < 0 && ebc < 0 && eca < 0);
      if (!inside) continue;
      const double x = (ebc * a(0) + eca * b(0) + eab * c(0)) / area2;
      cross.emplace_back(x, area2 > 0 ? 1 : -1);  // n_x > 0: the +x ray leaves the inside here
    }
    int kept = 0;
    if (!ambiguous) {
      std::sort(cross.begin(), cross.end());
      int ahead = 0;
      for (const auto& c : cross) ahead += c.second;
      size_t next = 0;
      for (int i = 0; i < dims_[0]; ++i) {
        const double x = origin_(0) + (i + 0.5) * h_;
        while (next < cross.size() && cross[next].first <= x) ahead -= cross[next++].second;
        if (ahead != 1) continue;
        if (grid_->any_within(Vec3(x, yc, zc), R_)) continue;
        if (out) out->push_back(i);
        ++kept;
      }
    } else {
      for (int i = 0; i < dims_[0]; ++i) {
        const Vec3 p(origin_(0) + (i + 0.5) * h_, yc, zc);
        if (grid_->any_within(p, R_)) continue;
        if (std::abs(cage_.winding_number(p) - 1.0) >= 1e-6) continue;
        if (out) out->push_back(i);
        ++kept;
      }
    }
    return kept;
  }

  long count() const {
    long n = 0;
#pragma omp parallel for schedule(dynamic, 8) reduction(+ : n)
    for (long l = 0; l < nlines_; ++l) n += scan_line(l, nullptr);
    return n;
  }

  VoxelSampling collect() const {
    std::vector<std::vector<int>> kept(nlines_);
#pragma omp parallel for schedule(dynamic, 8)
    for (long l = 0; l < nlines_; ++l) scan_line(l, &kept[l]);
    size_t n = 0;
    for (const auto& v : kept) n += v.size();
    VoxelSampling s;
    s.centers.resize(static_cast<Eigen::Index>(n), 3);
    s.grid_index.resize(static_cast<Eigen::Index>(n), 3);
    Eigen::Index r = 0;
    for (long l = 0; l < nlines_; ++l) {
      const int j = static_cast<int>(l % dims_[1]), k = static_cast<int>(l / dims_[1]);
      for (int i : kept[l]) {
        s.centers.row(r) = center(i, j, k).transpose();
        s.grid_index.row(r) << i, j, k;
        ++r;
      }
    }
    s.side = h_;
    s.origin = origin_;
    return s;
  }

 private:
  const Cage& cage_;
  double h_, R_, tol_ = 0;
  Vec3 origin_;
  int dims_[3];
  long nlines_;
  std::vector<int> start_, faces_;
  std::unique_ptr<FaceGrid> grid_;
};

// Interleaves the low 21 bits of x, y, z (Morton / Z-order code).
std::uint64_t morton3(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  auto spread = [](std::uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  return spread(x) | spread(y) << 1 | spread(z) << 2;
}

// sample_voxels on a cage already in its normalized frame (or any cage: the grid is aligned to its bbox).
VoxelSampling sample_voxels_here(const Cage& cage, const SamplingParams& p) {
  if (!(p.safety > 1.0))
    throw InputError(cage.source, "sampling: safety factor must be > 1 (got " + std::to_string(p.safety) +
                                      "): a voxel ball touching the cage has no finite third-order bound");
  if (!(p.hessian_fraction >= 0 && p.hessian_fraction <= 1))
    throw InputError(cage.source, "sampling: hessian_fraction must lie in [0,1]");
  if (!(cage.volume > 0))
    throw InputError(cage.source, "sampling: cage encloses non-positive volume (inward-oriented faces?)");

  VoxelSampling out;
  if (p.voxel_side > 0) {
    out = GridScan(cage, p.voxel_side, p.safety).collect();
    out.search_iterations = 1;
  } else {
    if (p.target_count < 1) throw InputError(cage.source, "sampling: target_count must be >= 1");
    if (!(p.count_tolerance >= 0)) throw InputError(cage.source, "sampling: count_tolerance must be >= 0");
    // Count search on h. N(h) ≈ V_eff(h) / h³ (V_eff shrinks with h by the clearance layer), so the secant
    // step in log space, h ← h (N/T)^{1/3}, converges in a few evaluations; it is safeguarded by bisection
    // (geometric mean) inside the bracket [h with N > T, h with N < T]. N jumps as the aligned grid shifts
    // with h, so the tolerance (±3% by default) is met by a band of h, not by a root.
    const double T = p.target_count;
    double h = std::cbrt(cage.volume / T);
    double lo = 0, hi = std::numeric_limits<double>::infinity();  // N(lo) > T > N(hi)
    double best_h = h;
    long best_n = -1;
    int it = 0;
    for (; it < std::max(1, p.max_search_iterations); ++it) {
      const long n = GridScan(cage, h, p.safety).count();
      // Closest count wins, but an empty sampling only when nothing else was seen.
      if (best_n <= 0 || (n > 0 && std::abs(n - T) < std::abs(best_n - T))) best_n = n, best_h = h;
      if (std::abs(n - T) <= p.count_tolerance * T) break;
      if (n > T)
        lo = std::max(lo, h);
      else
        hi = std::min(hi, h);
      double next = n > 0 ? h * std::cbrt(n / T) : 0.5 * h;
      if (lo > 0 && std::isfinite(hi) && !(next > lo && next < hi)) next = std::sqrt(lo * hi);
      if (std::isfinite(hi) && lo > 0 && hi / lo < 1 + 1e-12) break;
      h = next;
    }
    out = GridScan(cage, best_h, p.safety).collect();
    out.search_iterations = std::min(it + 1, std::max(1, p.max_search_iterations));
    out.target_met = std::abs(out.size() - T) <= p.count_tolerance * T;
  }
  out.safety = p.safety;
  out.hessian_subset = select_hessian_subset(out, p.hessian_fraction);
  return out;
}

}  // namespace

// The grid is laid out and the voxel side searched in the cage's normalized frame (normalization.h), so a
// translated or scaled copy of a model gets the same voxels up to the transform: the search starts from
// cbrt(volume / samples), and the inside and clearance tests decide cells near the cage by comparisons that
// would otherwise see the ULPs of the model's position and units.
VoxelSampling sample_voxels(const Cage& cage, const SamplingParams& p) {
  const Frame f = Frame::of(cage);
  if (f.is_identity()) return sample_voxels_here(cage, p);
  SamplingParams np = p;
  np.voxel_side = p.voxel_side > 0 ? f.length_to_normalized(p.voxel_side) : 0;
  VoxelSampling out = sample_voxels_here(f.normalized(cage), np);
  // The cells were chosen in the frame; their centers are laid out again in model units exactly as the scan
  // lays them out (origin = the cage's bbox minimum, center = origin + (ijk + ½) h), so that the documented
  // grid relation holds to the bit and closed-cube tests at faces and corners (containing_voxel) behave as
  // for an unnormalized sampling.
  out.side = f.length_from_normalized(out.side);
  out.origin = cage.bbox_min;
  for (int i = 0; i < out.size(); ++i)
    out.centers.row(i) =
        (out.origin + (out.grid_index.row(i).cast<double>().transpose() + Vec3::Constant(0.5)) * out.side)
            .transpose();
  return out;
}

std::vector<int> select_hessian_subset(const VoxelSampling& s, double fraction) {
  if (!(fraction >= 0 && fraction <= 1)) throw InputError("", "hessian subset: fraction must lie in [0,1]");
  const int n = s.size();
  if (n == 0 || fraction == 0) return {};
  const int m = std::max(1, std::min(n, static_cast<int>(std::lround(fraction * n))));
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  if (s.grid_index.rows() == n) {
    std::vector<std::uint64_t> code(n);
    for (int i = 0; i < n; ++i) code[i] = morton3(s.grid_index(i, 0), s.grid_index(i, 1), s.grid_index(i, 2));
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return code[a] < code[b]; });
  }
  // Stratum k = ranks [⌊k n/m⌋, ⌊(k+1) n/m⌋) along the curve (a compact lump of cells); one pick per stratum
  // at a golden-ratio offset. A fixed offset would alias with the curve's power-of-two structure (with
  // stride 20, the picks' lowest x bit is always the same).
  std::vector<int> out(m);
  for (int k = 0; k < m; ++k) {
    const long a = static_cast<long>(k) * n / m, b = static_cast<long>(k + 1) * n / m;
    const double u = std::fmod(0.5 + k * 0.6180339887498949, 1.0);
    out[k] = order[std::min(b - 1, a + static_cast<long>(u * (b - a)))];
  }
  std::sort(out.begin(), out.end());
  return out;
}

VecXi containing_voxel(const VoxelSampling& s, const MatX3d& P) {
  VecXi out = VecXi::Constant(P.rows(), -1);
  if (s.size() == 0 || P.rows() == 0) return out;
  const double h = s.side;
  if (!(h > 0)) throw InputError("", "containing_voxel: sampling has no voxel side");
  // Buckets of side h: a cube containing p has its center within h/2 of p in every coordinate, so it sits in
  // p's bucket or one of the 26 around it.
  const Vec3 o = s.centers.colwise().minCoeff().transpose();
  constexpr long kOff = 1 << 20;
  auto key = [&](long x, long y, long z) {
    return (static_cast<std::uint64_t>(z + kOff) << 42) | (static_cast<std::uint64_t>(y + kOff) << 21) |
           static_cast<std::uint64_t>(x + kOff);
  };
  auto cell = [&](const Vec3& p, int a) { return static_cast<long>(std::floor((p(a) - o(a)) / h)); };
  std::unordered_map<std::uint64_t, std::vector<int>> buckets;
  for (int i = 0; i < s.size(); ++i) {
    const Vec3 c = s.centers.row(i);
    buckets[key(cell(c, 0), cell(c, 1), cell(c, 2))].push_back(i);
  }
  const double half = 0.5 * h;
#pragma omp parallel for schedule(static)
  for (Eigen::Index v = 0; v < P.rows(); ++v) {
    const Vec3 p = P.row(v);
    const long cx = cell(p, 0), cy = cell(p, 1), cz = cell(p, 2);
    if (std::abs(cx) > kOff - 2 || std::abs(cy) > kOff - 2 || std::abs(cz) > kOff - 2) continue;
    int found = -1;
    for (long dz = -1; dz <= 1 && found < 0; ++dz)
      for (long dy = -1; dy <= 1 && found < 0; ++dy)
        for (long dx = -1; dx <= 1 && found < 0; ++dx) {
          auto it = buckets.find(key(cx + dx, cy + dy, cz + dz));
          if (it == buckets.end()) continue;
          for (int i : it->second)
            if ((p - s.centers.row(i).transpose()).cwiseAbs().maxCoeff() <= half) {
              found = i;
              break;
            }
        }
    out(v) = found;
  }
  return out;
}

double mesh_coverage(const VoxelSampling& s, const MatX3d& mesh_V) {
  if (mesh_V.rows() == 0) throw InputError("", "mesh_coverage: mesh has no vertices");
  const VecXi idx = containing_voxel(s, mesh_V);
  return static_cast<double>((idx.array() >= 0).count()) / static_cast<double>(mesh_V.rows());
}

VoxelSampling load_published_samples(const std::string& path, double voxel_side, double hessian_fraction) {
  if (!(voxel_side > 0)) throw InputError(path, "voxel side must be > 0 (model.json samples.voxel_side)");
  VoxelSampling s;
  s.centers = read_points_xyz(path);
  s.side = voxel_side;
  const Vec3 lo = s.centers.colwise().minCoeff().transpose();
  s.origin = lo - Vec3::Constant(0.5 * voxel_side);
  // Grid indices when every point is within 1e-3 h of a node of the grid through the minimum corner.
  s.grid_index.resize(s.size(), 3);
  for (int i = 0; i < s.size(); ++i) {
    const Vec3 g = (s.centers.row(i).transpose() - lo) / voxel_side;
    const Vec3 r = g.array().round();
    if ((g - r).cwiseAbs().maxCoeff() > 1e-3) {
      s.grid_index.resize(0, 3);
      break;
    }
    s.grid_index.row(i) = r.cast<int>().transpose();
  }
  s.hessian_subset = select_hessian_subset(s, hessian_fraction);
  return s;
}

}  // namespace lidef
