// The σ3 explorer (docs/explorer.md): the harmonic polynomial family, σ derivatives, the ball certificate,
// the shipped counterexample, the search's determinism and the `lidef explore` CLI. Truths: finite
// differences (values → J → H → T → F, σ → ∇σ → Hessian of σ), Laplacians by finite differences, quadrature
// on the sphere, dense sampling of σ3 against the certificate's bounds, the closed-form Hessian of the twist
// family.
#include <gtest/gtest.h>
#include <omp.h>
#include <vtkDataArray.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkXMLImageDataReader.h>
#include <vtkXMLPolyDataReader.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <filesystem>
#include <random>

#include "lidef/explorer/ball_certificate.h"
#include "lidef/explorer/boundary_injectivity.h"
#include "lidef/explorer/counterexample.h"
#include "lidef/explorer/explorer_example.h"
#include "lidef/explorer/harmonic_polynomials.h"
#include "lidef/explorer/laplacian_experiment.h"
#include "lidef/explorer/random_search.h"
#include "lidef/explorer/sigma_minima.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/procedural_models.h"
#include "lidef/signed_svd.h"
#include "lidef/singular_value_derivatives.h"
#include "test_support.h"

using namespace lidef;
namespace fs = std::filesystem;
using lidef::test::TempDir;

namespace {

Vec3 random_in_ball(std::mt19937_64& rng, double r = 1) {
  std::uniform_real_distribution<double> u(-1, 1);
  for (;;) {
    const Vec3 v(u(rng), u(rng), u(rng));
    if (v.norm() <= 1) return r * v;
  }
}

std::string shipped_example() {
  return lidef::test::project_data() + "/explorer/sigma3_interior_min.json";
}

}  // namespace

TEST(ExplorePoly, BasisIsHarmonicHomogeneousAndOrthonormal) {
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(4);
  ASSERT_EQ(B.size(), 25);
  std::mt19937_64 rng(7);
  // Sphere quadrature independent of the exact moments: a Fibonacci lattice of 40,000 points.
  const int nq = 40000;
  std::vector<Vec3> sphere(nq);
  for (int i = 0; i < nq; ++i) {
    const double z = 1 - (2 * i + 1.0) / nq, r = std::sqrt(1 - z * z), t = M_PI * (3 - std::sqrt(5.0)) * i;
    sphere[i] = Vec3(r * std::cos(t), r * std::sin(t), z);
  }
  for (int j = 0; j < B.size(); ++j) {
    const Polynomial& q = B.q[j];
    EXPECT_EQ(q.degree(), B.degree_of[j]) << B.names[j];
    // Exact Laplacian: every monomial coefficient vanishes.
    const Polynomial L = laplacian(q);
    for (double c : L.c) EXPECT_LT(std::abs(c), 1e-12) << B.names[j];
    for (int t = 0; t < 5; ++t) {
      const Vec3 p = random_in_ball(rng);
      // Homogeneity of degree l.
      EXPECT_NEAR(q.eval(2 * p), std::pow(2.0, B.degree_of[j]) * q.eval(p), 1e-11) << B.names[j];
      // Laplacian by 7-point finite differences.
      const double h = 1e-3;
      double lap = -6 * q.eval(p);
      for (int k = 0; k < 3; ++k) {
        Vec3 e = Vec3::Zero();
        e(k) = h;
        lap += q.eval(p + e) + q.eval(p - e);
      }
      // The stencil's truncation error for a quartic is (h²/12) Σ ∂⁴u ≈ 1e-5 here; a non-harmonic q gives
      // O(1).
      EXPECT_LT(std::abs(lap / (h * h)), 1e-4) << B.names[j];
    }
    for (int i = 0; i <= j; ++i) {
      double s = 0;
      for (const Vec3& u : sphere) s += B.q[i].eval(u) * q.eval(u);
      s /= nq;
      EXPECT_NEAR(s, i == j ? 1.0 : 0.0, 2e-3) << B.names[i] << " . " << B.names[j];
      EXPECT_NEAR(sphere_mean_product(B.q[i], q), i == j ? 1.0 : 0.0, 1e-12)
          << B.names[i] << " . " << B.names[j];
    }
  }
}

TEST(ExplorePoly, JetMatchesFiniteDifferences) {
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 6; ++trial) {
    const int degree = 2 + trial % 3;
    const HarmonicPolynomialMap m = random_harmonic_map(degree, 100 + trial, 0.8);
    for (int t = 0; t < 5; ++t) {
      const Vec3 p = random_in_ball(rng);
      const PolyJet j = m.jet(p, 3);
      EXPECT_LT((j.f - m.value(p)).norm(), 1e-14);
      const double h = 1e-5;
      for (int k = 0; k < 3; ++k) {
        Vec3 e = Vec3::Zero();
        e(k) = h;
        const PolyJet jp = m.jet(p + e, 3), jm = m.jet(p - e, 3);
        const Vec3 df = (jp.f - jm.f) / (2 * h);
        for (int a = 0; a < 3; ++a) {
          EXPECT_NEAR(df(a), j.J(a, k), 1e-8 * (1 + j.J.norm()));
          for (int b = 0; b < 3; ++b) {
            EXPECT_NEAR((jp.J(a, b) - jm.J(a, b)) / (2 * h), j.H[a](b, k), 1e-8 * (1 + j.hessian_norm()));
            for (int c = 0; c < 3; ++c) {
              EXPECT_NEAR((jp.H[a](b, c) - jm.H[a](b, c)) / (2 * h), j.T[a][b](c, k),
                          1e-8 * (1 + j.third_norm()));
              for (int d = 0; d < 3; ++d)
                EXPECT_NEAR((jp.T[a][b](c, d) - jm.T[a][b](c, d)) / (2 * h), m.fourth()[a][b][c](d, k),
                            1e-7 * (1 + m.fourth_norm()));
            }
          }
        }
      }
      // Harmonic components: trace of each component Hessian vanishes; so do the traces in T (ΔJ = 0).
      for (int a = 0; a < 3; ++a) {
        EXPECT_LT(std::abs(j.H[a].trace()), 1e-12 * (1 + j.hessian_norm()));
        for (int b = 0; b < 3; ++b) EXPECT_LT(std::abs(j.T[a][b].trace()), 1e-12 * (1 + j.third_norm()));
      }
      // Norms count every entry.
      double s = 0;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          for (int c = 0; c < 3; ++c) s += j.H[a](b, c) * j.H[a](b, c);
      EXPECT_NEAR(j.hessian_norm(), std::sqrt(s), 1e-14 * (1 + std::sqrt(s)));
    }
  }
}

