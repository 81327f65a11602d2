#include "lidef/sampling.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <numeric>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/internal/mesh_queries.h"
#include "lidef/mesh_io.h"
#include "lidef/normalization.h"

namespace lidef {

double VoxelSampling::radius() const {
  return 0.5 * std::sqrt(3.0) * side;
}

double VoxelSampling::radius_of(int i) const {
  return 0.5 * std::sqrt(3.0) * side_of(i);
}

int VoxelSampling::max_level() const {
  return level.empty() ? 0 : *std::max_element(level.begin(), level.end());
}

namespace {

// The grid for one voxel side h, and the scan that classifies its cells.
//
// Inside test: along each x-scanline (fixed j,k) the winding number of a point is the signed count of the
// surface crossings ahead of it (+1 where the outward normal points along +x, i.e. the ray exits, −1 where it
// enters). That is exact and O(crossings) per line instead of O(#F) per cell. A line passing within `tol_`
// of a projected triangle edge or vertex (e.g. along a box's face diagonal) is ambiguous; its cells fall back
// to the solid-angle winding number (Cage::winding_number, |w − 1| < 1e-6).
// Clearance test: TriangleGrid, run only on cells that are inside.
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
    grid_ = std::make_unique<TriangleGrid>(cage.V, cage.F, std::max(R_, ext.norm() / 128.0));
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
  std::unique_ptr<TriangleGrid> grid_;
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
  check_sampling_params(cage, p);
  VoxelSampling out;
  if (p.voxel_side > 0) {
    out = GridScan(cage, p.voxel_side, p.safety).collect();
    out.search_iterations = 1;
  } else {
    const SideSearch ss = search_voxel_side(p, std::cbrt(cage.volume / p.target_count),
                                            [&](double h) { return GridScan(cage, h, p.safety).count(); });
    out = GridScan(cage, ss.side, p.safety).collect();
    out.search_iterations = ss.iterations;
    out.target_met =
        std::abs(out.size() - static_cast<double>(p.target_count)) <= p.count_tolerance * p.target_count;
  }
  out.safety = p.safety;
  out.hessian_subset = select_hessian_subset(out, p.hessian_fraction);
  return out;
}

}  // namespace

void check_sampling_params(const Cage& cage, const SamplingParams& p) {
  if (!(p.safety > 1.0))
    throw InputError(cage.source, "sampling: safety factor must be > 1 (got " + std::to_string(p.safety) +
                                      "): a voxel ball touching the cage has no finite third-order bound");
  if (!(p.hessian_fraction >= 0 && p.hessian_fraction <= 1))
    throw InputError(cage.source, "sampling: hessian_fraction must lie in [0,1]");
  if (!(cage.volume > 0))
    throw InputError(cage.source, "sampling: cage encloses non-positive volume (inward-oriented faces?)");
  if (!(p.voxel_side > 0)) {
    if (p.target_count < 1) throw InputError(cage.source, "sampling: target_count must be >= 1");
    if (!(p.count_tolerance >= 0)) throw InputError(cage.source, "sampling: count_tolerance must be >= 0");
  }
}

