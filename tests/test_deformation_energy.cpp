// DeformationEnergy (deformation_energy.h) against independent truths, on the project's beam cage with a real
// spectral subspace, a few hundred voxel samples and four handles: its gradient and exact Hessian against
// central differences, the projected single-precision Hessian against a brute-force double assembly of
// Σ_i B_iᵀ H_i⁺ B_i with explicit 9 x 3s matrices B_i, E_smooth against the sparse K of smoothness.h, E_P2P
// against the basis evaluated in full space, the det J ≤ 0 barrier, thread-count independence, and the
// identity as a zero of energy and gradient.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>

#include "lidef/deformation_energy.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/model_check.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"
#include "lidef/smoothness.h"
#include "lidef/subspace.h"
#include "lidef/symmetric_dirichlet.h"
#include "test_support.h"

using namespace lidef;

namespace {

// Everything that depends only on the cage: built once for the whole file.
struct EnergySetup {
  explicit EnergySetup(Model m) : model(std::move(m)) {}
  Model model;
  SpectralSubspace sub;  // s = 40
  VoxelSampling sampling;
  std::unique_ptr<HarmonicBasis> basis;
  MatXdR G;          // 3|I| by s, as in DeformationSolver's constructor
  MatX3d sources;    // 4 handles
  MatXd D;           // #h by s
  MatS3 y_identity;  // Ξᵀ y_id
};

const EnergySetup& setup() {
  static const std::unique_ptr<EnergySetup> S = [] {
    auto s = std::make_unique<EnergySetup>(load_model(lidef::test::project_data() + "/models/beam"));
    const Cage& cage = s->model.cage;
    s->sub = compute_subspace(cage, 40);
    SamplingParams sp;
    sp.target_count = 600;  // > 2 chunks of 256 samples, so the chunked sums are exercised
    sp.count_tolerance = 0.15;
    s->sampling = sample_voxels(cage, sp);
    s->basis = std::make_unique<HarmonicBasis>(cage);
    s->G = s->basis->gradient_matrix(s->sampling.centers) * s->sub.basis;
    s->sources.resize(4, 3);
    s->sources << -0.8, 0.0, 0.0, 0.8, 0.1, -0.05, 0.0, -0.1, 0.1, 0.35, 0.15, -0.15;
    s->D = s->basis->value_matrix(s->sources) * s->sub.basis;
    s->y_identity = s->sub.basis.transpose() * cage.identity_coefficients();
    return s;
  }();
  return *S;
}

DeformationEnergy make_energy(std::vector<int> subset = {}) {
  const EnergySetup& S = setup();
  return DeformationEnergy(S.G, std::move(subset), S.sub.eigenvalues, S.model.cage.num_edges());
}

// Targets = sources + a seeded offset of about 0.05 (the beam is 2 x 0.4 x 0.4).
MatX3d offset_targets(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01;
  MatX3d Q = setup().sources;
  for (int i = 0; i < Q.rows(); ++i)
    for (int c = 0; c < 3; ++c) Q(i, c) += 0.03 * N01(rng);
  return Q;
}

// Amplitude of the random reduced perturbation: large enough that the singular values of the test map's
// Jacobians spread to about ±0.3 around 1 (so SD is far from its quadratic regime and some twist eigenvalues
// are clearly negative), small enough that det J stays well above 0 at every sample.
constexpr double kAmp = 0.3;

// A smooth non-rigid map near the identity: ỹ = Ξᵀ y_id + amp · N(0,1) on every reduced coefficient (the
// affine columns too, so it is also a small random affine change).
MatS3 random_map(double amp, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01;
  MatS3 y = setup().y_identity;
  for (int j = 0; j < y.rows(); ++j)
    for (int a = 0; a < 3; ++a) y(j, a) += amp * N01(rng);
  return y;
}

double min_det(const MatJT& JT) {
  double m = std::numeric_limits<double>::infinity();
  for (int i = 0; i < JT.rows() / 3; ++i) m = std::min(m, JT.middleRows<3>(3 * i).determinant());
  return m;
}

// Largest |σ − 1| over the samples: how far from a rotation-free map the test map is.
double max_stretch(const MatJT& JT) {
  double m = 0;
  for (int i = 0; i < JT.rows() / 3; ++i) {
    const Vec3 sv = signed_singular_values(JT.middleRows<3>(3 * i).transpose());
    m = std::max(m, (sv.array() - 1.0).abs().maxCoeff());
  }
  return m;
}

// The test map: checked to keep det J > 0 at every sample, and to be far enough from the identity that the
// SD Hessian has negative (twist) eigenvalues somewhere, so that the PSD projection does something.
struct TestMap {
  MatS3 y;
  MatJT JT;
};
TestMap test_map(const DeformationEnergy& E) {
  TestMap m{random_map(kAmp, 17), {}};
  m.JT = E.jacobians(m.y);
  return m;
}

MatXd vec_hessian_fd(const DeformationEnergy& E, const MatS3& y, const EnergyWeights& w, double h) {
  const int s = E.reduced_size();
  MatXd H(3 * s, 3 * s);
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < s; ++j) {
      MatS3 yp = y, ym = y;
      yp(j, a) += h;
      ym(j, a) -= h;
      const MatS3 gp = E.gradient(E.jacobians(yp), yp, w), gm = E.gradient(E.jacobians(ym), ym, w);
      const MatS3 col = (gp - gm) / (2 * h);
      H.col(j + s * a) = Eigen::Map<const VecXd>(col.data(), 3 * s);
    }
  return H;
}

}  // namespace

