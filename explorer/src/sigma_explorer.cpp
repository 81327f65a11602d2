#include "lidef/explorer/sigma_explorer.h"

#include <omp.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"
#include "lidef/self_intersections.h"
#include "lidef/signed_svd.h"

namespace lidef {
namespace {

// --- Deterministic random numbers (own transforms, so results do not depend on the standard library).
std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : s_(splitmix64(seed)) {}
  std::uint64_t next() { return s_ = splitmix64(s_); }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double normal() {                                                           // Box-Muller
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2 * M_PI * u2);
  }
  Vec3 in_ball(const Ball& b) {
    for (;;) {
      const Vec3 v(2 * uniform() - 1, 2 * uniform() - 1, 2 * uniform() - 1);
      if (v.squaredNorm() <= 1) return b.center + b.radius * v;
    }
  }
  Mat3 rotation() {
    Eigen::Quaterniond q(normal(), normal(), normal(), normal());
    q.normalize();
    return q.toRotationMatrix();
  }

 private:
  std::uint64_t s_;
};

// dJ[k](a,b) = ∂²f_a/∂x_b∂x_k and d2J[k][l](a,b) = ∂³f_a/∂x_b∂x_k∂x_l from a jet.
void jacobian_derivatives(const PolyJet& j, std::array<Mat3, 3>& dJ,
                          std::array<std::array<Mat3, 3>, 3>& d2J) {
  for (int k = 0; k < 3; ++k)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        dJ[k](a, b) = j.H[a](b, k);
        for (int l = 0; l < 3; ++l) d2J[k][l](a, b) = j.T[a][b](k, l);
      }
}

// Fibonacci points on the unit sphere.
std::vector<Vec3> fibonacci_sphere(int n) {
  std::vector<Vec3> p(n);
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1 - (2 * i + 1.0) / n, r = std::sqrt(std::max(0.0, 1 - z * z));
    p[i] = Vec3(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return p;
}

struct DescentResult {
  Vec3 x;
  double sigma3;
  double grad_norm;
  double sigma1;
};

// Projected trust-region Newton descent of σ3 from x0 (see find_sigma3_minima).
DescentResult descend(const ExplorerMap& map, const Ball& ball, Vec3 x, int max_iterations, double tol) {
  SigmaDerivatives d = map_sigma_derivatives(map, x, true);
  double delta = 0.1 * ball.radius;
  for (int it = 0; it < max_iterations; ++it) {
    const Vec3 g = d.grad.row(2).transpose();
    const bool interior = (x - ball.center).norm() < ball.radius * (1 - 1e-9);
    if (g.norm() <= tol * (1 + std::abs(d.sigma(0))) && interior) break;
    Eigen::SelfAdjointEigenSolver<Mat3> es(d.hess[2]);
    Vec3 p;
    if (es.info() == Eigen::Success && es.eigenvalues()(0) > 0)
      p = -(es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() *
            es.eigenvectors().transpose()) *
          g;
    else
      p = -g.normalized() * delta;
    if (!p.allFinite()) break;
    if (p.norm() > delta) p *= delta / p.norm();
    Vec3 xn = x + p;
    if ((xn - ball.center).norm() > ball.radius)
      xn = ball.center + ball.radius * (xn - ball.center).normalized();
    const SigmaDerivatives dn = map_sigma_derivatives(map, xn, true);
    if (dn.sigma(2) <= d.sigma(2) + 4e-16 * std::abs(d.sigma(2))) {
      const bool full = p.norm() >= 0.99 * delta;
      x = xn;
      d = dn;
      if (full) delta = std::min(2 * delta, ball.radius);
    } else {
      delta *= 0.25;
      if (delta < 1e-13 * ball.radius) break;
    }
  }
  return {x, d.sigma(2), d.grad.row(2).norm(), d.sigma(0)};
}

double region_min_dist(const Vec3& q, double half, const Vec3& c) {
  return ((q - c).cwiseAbs() - Vec3::Constant(half)).cwiseMax(0.0).norm();
}
double region_max_dist(const Vec3& q, double half, const Vec3& c) {
  return ((q - c).cwiseAbs() + Vec3::Constant(half)).norm();
}

std::string fmt(double x) {
  return format_double(x);
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
std::string PolynomialExplorerMap::description() const {
  return "harmonic polynomial map of degree " + std::to_string(map_.degree());
}

CageExplorerMap::CageExplorerMap(const Cage& cage, const MatX3d& y, std::string name, double fd_step)
    : cage_(cage), y_(y), basis_(cage_), name_(std::move(name)), h_(fd_step) {
  if (y.rows() != cage.num_coeffs()) throw InputError(name_, "coefficient rows do not match the cage");
}

Vec3 CageExplorerMap::value(const Vec3& p) const {
  return basis_.map_jet(y_, p, 0).f;
}

Mat3 CageExplorerMap::jacobian(const Vec3& p) const {
  return basis_.map_jet(y_, p, 1).J;
}

PolyJet CageExplorerMap::jet(const Vec3& p) const {
  const MapJet m = basis_.map_jet(y_, p, 2);
  PolyJet j;
  j.f = m.f;
  j.J = m.J;
  j.H = m.H;
  // T[a][b](c,d) = ∂_d H[a](b,c): central differences of the closed-form Hessian along each axis d.
  for (int d = 0; d < 3; ++d) {
    Vec3 e = Vec3::Zero();
    e(d) = h_;
    const MapJet mp = basis_.map_jet(y_, p + e, 2), mm = basis_.map_jet(y_, p - e, 2);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int c = 0; c < 3; ++c) j.T[a][b](c, d) = (mp.H[a](b, c) - mm.H[a](b, c)) / (2 * h_);
  }
  // Symmetrize over (b, c, d): the exact tensor is symmetric; this averages the difference errors.
  for (int a = 0; a < 3; ++a) {
    std::array<std::array<std::array<double, 3>, 3>, 3> s{};
    for (int b = 0; b < 3; ++b)
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d)
          s[b][c][d] = (j.T[a][b](c, d) + j.T[a][b](d, c) + j.T[a][c](b, d) + j.T[a][c](d, b) +
                        j.T[a][d](b, c) + j.T[a][d](c, b)) /
                       6;
    for (int b = 0; b < 3; ++b)
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d) j.T[a][b](c, d) = s[b][c][d];
  }
  return j;
}