SideSearch search_voxel_side(const SamplingParams& p, double h0, const std::function<long(double)>& count) {
  // Count search on h. N(h) ≈ V_eff(h) / h³ (V_eff shrinks with h by the clearance layer), so the secant
  // step in log space, h ← h (N/T)^{1/3}, converges in a few evaluations; it is safeguarded by bisection
  // (geometric mean) inside the bracket [h with N > T, h with N < T]. N jumps as the aligned grid shifts
  // with h, so the tolerance (±3% by default) is met by a band of h, not by a root.
  const double T = p.target_count;
  double h = h0;
  double lo = 0, hi = std::numeric_limits<double>::infinity();  // N(lo) > T > N(hi)
  double best_h = h;
  long best_n = -1;
  int it = 0;
  for (; it < std::max(1, p.max_search_iterations); ++it) {
    const long n = count(h);
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
  return {best_h, std::min(it + 1, std::max(1, p.max_search_iterations))};
}

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
  if (s.level.empty()) {
    for (int k = 0; k < m; ++k) {
      const long a = static_cast<long>(k) * n / m, b = static_cast<long>(k + 1) * n / m;
      const double u = std::fmod(0.5 + k * 0.6180339887498949, 1.0);
      out[k] = order[std::min(b - 1, a + static_cast<long>(u * (b - a)))];
    }
  } else {
    // Refined leaves (mesh domain): strata of equal volume, not of equal count, so that H is spread evenly in
    // space like the energy's volume weights (a level-k leaf weighs 8^-k). Pick k = the sample whose volume
    // interval along the curve contains (k + u_k) W / m; a sample is taken at most once.
    std::vector<double> cum(n + 1, 0.0);
    for (int r = 0; r < n; ++r) cum[r + 1] = cum[r] + s.weight_of(order[r]);
    const double W = cum[n];
    std::vector<char> taken(n, 0);
    int got = 0;
    for (int k = 0; k < m; ++k) {
      const double u = std::fmod(0.5 + k * 0.6180339887498949, 1.0);
      const double target = (k + u) * W / m;
      long r = std::upper_bound(cum.begin() + 1, cum.end(), target) - (cum.begin() + 1);
      r = std::min<long>(r, n - 1);
      while (r < n - 1 && taken[r]) ++r;
      if (taken[r]) continue;
      taken[r] = 1;
      out[got++] = order[r];
    }
    out.resize(got);
  }
  std::sort(out.begin(), out.end());
  return out;
}

namespace {
constexpr long kBucketOffset = 1 << 20;
std::uint64_t bucket_key(long x, long y, long z) {
  return (static_cast<std::uint64_t>(z + kBucketOffset) << 42) |
         (static_cast<std::uint64_t>(y + kBucketOffset) << 21) |
         static_cast<std::uint64_t>(x + kBucketOffset);
}
}  // namespace

// Buckets of side h: a cube containing p has its center within h/2 of p in every coordinate, so it sits in
// p's bucket or one of the 26 around it (a refined voxel lies in its base cell: within h of p too).
VoxelLocator::VoxelLocator(const VoxelSampling& s) : s_(s) {
  if (s.size() == 0) return;
  if (!(s.side > 0)) throw InputError("", "containing_voxel: sampling has no voxel side");
  origin_ = s.centers.colwise().minCoeff().transpose();
  for (int i = 0; i < s.size(); ++i) {
    const Vec3 c = s.centers.row(i);
    const Vec3 k = ((c - origin_) / s.side).array().floor();
    buckets_[bucket_key(static_cast<long>(k(0)), static_cast<long>(k(1)), static_cast<long>(k(2)))].push_back(
        i);
  }
}

VecXi VoxelLocator::find(const MatX3d& P) const {
  VecXi out = VecXi::Constant(P.rows(), -1);
  if (s_.size() == 0 || P.rows() == 0) return out;
  const double h = s_.side;
  auto cell = [&](const Vec3& p, int a) { return static_cast<long>(std::floor((p(a) - origin_(a)) / h)); };
#pragma omp parallel for schedule(static) if (P.rows() > 64)
  for (Eigen::Index v = 0; v < P.rows(); ++v) {
    const Vec3 p = P.row(v);
    const long cx = cell(p, 0), cy = cell(p, 1), cz = cell(p, 2);
    if (std::abs(cx) > kBucketOffset - 2 || std::abs(cy) > kBucketOffset - 2 ||
        std::abs(cz) > kBucketOffset - 2)
      continue;
    int found = -1;
    for (long dz = -1; dz <= 1 && found < 0; ++dz)
      for (long dy = -1; dy <= 1 && found < 0; ++dy)
        for (long dx = -1; dx <= 1 && found < 0; ++dx) {
          auto it = buckets_.find(bucket_key(cx + dx, cy + dy, cz + dz));
          if (it == buckets_.end()) continue;
          for (int i : it->second)
            if ((p - s_.centers.row(i).transpose()).cwiseAbs().maxCoeff() <= 0.5 * s_.side_of(i)) {
              found = i;
              break;
            }
        }
    out(v) = found;
  }
  return out;
}

VecXi containing_voxel(const VoxelSampling& s, const MatX3d& P) {
  if (s.size() == 0 || P.rows() == 0) return VecXi::Constant(P.rows(), -1);
  return VoxelLocator(s).find(P);
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