TEST(DeformationEnergy, TestMapIsOrientationPreservingAndNonTrivial) {
  const DeformationEnergy E = make_energy();
  const TestMap m = test_map(E);
  EXPECT_GE(E.num_samples(), 300);
  EXPECT_GT(min_det(m.JT), 0.3) << "the test map must keep det J > 0 at every sample";
  const double st = max_stretch(m.JT);
  EXPECT_GT(st, 0.05) << "the test map is too close to the identity to exercise the energy";
  EXPECT_LT(st, 0.7);
  // Some sample is compressed enough for a negative twist eigenvalue, so projection changes the Hessian.
  int indefinite = 0;
  for (int i = 0; i < E.num_samples(); ++i) {
    const Eigen::SelfAdjointEigenSolver<Mat9> es(sd_hessian(m.JT.middleRows<3>(3 * i).transpose()));
    if (es.eigenvalues()(0) < 0) ++indefinite;
  }
  EXPECT_GT(indefinite, 0);
  // ... and the projection changes the reduced Hessian by a visible amount.
  const MatXd Hp = E.distortion_hessian(m.JT, true, true), Hu = E.distortion_hessian(m.JT, false, true);
  const double change = (Hp - Hu).cwiseAbs().maxCoeff() / Hu.cwiseAbs().maxCoeff();
  EXPECT_GT(change, 1e-3);
  std::printf(
      "samples %d, reduced size %d, min det J %.4f, max |sigma-1| %.4f, indefinite samples %d, "
      "projection changes max|H| by %.3g\n",
      E.num_samples(), E.reduced_size(), min_det(m.JT), st, indefinite, change);
}

TEST(DeformationEnergy, GradientOfEachTermMatchesCentralDifferences) {
  // Each term isolated by the weights: E_dis = E(0,0) (its weight is always 1), E_P2P = E(1,0) − E(0,0),
  // E_smooth = E(0,1) − E(0,0); the same differences of gradient(). Central differences with h = 1e-6 on all
  // 3s coordinates: truncation error h²/6 |E'''| ~ 1e-12 and rounding ~1e-16 |E| / h ~ 1e-10 for |E| ≲ 1, so
  // a tolerance of 1e-6 · max|∇| (+1e-9 absolute) leaves a wide margin and still catches any wrong factor
  // or transposed index.
  DeformationEnergy E = make_energy();
  E.set_handles(setup().D, offset_targets(3));
  const TestMap m = test_map(E);
  const int s = E.reduced_size();
  const double h = 1e-6;
  const EnergyWeights w00{0, 0}, w10{1, 0}, w01{0, 1};
  const MatS3 g00 = E.gradient(m.JT, m.y, w00);
  const MatS3 g10 = E.gradient(m.JT, m.y, w10) - g00;
  const MatS3 g01 = E.gradient(m.JT, m.y, w01) - g00;
  MatS3 fd00(s, 3), fd10(s, 3), fd01(s, 3);
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < s; ++j) {
      MatS3 yp = m.y, ym = m.y;
      yp(j, a) += h;
      ym(j, a) -= h;
      const double p00 = E.evaluate(yp, w00).total, m00 = E.evaluate(ym, w00).total;
      fd00(j, a) = (p00 - m00) / (2 * h);
      fd10(j, a) = ((E.evaluate(yp, w10).total - p00) - (E.evaluate(ym, w10).total - m00)) / (2 * h);
      fd01(j, a) = ((E.evaluate(yp, w01).total - p00) - (E.evaluate(ym, w01).total - m00)) / (2 * h);
    }
  struct Term {
    const char* name;
    const MatS3 &g, &fd;
  } terms[] = {{"E_dis", g00, fd00}, {"E_P2P", g10, fd10}, {"E_smooth", g01, fd01}};
  for (const Term& t : terms) {
    const double scale = t.g.cwiseAbs().maxCoeff();
    EXPECT_GT(scale, 1e-6) << t.name << ": the term must not vanish at the test map";
    const double err = (t.g - t.fd).cwiseAbs().maxCoeff();
    EXPECT_LT(err, 1e-6 * scale + 1e-9) << t.name;
    std::printf("%-8s max|grad| %.3e  max|grad - fd| %.3e\n", t.name, scale, err);
  }
}

