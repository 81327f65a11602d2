// The harmonic basis against independent truth: brute-force quadrature of the defining integrals,
// central finite differences, identity/affine reproduction, harmonicity.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "lidef/geometry.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/lane_math.h"
#include "test_cages.h"
#include "test_support.h"

using namespace lidef;
using lidef::test::icosphere;
using lidef::test::interior_points;

namespace {

// Brute-force quadrature of the defining integrals of every basis function (value and gradient):
// each triangle is split into n² sub-triangles with the 7-point degree-5 rule on each.
struct Quadrature {
  VecXd value;  // #V+#F
  MatX3d grad;  // #V+#F by 3
};

Quadrature quadrature(const Cage& cage, const Vec3& p, int n) {
  const int nv = cage.num_vertices();
  Quadrature q{VecXd::Zero(cage.num_coeffs()), MatX3d::Zero(cage.num_coeffs(), 3)};
  const double s15 = std::sqrt(15.0);
  const double a1 = (6 - s15) / 21, b1 = (9 + 2 * s15) / 21, w1 = (155 - s15) / 1200;
  const double a2 = (6 + s15) / 21, b2 = (9 - 2 * s15) / 21, w2 = (155 + s15) / 1200;
  const std::vector<std::array<double, 4>> rule = {{1. / 3, 1. / 3, 1. / 3, 9. / 40},
                                                   {a1, a1, b1, w1},
                                                   {a1, b1, a1, w1},
                                                   {b1, a1, a1, w1},
                                                   {a2, a2, b2, w2},
                                                   {a2, b2, a2, w2},
                                                   {b2, a2, a2, w2}};
  const double k4pi = 1.0 / (4 * M_PI);
  for (int t = 0; t < cage.num_faces(); ++t) {
    const Vec3 X[3] = {cage.V.row(cage.F(t, 0)), cage.V.row(cage.F(t, 1)), cage.V.row(cage.F(t, 2))};
    const Vec3 nrm = cage.N.row(t);
    const double sub_area = cage.area(t) / (n * n);
    // Sub-triangles in barycentric (i, j) lattice coordinates: "up" and "down" triangles.
    for (int i = 0; i < n; ++i)
      for (int j = 0; j + i < n; ++j)
        for (int up = 0; up < 2; ++up) {
          if (!up && i + j + 1 >= n) continue;
          std::array<Eigen::Vector2d, 3> c;
          if (up)
            c = {Eigen::Vector2d(i, j), Eigen::Vector2d(i + 1, j), Eigen::Vector2d(i, j + 1)};
          else
            c = {Eigen::Vector2d(i + 1, j), Eigen::Vector2d(i + 1, j + 1), Eigen::Vector2d(i, j + 1)};
          for (const auto& r : rule) {
            const Eigen::Vector2d uv = (r[0] * c[0] + r[1] * c[1] + r[2] * c[2]) / n;  // bary of X1, X2
            const double lam[3] = {1 - uv(0) - uv(1), uv(0), uv(1)};
            const Vec3 xi = lam[0] * X[0] + lam[1] * X[1] + lam[2] * X[2];
            const Vec3 l = xi - p;
            const double R = l.norm(), R3 = R * R * R, w = r[3] * sub_area * k4pi;
            const double ln = l.dot(nrm);
            q.value(nv + t) += w / R;
            q.grad.row(nv + t) += w * l.transpose() / R3;
            const Vec3 gdl = -nrm / R3 + 3 * ln * l / (R3 * R * R);  // ∇_p [(ξ−p)·n / R³]
            for (int k = 0; k < 3; ++k) {
              q.value(cage.F(t, k)) += w * lam[k] * ln / R3;
              q.grad.row(cage.F(t, k)) += w * lam[k] * gdl.transpose();
            }
          }
        }
  }
  return q;
}

struct Eval {
  VecXd val;
  MatX3d grad;
  Eigen::Matrix<double, Eigen::Dynamic, kSym, Eigen::RowMajor> hess;
};
Eval eval(const HarmonicBasis& B, const Vec3& p) {
  Eval e{VecXd(B.size()), MatX3d(B.size(), 3), {}};
  e.hess.resize(B.size(), kSym);
  B.evaluate(p, 2, e.val.data(), e.grad.data(), e.hess.data());
  return e;
}

Cage test_cage() {
  return Cage(icosphere(1, 0.2, 3));
}

}  // namespace