SigmaDerivatives map_sigma_derivatives(const ExplorerMap& map, const Vec3& p, bool with_hessian) {
  const PolyJet j = map.jet(p);
  std::array<Mat3, 3> dJ;
  std::array<std::array<Mat3, 3>, 3> d2J;
  jacobian_derivatives(j, dJ, d2J);
  return sigma_derivatives(j.J, dJ, with_hessian ? &d2J : nullptr);
}

// ---------------------------------------------------------------------------------------------------------------
std::vector<Sigma3Minimum> find_sigma3_minima(const ExplorerMap& map, const Ball& ball,
                                              const MinimaSearchParams& params) {
  if (params.starts < 1) throw InputError("", "the minima search needs at least one start");
  Rng rng(params.seed);
  std::vector<Vec3> starts{ball.center};
  while (static_cast<int>(starts.size()) < params.starts) starts.push_back(rng.in_ball(ball));
  std::vector<DescentResult> res(starts.size());
#pragma omp parallel for schedule(dynamic) if (!omp_in_parallel())
  for (int s = 0; s < static_cast<int>(starts.size()); ++s)
    res[s] = descend(map, ball, starts[s], params.max_iterations, params.gradient_tolerance);

  // Converged interior points, merged when closer than 1e-6 R (keeping the lowest σ3).
  std::vector<DescentResult> good;
  for (const DescentResult& r : res)
    if ((r.x - ball.center).norm() < ball.radius * (1 - params.interior_margin) &&
        r.grad_norm <= params.gradient_tolerance * (1 + std::abs(r.sigma1)))
      good.push_back(r);
  std::stable_sort(good.begin(), good.end(),
                   [](const DescentResult& a, const DescentResult& b) { return a.sigma3 < b.sigma3; });
  std::vector<Sigma3Minimum> out;
  const std::vector<Vec3> sphere = fibonacci_sphere(params.sphere_points);
  for (const DescentResult& r : good) {
    bool merged = false;
    for (Sigma3Minimum& m : out)
      if ((m.position - r.x).norm() < 1e-6 * ball.radius) {
        ++m.starts;
        merged = true;
        break;
      }
    if (merged) continue;
    Sigma3Minimum m;
    m.position = r.x;
    m.starts = 1;
    const SigmaDerivatives d = map_sigma_derivatives(map, r.x, true);
    m.sigma3 = d.sigma(2);
    m.gradient_norm = d.grad.row(2).norm();
    m.gap = d.gap(2);
    Eigen::SelfAdjointEigenSolver<Mat3> es(d.hess[2], Eigen::EigenvaluesOnly);
    m.hessian_eigenvalues = es.eigenvalues();
    m.sphere_radius = std::min(0.01 * ball.radius, 0.5 * (ball.radius - (r.x - ball.center).norm()));
    m.sphere_min_sigma3 = std::numeric_limits<double>::infinity();
    for (const Vec3& u : sphere) {
      const Vec3 s = signed_singular_values(map.jacobian(r.x + m.sphere_radius * u));
      m.sphere_min_sigma3 = std::min(m.sphere_min_sigma3, s(2));
    }
    // Flat directions (a constant σ3, e.g. an affine map) are not strict minima: demand curvature and a rise
    // that clearly exceed rounding.
    const double scale = 1 + std::abs(d.sigma(0));
    m.strict = m.hessian_eigenvalues(0) > 1e-8 * scale && m.sphere_min_sigma3 > m.sigma3 + 1e-12 * scale;
    out.push_back(m);
  }
  return out;
}

std::pair<double, Vec3> sampled_sphere_min_sigma3(const ExplorerMap& map, const Ball& ball,
                                                  int subdivisions) {
  const TriMesh s = icosphere(ball.radius, subdivisions);
  double best = std::numeric_limits<double>::infinity();
  Vec3 where = ball.center;
  for (int i = 0; i < s.V.rows(); ++i) {
    const Vec3 p = ball.center + s.V.row(i).transpose();
    const double v = signed_singular_values(map.jacobian(p))(2);
    if (v < best) {
      best = v;
      where = p;
    }
  }
  return {best, where};
}