TEST(ExplorePoly, IdentityAffineAndFromComponents) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n;
  Mat3 A;
  for (int i = 0; i < 9; ++i) A(i / 3, i % 3) = n(rng);
  const Vec3 b(n(rng), n(rng), n(rng));
  for (int degree = 1; degree <= 4; ++degree) {
    const HarmonicPolynomialMap id(degree, HarmonicPolynomialMap::identity_coefficients(degree));
    const HarmonicPolynomialMap af(degree, HarmonicPolynomialMap::affine_coefficients(degree, A, b));
    for (int t = 0; t < 10; ++t) {
      const Vec3 p = random_in_ball(rng, 2);
      const PolyJet ji = id.jet(p), ja = af.jet(p);
      EXPECT_LT((ji.f - p).norm(), 1e-13);
      EXPECT_LT((ji.J - Mat3::Identity()).norm(), 1e-13);
      EXPECT_LT(ji.hessian_norm(), 1e-13);
      EXPECT_LT((ja.f - (A * p + b)).norm(), 1e-12 * (1 + A.norm()));
      EXPECT_LT((ja.J - A).norm(), 1e-12 * A.norm());
      EXPECT_LT(ja.hessian_norm(), 1e-12 * A.norm());
    }
  }
  // from_components reproduces a harmonic polynomial and refuses a non-harmonic one.
  std::array<Polynomial, 3> f;
  f[0].c[monomial_index(1, 1, 0)] = 1;  // xy
  f[1].c[monomial_index(2, 0, 0)] = 1;  // x² − z²
  f[1].c[monomial_index(0, 0, 2)] = -1;
  f[2].c[monomial_index(1, 1, 1)] = 2;  // 2xyz
  const HarmonicPolynomialMap m = HarmonicPolynomialMap::from_components(4, f);
  const Vec3 p(0.3, -0.2, 0.7);
  EXPECT_NEAR(m.value(p)(0), p.x() * p.y(), 1e-14);
  EXPECT_NEAR(m.value(p)(1), p.x() * p.x() - p.z() * p.z(), 1e-14);
  EXPECT_NEAR(m.value(p)(2), 2 * p.x() * p.y() * p.z(), 1e-14);
  f[0].c[monomial_index(2, 0, 0)] = 1;  // x² + xy: not harmonic
  EXPECT_THROW(HarmonicPolynomialMap::from_components(4, f), InputError);
  EXPECT_THROW(harmonic_polynomial_basis(5), Error);
  EXPECT_THROW(HarmonicPolynomialMap(3, Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, 10)), InputError);
}

TEST(ExploreSigma, DerivativesMatchFiniteDifferences) {
  std::mt19937_64 rng(5);
  int checked = 0;
  for (int trial = 0; trial < 8; ++trial) {
    const PolynomialExplorerMap m(random_harmonic_map(2 + trial % 3, 500 + trial, 0.6));
    for (int t = 0; t < 10; ++t) {
      const Vec3 p = random_in_ball(rng, 0.9);
      const SigmaDerivatives d = map_sigma_derivatives(m, p, true);
      if (d.gap.minCoeff() < 0.05) continue;  // the formulas need simple singular values
      ++checked;
      const double h = 1e-5, hh = 1e-4;
      for (int k = 0; k < 3; ++k) {
        Vec3 e = Vec3::Zero();
        e(k) = h;
        const Vec3 ds =
            (signed_singular_values(m.jet(p + e).J) - signed_singular_values(m.jet(p - e).J)) / (2 * h);
        e(k) = hh;
        const SigmaDerivatives dp = map_sigma_derivatives(m, p + e, false),
                               dm = map_sigma_derivatives(m, p - e, false);
        for (int i = 0; i < 3; ++i) {
          const double scale = 1 + d.grad.row(i).norm();
          EXPECT_NEAR(ds(i), d.grad(i, k), 1e-7 * scale) << "sigma" << i + 1;
          const Vec3 dg = (dp.grad.row(i) - dm.grad.row(i)).transpose() / (2 * hh);
          for (int l = 0; l < 3; ++l)
            EXPECT_NEAR(dg(l), d.hess[i](l, k), 1e-5 * (1 + d.hess[i].norm())) << "sigma" << i + 1;
        }
      }
      for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(d.laplacian(i), d.hess[i].trace(), 1e-12 * (1 + d.hess[i].norm()));
    }
  }
  EXPECT_GT(checked, 40);
}