TEST(DeformationEnergy, ExactHessianMatchesCentralDifferencesOfGradient) {
  // hessian(JT, w, projected=false, all_samples=true) is the exact ∇²E. Central differences of gradient()
  // with h = 1e-5: truncation h²/6 |E''''| ~ 1e-10 and rounding ~1e-16 |∇E| / h ~ 1e-11, so 1e-6 · max|H| is
  // a safe bound; it is far below the size of any block error (a missing cross block is O(max|H|)).
  DeformationEnergy E = make_energy();
  E.set_handles(setup().D, offset_targets(4));
  const TestMap m = test_map(E);
  const EnergyWeights w{10.0, 0.5};
  const MatXd H = E.hessian(m.JT, w, false, true);
  const MatXd Hfd = vec_hessian_fd(E, m.y, w, 1e-5);
  const double scale = H.cwiseAbs().maxCoeff();
  const double err = (H - Hfd).cwiseAbs().maxCoeff();
  EXPECT_LT(err, 1e-6 * scale) << "max|H| = " << scale;
  std::printf("max|H| %.3e  max|H - fd| %.3e\n", scale, err);
  // The unprojected Hessian of this map is indefinite: the projection in the solver's matrix is not moot.
  const MatXd Hd = E.distortion_hessian(m.JT, false, true);
  const Eigen::SelfAdjointEigenSolver<MatXd> es(Hd);
  std::printf("unprojected distortion Hessian eigenvalues: min %.3e max %.3e\n", es.eigenvalues()(0),
              es.eigenvalues()(es.eigenvalues().size() - 1));
}