// ---------------------------------------------------------------------------------------------------------------
double cell_lipschitz_bound(const PolyJet& jet_at_center, double fourth_norm, double r) {
  return jet_at_center.hessian_norm() + r * (jet_at_center.third_norm() + r * fourth_norm);
}

BallCertificate certify_sigma3_on_ball(const HarmonicPolynomialMap& map, const Ball& ball,
                                       const BallCertifyParams& params) {
  if (params.base_cells < 1 || params.max_depth < 0 || params.max_cells < 1)
    throw InputError("", "certify: base_cells ≥ 1, max_depth ≥ 0 and max_cells ≥ 1 are required");
  if (map.degree() > kMaxHarmonicDegree)
    throw Error("certify: degree above 4 has no constant fourth derivative");
  const int n = params.base_cells;
  const double h0 = 2 * ball.radius / n;
  auto meets = [&](const Vec3& q, double half) {
    const double dmin = region_min_dist(q, half, ball.center);
    if (dmin > ball.radius) return false;
    return !params.sphere_only || region_max_dist(q, half, ball.center) >= ball.radius;
  };
  struct Cell {
    Vec3 q;
    int depth;
  };
  std::vector<Vec3> base;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Vec3 q = ball.center - Vec3::Constant(ball.radius) + h0 * Vec3(i + 0.5, j + 0.5, k + 0.5);
        if (meets(q, h0 / 2)) base.push_back(q);
      }
  const long budget = std::max<long>(1, params.max_cells / std::max<long>(1, base.size()));
  const double F = map.fourth_norm(), S = map.abs_coefficient_sum();
  struct Result {
    long evaluated = 0, leaves = 0;
    int depth = 0;
    double min_lb = INFINITY, min_sigma = INFINITY, max_L = 0, max_J = 0;
    Vec3 worst = Vec3::Zero();
    std::string fail;
  };
  std::vector<Result> res(base.size());
#pragma omp parallel for schedule(dynamic)
  for (int b = 0; b < static_cast<int>(base.size()); ++b) {
    Result& r = res[b];
    std::vector<Cell> stack{{base[b], 0}};
    while (!stack.empty() && r.fail.empty()) {
      const Cell c = stack.back();
      stack.pop_back();
      if (++r.evaluated > budget) {
        r.fail = "cell budget exhausted";
        break;
      }
      const double h = h0 / std::ldexp(1.0, c.depth), rad = std::sqrt(3.0) / 2 * h;
      const PolyJet jt = map.jet(c.q, 3);
      const double s3 = signed_singular_values(jt.J)(2);
      const double L = cell_lipschitz_bound(jt, F, rad);
      const double rho = std::max(1.0, (c.q.cwiseAbs() + Vec3::Constant(h / 2)).maxCoeff());
      const double tau = 1e-9 * (std::abs(s3) + rad * L + 24 * std::pow(rho, 4) * S);
      const double lb = s3 - rad * L - tau;
      r.depth = std::max(r.depth, c.depth);
      r.min_sigma = std::min(r.min_sigma, s3);
      if (!(s3 > params.threshold)) {
        r.fail = "sigma3 = " + fmt(s3) + " <= " + fmt(params.threshold) + " at (" + fmt(c.q.x()) + ", " +
                 fmt(c.q.y()) + ", " + fmt(c.q.z()) + ")";
        r.min_lb = std::min(r.min_lb, lb);
        r.worst = c.q;
        break;
      }
      if (lb > params.threshold) {
        ++r.leaves;
        r.max_L = std::max(r.max_L, L);
        r.max_J = std::max(r.max_J, jt.J.norm() + rad * L);
        if (lb < r.min_lb) {
          r.min_lb = lb;
          r.worst = c.q;
        }
        continue;
      }
      if (c.depth >= params.max_depth) {
        r.fail = "a cell still fails at depth " + std::to_string(params.max_depth) + " near (" +
                 fmt(c.q.x()) + ", " + fmt(c.q.y()) + ", " + fmt(c.q.z()) + ")";
        r.min_lb = std::min(r.min_lb, lb);
        r.worst = c.q;
        break;
      }
      // Children in reverse order so the stack visits them in index order (deterministic).
      for (int o = 7; o >= 0; --o) {
        const Vec3 q = c.q + (h / 4) * Vec3(o & 1 ? 1 : -1, o & 2 ? 1 : -1, o & 4 ? 1 : -1);
        if (meets(q, h / 4)) stack.push_back({q, c.depth + 1});
      }
    }
  }
  BallCertificate out;
  out.threshold = params.threshold;
  out.sphere_only = params.sphere_only;
  out.min_lower_bound = INFINITY;
  out.min_sigma3_center = INFINITY;
  for (const Result& r : res) {
    out.cells_evaluated += r.evaluated;
    out.leaves += r.leaves;
    out.max_depth_used = std::max(out.max_depth_used, r.depth);
    if (r.min_lb < out.min_lower_bound) {
      out.min_lower_bound = r.min_lb;
      out.worst_center = r.worst;
    }
    out.min_sigma3_center = std::min(out.min_sigma3_center, r.min_sigma);
    out.max_hessian_bound = std::max(out.max_hessian_bound, r.max_L);
    out.max_jacobian_bound = std::max(out.max_jacobian_bound, r.max_J);
    if (out.reason.empty() && !r.fail.empty()) out.reason = r.fail;
  }
  if (base.empty()) out.reason = "no cell meets the region";
  out.certified = out.reason.empty();
  return out;
}