TEST(GreenCoordinates, ValuesAndGradientsMatchQuadratureFarAndNear) {
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  // A point well inside, and points at 2% and 5% of the edge length inside a face / near a vertex.
  const Vec3 c = cage.V.row(cage.F(0, 0)) / 3 + cage.V.row(cage.F(0, 1)) / 3 + cage.V.row(cage.F(0, 2)) / 3;
  const Vec3 n0 = cage.N.row(0);
  const std::vector<std::pair<Vec3, int>> pts = {{Vec3(0.1, -0.2, 0.15), 24},
                                                 {c - 0.05 * n0, 96},
                                                 {c - 0.02 * n0, 192},
                                                 {0.93 * Vec3(cage.V.row(5)), 128}};
  for (const auto& [p, n] : pts) {
    ASSERT_NEAR(cage.winding_number(p), 1.0, 1e-9);
    const Eval e = eval(B, p);
    const Quadrature q = quadrature(cage, p, n);
    const double vscale = q.value.cwiseAbs().maxCoeff(), gscale = q.grad.cwiseAbs().maxCoeff();
    EXPECT_LT((e.val - q.value).cwiseAbs().maxCoeff(), 1e-7 * vscale) << "p = " << p.transpose();
    EXPECT_LT((e.grad - q.grad).cwiseAbs().maxCoeff(), 1e-6 * gscale) << "p = " << p.transpose();
  }
}