TEST(DeformationEnergy, ProjectedSinglePrecisionHessianEqualsBruteForceAssembly) {
  // Three assemblies of the projected Hessian, weights (0, 0) so that only the distortion part is compared:
  //  (a) hessian(JT, w, true, false) on an energy whose subset H is every sample: float GHᵀ diag(H̃) GH;
  //  (b) hessian(JT, w, true, true): the same in double;
  //  (c) brute force Σ_i B_iᵀ H_i⁺ B_i / |I| with the explicit 9 x 3s matrices
  //      B_i(a + 3b, j + s·a) = G(3i + b, j)   (vec(J_i)(a+3b) = Σ_j G(3i+b, j) ỹ(j,a), vec(ỹ) index j +
  //      s·a), which checks the Kronecker block formula independently.
  // (a) vs (b): float storage of G and of the blocks (2⁻²⁴ each) and float accumulation over 3|I| terms give
  // ~1e-6 relative to max|H|; 1e-5 is the float-precision tolerance. (b) vs (c): double, different summation
  // order only: 1e-12 relative.
  const EnergySetup& S = setup();
  const DeformationEnergy E = make_energy();  // empty subset = all samples
  ASSERT_EQ(static_cast<int>(E.hessian_subset().size()), E.num_samples());
  const TestMap m = test_map(E);
  const int s = E.reduced_size(), n = E.num_samples();
  const EnergyWeights w{0, 0};
  const MatXd Hf = E.hessian(m.JT, w, true, false);
  const MatXd Hd = E.hessian(m.JT, w, true, true);
  // B_i from the energy's own stored G (rounded to float by the implementation; see the storage test), so
  // that B_i ỹ reproduces its Jacobians to double rounding.
  const MatXdR Gs = E.gradient_matrix().template cast<double>();
  MatXd Hb = MatXd::Zero(3 * s, 3 * s);
  for (int i = 0; i < n; ++i) {
    Eigen::Matrix<double, 9, Eigen::Dynamic> B = Eigen::Matrix<double, 9, Eigen::Dynamic>::Zero(9, 3 * s);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int j = 0; j < s; ++j) B(a + 3 * b, j + s * a) = Gs(3 * i + b, j);
    // B reproduces vec(J_i) (a direct check of the index convention before using it).
    const Vec9 vecJ = B * Eigen::Map<const VecXd>(m.y.data(), 3 * s);
    const Mat3 Ji = m.JT.middleRows<3>(3 * i).transpose();
    ASSERT_LT((vecJ - Eigen::Map<const Vec9>(Ji.data())).cwiseAbs().maxCoeff(),
              1e-13 * (1 + Ji.cwiseAbs().maxCoeff()));
    Hb.noalias() += B.transpose() * sd_hessian_psd(Ji) * B;
  }
  Hb /= n;
  const double scale = Hd.cwiseAbs().maxCoeff();
  const double err_fd = (Hf - Hd).cwiseAbs().maxCoeff(), err_db = (Hd - Hb).cwiseAbs().maxCoeff();
  EXPECT_LT(err_fd, 1e-5 * scale);
  EXPECT_LT(err_db, 1e-12 * scale);
  std::printf("max|H| %.3e  max|H_float - H_double| %.3e  max|H_double - brute force| %.3e\n", scale, err_fd,
              err_db);

  // Exactly symmetric (the implementation symmetrizes), and PSD up to float rounding.
  EXPECT_EQ((Hf - Hf.transpose()).cwiseAbs().maxCoeff(), 0.0);
  const Eigen::SelfAdjointEigenSolver<MatXd> es(Hf);
  const double lmin = es.eigenvalues()(0), lmax = es.eigenvalues()(3 * s - 1);
  EXPECT_GE(lmin, -1e-6 * lmax);
  std::printf("projected float Hessian eigenvalues: min %.3e max %.3e\n", lmin, lmax);

  // With a real 5% subset the float matrix is the same formula on those samples: compare with a brute-force
  // assembly restricted to the subset (weight 1/|H|).
  const DeformationEnergy Esub = make_energy(S.sampling.hessian_subset);
  const std::vector<int>& sub = Esub.hessian_subset();
  ASSERT_GT(sub.size(), 0u);
  ASSERT_LT(static_cast<int>(sub.size()), n);
  const MatXd Hs = Esub.hessian(m.JT, w, true, false);
  MatXd Hsb = MatXd::Zero(3 * s, 3 * s);
  for (int i : sub) {
    Eigen::Matrix<double, 9, Eigen::Dynamic> B = Eigen::Matrix<double, 9, Eigen::Dynamic>::Zero(9, 3 * s);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int j = 0; j < s; ++j) B(a + 3 * b, j + s * a) = Gs(3 * i + b, j);
    Hsb.noalias() += B.transpose() * sd_hessian_psd(m.JT.middleRows<3>(3 * i).transpose()) * B;
  }
  Hsb /= static_cast<double>(sub.size());
  EXPECT_LT((Hs - Hsb).cwiseAbs().maxCoeff(), 1e-5 * Hsb.cwiseAbs().maxCoeff());
}

TEST(DeformationEnergy, HessianFromPairBlocksIsTheSymmetrizedBlockMatrix) {
  // hessian_from writes ½(H₀ + H₀ᵀ) in one pass, H₀ the 3 x 3 block matrix of the six pair blocks (columns
  // q·s.. of `blocks`, q over (0,0) (0,1) (0,2) (1,1) (1,2) (2,2)) with their transposes below the diagonal:
  // bit for bit the formula written out with Eigen, for any thread count. Random, non-symmetric blocks, zero
  // weights (the quadratic terms then add exact zeros).
  const DeformationEnergy E = make_energy();
  const int s = E.reduced_size();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-1, 1);
  MatXd blocks(s, 6 * s);
  for (Eigen::Index k = 0; k < blocks.size(); ++k) blocks.data()[k] = U(rng);
  constexpr int kPairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  MatXd H0(3 * s, 3 * s);
  for (int q = 0; q < 6; ++q) {
    const int a = kPairs[q][0], a2 = kPairs[q][1];
    H0.block(a * s, a2 * s, s, s) = blocks.middleCols(q * s, s);
    if (a2 != a) H0.block(a2 * s, a * s, s, s) = blocks.middleCols(q * s, s).transpose();
  }
  const MatXd expected = 0.5 * (H0 + H0.transpose());
  const int saved = omp_get_max_threads();
  for (const int threads : {1, 2, 3}) {
    omp_set_num_threads(threads);
    EXPECT_EQ(E.hessian_from(blocks, EnergyWeights{0, 0}), expected) << threads << " threads";
  }
  omp_set_num_threads(saved);
}