BallCertificate certify_cage_map_on_ball(const CageExplorerMap& map, const Ball& ball, int max_depth,
                                         long max_cells) {
  BallCertificate out;
  const Cage& cage = map.cage();
  const double clearance = cage.distance(ball.center) - ball.radius;
  if (!(clearance > 0) || std::abs(cage.winding_number(ball.center) - 1) > 1e-6) {
    out.reason = "the domain ball is not strictly inside the cage";
    return out;
  }
  // A cube meeting the ball has its center within R + r of the ball's center, so its ball reaches R + 2r:
  // r ≤ clearance / 4 keeps it at least clearance / 2 away from the cage.
  const int n = static_cast<int>(std::ceil(2 * ball.radius / (clearance / (2 * std::sqrt(3.0)))));
  if (static_cast<double>(n) * n * n * 0.6 > static_cast<double>(max_cells)) {
    out.reason = "the domain ball is too close to the cage (clearance " + fmt(clearance) + ") for " +
                 std::to_string(max_cells) + " cells";
    return out;
  }
  VoxelSampling vs;
  vs.side = 2 * ball.radius / n;
  vs.origin = ball.center - Vec3::Constant(ball.radius);
  std::vector<Vec3> centers;
  std::vector<Eigen::Vector3i> idx;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Vec3 q = vs.origin + vs.side * Vec3(i + 0.5, j + 0.5, k + 0.5);
        if (region_min_dist(q, vs.side / 2, ball.center) <= ball.radius) {
          centers.push_back(q);
          idx.emplace_back(i, j, k);
        }
      }
  vs.centers.resize(static_cast<long>(centers.size()), 3);
  vs.grid_index.resize(static_cast<long>(centers.size()), 3);
  for (size_t i = 0; i < centers.size(); ++i) {
    vs.centers.row(static_cast<long>(i)) = centers[i].transpose();
    vs.grid_index.row(static_cast<long>(i)) = idx[i].transpose();
  }
  CertifyParams cp;
  cp.max_depth = max_depth;
  cp.keep_leaves = false;
  const Certificate c = certify_map(cage, vs, map.coefficients(), cp);
  out.certified = c.certified;
  out.reason = c.reason;
  out.cells_evaluated = c.voxels + 8 * c.refined;
  out.leaves = c.num_leaves;
  out.max_depth_used = c.max_depth_used;
  out.min_lower_bound = c.min_lower_bound;
  out.min_sigma3_center = c.min_sigma3_center;
  return out;
}

// ---------------------------------------------------------------------------------------------------------------
BoundaryEmbedding check_boundary_embedding(const ExplorerMap& map, const Ball& ball, int subdivisions) {
  if (subdivisions < 0 || subdivisions > 7) throw InputError("", "sphere subdivisions must be in 0..7");
  BoundaryEmbedding out;
  out.subdivisions = subdivisions;
  out.source = icosphere(ball.radius, subdivisions);
  out.source.V.rowwise() += ball.center.transpose();
  out.image = out.source;
  const int nv = static_cast<int>(out.source.V.rows());
#pragma omp parallel for schedule(static)
  for (int i = 0; i < nv; ++i) out.image.V.row(i) = map.value(out.source.V.row(i).transpose()).transpose();
  if (!out.image.V.allFinite()) throw Error("the image of the boundary sphere has non-finite points");
  out.min_image_edge = INFINITY;
  double vol = 0;
  for (int f = 0; f < out.image.F.rows(); ++f) {
    const Vec3 a = out.image.V.row(out.image.F(f, 0)), b = out.image.V.row(out.image.F(f, 1)),
               c = out.image.V.row(out.image.F(f, 2));
    out.min_image_edge = std::min({out.min_image_edge, (b - a).norm(), (c - b).norm(), (a - c).norm()});
    vol += a.dot(b.cross(c)) / 6;
  }
  out.signed_volume = vol;
  out.intersecting_pairs = static_cast<long>(find_self_intersections(out.image.V, out.image.F).size());
  out.embedded = out.intersecting_pairs == 0 && out.min_image_edge > 0 && vol > 0;
  return out;
}

namespace {

// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Vec3 closest_point_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double den = 1 / (va + vb + vc);
  return a + ab * (vb * den) + ac * (vc * den);
}

// Distance between segments p1q1 and p2q2 (Ericson 5.1.9).
double segment_distance(const Vec3& p1, const Vec3& q1, const Vec3& p2, const Vec3& q2) {
  const Vec3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0, t = 0;
  if (a <= 1e-300 && e <= 1e-300) return r.norm();
  if (a <= 1e-300) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-300) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), den = a * e - b * b;
      s = den > 0 ? std::clamp((b * f - c * e) / den, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p1 + d1 * s) - (p2 + d2 * t)).norm();
}

}  // namespace

double disjoint_triangle_distance(const std::array<Vec3, 3>& A, const std::array<Vec3, 3>& B) {
  double d = INFINITY;
  for (int i = 0; i < 3; ++i) {
    d = std::min(d, (A[i] - closest_point_triangle(A[i], B[0], B[1], B[2])).norm());
    d = std::min(d, (B[i] - closest_point_triangle(B[i], A[0], A[1], A[2])).norm());
    for (int j = 0; j < 3; ++j) d = std::min(d, segment_distance(A[i], A[(i + 1) % 3], B[j], B[(j + 1) % 3]));
  }
  return d;
}