TEST(GreenCoordinates, GradientsAndHessiansMatchFiniteDifferences) {
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  const MatX3d P = interior_points(cage, 20, 0.05);
  const double h = 1e-5, hh = 1e-4;
  for (int i = 0; i < P.rows(); ++i) {
    const Vec3 p = P.row(i);
    const Eval e = eval(B, p);
    double gerr = 0, herr = 0, gmax = e.grad.cwiseAbs().maxCoeff(), hmax = e.hess.cwiseAbs().maxCoeff();
    for (int b = 0; b < 3; ++b) {
      const Vec3 dp = Vec3::Unit(b);
      const Eval ep = eval(B, p + h * dp), em = eval(B, p - h * dp);
      gerr = std::max(gerr, ((ep.val - em.val) / (2 * h) - e.grad.col(b)).cwiseAbs().maxCoeff());
      const Eval Ep = eval(B, p + hh * dp), Em = eval(B, p - hh * dp);
      const MatX3d dgrad = (Ep.grad - Em.grad) / (2 * hh);  // column c: ∂²/∂p_c∂p_b
      const int idx[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
      for (int c = 0; c < 3; ++c)
        herr = std::max(herr, (dgrad.col(c) - e.hess.col(idx[b][c])).cwiseAbs().maxCoeff());
    }
    EXPECT_LT(gerr, 1e-7 * gmax) << "gradient at " << p.transpose();
    EXPECT_LT(herr, 1e-6 * hmax) << "Hessian at " << p.transpose();
  }
}

TEST(GreenCoordinates, HarmonicPartitionOfUnityAndOutside) {
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  const MatX3d P = interior_points(cage, 50, 0.03);
  for (int i = 0; i < P.rows(); ++i) {
    const Eval e = eval(B, P.row(i));
    EXPECT_NEAR(e.val.head(cage.num_vertices()).sum(), 1.0, 1e-12);
    const VecXd lap = e.hess.col(0) + e.hess.col(3) + e.hess.col(5);
    EXPECT_LT(lap.cwiseAbs().maxCoeff(), 1e-9 * e.hess.cwiseAbs().maxCoeff());
  }
  // Outside the cage the double-layer functions sum to the winding number 0.
  const Eval out = eval(B, Vec3(2.5, 0.3, -0.4));
  EXPECT_NEAR(out.val.head(cage.num_vertices()).sum(), 0.0, 1e-12);
}

TEST(GreenCoordinates, IdentityAndAffineReproduction) {
  std::vector<Cage> cages = {test_cage(), Cage(icosphere(2, 0.1, 11))};
  if (!lidef::test::shared_data().empty())
    cages.emplace_back(lidef::test::read_obj_simple(lidef::test::shared_model("bar") + "/cage.obj"));
  std::mt19937 rng(5);
  std::normal_distribution<double> N01;
  for (const Cage& cage : cages) {
    const HarmonicBasis B(cage);
    const double size = (cage.bbox_max - cage.bbox_min).norm();
    const MatX3d P = interior_points(cage, 25, 0.02 * size);
    Mat3 A;
    for (int k = 0; k < 9; ++k) A(k / 3, k % 3) = N01(rng);
    const Vec3 b(N01(rng), N01(rng), N01(rng));
    const MatX3d yid = cage.identity_coefficients(), yaff = cage.affine_coefficients(A, b);
    for (int i = 0; i < P.rows(); ++i) {
      const Vec3 p = P.row(i);
      const MapJet id = B.map_jet(yid, p), af = B.map_jet(yaff, p);
      EXPECT_LT((id.f - p).norm(), 1e-12 * size) << cage.source;
      EXPECT_LT((id.J - Mat3::Identity()).norm(), 1e-11);
      EXPECT_LT(id.hessian_norm(), 1e-9 / size);
      EXPECT_LT((af.f - (A * p + b)).norm(), 1e-11 * (A.norm() * size + b.norm()));
      EXPECT_LT((af.J - A).norm(), 1e-11 * A.norm());
      EXPECT_LT(af.hessian_norm(), 1e-9 * A.norm() / size);
    }
  }
}

TEST(GreenCoordinates, BatchedMatricesAgreeWithPointwise) {
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  const MatX3d P = interior_points(cage, 9, 0.05);
  const MatXd D = B.value_matrix(P), G = B.gradient_matrix(P), Hm = B.hessian_matrix(P);
  std::mt19937 rng(2);
  std::normal_distribution<double> N01;
  MatX3d y(B.size(), 3);
  for (int i = 0; i < y.rows(); ++i) y.row(i) << N01(rng), N01(rng), N01(rng);
  const MatX3d F = B.map_values(y, P);
  for (int i = 0; i < P.rows(); ++i) {
    const Eval e = eval(B, P.row(i));
    // Same function, but inlined with a constant order the compiler may contract multiply-adds differently
    // (FMA), so agreement is to rounding, not bitwise.
    const double tv = 1e-14 * e.val.cwiseAbs().maxCoeff(), tg = 1e-14 * e.grad.cwiseAbs().maxCoeff(),
                 th = 1e-14 * e.hess.cwiseAbs().maxCoeff();
    EXPECT_LE((D.row(i).transpose() - e.val).cwiseAbs().maxCoeff(), tv);
    for (int b = 0; b < 3; ++b)
      EXPECT_LE((G.row(3 * i + b).transpose() - e.grad.col(b)).cwiseAbs().maxCoeff(), tg);
    for (int k = 0; k < kSym; ++k)
      EXPECT_LE((Hm.row(kSym * i + k).transpose() - e.hess.col(k)).cwiseAbs().maxCoeff(), th);
    const MapJet jet = B.map_jet(y, P.row(i));
    EXPECT_LT((F.row(i).transpose() - jet.f).norm(), 1e-12 * jet.f.norm());
    const Mat3 Jt = G.middleRows(3 * i, 3) * y;  // rows: ∂/∂p_b, columns: components
    EXPECT_LT((Jt.transpose() - jet.J).norm(), 1e-12 * jet.J.norm());
  }
}

TEST(GreenCoordinates, EdgeAlphaBetaAreGradientsOfSolidAngleAndEdgeLog) {
  // ∇ω_t = −Σ_e α_e (erratum of (51)) and ∇C_e = β_e (52), checked by finite differences.
  std::mt19937 rng(9);
  std::normal_distribution<double> N01;
  for (int trial = 0; trial < 20; ++trial) {
    Vec3 X[3];
    for (auto& x : X) x = Vec3(N01(rng), N01(rng), N01(rng));
    const Vec3 p = Vec3(N01(rng), N01(rng), N01(rng)) * 2.0;
    const double h = 1e-6;
    auto omega = [&](const Vec3& q) { return lidef::solid_angle_fraction(X[0], X[1], X[2], q); };
    auto C = [&](int k, const Vec3& q) {
      const Vec3 u = X[(k + 2) % 3], w = X[(k + 1) % 3];
      const double m = (u - q).norm() + (w - q).norm(), d = (w - u).norm();
      return std::log((m + d) / (m - d)) / (4 * M_PI);
    };
    Vec3 sum_alpha = Vec3::Zero();
    for (int k = 0; k < 3; ++k) {
      const EdgeAlphaBeta ab = edge_alpha_beta(X[(k + 2) % 3], X[(k + 1) % 3], p);
      sum_alpha += ab.alpha;
      Vec3 fd;
      for (int b = 0; b < 3; ++b)
        fd(b) = (C(k, p + h * Vec3::Unit(b)) - C(k, p - h * Vec3::Unit(b))) / (2 * h);
      EXPECT_LT((fd - ab.beta).norm(), 1e-6 * (1 + ab.beta.norm()));
      EXPECT_NEAR(ab.alpha.dot(ab.beta), 0.0, 1e-12 * (1 + ab.alpha.norm() * ab.beta.norm()));
    }
    Vec3 fd;
    for (int b = 0; b < 3; ++b)
      fd(b) = (omega(p + h * Vec3::Unit(b)) - omega(p - h * Vec3::Unit(b))) / (2 * h);
    EXPECT_LT((fd + sum_alpha).norm(), 1e-6 * (1 + sum_alpha.norm()));
  }
}

TEST(GreenCoordinates, DifferentialJetEqualsBasisJet) {
  // (49) and (53) with the MATH-NOTES signs against the basis-function evaluation, for random coefficients.
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  std::mt19937 rng(17);
  std::normal_distribution<double> N01;
  MatX3d y = cage.identity_coefficients();
  for (int i = 0; i < y.rows(); ++i) y.row(i) += 0.3 * Vec3(N01(rng), N01(rng), N01(rng)).transpose();
  const HarmonicBasis::FaceMatrices fm = B.face_matrices(y);
  const MatX3d P = interior_points(cage, 15, 0.03);
  for (int i = 0; i < P.rows(); ++i) {
    const MapJet a = B.map_jet(y, P.row(i)), b = B.differential_jet(fm, P.row(i), 2);
    EXPECT_LT((a.J - b.J).norm(), 1e-11 * a.J.norm()) << P.row(i);
    double dh = 0;
    for (int k = 0; k < 3; ++k) dh += (a.H[k] - b.H[k]).squaredNorm();
    EXPECT_LT(std::sqrt(dh), 1e-10 * a.hessian_norm()) << P.row(i);
  }
  // Affine maps: J = A and H = 0 exactly up to rounding.
  Mat3 A;
  for (int k = 0; k < 9; ++k) A(k / 3, k % 3) = N01(rng);
  const MapJet c =
      B.differential_jet(B.face_matrices(cage.affine_coefficients(A, Vec3(1, 2, 3))), P.row(0), 2);
  EXPECT_LT((c.J - A).norm(), 1e-12 * A.norm());
  EXPECT_LT(c.hessian_norm(), 1e-12 * A.norm());
}

namespace {
// |a − ref| in units of the last place of ref (ref rounded to double from a long double reference).
double ulps(double a, long double ref) {
  const double r = static_cast<double>(ref);
  if (a == r) return 0;
  const double ulp = std::nextafter(std::abs(r), INFINITY) - std::abs(r);
  return static_cast<double>(std::abs(static_cast<long double>(a) - ref) / ulp);
}
}  // namespace

TEST(LaneMath, LogAndAtan2AreWithinTwoUlpOfALongDoubleReference) {
  // The SIMD kernel's log and atan2 (lane_math.h) against logl/atan2l (64-bit mantissa): over many
  // magnitudes, near 1 (where log is small), and the kernel's own argument (m+d)²/(m²−d²) > 1.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  double worst_log = 0, worst_atan2 = 0;
  for (int i = 0; i < 200000; ++i) {
    const double x =
        i % 3 == 0 ? std::exp(700 * U(rng)) : (i % 3 == 1 ? 1 + 0.3 * U(rng) : 1 + std::exp(30 * U(rng)));
    worst_log = std::max(worst_log, ulps(lane_log(x), logl(static_cast<long double>(x))));
    const double y = U(rng) * std::exp(20 * U(rng)), z = U(rng) * std::exp(20 * U(rng));
    worst_atan2 = std::max(worst_atan2, ulps(lane_atan2(y, z), atan2l(static_cast<long double>(y), z)));
  }
  EXPECT_LE(worst_log, 2.0);
  EXPECT_LE(worst_atan2, 2.0);
  // Subnormals, the axes, and what std::log gives outside the domain.
  EXPECT_LE(ulps(lane_log(1e-310), logl(1e-310L)), 2.0);
  EXPECT_EQ(lane_log(1.0), 0.0);
  EXPECT_EQ(lane_log(0.0), -INFINITY);
  EXPECT_EQ(lane_log(INFINITY), INFINITY);
  EXPECT_TRUE(std::isnan(lane_log(-1.0)));
  EXPECT_TRUE(std::isnan(lane_log(NAN)));
  EXPECT_EQ(lane_atan2(0, 0), 0.0);
  EXPECT_EQ(lane_atan2(0, 2), 0.0);
  EXPECT_EQ(lane_atan2(2, 0), std::atan2(2.0, 0.0));
  EXPECT_EQ(lane_atan2(0, -2), std::atan2(0.0, -2.0));
  EXPECT_EQ(lane_atan2(-3, -3), std::atan2(-3.0, -3.0));
}

// The certifier's precomputation takes 5 Hessian rows and stores zz = −xx − yy (docs/certificate.md, Step 5):
// the rows are the full call's, and the computed basis is harmonic to rounding, entry by entry.
TEST(GreenCoordinates, EvaluateRowsWithoutZzAndTheLaplacianResidual) {
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  const MatX3d P = interior_points(cage, 40, 0.01);
  MatXdR full, five;
  B.evaluate_rows(P, false, true, true, full);
  B.evaluate_rows(P, false, true, true, five, /*drop_zz=*/true);
  ASSERT_EQ(full.rows(), 9 * P.rows());
  ASSERT_EQ(five.rows(), 8 * P.rows());
  double worst = 0;
  for (int i = 0; i < P.rows(); ++i) {
    EXPECT_TRUE(five.middleRows(8 * i, 8) == full.middleRows(9 * i, 8)) << i;
    for (int k = 0; k < B.size(); ++k) {
      const double xx = full(9 * i + 3, k), yy = full(9 * i + 6, k), zz = full(9 * i + 8, k);
      worst = std::max(worst, std::abs(xx + yy + zz) / (std::abs(xx) + std::abs(yy) + std::abs(zz)));
    }
  }
  // Relative to the entries, far below the float storage's 2^-24 ≈ 6e-8 that the certificate accounts for.
  EXPECT_LT(worst, 1e-10);
  std::printf("largest |xx + yy + zz| / (|xx| + |yy| + |zz|): %.3g\n", worst);
}

TEST(GreenCoordinates, EvaluateRowsMatchesPointwiseAndNotItsBatch) {
  const Cage cage = test_cage();
  const HarmonicBasis B(cage);
  const int n = B.size();
  MatX3d P = interior_points(cage, 11, 0.05);  // not a multiple of kLanes: a partial last batch
  ASSERT_NE(P.rows() % HarmonicBasis::kLanes, 0);
  MatXdR all, vg, h;
  B.evaluate_rows(P, true, true, true, all);
  B.evaluate_rows(P, true, true, false, vg);
  B.evaluate_rows(P, false, false, true, h);
  ASSERT_EQ(all.rows(), 10 * P.rows());
  ASSERT_EQ(all.cols(), n);
  for (int i = 0; i < P.rows(); ++i) {
    const Eval e = eval(B, P.row(i));
    // The pointwise evaluate() runs the same kernel one lane wide; the compiler may contract the vector and
    // the scalar code's multiply-adds differently, so agreement is to rounding.
    const double tv = 1e-14 * e.val.cwiseAbs().maxCoeff(), tg = 1e-14 * e.grad.cwiseAbs().maxCoeff(),
                 th = 1e-14 * e.hess.cwiseAbs().maxCoeff();
    EXPECT_LE((all.row(10 * i).transpose() - e.val).cwiseAbs().maxCoeff(), tv);
    for (int b = 0; b < 3; ++b)
      EXPECT_LE((all.row(10 * i + 1 + b).transpose() - e.grad.col(b)).cwiseAbs().maxCoeff(), tg);
    for (int q = 0; q < kSym; ++q)
      EXPECT_LE((all.row(10 * i + 4 + q).transpose() - e.hess.col(q)).cwiseAbs().maxCoeff(), th);
    // The kernel for a subset of the outputs (another instantiation: contracted differently, so to rounding).
    EXPECT_LE((vg.row(4 * i).transpose() - e.val).cwiseAbs().maxCoeff(), tv);
    for (int b = 0; b < 3; ++b)
      EXPECT_LE((vg.row(4 * i + 1 + b).transpose() - e.grad.col(b)).cwiseAbs().maxCoeff(), tg);
    for (int q = 0; q < kSym; ++q)
      EXPECT_LE((h.row(kSym * i + q).transpose() - e.hess.col(q)).cwiseAbs().maxCoeff(), th);
  }
  // A point's numbers do not depend on the points it shares a batch with, nor on its lane.
  MatX3d Q = P.colwise().reverse();
  Q.row(0) = P.row(3);
  MatXdR other;
  B.evaluate_rows(Q, true, true, true, other);
  for (int i = 0; i < Q.rows(); ++i) {
    const int src = i == 0 ? 3 : static_cast<int>(P.rows()) - 1 - i;
    EXPECT_TRUE(other.middleRows(10 * i, 10) == all.middleRows(10 * src, 10)) << i;
  }
}
