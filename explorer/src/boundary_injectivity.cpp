#include "lidef/explorer/boundary_injectivity.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "lidef/errors.h"
#include "lidef/explorer/ball_certificate.h"
#include "lidef/geometry.h"
#include "lidef/number_format.h"
#include "lidef/procedural_models.h"
#include "lidef/self_intersections.h"

namespace lidef {
namespace {

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
  for (int f = 0; f < out.image.F.rows(); ++f) {
    const Vec3 a = out.image.V.row(out.image.F(f, 0)), b = out.image.V.row(out.image.F(f, 1)),
               c = out.image.V.row(out.image.F(f, 2));
    out.min_image_edge = std::min({out.min_image_edge, (b - a).norm(), (c - b).norm(), (a - c).norm()});
  }
  out.signed_volume = signed_volume(out.image.V, out.image.F);
  out.intersecting_pairs = static_cast<long>(find_self_intersections(out.image.V, out.image.F).size());
  out.embedded = out.intersecting_pairs == 0 && out.min_image_edge > 0 && out.signed_volume > 0;
  return out;
}

double disjoint_triangle_distance(const std::array<Vec3, 3>& A, const std::array<Vec3, 3>& B) {
  double d = INFINITY;
  for (int i = 0; i < 3; ++i) {
    d = std::min(d, std::sqrt(point_triangle_dist2(A[i], B[0], B[1], B[2])));
    d = std::min(d, std::sqrt(point_triangle_dist2(B[i], A[0], A[1], A[2])));
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
    out.reason = "sigma3 > " + format_double(sigma3_threshold) + " not certified on the ball: " + c.reason;
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
    out.reason = "two boundary triangles at least rho = " + format_double(out.rho) +
                 " apart have images closer than their "
                 "error bounds (margin " +
                 format_double(min_margin) + "): refine the net (more subdivisions)";
    return out;
  }
  out.certified = true;
  return out;
}

}  // namespace lidef