BoundaryInjectivity certify_boundary_injective(const HarmonicPolynomialMap& map, const Ball& ball,
                                               double sigma3_threshold, int subdivisions, int max_depth) {
  BoundaryInjectivity out;
  out.subdivisions = subdivisions;
  out.min_pair_margin = INFINITY;
  if (!(sigma3_threshold > 0)) {
    out.reason = "needs a positive sigma3 threshold";
    return out;
  }
  BallCertifyParams cp;
  cp.threshold = sigma3_threshold;
  cp.max_depth = max_depth;
  const BallCertificate c = certify_sigma3_on_ball(map, ball, cp);
  if (!c.certified) {
    out.reason = "sigma3 > " + fmt(sigma3_threshold) + " not certified on the ball: " + c.reason;
    return out;
  }
  out.sigma3_lower = c.min_lower_bound;
  out.hessian_bound = c.max_hessian_bound;
  out.jacobian_bound = c.max_jacobian_bound;
  const double H = std::max(out.hessian_bound, 1e-300), G = out.jacobian_bound;
  out.rho = out.sigma3_lower / H;

  TriMesh src = icosphere(ball.radius, subdivisions);
  src.V.rowwise() += ball.center.transpose();
  const long nv = src.V.rows(), nf = src.F.rows();
  out.triangles = nf;
  MatX3d img(nv, 3);
#pragma omp parallel for schedule(static)
  for (long i = 0; i < nv; ++i) img.row(i) = map.value(src.V.row(i).transpose()).transpose();
  if (!img.allFinite()) {
    out.reason = "non-finite image point";
    return out;
  }
  // The linear images must be proper triangles (the exact intersection test skips degenerate ones) and must
  // not intersect at all (exact predicates); then distances are vertex/edge distances.
  for (long t = 0; t < nf; ++t) {
    const Vec3 a = img.row(src.F(t, 0)), b = img.row(src.F(t, 1)), c2 = img.row(src.F(t, 2));
    const double e2 = std::max({(b - a).squaredNorm(), (c2 - b).squaredNorm(), (a - c2).squaredNorm()});
    if (!((b - a).cross(c2 - a).norm() > 1e-12 * e2)) {
      out.reason = "a triangle of the sphere's image is degenerate";
      return out;
    }
  }
  if (!find_self_intersections(img, src.F).empty()) {
    out.reason = "the triangulated image of the sphere intersects itself";
    return out;
  }
  std::vector<double> delta(nf), rad(nf);
  std::vector<Vec3> cen(nf);
  std::vector<Eigen::AlignedBox3d> box(nf);
  double scale = 0;
  for (long t = 0; t < nf; ++t) {
    const Vec3 a = src.V.row(src.F(t, 0)), b = src.V.row(src.F(t, 1)), cc = src.V.row(src.F(t, 2));
    const double e = std::max({(b - a).norm(), (cc - b).norm(), (a - cc).norm()});
    const Vec3 n = (b - a).cross(cc - a).normalized();
    const double sag = std::max(0.0, ball.radius - std::abs(n.dot(a - ball.center)));
    cen[t] = (a + b + cc) / 3;
    rad[t] = std::max({(a - cen[t]).norm(), (b - cen[t]).norm(), (cc - cen[t]).norm()}) + sag;
    delta[t] = G * sag + 0.5 * H * e * e;
    out.max_delta = std::max(out.max_delta, delta[t]);
    for (int k = 0; k < 3; ++k) {
      box[t].extend(img.row(src.F(t, k)).transpose());
      scale = std::max(scale, img.row(src.F(t, k)).cwiseAbs().maxCoeff());
    }
    box[t].min().array() -= delta[t];
    box[t].max().array() += delta[t];
  }
  const double allowance = 1e-9 * (1 + scale);  // rounding of the image points and of the distances
  // Sweep over x of the grown boxes.
  std::vector<long> order(nf);
  for (long t = 0; t < nf; ++t) order[t] = t;
  std::sort(order.begin(), order.end(), [&](long a, long b) {
    return box[a].min().x() < box[b].min().x() || (box[a].min().x() == box[b].min().x() && a < b);
  });
  long measured = 0;
  double min_margin = INFINITY;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : measured) reduction(min : min_margin)
  for (long oi = 0; oi < nf; ++oi) {
    const long i = order[oi];
    for (long oj = oi + 1; oj < nf && box[order[oj]].min().x() <= box[i].max().x(); ++oj) {
      const long j = order[oj];
      if (box[i].intersection(box[j]).isEmpty()) continue;
      // All point pairs of these two triangles are closer than ρ: the local argument covers them.
      if ((cen[i] - cen[j]).norm() + rad[i] + rad[j] < out.rho) continue;
      std::array<Vec3, 3> A, B;
      bool shared = false;
      for (int k = 0; k < 3; ++k) {
        A[k] = img.row(src.F(i, k)).transpose();
        B[k] = img.row(src.F(j, k)).transpose();
        for (int l = 0; l < 3; ++l) shared = shared || src.F(i, k) == src.F(j, l);
      }
      ++measured;
      const double m = (shared ? 0.0 : disjoint_triangle_distance(A, B)) - delta[i] - delta[j] - allowance;
      min_margin = std::min(min_margin, m);
    }
  }
  out.pairs_measured = measured;
  out.min_pair_margin = min_margin;
  if (!(min_margin > 0)) {
    out.reason = "two boundary triangles at least rho = " + fmt(out.rho) +
                 " apart have images closer than their "
                 "error bounds (margin " +
                 fmt(min_margin) + "): refine the net (more subdivisions)";
    return out;
  }
  out.certified = true;
  return out;
}