TEST(ExploreSigma, TwistExampleHessianMatchesClosedForm) {
  // The closed form of the twist family at the center (docs/explorer.md) against the general formula.
  const Vec3 s(2.0, 1.5, 0.7);
  const double c = 0.6, d = 0.04;
  const PolynomialExplorerMap m(twist_example(s, c, d));
  const SigmaDerivatives sd = map_sigma_derivatives(m, Vec3::Zero(), true);
  EXPECT_LT((sd.sigma - s).norm(), 1e-14);
  EXPECT_LT(sd.grad.row(2).norm(), 1e-14);
  const Vec3 expect(2 * c * c / (s(2) + s(0)) - 3 * d, 2 * c * c / (s(2) + s(1)) - 3 * d, 6 * d);
  EXPECT_LT((sd.hess[2] - Mat3(expect.asDiagonal())).norm(), 1e-13);
}

TEST(ExploreSigma, Sigma1SubharmonicSigma3NotSuperharmonic) {
  const std::vector<LaplacianSample> L = laplacian_experiment(4, 20, 40, 9);
  long used = 0, s3pos = 0;
  for (const LaplacianSample& q : L) {
    if (q.gap < 0.05) continue;
    ++used;
    // App. D: Δσ1 ≥ 0 (up to rounding).
    EXPECT_GE(q.lap_sigma1, -1e-10 * (1 + std::abs(q.lap_sigma1)));
    // The exact Laplacians agree with finite differences.
    EXPECT_NEAR(q.lap_sigma1, q.lap_sigma1_fd, 1e-3 * (1 + std::abs(q.lap_sigma1)));
    EXPECT_NEAR(q.lap_sigma3, q.lap_sigma3_fd, 1e-3 * (1 + std::abs(q.lap_sigma3)));
    s3pos += q.lap_sigma3 > 0;
    // The Laplacian is the sum of a non-positive (symmetric) and a non-negative (antisymmetric) part.
    EXPECT_LE(q.lap_sigma3_sym, 0);
    EXPECT_GE(q.lap_sigma3_anti, 0);
    EXPECT_NEAR(q.lap_sigma3, q.lap_sigma3_sym + q.lap_sigma3_anti, 1e-9 * (1 + std::abs(q.lap_sigma3_sym)));
  }
  EXPECT_GT(used, 500);
  // σ3 is not superharmonic: its Laplacian is positive at some points (and negative at others).
  EXPECT_GT(s3pos, 0);
  EXPECT_LT(s3pos, used);
}

TEST(ExploreCertificate, LowerBoundsHoldUnderDenseSamplingAndFoldsFail) {
  std::mt19937_64 rng(21);
  int certified = 0;
  for (int trial = 0; trial < 6; ++trial) {
    const HarmonicPolynomialMap map = trial < 3 ? twist_example(Vec3(2, 1.5, 0.6), 0.2 * trial, 0.03)
                                                : random_twist_map(4, 900 + trial, 0.3);
    BallCertifyParams p;
    p.max_depth = 6;
    const BallCertificate c = certify_sigma3_on_ball(map, Ball(), p);
    const PolynomialExplorerMap m(map);
    // The certificate's lower bound holds at every sampled point of the ball.
    double sampled = INFINITY;
    for (int t = 0; t < 3000; ++t)
      sampled = std::min(sampled, signed_singular_values(m.jet(random_in_ball(rng)).J)(2));
    if (c.certified) {
      ++certified;
      EXPECT_GT(c.min_lower_bound, 0);
      EXPECT_LE(c.min_lower_bound, sampled);
      EXPECT_LE(c.min_lower_bound, c.min_sigma3_center);
    }
    // Sphere-only certificate with a threshold just above the sampled minimum on the sphere must fail.
    const double sphere_min = sampled_sphere_min_sigma3(m, Ball(), 4).first;
    BallCertifyParams ps = p;
    ps.sphere_only = true;
    ps.threshold = sphere_min + 1e-9;
    EXPECT_FALSE(certify_sigma3_on_ball(map, Ball(), ps).certified);
  }
  EXPECT_GE(certified, 3);
  // A fold (det J < 0 somewhere in the ball) is never certified.
  const HarmonicPolynomialMap fold = twist_example(Vec3(1, 0.8, 0.1), 0, 0.5);
  const PolynomialExplorerMap fm(fold);
  EXPECT_LT(signed_singular_values(fm.jet(Vec3(0.9, 0, 0)).J)(2), 0);
  EXPECT_FALSE(certify_sigma3_on_ball(fold, Ball()).certified);
}