TEST(DeformationEnergy, SmoothnessTermEqualsSparseKOfTheFullCoefficients) {
  // E_smooth = Σ_j μ_j ‖ỹ_j‖² / |E| must equal ‖K Ξ ỹ‖² / |E| with K from smoothness.h. Ξ's columns are
  // eigenvectors of KᵀK only to the eigen-solver's precision (~1e-15 ‖KᵀK‖ per entry), which enters through
  // the cross terms ỹ_jᵀ (Ξ_jᵀ KᵀK Ξ_k) ỹ_k; relative 1e-8 bounds that comfortably.
  const EnergySetup& S = setup();
  const DeformationEnergy E = make_energy();
  const Eigen::SparseMatrix<double> K = smoothness_matrix(S.model.cage);
  for (unsigned seed : {17u, 18u, 19u}) {
    const MatS3 y = random_map(kAmp, seed);
    const EnergyTerms t = E.evaluate(y, EnergyWeights{0, 1});
    const MatX3d yfull = S.sub.basis * y;
    const double ref = smoothness_energy(K, yfull) / S.model.cage.num_edges();
    const double direct = (MatX3d(K * yfull)).squaredNorm() / S.model.cage.num_edges();
    EXPECT_GT(ref, 0);
    EXPECT_NEAR(t.smooth, ref, 1e-8 * ref) << "seed " << seed;
    EXPECT_NEAR(direct, ref, 1e-12 * ref);
    // total = dis + λ2 smooth with λ1 = 0 (the weighting itself).
    EXPECT_EQ(t.total, t.dis + 1.0 * t.smooth);
  }
}

TEST(DeformationEnergy, P2PTermEqualsHandleErrorsOfTheFullSpaceMap) {
  // E_P2P = Σ_h ‖f(p_h) − q_h‖² with f evaluated by HarmonicBasis::map_values on y = Ξ ỹ (full space, another
  // product order than D ỹ = (Φ Ξ) ỹ): both are exact up to ~1e-15 in f, so relative 1e-10 on a sum of
  // squared distances of ~0.05.
  const EnergySetup& S = setup();
  DeformationEnergy E = make_energy();
  const MatX3d Q = offset_targets(5);
  E.set_handles(S.D, Q);
  const MatS3 y = random_map(kAmp, 21);
  const MatX3d f = S.basis->map_values(S.sub.basis * y, S.sources);
  const double ref = (f - Q).squaredNorm();
  const EnergyTerms t = E.evaluate(y, EnergyWeights{1, 0});
  EXPECT_GT(ref, 1e-4);
  EXPECT_NEAR(t.p2p, ref, 1e-10 * ref);
  EXPECT_LT((E.handle_positions(y) - f).cwiseAbs().maxCoeff(), 1e-12);
  const VecXd errs = E.handle_errors(y);
  ASSERT_EQ(errs.size(), 4);
  for (int h = 0; h < 4; ++h) EXPECT_NEAR(errs(h), (f.row(h) - Q.row(h)).norm(), 1e-12);
  // λ1 scales only this term.
  const EnergyTerms t7 = E.evaluate(y, EnergyWeights{7, 0});
  EXPECT_EQ(t7.p2p, t.p2p);
  EXPECT_EQ(t7.total, t7.dis + 7 * t7.p2p);
}

TEST(DeformationEnergy, InvertedSamplesGiveInfiniteEnergy) {
  const EnergySetup& S = setup();
  DeformationEnergy E = make_energy();
  E.set_handles(S.D, S.sources);
  const double inf = std::numeric_limits<double>::infinity();
  // (a) A global reflection p ↦ diag(−1, 1, 1) p: affine, hence exactly in span Ξ; det J = −1 everywhere.
  const MatS3 yr = S.sub.basis.transpose() *
                   S.model.cage.affine_coefficients(Mat3(Vec3(-1, 1, 1).asDiagonal()), Vec3::Zero());
  const MatJT JTr = E.jacobians(yr);
  EXPECT_LT(min_det(JTr), -0.99);
  EXPECT_EQ(E.evaluate(JTr, yr, EnergyWeights{}).total, inf);
  EXPECT_EQ(E.evaluate(JTr, yr, EnergyWeights{0, 0}).total, inf);
  // (b) Only some samples inverted: identity plus a growing multiple of one smooth non-affine direction
  // (reduced column 6) until det J ≤ 0 at some but not all samples.
  bool found = false;
  for (double amp = 0.5; amp < 1e4 && !found; amp *= 1.25) {
    MatS3 y = S.y_identity;
    y(6, 0) += amp;
    y(7, 1) -= amp;
    const MatJT JT = E.jacobians(y);
    int neg = 0;
    for (int i = 0; i < E.num_samples(); ++i) neg += JT.middleRows<3>(3 * i).determinant() <= 0;
    if (neg == 0) {
      EXPECT_TRUE(std::isfinite(E.evaluate(JT, y, EnergyWeights{}).total));
      continue;
    }
    found = true;
    EXPECT_LT(neg, E.num_samples());
    const EnergyTerms t = E.evaluate(JT, y, EnergyWeights{});
    EXPECT_EQ(t.total, inf) << neg << " of " << E.num_samples() << " samples inverted at amplitude " << amp;
    EXPECT_EQ(t.dis, inf);
    std::printf("amplitude %.3g: %d of %d samples inverted, total = %g\n", amp, neg, E.num_samples(),
                t.total);
  }
  EXPECT_TRUE(found);
  // (c) A single sample with det J = 0 exactly (a rank-2 Jacobian inserted by hand): the barrier includes 0.
  MatJT JT0 = E.jacobians(S.y_identity);
  JT0.middleRows<3>(3 * 5).row(2).setZero();
  EXPECT_EQ(E.evaluate(JT0, S.y_identity, EnergyWeights{}).total, inf);
}

