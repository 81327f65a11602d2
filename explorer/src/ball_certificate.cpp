#include "lidef/explorer/ball_certificate.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"

namespace lidef {
namespace {

double region_min_dist(const Vec3& q, double half, const Vec3& c) {
  return ((q - c).cwiseAbs() - Vec3::Constant(half)).cwiseMax(0.0).norm();
}
double region_max_dist(const Vec3& q, double half, const Vec3& c) {
  return ((q - c).cwiseAbs() + Vec3::Constant(half)).norm();
}

// Center of cell (i, j, k) of side h of the grid over the ball's bounding cube [c − R, c + R]³.
Vec3 ball_grid_center(const Ball& ball, double h, const Eigen::Vector3i& cell) {
  return ball.center - Vec3::Constant(ball.radius) + h * Vec3(cell.x() + 0.5, cell.y() + 0.5, cell.z() + 0.5);
}

// The cells of the n³ grid over the ball's bounding cube (side h = 2R / n) for which meets(center, h / 2)
// holds, in grid order (x fastest).
template <class Meets>
std::vector<Eigen::Vector3i> ball_grid_cells(const Ball& ball, int n, const Meets& meets) {
  const double h = 2 * ball.radius / n;
  std::vector<Eigen::Vector3i> cells;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        if (meets(ball_grid_center(ball, h, Eigen::Vector3i(i, j, k)), h / 2)) cells.emplace_back(i, j, k);
  return cells;
}

std::string point_text(const Vec3& q) {
  return "(" + format_double(q.x()) + ", " + format_double(q.y()) + ", " + format_double(q.z()) + ")";
}

}  // namespace

double cell_lipschitz_bound(const PolyJet& jet_at_center, double fourth_norm, double r) {
  return jet_at_center.hessian_norm() + r * (jet_at_center.third_norm() + r * fourth_norm);
}

// This refinement is separate from the core certifier (octree_certifier.h) on purpose: it bounds ‖H‖ on a
// cell by the fourth-norm bound L = ‖H(q)‖ + r (‖T(q)‖ + r ‖F‖), exact for polynomials of degree ≤ 4 (F
// constant), where the core bound needs a cage (its Lipschitz constants are sums over cage edges). It also
// certifies σ3 > threshold ≠ 0 and on the sphere alone, and yields the max ‖H‖ and ‖J‖ that
// certify_boundary_injective needs. Cage maps use the core certifier (certify_cage_map_on_ball).
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
  for (const Eigen::Vector3i& cell : ball_grid_cells(ball, n, meets))
    base.push_back(ball_grid_center(ball, h0, cell));
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
        r.fail = "sigma3 = " + format_double(s3) + " <= " + format_double(params.threshold) + " at " +
                 point_text(c.q);
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
        r.fail =
            "a cell still fails at depth " + std::to_string(params.max_depth) + " near " + point_text(c.q);
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
  const double center_distance = cage.distance(ball.center), clearance = center_distance - ball.radius;
  if (!(clearance > 0) || std::abs(cage.winding_number(ball.center) - 1) > 1e-6) {
    out.reason = "the domain ball is not strictly inside the cage";
    return out;
  }
  // A cube meeting the ball has its center within R + r of the ball's center, so its ball reaches R + 2r:
  // r ≤ clearance / 4 keeps it at least clearance / 2 away from the cage.
  const int n = static_cast<int>(std::ceil(2 * ball.radius / (clearance / (2 * std::sqrt(3.0)))));
  if (static_cast<double>(n) * n * n * 0.6 > static_cast<double>(max_cells)) {
    out.reason = "the domain ball is too close to the cage (clearance " + format_double(clearance) +
                 ") for " + std::to_string(max_cells) + " cells";
    return out;
  }
  // The voxels (sampling.h): the cubes that meet the ball, each clearing the cage as sample_voxels demands
  // (center distance ≥ safety · r, bounded below by the distance of the ball's center minus |q − c|; the
  // cube's ball then lies in the cage's winding-number-1 region around the ball's center).
  VoxelSampling voxels;
  voxels.side = 2 * ball.radius / n;
  voxels.origin = ball.center - Vec3::Constant(ball.radius);
  voxels.safety = SamplingParams().safety;
  const std::vector<Eigen::Vector3i> cells = ball_grid_cells(ball, n, [&](const Vec3& q, double half) {
    return region_min_dist(q, half, ball.center) <= ball.radius;
  });
  voxels.centers.resize(static_cast<long>(cells.size()), 3);
  voxels.grid_index.resize(static_cast<long>(cells.size()), 3);
  for (size_t i = 0; i < cells.size(); ++i) {
    const Vec3 q = ball_grid_center(ball, voxels.side, cells[i]);
    if (!(center_distance - (q - ball.center).norm() >= voxels.safety * voxels.radius())) {
      out.reason = "a cube meeting the domain ball comes too close to the cage at " + point_text(q);
      return out;
    }
    voxels.centers.row(static_cast<long>(i)) = q.transpose();
    voxels.grid_index.row(static_cast<long>(i)) = cells[i].transpose();
  }
  CertifyParams cp;
  cp.max_depth = max_depth;
  cp.keep_leaves = false;
  const Certificate c = OctreeCertifier(cage, voxels).certify(map.coefficients(), cp);
  out.certified = c.certified;
  out.reason = c.reason;
  out.cells_evaluated = c.voxels + 8 * c.refined;
  out.leaves = c.num_leaves;
  out.max_depth_used = c.max_depth_used;
  out.min_lower_bound = c.min_lower_bound;
  out.min_sigma3_center = c.min_sigma3_center;
  return out;
}

}  // namespace lidef