// ---------------------------------------------------------------------------------------------------------------
std::uint64_t trial_seed(std::uint64_t seed, std::uint64_t trial) {
  return splitmix64(splitmix64(seed) ^ (trial * 0xd1b54a32d192ed03ULL + 1));
}

HarmonicPolynomialMap random_harmonic_map(int degree, std::uint64_t seed, double max_amplitude) {
  if (degree < 2 || degree > kMaxHarmonicDegree)
    throw InputError("", "random maps need a degree in 2.." + std::to_string(kMaxHarmonicDegree) + " (got " +
                             std::to_string(degree) + ")");
  Rng rng(seed);
  const Mat3 R1 = rng.rotation(), R2 = rng.rotation();
  Vec3 s;
  for (int i = 0; i < 3; ++i) s(i) = std::exp(0.35 * rng.normal());
  const Mat3 A = R1 * s.asDiagonal() * R2.transpose();
  Eigen::Matrix<double, 3, Eigen::Dynamic> C =
      HarmonicPolynomialMap::affine_coefficients(degree, A, Vec3::Zero());
  const double amp = max_amplitude * rng.uniform();
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  for (int j = 0; j < B.size(); ++j)
    if (B.degree_of[j] >= 2)
      for (int a = 0; a < 3; ++a) C(a, j) = amp / B.degree_of[j] * rng.normal();
  return HarmonicPolynomialMap(degree, C);
}

HarmonicPolynomialMap twist_example(const Vec3& s, double c, double d, int degree) {
  if (degree < 3 || degree > kMaxHarmonicDegree)
    throw InputError("", "the twist example needs degree 3 or 4");
  std::array<Polynomial, 3> f;
  auto set = [&](Polynomial& p, int a, int b, int cc, double v) { p.c[monomial_index(a, b, cc)] += v; };
  set(f[0], 1, 0, 0, s(0));
  set(f[0], 1, 0, 1, c);
  set(f[1], 0, 1, 0, s(1));
  set(f[1], 0, 1, 1, -c);
  set(f[2], 0, 0, 1, s(2));
  set(f[2], 0, 2, 0, c / 2);
  set(f[2], 2, 0, 0, -c / 2);
  set(f[2], 0, 0, 3, d);
  set(f[2], 2, 0, 1, -1.5 * d);
  set(f[2], 0, 2, 1, -1.5 * d);
  return HarmonicPolynomialMap::from_components(degree, f);
}

HarmonicPolynomialMap random_twist_map(int degree, std::uint64_t seed, double max_amplitude) {
  if (degree < 3 || degree > kMaxHarmonicDegree)
    throw InputError("", "the twist family needs a degree in 3.." + std::to_string(kMaxHarmonicDegree) +
                             " (got " + std::to_string(degree) + ")");
  Rng rng(seed);
  Vec3 s;
  s(2) = 0.3 + 0.5 * rng.uniform();
  s(1) = s(2) + 0.3 + 0.9 * rng.uniform();
  s(0) = s(1) + 0.1 + 0.5 * rng.uniform();
  const double c = 1.2 * (s(1) - s(2)) * rng.uniform(), d = 0.1 * rng.uniform();
  Eigen::Matrix<double, 3, Eigen::Dynamic> C = twist_example(s, c, d, degree).coefficients();
  const double amp = max_amplitude * rng.uniform();
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(degree);
  for (int j = 0; j < B.size(); ++j)
    if (B.degree_of[j] >= 1)
      for (int a = 0; a < 3; ++a) C(a, j) += amp / B.degree_of[j] * rng.normal();
  return HarmonicPolynomialMap(degree, C);
}

std::vector<SearchTrial> search_sigma3_minima(const SearchParams& params,
                                              const std::function<void(int)>& progress) {
  if (params.trials < 1) throw InputError("--trials", "must be at least 1");
  std::vector<SearchTrial> out(params.trials);
  int done = 0;
  const Ball ball;
#pragma omp parallel for schedule(dynamic)
  for (int t = 0; t < params.trials; ++t) {
    SearchTrial& tr = out[t];
    tr.trial = t;
    tr.seed = trial_seed(params.seed, t);
    tr.map = params.family == SearchFamily::kTwist
                 ? random_twist_map(params.degree, tr.seed, params.max_amplitude)
                 : random_harmonic_map(params.degree, tr.seed, params.max_amplitude);
    const PolynomialExplorerMap m(tr.map);
    MinimaSearchParams mp = params.minima;
    mp.seed = splitmix64(tr.seed);
    tr.minima = find_sigma3_minima(m, ball, mp);
    tr.sphere_min_sigma3 = sampled_sphere_min_sigma3(m, ball).first;
    for (const Sigma3Minimum& mn : tr.minima) {
      tr.strict_minima += mn.strict;
      if (!tr.candidate && mn.strict && mn.sigma3 > 0 && mn.sigma3 < tr.sphere_min_sigma3) {
        tr.candidate = true;
        tr.candidate_gap = (tr.sphere_min_sigma3 - mn.sigma3) / mn.sigma3;
      }
    }
    // A lower strict minimum that is not positive disqualifies the map (it is not locally injective).
    if (tr.candidate)
      for (const Sigma3Minimum& mn : tr.minima)
        if (mn.sigma3 <= 0) tr.candidate = false;
    if (progress) {
#pragma omp critical(lidef_search_progress)
      progress(++done);
    }
  }
  return out;
}