TEST(DeformationEnergy, EvaluateIsBitwiseIdenticalForOneAndTwoThreads) {
  // The sample sum runs in fixed chunks of 256 added in chunk order: the thread count must not change a bit.
  // |I| ≥ 300 here, so there are at least two chunks.
  const EnergySetup& S = setup();
  DeformationEnergy E = make_energy(S.sampling.hessian_subset);
  E.set_handles(S.D, offset_targets(6));
  ASSERT_GT(E.num_samples(), 256);
  const int saved = omp_get_max_threads();
  struct Out {
    MatJT JT;
    EnergyTerms t;
    MatS3 g;
  };
  auto run = [&](int threads) {
    omp_set_num_threads(threads);
    Out o;
    const MatS3 y = random_map(kAmp, 23);
    o.JT = E.jacobians(y);
    o.t = E.evaluate(o.JT, y, EnergyWeights{});
    o.g = E.gradient(o.JT, y, EnergyWeights{});
    return o;
  };
  const Out a = run(1), b = run(2);
  omp_set_num_threads(saved);
  EXPECT_EQ(std::memcmp(a.JT.data(), b.JT.data(), sizeof(double) * a.JT.size()), 0);
  EXPECT_EQ(std::memcmp(&a.t.dis, &b.t.dis, sizeof(double)), 0);
  EXPECT_EQ(std::memcmp(&a.t.p2p, &b.t.p2p, sizeof(double)), 0);
  EXPECT_EQ(std::memcmp(&a.t.smooth, &b.t.smooth, sizeof(double)), 0);
  EXPECT_EQ(std::memcmp(&a.t.total, &b.t.total, sizeof(double)), 0);
  // The gradient uses the same fixed chunks (partial products added in chunk order).
  EXPECT_EQ(std::memcmp(a.g.data(), b.g.data(), sizeof(double) * a.g.size()), 0);
}

TEST(DeformationEnergy, JacobiansAreTheReducedGradientMatrixTimesY) {
  // JT = G ỹ for the G given to the constructor, up to the storage of G: the implementation keeps G rounded
  // to single precision (deformation_energy.h, "Storage"), so each entry of JT may differ from the double
  // product by at most 2⁻²⁴ Σ_j |G(r, j)| |ỹ(j, a)| (relative rounding of each stored entry; the double
  // arithmetic adds ~1e-16 of the same sum). The bound holds as well for a double G.
  const EnergySetup& S = setup();
  const DeformationEnergy E = make_energy();
  const MatS3 y = random_map(kAmp, 29);
  const MatJT JT = E.jacobians(y);
  const MatJT ref = S.G * y;
  const MatJT bound = S.G.cwiseAbs() * y.cwiseAbs();
  const double u = std::ldexp(1.0, -24) * (1 + 1e-6);
  double worst = 0;
  for (Eigen::Index r = 0; r < JT.rows(); ++r)
    for (int a = 0; a < 3; ++a)
      worst = std::max(worst, std::abs(JT(r, a) - ref(r, a)) / (u * bound(r, a) + 1e-300));
  EXPECT_LE(worst, 1.0) << "JT deviates from G ỹ by more than float storage of G explains";
  std::printf("max |JT - G y| / (2^-24 |G||y|) = %.3f (0 for double storage)\n", worst);
}