TEST(ExploreCounterexample, ShippedExampleIsVerified) {
  const std::string path = shipped_example();
  ASSERT_TRUE(fs::exists(path)) << path;
  const ExplorerExample ex = read_explorer_example(path);
  ASSERT_NE(ex.polynomial(), nullptr);
  const ExplorerMap& map = *ex.map;
  // Interior strict local minimum: critical point, positive definite Hessian (checked against a
  // finite-difference Hessian of σ3 itself), larger values on a small sphere around it.
  const std::vector<Sigma3Minimum> minima = find_sigma3_minima(map, ex.ball);
  ASSERT_FALSE(minima.empty());
  const Sigma3Minimum& m = minima[0];
  EXPECT_TRUE(m.strict);
  EXPECT_GT(m.sigma3, 0);
  EXPECT_LT((m.position - ex.ball.center).norm(), 0.5 * ex.ball.radius);
  EXPECT_LT(m.gradient_norm, 1e-9);
  EXPECT_GT(m.hessian_eigenvalues(0), 0.05);
  const double h = 1e-3;
  auto s3 = [&](const Vec3& p) { return signed_singular_values(map.jet(p).J)(2); };
  Mat3 Hfd;
  for (int k = 0; k < 3; ++k)
    for (int l = 0; l < 3; ++l) {
      Vec3 ek = Vec3::Zero(), el = Vec3::Zero();
      ek(k) = h;
      el(l) = h;
      Hfd(k, l) = (s3(m.position + ek + el) - s3(m.position + ek - el) - s3(m.position - ek + el) +
                   s3(m.position - ek - el)) /
                  (4 * h * h);
    }
  Eigen::SelfAdjointEigenSolver<Mat3> es(0.5 * (Hfd + Hfd.transpose()));
  EXPECT_GT(es.eigenvalues()(0), 0.05);
  EXPECT_LT((es.eigenvalues() - m.hessian_eigenvalues).norm(), 1e-4);
  EXPECT_GT(m.sphere_min_sigma3, m.sigma3);
  // The minimum over the closed ball is interior: σ3 > σ3(x*) on the whole boundary sphere (certified) —
  // strictly below every sampled sphere value too.
  const double sphere_sampled = sampled_sphere_min_sigma3(map, ex.ball, 4).first;
  EXPECT_GT(sphere_sampled, m.sigma3 * 1.1);
  BallCertifyParams ps;
  ps.sphere_only = true;
  ps.threshold = m.sigma3;
  const BallCertificate sc = certify_sigma3_on_ball(*ex.polynomial(), ex.ball, ps);
  EXPECT_TRUE(sc.certified) << sc.reason;
  // Locally injective on the whole ball (certified σ3 > 0).
  const BallCertificate c = certify_sigma3_on_ball(*ex.polynomial(), ex.ball);
  EXPECT_TRUE(c.certified) << c.reason;
  EXPECT_GT(c.min_lower_bound, 0);
  // The boundary sphere maps to an embedded surface (exact self-intersection test of its triangulated image).
  const BoundaryEmbedding be = check_boundary_embedding(map, ex.ball, 5);
  EXPECT_TRUE(be.embedded);
  EXPECT_EQ(be.intersecting_pairs, 0);
  EXPECT_GT(be.signed_volume, 0);
}

TEST(ExploreCounterexample, BoundaryCheckDetectsASelfIntersectingImage) {
  // f = (x² − y², 2xy, z) wraps the sphere around the z axis twice: locally injective away from the axis but
  // the boundary image overlaps itself.
  std::array<Polynomial, 3> f;
  f[0].c[monomial_index(2, 0, 0)] = 1;
  f[0].c[monomial_index(0, 2, 0)] = -1;
  f[1].c[monomial_index(1, 1, 0)] = 2;
  f[2].c[monomial_index(0, 0, 1)] = 1;
  const PolynomialExplorerMap m(HarmonicPolynomialMap::from_components(2, f));
  const BoundaryEmbedding be = check_boundary_embedding(m, Ball(), 3);
  EXPECT_FALSE(be.embedded);
  EXPECT_GT(be.intersecting_pairs, 0);
}

TEST(ExploreCounterexample, VerdictNeedsEveryCheck) {
  // Check results as the checks report them; the verdict holds only with all five, each failing one named.
  Sigma3Minimum m;
  m.sigma3 = 0.6;
  m.strict = true;
  BallCertificate li, ba;
  li.certified = ba.certified = true;
  li.min_sigma3_center = 0.5;
  ba.sphere_only = true;
  ba.threshold = 0.6;
  BoundaryInjectivity bi;
  bi.certified = true;
  BoundaryEmbedding be;
  be.embedded = true;
  CounterexampleChecks c{&m, &li, &ba, &bi, &be};
  EXPECT_TRUE(counterexample_verdict(c).verified);
  EXPECT_TRUE(counterexample_verdict(c).reasons.empty());
  EXPECT_DOUBLE_EQ(boundary_injectivity_threshold(li, &m), 0.25);
  EXPECT_DOUBLE_EQ(boundary_injectivity_threshold(li, nullptr), 0.25);
  auto fails_once = [&](const CounterexampleChecks& k) {
    const CounterexampleVerdict v = counterexample_verdict(k);
    return !v.verified && v.reasons.size() == 1;
  };
  m.strict = false;
  EXPECT_TRUE(fails_once(c));
  m.strict = true;
  m.sigma3 = -0.1;  // not locally injective at x*
  EXPECT_FALSE(counterexample_verdict(c).verified);
  m.sigma3 = 0.6;
  ba.threshold = 0.5;  // the sphere certified above less than σ3(x*)
  EXPECT_TRUE(fails_once(c));
  ba.threshold = 0.6;
  li.sphere_only = true;  // σ3 > 0 on the sphere only is not local injectivity
  EXPECT_TRUE(fails_once(c));
  li.sphere_only = false;
  bi.certified = false;
  EXPECT_TRUE(fails_once(c));
  bi.certified = true;
  be.embedded = false;
  EXPECT_TRUE(fails_once(c));
  be.embedded = true;
  // A check that was not run fails the verdict (cage maps have no sphere certificates).
  EXPECT_TRUE(fails_once({&m, &li, &ba, nullptr, &be}));
  EXPECT_EQ(counterexample_verdict({&m, &li, nullptr, nullptr, &be}).reasons.size(), 2u);
  EXPECT_TRUE(counterexample_verdict(c).verified);
}