std::vector<LaplacianSample> laplacian_experiment(int degree, int maps, int points_per_map,
                                                  std::uint64_t seed, double max_amplitude) {
  if (maps < 1 || points_per_map < 1)
    throw InputError("", "the Laplacian experiment needs maps ≥ 1 and points ≥ 1");
  std::vector<LaplacianSample> out(static_cast<size_t>(maps) * points_per_map);
  const Ball ball;
#pragma omp parallel for schedule(dynamic)
  for (int m = 0; m < maps; ++m) {
    const std::uint64_t s = trial_seed(seed, m);
    const PolynomialExplorerMap map(random_harmonic_map(degree, s, max_amplitude));
    Rng rng(splitmix64(s) + 1);
    for (int i = 0; i < points_per_map; ++i) {
      LaplacianSample& o = out[static_cast<size_t>(m) * points_per_map + i];
      o.map = m;
      o.p = rng.in_ball(ball);
      const SigmaDerivatives d = map_sigma_derivatives(map, o.p, true);
      o.sigma = d.sigma;
      o.lap_sigma1 = d.laplacian(0);
      o.lap_sigma3 = d.laplacian(2);
      o.lap_sigma3_sym = d.laplacian_symmetric(2);
      o.lap_sigma3_anti = d.laplacian_antisymmetric(2);
      o.gap = std::min(d.gap(0), d.gap(2));
      const double h = 1e-3;
      Vec3 sum = -6 * d.sigma;
      for (int k = 0; k < 3; ++k) {
        Vec3 e = Vec3::Zero();
        e(k) = h;
        sum += signed_singular_values(map.jet(o.p + e).J) + signed_singular_values(map.jet(o.p - e).J);
      }
      o.lap_sigma1_fd = sum(0) / (h * h);
      o.lap_sigma3_fd = sum(2) / (h * h);
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------------------------
const HarmonicPolynomialMap* ExplorerExample::polynomial() const {
  const auto* p = dynamic_cast<const PolynomialExplorerMap*>(map.get());
  return p ? &p->map() : nullptr;
}

ExplorerExample read_explorer_example(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the map file");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(path, std::string("malformed JSON: ") + e.what());
  }
  auto number = [&](const nlohmann::json& v, const std::string& what) {
    if (!v.is_number()) throw InputError(path, what + " must be a number");
    const double x = v.get<double>();
    if (!std::isfinite(x)) throw InputError(path, what + " is not finite");
    return x;
  };
  auto vec3 = [&](const nlohmann::json& v, const std::string& what) {
    if (!v.is_array() || v.size() != 3) throw InputError(path, what + " must be an array of 3 numbers");
    return Vec3(number(v[0], what), number(v[1], what), number(v[2], what));
  };
  if (!j.is_object()) throw InputError(path, "the map file must hold a JSON object");
  if (j.value("format", "") != "lidef-explorer-map")
    throw InputError(path, "not a lidef explorer map (\"format\": \"lidef-explorer-map\" missing)");
  ExplorerExample ex;
  ex.kind = j.value("type", "");
  if (j.contains("note")) {
    if (!j["note"].is_string()) throw InputError(path, "\"note\" must be a string");
    ex.note = j["note"].get<std::string>();
  }
  if (j.contains("domain")) {
    const nlohmann::json& d = j["domain"];
    if (!d.is_object()) throw InputError(path, "\"domain\" must be an object {center, radius}");
    if (d.contains("center")) ex.ball.center = vec3(d["center"], "domain.center");
    if (d.contains("radius")) ex.ball.radius = number(d["radius"], "domain.radius");
    if (!(ex.ball.radius > 0)) throw InputError(path, "domain.radius must be positive");
  }
  if (ex.kind == "harmonic_polynomial") {
    if (!j.contains("degree") || !j["degree"].is_number_integer())
      throw InputError(path, "\"degree\" (an integer) is missing");
    const long deg = j["degree"].get<long>();
    if (deg < 1 || deg > kMaxHarmonicDegree)
      throw InputError(path, "degree must be in 1.." + std::to_string(kMaxHarmonicDegree) + " (got " +
                                 std::to_string(deg) + ")");
    const int n = harmonic_basis_size(static_cast<int>(deg));
    const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(static_cast<int>(deg));
    if (!j.contains("coefficients") || !j["coefficients"].is_array())
      throw InputError(path, "\"coefficients\" (an array of [x, y, z] rows) is missing");
    const nlohmann::json& c = j["coefficients"];
    if (static_cast<int>(c.size()) != n)
      throw InputError(path, "a degree-" + std::to_string(deg) + " map needs " + std::to_string(n) +
                                 " coefficient rows (got " + std::to_string(c.size()) + ")");
    if (j.contains("basis")) {
      const nlohmann::json& b = j["basis"];
      if (!b.is_array() || static_cast<int>(b.size()) != n)
        throw InputError(path, "\"basis\" must list the " + std::to_string(n) + " basis names");
      for (int i = 0; i < n; ++i)
        if (!b[i].is_string() || b[i].get<std::string>() != B.names[i])
          throw InputError(path,
                           "basis entry " + std::to_string(i + 1) + " should be \"" + B.names[i] + "\"");
    }
    Eigen::Matrix<double, 3, Eigen::Dynamic> C(3, n);
    for (int i = 0; i < n; ++i)
      C.col(i) = vec3(c[i], "coefficient row " + std::to_string(i + 1) + " (" + B.names[i] + ")");
    ex.map = std::make_shared<PolynomialExplorerMap>(HarmonicPolynomialMap(static_cast<int>(deg), C));
  } else if (ex.kind == "cage") {
    if (!j.contains("model") || !j["model"].is_string())
      throw InputError(path, "\"model\" (a folder) is missing");
    if (!j.contains("coefficients") || !j["coefficients"].is_string())
      throw InputError(path, "\"coefficients\" (a coefficient file or \"identity\") is missing");
    const std::filesystem::path base = std::filesystem::path(path).parent_path();
    auto resolve = [&](const std::string& p) {
      if (p == "identity" || std::filesystem::path(p).is_absolute()) return p;
      return (base / p).string();
    };
    const Model model = load_model(resolve(j["model"].get<std::string>()));
    const MatX3d y = read_coefficients(resolve(j["coefficients"].get<std::string>()), model.cage);
    // The ball must stay inside the cage, away from it (the basis is singular on the cage).
    const double clearance = ex.ball.radius * 1e-3;
    const TriMesh s = icosphere(ex.ball.radius, 3);
    for (int i = 0; i < s.V.rows(); ++i) {
      const Vec3 p = ex.ball.center + s.V.row(i).transpose();
      if (std::abs(model.cage.winding_number(p) - 1) > 1e-6 || model.cage.distance(p) < clearance)
        throw InputError(path, "the domain ball is not inside the cage of " + j["model"].get<std::string>());
    }
    ex.map = std::make_shared<CageExplorerMap>(model.cage, y, path);
    ex.cage_model = resolve(j["model"].get<std::string>());
    ex.cage_coefficients = resolve(j["coefficients"].get<std::string>());
  } else {
    throw InputError(path, "\"type\" must be \"harmonic_polynomial\" or \"cage\"");
  }
  return ex;
}

std::string explorer_example_json(const HarmonicPolynomialMap& map, const Ball& ball,
                                  const std::string& note) {
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(map.degree());
  std::ostringstream s;
  s << "{\n  \"format\": \"lidef-explorer-map\",\n  \"type\": \"harmonic_polynomial\",\n";
  s << "  \"note\": " << nlohmann::json(note).dump() << ",\n";
  s << "  \"degree\": " << map.degree() << ",\n";
  s << "  \"domain\": {\"center\": [" << fmt(ball.center.x()) << ", " << fmt(ball.center.y()) << ", "
    << fmt(ball.center.z()) << "], \"radius\": " << fmt(ball.radius) << "},\n";
  s << "  \"basis\": [";
  for (int i = 0; i < B.size(); ++i) s << (i ? ", " : "") << '"' << B.names[i] << '"';
  s << "],\n  \"coefficients\": [\n";
  for (int i = 0; i < B.size(); ++i) {
    const auto& c = map.coefficients().col(i);
    s << "    [" << fmt(c(0)) << ", " << fmt(c(1)) << ", " << fmt(c(2)) << "]"
      << (i + 1 < B.size() ? "," : "") << "\n";
  }
  s << "  ]\n}\n";
  return s.str();
}

BallFieldGrid compute_ball_fields(const ExplorerMap& map, const Ball& ball, int resolution) {
  if (resolution < 2 || resolution > 1024) throw InputError("--grid", "must be in 2..1024");
  BallFieldGrid g;
  g.n = resolution;
  g.origin = ball.center - Vec3::Constant(ball.radius);
  g.spacing = 2 * ball.radius / (resolution - 1);
  const long n3 = static_cast<long>(resolution) * resolution * resolution;
  g.sigma1.assign(n3, NAN);
  g.sigma2.assign(n3, NAN);
  g.sigma3.assign(n3, NAN);
  g.det_j.assign(n3, NAN);
  g.inside.assign(n3, 0);
#pragma omp parallel for schedule(dynamic)
  for (long idx = 0; idx < n3; ++idx) {
    const long i = idx % resolution, j = (idx / resolution) % resolution, k = idx / (resolution * resolution);
    const Vec3 p = g.origin + g.spacing * Vec3(i, j, k);
    if (!ball.contains(p)) continue;
    const Mat3 J = map.jacobian(p);
    const Vec3 s = signed_singular_values(J);
    g.sigma1[idx] = static_cast<float>(s(0));
    g.sigma2[idx] = static_cast<float>(s(1));
    g.sigma3[idx] = static_cast<float>(s(2));
    g.det_j[idx] = static_cast<float>(J.determinant());
    g.inside[idx] = 1;
  }
  return g;
}

}  // namespace lidef