// The exact second derivatives along a direction (the solver's conjugate-gradient correction) against the
// all-sample unprojected Hessian matrix, with volume weights: Σ w_i G_iᵀ ∇²E_iso[dJ_i] / |I| plus the
// quadratic terms equals H vec(d), and the curvature equals vec(d)ᵀ H vec(d), both to rounding (1e-10
// relative).
TEST(DeformationEnergy, HessianTimesDirectionEqualsTheExactHessianMatrix) {
  const EnergySetup& S = setup();
  DeformationEnergy E = make_energy();
  E.set_handles(S.D, offset_targets(8));
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> U(0.2, 3.0);
  VecXd w(E.num_samples());
  for (Eigen::Index i = 0; i < w.size(); ++i) w(i) = U(rng);
  E.set_sample_weights(w);
  const TestMap m = test_map(E);
  const EnergyWeights ew{10.0, 0.5};
  const MatXd H = E.hessian(m.JT, ew, false, true);
  const int s = E.reduced_size();
  for (unsigned seed : {3u, 4u, 5u}) {
    const MatS3 d = random_map(0.1, seed) - S.y_identity;
    const MatJT dJ = E.jacobians(d);
    const MatS3 Hd =
        E.distortion_hessian_times_sum(m.JT, dJ) / E.num_samples() + E.quadratic_hessian_times(d, ew);
    const VecXd ref = H * Eigen::Map<const VecXd>(d.data(), 3 * s);
    const double err = (Eigen::Map<const VecXd>(Hd.data(), 3 * s) - ref).norm();
    EXPECT_LT(err, 1e-10 * ref.norm()) << "seed " << seed;
    const double curvature =
        E.distortion_curvature(m.JT, dJ) / E.num_samples() +
        Eigen::Map<const VecXd>(d.data(), 3 * s)
            .dot(Eigen::Map<const VecXd>(E.quadratic_hessian_times(d, ew).data(), 3 * s));
    const double ref_curvature = Eigen::Map<const VecXd>(d.data(), 3 * s).dot(ref);
    EXPECT_NEAR(curvature, ref_curvature, 1e-10 * std::abs(ref_curvature)) << "seed " << seed;
  }
}

// The kept factor's operator (subset_hessian_times, through the per-sample blocks) is the subset Hessian the
// solver assembles: the blocks are those distortion_pair_blocks takes (the same bits assembled), and their
// product with a direction equals the assembled matrix (double-precision products) times it to double
// rounding. A subset of more than one chunk (256 samples) exercises the chunked sum.
TEST(DeformationEnergy, SubsetHessianTimesEqualsTheAssembledSubsetHessian) {
  const EnergySetup& S = setup();
  std::vector<int> subset;
  for (int i = 0; i < 600 && i < static_cast<int>(S.sampling.size()); i += 2) subset.push_back(i);
  ASSERT_GT(subset.size(), 256u);
  DeformationEnergy E = make_energy(subset);
  const TestMap m = test_map(E);
  const std::vector<Mat9> blocks = E.subset_hessian_blocks(m.JT);
  ASSERT_EQ(blocks.size(), subset.size());
  for (const bool dbl : {false, true})
    EXPECT_EQ((E.distortion_pair_blocks_from(blocks, dbl) - E.distortion_pair_blocks(m.JT, dbl)).norm(), 0.0);
  const EnergyWeights none{0.0, 0.0};
  const MatXd H = E.hessian_from(E.distortion_pair_blocks_from(blocks, true), none);
  const int s = E.reduced_size();
  for (unsigned seed : {3u, 4u, 5u}) {
    const MatS3 d = random_map(0.1, seed) - S.y_identity;
    const MatS3 Hd = E.subset_hessian_times(blocks, d);
    const VecXd ref = H * Eigen::Map<const VecXd>(d.data(), 3 * s);
    const double err = (Eigen::Map<const VecXd>(Hd.data(), 3 * s) - ref).norm();
    EXPECT_LT(err, 1e-12 * ref.norm()) << "seed " << seed;
    EXPECT_GT(ref.norm(), 0) << "seed " << seed;
  }
  EXPECT_THROW(E.subset_hessian_times(std::vector<Mat9>(3), MatS3::Zero(s, 3)), Error);
}

// The two passes over the stored float rows (jacobians, and the transposed sum behind the gradient) on a
// shape that reaches every remainder path of their vector loops: s = 43 (not a multiple of 4) and 3|I| = 903
// rows (odd, not a multiple of 4; 301 samples = two chunks). Reference: the same float-rounded G in double
// arithmetic.
TEST(DeformationEnergy, GradientMatrixPassesHandleEveryShape) {
  const int n = 301, s = 43;
  std::mt19937 rng(37);
  std::normal_distribution<double> N01;
  MatXdR G(3 * n, s);
  for (Eigen::Index r = 0; r < G.rows(); ++r)
    for (int j = 0; j < s; ++j) G(r, j) = 0.01 * N01(rng) + (j == r % 3 ? 1.0 : 0.0);
  // y = [I₃; 0] + noise: J_i = I + O(0.05), det J_i > 0.
  MatS3 y = MatS3::Zero(s, 3);
  y.topRows<3>().setIdentity();
  for (int j = 0; j < s; ++j)
    for (int a = 0; a < 3; ++a) y(j, a) += 0.003 * N01(rng);
  const DeformationEnergy E(G, {}, VecXd::Ones(s), 10);
  const MatXd Gf = G.cast<float>().cast<double>();
  const MatJT JT = E.jacobians(y);
  const MatJT JT_ref = Gf * y;
  EXPECT_LT((JT - JT_ref).cwiseAbs().maxCoeff(), 1e-14);
  MatJT P(3 * n, 3);
  for (int i = 0; i < n; ++i)
    P.middleRows<3>(3 * i) = sd_gradient(JT.middleRows<3>(3 * i).transpose()).transpose();
  const MatS3 g_ref = Gf.transpose() * P;
  const MatS3 g = E.distortion_gradient_sum(JT);
  EXPECT_LT((g - g_ref).cwiseAbs().maxCoeff(), 1e-12 * g_ref.cwiseAbs().maxCoeff());
}