TEST(ExploreSearch, DeterministicWithFixedSeedAndThreadCount) {
  SearchParams p;
  p.family = SearchFamily::kTwist;
  p.trials = 30;
  p.seed = 42;
  p.max_amplitude = 0.05;
  p.minima.starts = 8;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const std::vector<SearchTrial> a = search_sigma3_minima(p);
  omp_set_num_threads(std::max(2, threads));
  const std::vector<SearchTrial> b = search_sigma3_minima(p);
  omp_set_num_threads(threads);
  ASSERT_EQ(a.size(), b.size());
  int found = 0;
  for (size_t t = 0; t < a.size(); ++t) {
    EXPECT_EQ(a[t].seed, b[t].seed);
    EXPECT_EQ(a[t].map.coefficients(), b[t].map.coefficients());
    ASSERT_EQ(a[t].minima.size(), b[t].minima.size());
    for (size_t i = 0; i < a[t].minima.size(); ++i) {
      EXPECT_EQ(a[t].minima[i].position, b[t].minima[i].position);
      EXPECT_EQ(a[t].minima[i].sigma3, b[t].minima[i].sigma3);
    }
    EXPECT_EQ(a[t].sphere_min_sigma3, b[t].sphere_min_sigma3);
    found += a[t].strict_minima > 0;
  }
  EXPECT_GT(found, 0);  // the twist family does produce interior minima
  // Another seed gives other maps.
  p.seed = 43;
  EXPECT_NE(search_sigma3_minima(p)[0].map.coefficients(), a[0].map.coefficients());
}

// --- The CLI.
TEST(ExploreCli, ShowWritesEverythingAndIsDeterministic) {
  TempDir tmp;
  std::string log;
  const std::string base =
      lidef::test::cli() + " explore show " + shipped_example() + " --grid 16 --sphere-subdivisions 3";
  ASSERT_EQ(lidef::test::run_command(base + " --out " + tmp / "a", &log), 0) << log;
  EXPECT_NE(log.find("verified counterexample"), std::string::npos) << log;
  for (const char* f : {"map.json", "minima.csv", "fields.vti", "sphere.vtp", "image.vtp", "slice.gp",
                        "slice_xy.dat", "slice_xz.dat", "summary.json"})
    EXPECT_TRUE(fs::exists(tmp / "a" + std::string("/") + f)) << f;
  // map.json round-trips: it is a loadable example with the same coefficients.
  const ExplorerExample a = read_explorer_example(tmp / "a/map.json");
  const ExplorerExample s = read_explorer_example(shipped_example());
  EXPECT_EQ(a.polynomial()->coefficients(), s.polynomial()->coefficients());
  ASSERT_EQ(lidef::test::run_command(base + " --threads 1 --out " + tmp / "b", &log), 0) << log;
  for (const char* f : {"map.json", "minima.csv", "summary.json", "slice_xy.dat", "fields.vti", "image.vtp"})
    EXPECT_EQ(lidef::test::read_text(tmp / "a/" + f), lidef::test::read_text(tmp / "b/" + f)) << f;
}

TEST(ExploreCli, VtkFilesHoldTheFields) {
  TempDir tmp;
  std::string log;
  ASSERT_EQ(lidef::test::run_command(lidef::test::cli() + " explore show " + shipped_example() +
                                         " --grid 17 --sphere-subdivisions 2 --out " + tmp / "o",
                                     &log),
            0)
      << log;
  const ExplorerExample ex = read_explorer_example(shipped_example());
  vtkNew<vtkXMLImageDataReader> ir;
  ir->SetFileName((tmp / "o/fields.vti").c_str());
  ir->Update();
  vtkImageData* im = ir->GetOutput();
  int dims[3];
  im->GetDimensions(dims);
  EXPECT_EQ(dims[0], 17);
  EXPECT_EQ(dims[2], 17);
  vtkDataArray *s1 = im->GetPointData()->GetArray("sigma1"), *s3 = im->GetPointData()->GetArray("sigma3"),
               *det = im->GetPointData()->GetArray("detJ"), *in = im->GetPointData()->GetArray("inside_ball");
  ASSERT_TRUE(s1 && s3 && det && in && im->GetPointData()->GetArray("sigma2"));
  long inside = 0;
  for (vtkIdType i = 0; i < im->GetNumberOfPoints(); ++i) {
    double p[3];
    im->GetPoint(i, p);
    const Vec3 x(p[0], p[1], p[2]);
    EXPECT_EQ(in->GetTuple1(i) == 1, x.norm() <= 1 + 1e-12) << x.transpose();
    if (in->GetTuple1(i) != 1) {
      EXPECT_TRUE(std::isnan(s3->GetTuple1(i)));
      continue;
    }
    ++inside;
    const Mat3 J = ex.map->jacobian(x);
    const Vec3 s = signed_singular_values(J);
    EXPECT_NEAR(s3->GetTuple1(i), s(2), 1e-6);
    EXPECT_NEAR(s1->GetTuple1(i), s(0), 1e-6);
    EXPECT_NEAR(det->GetTuple1(i), J.determinant(), 1e-5);
  }
  EXPECT_GT(inside, 1000);
  // The image surface: the boundary sphere's image, with σ3 per vertex.
  vtkNew<vtkXMLPolyDataReader> pr;
  pr->SetFileName((tmp / "o/image.vtp").c_str());
  pr->Update();
  vtkPolyData* pd = pr->GetOutput();
  ASSERT_GT(pd->GetNumberOfPoints(), 100);
  ASSERT_NE(pd->GetPointData()->GetArray("sigma3"), nullptr);
  vtkNew<vtkXMLPolyDataReader> sr;
  sr->SetFileName((tmp / "o/sphere.vtp").c_str());
  sr->Update();
  for (vtkIdType i = 0; i < pd->GetNumberOfPoints(); i += 7) {
    double a[3], b[3];
    sr->GetOutput()->GetPoint(i, a);
    pd->GetPoint(i, b);
    EXPECT_NEAR((ex.map->value(Vec3(a[0], a[1], a[2])) - Vec3(b[0], b[1], b[2])).norm(), 0, 1e-6);
  }
}