TEST(DeformationEnergy, IdentityWithTargetsAtSourcesIsAZero) {
  // At ỹ = Ξᵀ y_id with q_h = p_h the energy's minimum 0 is attained, up to rounding:
  //  - J_i = I up to the storage of G: with G rounded to float (deformation_energy.h) |J − I| ≲ 2⁻²⁴ Σ|G||ỹ|
  //    ≈ 3e-8 here; a tolerance of 1e-6 (1e-12 would hold for double storage);
  //  - E_dis = O(|J − I|²) plus the ~1e-15 rounding of ‖J‖² + ‖J⁻¹‖² − 6: < 1e-12;
  //  - E_P2P: D is double, D ỹ − q ~ 1e-15: < 1e-24;  E_smooth: the identity is affine, μ_j ~ 1e-25 on the
  //    affine columns: < 1e-20;
  //  - gradients, each term isolated: P2P (λ1 = 1) 2 Dᵀ(Dỹ − q) and smooth (λ2 = 1) 2 μ ỹ / |E| are pure
  //  double
  //    arithmetic: < 1e-9. E_dis's gradient is Gᵀ of 2(J − J⁻ᵀJ⁻¹J⁻ᵀ) ≈ 8 (J − I)-sized entries: < 1e-9 for
  //    double storage of G, and < 1e-6 with G in float (measured ~3e-8).
  const EnergySetup& S = setup();
  DeformationEnergy E = make_energy();
  E.set_handles(S.D, S.sources);
  const MatS3& y = S.y_identity;
  const MatJT JT = E.jacobians(y);
  double maxdev = 0;
  for (int i = 0; i < E.num_samples(); ++i)
    maxdev = std::max(maxdev, (JT.middleRows<3>(3 * i) - Mat3::Identity()).cwiseAbs().maxCoeff());
  EXPECT_LT(maxdev, 1e-6);
  // In double (the constructor's input G), the identity is reproduced to rounding.
  const MatJT JTd = S.G * y;
  double maxdev_d = 0;
  for (int i = 0; i < E.num_samples(); ++i)
    maxdev_d = std::max(maxdev_d, (JTd.middleRows<3>(3 * i) - Mat3::Identity()).cwiseAbs().maxCoeff());
  EXPECT_LT(maxdev_d, 1e-12);
  const EnergyTerms t = E.evaluate(JT, y, EnergyWeights{});
  EXPECT_LT(std::abs(t.dis), 1e-12);
  EXPECT_LT(t.p2p, 1e-24);
  EXPECT_LT(t.smooth, 1e-20);
  const MatS3 g00 = E.gradient(JT, y, EnergyWeights{0, 0});
  const double g_p2p = (E.gradient(JT, y, EnergyWeights{1, 0}) - g00).norm();
  const double g_smooth = (E.gradient(JT, y, EnergyWeights{0, 1}) - g00).norm();
  EXPECT_LT(g_p2p, 1e-9);
  EXPECT_LT(g_smooth, 1e-9);
  EXPECT_LT(g00.norm(), 1e-6);
  const EnergyWeights wd{};  // λ1 = 1e5, λ2 = 0.1: the P2P part scales with λ1
  const double gd = E.gradient(JT, y, wd).norm();
  EXPECT_LT(gd, 1e-6 + 1e-9 * wd.p2p);
  std::printf(
      "identity: max|J - I| %.2e (double G: %.2e), E_dis %.2e, E_P2P %.2e, E_smooth %.2e, |grad| dis %.2e "
      "p2p %.2e smooth %.2e, default weights %.2e\n",
      maxdev, maxdev_d, t.dis, t.p2p, t.smooth, g00.norm(), g_p2p, g_smooth, gd);
}