TEST(ExploreCli, BadInputsFailWithoutOutput) {
  TempDir tmp;
  const std::string good = lidef::test::read_text(shipped_example());
  struct Case {
    std::string name, text, expect;
  };
  std::string wrong_degree = good;
  wrong_degree.replace(wrong_degree.find("\"degree\": 4"), 11, "\"degree\": 7");
  std::string wrong_rows = good;
  wrong_rows.replace(wrong_rows.find("\"degree\": 4"), 11, "\"degree\": 3");
  std::string nan = good;
  nan.replace(nan.find("[0, 0, 0]"), 9, "[NaN, 0, 0]");
  std::string big = good;
  big.replace(big.find("[0, 0, 0]"), 9, "[1e999, 0, 0]");
  const std::vector<Case> cases = {
      {"malformed.json", "{\"format\": \"lidef-explorer-map\", ", "malformed JSON"},
      {"degree.json", wrong_degree, "degree must be in 1..4"},
      {"rows.json", wrong_rows, "needs 16 coefficient rows"},
      {"nan.json", nan, "malformed JSON"},
      {"big.json", big, "number overflow"},
      {"type.json", "{\"format\": \"lidef-explorer-map\", \"type\": \"spline\"}", "\"type\" must be"},
      // Members of the wrong JSON type get a message, not the JSON library's type error.
      {"format_number.json", "{\"format\": 3, \"type\": \"cage\"}", "\"format\" must be a string"},
      {"type_array.json", "{\"format\": \"lidef-explorer-map\", \"type\": [1]}", "\"type\" must be a string"},
  };
  for (const Case& c : cases) {
    lidef::test::write_text(tmp / c.name, c.text);
    std::string log;
    const std::string out = tmp / ("out_" + c.name);
    EXPECT_EQ(lidef::test::run_command(lidef::test::cli() + " explore show " + tmp / c.name + " --out " + out,
                                       &log),
              2)
        << c.name << ": " << log;
    EXPECT_NE(log.find(c.name), std::string::npos) << log;
    EXPECT_NE(log.find(c.expect), std::string::npos) << c.name << ": " << log;
    EXPECT_FALSE(fs::exists(out)) << c.name;
  }
  std::string log;
  EXPECT_EQ(
      lidef::test::run_command(lidef::test::cli() + " explore search --degree 5 --out " + tmp / "s", &log),
      2);
  EXPECT_NE(log.find("--degree"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(tmp / "s"));
  EXPECT_EQ(lidef::test::run_command(
                lidef::test::cli() + " explore show " + tmp / "missing.json --out " + tmp / "m", &log),
            2);
  EXPECT_FALSE(fs::exists(tmp / "m"));
}

TEST(ExploreCli, SearchIsByteIdenticalForAFixedSeed) {
  TempDir tmp;
  const std::string cmd =
      lidef::test::cli() +
      " explore search --family twist --trials 10 --amplitude 0.15 --starts 8 --verify 1 --grid 8 "
      "--sphere-subdivisions 2 --seed 5";
  std::string log;
  const int rc = lidef::test::run_command(cmd + " --out " + tmp / "a", &log);
  ASSERT_TRUE(rc == 0 || rc == 1) << log;
  ASSERT_EQ(lidef::test::run_command(cmd + " --threads 1 --out " + tmp / "b", &log), rc) << log;
  for (const char* f : {"trials.csv", "minima.csv", "summary.json"})
    EXPECT_EQ(lidef::test::read_text(tmp / "a/" + f), lidef::test::read_text(tmp / "b/" + f)) << f;
  EXPECT_FALSE(lidef::test::read_text(tmp / "a/trials.csv").empty());
}

TEST(ExploreCage, CageMapsThroughTheSameInterface) {
  TempDir tmp;
  const std::string model = lidef::test::project_data() + "/models/ball";
  ASSERT_TRUE(fs::exists(model)) << model;
  // A cage map file: identity coefficients on the project's ball model, a ball of radius 0.8 inside the cage.
  lidef::test::write_text(tmp / "id.json",
                          "{\"format\": \"lidef-explorer-map\", \"type\": \"cage\", \"model\": \"" + model +
                              "\", \"coefficients\": \"identity\", \"domain\": {\"radius\": 0.8}}");
  const ExplorerExample ex = read_explorer_example(tmp / "id.json");
  ASSERT_EQ(ex.polynomial(), nullptr);
  const auto* cm = dynamic_cast<const CageExplorerMap*>(ex.map.get());
  ASSERT_NE(cm, nullptr);
  // The identity is reproduced; the finite-difference third derivatives vanish.
  std::mt19937_64 rng(1);
  for (int t = 0; t < 5; ++t) {
    const Vec3 p = random_in_ball(rng, 0.8);
    const PolyJet j = cm->jet(p);
    EXPECT_LT((j.f - p).norm(), 1e-10);
    EXPECT_LT((j.J - Mat3::Identity()).norm(), 1e-9);
    EXPECT_LT(j.third_norm(), 1e-4);
  }
  // σ3 ≡ 1: no strict minimum; certified with σ3 ≥ 1 − rounding.
  EXPECT_TRUE(find_sigma3_minima(*cm, ex.ball, {4}).empty() ||
              !find_sigma3_minima(*cm, ex.ball, {4})[0].strict);
  const BallCertificate c = certify_cage_map_on_ball(*cm, ex.ball, 2);
  EXPECT_TRUE(c.certified) << c.reason;
  // The bound includes the rounding allowance (float storage of the basis derivatives, ~5e-6 here) and is
  // never above the true σ3 = 1.
  EXPECT_NEAR(c.min_lower_bound, 1, 1e-5);
  EXPECT_LE(c.min_lower_bound, 1);
  // A reflection (σ3 = −1) is not certified; a domain ball that sticks out of the cage is refused.
  const Model m = load_model(model);
  const CageExplorerMap refl(m.cage, m.cage.affine_coefficients(Vec3(1, 1, -1).asDiagonal(), Vec3::Zero()),
                             "refl");
  EXPECT_FALSE(certify_cage_map_on_ball(refl, ex.ball, 2).certified);
  Ball big;
  big.radius = 1.5;
  EXPECT_FALSE(certify_cage_map_on_ball(*cm, big, 2).certified);
  lidef::test::write_text(tmp / "big.json",
                          "{\"format\": \"lidef-explorer-map\", \"type\": \"cage\", \"model\": \"" + model +
                              "\", \"coefficients\": \"identity\", \"domain\": {\"radius\": 1.5}}");
  EXPECT_NE(lidef::test::input_error_message([&] {
              read_explorer_example(tmp / "big.json");
            }).find("not inside the cage"),
            std::string::npos);
  // T of a non-affine cage map: finite differences of H with two steps agree (the difference error is small).
  MatX3d y = m.cage.identity_coefficients();
  for (int i = 0; i < y.rows(); ++i)
    y.row(i) += 0.05 * Vec3(std::sin(3.0 * i), std::cos(5.0 * i), std::sin(7.0 * i)).transpose();
  const CageExplorerMap a(m.cage, y, "a", 1e-4), b(m.cage, y, "b", 1e-3);
  const Vec3 p(0.2, -0.3, 0.1);
  const PolyJet ja = a.jet(p), jb = b.jet(p);
  for (int q = 0; q < 3; ++q)
    for (int r = 0; r < 3; ++r) EXPECT_LT((ja.T[q][r] - jb.T[q][r]).norm(), 1e-4 * (1 + ja.third_norm()));
}

TEST(ExploreCertificate, CellBoundDominatesHessianNormOnTheBall) {
  // ‖H(x)‖ ≤ L(q, r) for x in B(q, r), sampled inside and on the sphere; includes a quartic with H = T = 0 at
  // the center, where only the fourth-derivative term r²‖F‖ is left.
  std::array<Polynomial, 3> f;
  f[0].c[monomial_index(4, 0, 0)] = 1;  // Re (x + iy)⁴
  f[0].c[monomial_index(2, 2, 0)] = -6;
  f[0].c[monomial_index(0, 4, 0)] = 1;
  f[1].c[monomial_index(0, 1, 0)] = 1;
  f[2].c[monomial_index(0, 0, 1)] = 1;
  std::vector<HarmonicPolynomialMap> maps{HarmonicPolynomialMap::from_components(4, f)};
  for (int i = 0; i < 4; ++i) maps.push_back(random_harmonic_map(2 + i % 3, 70 + i, 0.8));
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(0, 1);
  for (const HarmonicPolynomialMap& m : maps)
    for (int c = 0; c < 20; ++c) {
      const Vec3 q = c == 0 ? Vec3::Zero() : random_in_ball(rng);
      const double r = 0.02 + 0.3 * u(rng);
      const double L = cell_lipschitz_bound(m.jet(q, 3), m.fourth_norm(), r);
      const double s3q = signed_singular_values(m.jet(q, 1).J)(2);
      for (int t = 0; t < 200; ++t) {
        Vec3 d = random_in_ball(rng);
        if (t % 2) d.normalize();
        const Vec3 x = q + r * d;
        const PolyJet jx = m.jet(x, 2);
        EXPECT_LE(jx.hessian_norm(), L * (1 + 1e-12) + 1e-14);
        // Theorem 4.1 on the segment [q, x]: |σ3(x) − σ3(q)| ≤ |x − q| L.
        EXPECT_LE(std::abs(signed_singular_values(jx.J)(2) - s3q), (x - q).norm() * L * (1 + 1e-12) + 1e-14);
      }
    }
}

TEST(ExploreBoundary, TriangleDistanceMatchesSampling) {
  std::mt19937_64 rng(8);
  std::normal_distribution<double> n;
  int tested = 0;
  for (int t = 0; t < 200 && tested < 60; ++t) {
    std::array<Vec3, 3> A, B;
    const Vec3 shift(n(rng), n(rng), n(rng));
    for (int k = 0; k < 3; ++k) {
      A[k] = Vec3(n(rng), n(rng), n(rng)) * 0.5;
      B[k] = Vec3(n(rng), n(rng), n(rng)) * 0.5 + 1.5 * shift;
    }
    // Brute force over barycentric grids of both triangles (a dense sampling of their points).
    auto pts = [](const std::array<Vec3, 3>& T) {
      std::vector<Vec3> p;
      const int m = 40;
      for (int i = 0; i <= m; ++i)
        for (int j = 0; i + j <= m; ++j)
          p.push_back(T[0] + (T[1] - T[0]) * (double(i) / m) + (T[2] - T[0]) * (double(j) / m));
      return p;
    };
    const std::vector<Vec3> pa = pts(A), pb = pts(B);
    double brute = INFINITY;
    for (const Vec3& a : pa)
      for (const Vec3& b : pb) brute = std::min(brute, (a - b).norm());
    if (brute < 0.05) continue;  // possibly intersecting: outside the function's contract
    ++tested;
    const double d = disjoint_triangle_distance(A, B);
    EXPECT_LE(d, brute + 1e-12);
    // The grid spacing bounds how far the sampled minimum can be above the true one.
    const double spacing =
        std::max({(A[1] - A[0]).norm(), (A[2] - A[0]).norm(), (B[1] - B[0]).norm(), (B[2] - B[0]).norm()}) /
        40;
    EXPECT_GE(d, brute - 2 * spacing);
  }
  EXPECT_GE(tested, 30);
}

TEST(ExploreBoundary, BoundaryInjectivityCertificate) {
  const ExplorerExample ex = read_explorer_example(shipped_example());
  const HarmonicPolynomialMap& m = *ex.polynomial();
  // A fine enough net certifies it, with some pairs measured exactly; a coarse net cannot.
  const BoundaryInjectivity fine = certify_boundary_injective(m, ex.ball, 0.3, 5);
  EXPECT_TRUE(fine.certified) << fine.reason;
  EXPECT_GT(fine.pairs_measured, 0);
  EXPECT_GT(fine.min_pair_margin, 0);
  EXPECT_GE(fine.sigma3_lower, 0.3);
  EXPECT_GT(fine.rho, 0);
  EXPECT_FALSE(certify_boundary_injective(m, ex.ball, 0.3, 3).certified);
  // The bounds it uses hold at sampled points: ‖H‖ ≤ H, ‖J‖_F ≤ G, σ3 ≥ s.
  std::mt19937_64 rng(4);
  for (int t = 0; t < 2000; ++t) {
    const PolyJet j = m.jet(random_in_ball(rng), 2);
    EXPECT_LE(j.hessian_norm(), fine.hessian_bound);
    EXPECT_LE(j.J.norm(), fine.jacobian_bound);
    EXPECT_GE(signed_singular_values(j.J)(2), fine.sigma3_lower);
  }
  // Far-apart sphere points have far-apart images: the margin the certificate relies on, sampled.
  double worst = INFINITY;
  for (int t = 0; t < 20000; ++t) {
    const Vec3 p = random_in_ball(rng).normalized(), q = random_in_ball(rng).normalized();
    if ((p - q).norm() >= fine.rho) worst = std::min(worst, (m.value(p) - m.value(q)).norm());
  }
  EXPECT_GT(worst, 0);
  // The σ3 threshold must be certified first: a threshold above the minimum 0.6 fails.
  EXPECT_FALSE(certify_boundary_injective(m, ex.ball, 0.7, 5).certified);
  // The double cover (x² − y², 2xy, z) is not locally injective on the axis: refused.
  std::array<Polynomial, 3> f;
  f[0].c[monomial_index(2, 0, 0)] = 1;
  f[0].c[monomial_index(0, 2, 0)] = -1;
  f[1].c[monomial_index(1, 1, 0)] = 2;
  f[2].c[monomial_index(0, 0, 1)] = 1;
  EXPECT_FALSE(
      certify_boundary_injective(HarmonicPolynomialMap::from_components(2, f), Ball(), 0.01, 4).certified);
}

TEST(ExploreCage, ShowOnACageMapWritesAReloadableMapFile) {
  TempDir tmp;
  const std::string model = lidef::test::project_data() + "/models/ball";
  ASSERT_TRUE(fs::exists(model)) << model;
  lidef::test::write_text(tmp / "id.json",
                          "{\"format\": \"lidef-explorer-map\", \"type\": \"cage\", \"model\": \"" + model +
                              "\", \"coefficients\": \"identity\", \"domain\": {\"radius\": 0.8}}");
  std::string log;
  // Not a counterexample (σ3 ≡ 1: no strict minimum): exit 1, but every file is written.
  ASSERT_EQ(lidef::test::run_command(lidef::test::cli() + " explore show " + tmp / "id.json" +
                                         " --grid 8 --sphere-subdivisions 2 --starts 2 --max-depth 2 --out " +
                                         tmp / "o",
                                     &log),
            1)
      << log;
  EXPECT_NE(log.find("local injectivity on the ball: certified"), std::string::npos) << log;
  const ExplorerExample again = read_explorer_example(tmp / "o/map.json");
  EXPECT_EQ(again.kind, "cage");
  EXPECT_EQ(again.ball.radius, 0.8);
  EXPECT_LT((again.map->value(Vec3(0.1, 0.2, 0.3)) - Vec3(0.1, 0.2, 0.3)).norm(), 1e-10);
}
