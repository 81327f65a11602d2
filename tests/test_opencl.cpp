// The OpenCL backend (opencl/) against the CPU reference: every kernel on random inputs (including
// near-singular Jacobians and clustered singular values), whole certificates (same verdicts, leaves and
// margins), the solver (same accepted steps and coefficients to ~1e-9 with double-precision Hessian
// products), the CLI (--backend, auto's fallback, failures reported with exit 2). Runs on whatever OpenCL
// platform exists (PoCL in CI); skips with a message where there is none.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>

#include "lidef/compute_backend.h"
#include "lidef/deformation_energy.h"
#include "lidef/green_coordinates.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/model_check.h"
#include "lidef/octree_certifier.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/projected_newton.h"
#include "lidef/sampling.h"
#include "lidef/scenario.h"
#include "lidef/signed_svd.h"
#include "test_cages.h"
#include "test_support.h"

using namespace lidef;

namespace {

// The OpenCL backend, built once for the whole file; nullptr (and the reason) when there is none.
std::shared_ptr<const ComputeBackend> opencl(std::string* why = nullptr) {
  static std::string reason;
  static const std::shared_ptr<const ComputeBackend> b = []() -> std::shared_ptr<const ComputeBackend> {
    try {
      static lidef::test::TempDir cache;
      return make_opencl_backend({opencl_device_filter_from_env()}, cache.str());
    } catch (const OpenCLError& e) {
      reason = e.what();
      return nullptr;
    }
  }();
  if (why) *why = reason;
  return b;
}

// A second backend on the same device that takes the GPU code paths even on a CPU device.
std::shared_ptr<const ComputeBackend> as_gpu_backend(const std::string& cache) {
  OpenCLOptions options;
  options.device = opencl_device_filter_from_env();
  options.gpu_layout = true;
  return make_opencl_backend(options, cache);
}

#define REQUIRE_OPENCL()                                                                           \
  std::string why_;                                                                                \
  if (!opencl(&why_)) {                                                                            \
    std::string platforms_;                                                                        \
    if (opencl_devices(&platforms_).empty()) GTEST_SKIP() << "no OpenCL platform: " << platforms_; \
    FAIL() << "an OpenCL platform exists but the backend failed: " << why_;                        \
  }

// Relative difference; 0 for equal values (infinities, and NaN for "not evaluated" on both sides).
double rel(double a, double b) {
  if (a == b || (std::isnan(a) && std::isnan(b))) return 0;
  return std::abs(a - b) / std::max({std::abs(a), std::abs(b), 1e-300});
}

// A DeformationEnergy on random data: n samples, s coefficients; G's rows scaled so that J = G y is a
// perturbed rotation-like matrix for the y returned.
struct RandomEnergy {
  std::unique_ptr<DeformationEnergy> energy;
  MatS3 y, d;
};

RandomEnergy random_energy(int n, int s, unsigned seed, double noise) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01(0.0, 1.0);
  MatXdR G(3 * n, s);
  // The first 3 coefficients carry the identity (J = I for y = e_a), the rest random perturbations.
  G.setZero();
  for (int i = 0; i < n; ++i)
    for (int b = 0; b < 3; ++b) {
      G(3 * i + b, b) = 1.0;
      for (int k = 3; k < s; ++k) G(3 * i + b, k) = noise * N01(rng);
    }
  std::vector<int> subset;
  for (int i = 0; i < n; i += 7) subset.push_back(i);
  VecXd mu = VecXd::LinSpaced(s, 0.0, 3.0);
  RandomEnergy r;
  r.energy = std::make_unique<DeformationEnergy>(G, subset, mu, 30);
  r.y = MatS3::Zero(s, 3);
  for (int a = 0; a < 3; ++a) r.y(a, a) = 1.0;
  for (int k = 3; k < s; ++k)
    for (int a = 0; a < 3; ++a) r.y(k, a) = 0.3 * N01(rng);
  r.d = MatS3(s, 3);
  for (int k = 0; k < s; ++k)
    for (int a = 0; a < 3; ++a) r.d(k, a) = 0.05 * N01(rng);
  return r;
}

}  // namespace

TEST(OpenCL, DevicesAreListedWithoutThrowing) {
  std::string why;
  const auto devs = opencl_devices(&why);
  if (devs.empty()) {
    EXPECT_FALSE(why.empty());
    GTEST_SKIP() << "no OpenCL platform: " << why;
  }
  for (const auto& d : devs) {
    EXPECT_FALSE(d.name.empty());
    EXPECT_GT(d.global_mem, 0u);
  }
}

// Both ways of forming the Hessian product: on the host BLAS (what a CPU device such as PoCL does) and on the
// device with CLBlast and the transposed layouts (what a GPU does; forced here by OpenCLOptions::gpu_layout).
class OpenCLEnergy : public ::testing::TestWithParam<bool> {};

TEST_P(OpenCLEnergy, KernelsMatchCpu) {
  REQUIRE_OPENCL();
  std::shared_ptr<const ComputeBackend> backend = opencl();
  lidef::test::TempDir cache;
  if (GetParam()) {
    backend = as_gpu_backend(cache.str());
  }
  RandomEnergy r = random_energy(1500, 24, 3, 0.02);
  // Uniform samples (the paper's grid), then volume weights as the mesh domain's refined leaves have them
  // (8^-level, here random levels 0..2): the device must weigh the energy, gradient and Hessian blocks as the
  // CPU does.
  for (const bool weighted : {false, true}) {
    SCOPED_TRACE(weighted ? "volume-weighted samples" : "uniform samples");
    if (weighted) {
      VecXd w(r.energy->num_samples());
      for (int i = 0; i < w.size(); ++i) w(i) = std::pow(8.0, -((i * 7) % 3));
      r.energy->set_sample_weights(w);
    }
    auto cpu = cpu_backend()->energy_kernels(*r.energy);
    auto gpu = backend->energy_kernels(*r.energy);
    for (auto* k : {cpu.get(), gpu.get()}) {
      k->set_current(r.y);
      k->set_direction(r.d);
    }
    const MatJT Jc = cpu->current_jacobians(), Jg = gpu->current_jacobians();
    EXPECT_LT((Jc - Jg).cwiseAbs().maxCoeff(), 1e-13 * Jc.cwiseAbs().maxCoeff());
    const double e0c = cpu->distortion_sum(0), e0g = gpu->distortion_sum(0);
    ASSERT_TRUE(std::isfinite(e0c));
    EXPECT_LT(rel(e0c, e0g), 1e-11) << e0c << " vs " << e0g;
    EXPECT_LT(rel(cpu->distortion_sum(0.7), gpu->distortion_sum(0.7)), 1e-11);
    const MatS3 gc = cpu->distortion_gradient_sum(), gg = gpu->distortion_gradient_sum();
    EXPECT_LT((gc - gg).norm(), 1e-11 * gc.norm());
    const MatXd Bc = cpu->distortion_pair_blocks(true), Bg = gpu->distortion_pair_blocks(true);
    ASSERT_EQ(Bc.rows(), Bg.rows());
    EXPECT_LT((Bc - Bg).norm(), 1e-11 * Bc.norm());
    const MatXd Bcf = cpu->distortion_pair_blocks(false), Bgf = gpu->distortion_pair_blocks(false);
    EXPECT_LT((Bcf - Bgf).norm(), 1e-5 * Bcf.norm());  // single precision products, different order
    EXPECT_LT((Bcf - Bc).norm(), 1e-5 * Bc.norm());
    // The exact Hessian along the direction (the conjugate-gradient correction's products): equal on both
    // backends, and against the device's own energy and gradient by central differences (an independent
    // check: a kernel that agreed with a wrong CPU formula would fail here).
    ASSERT_TRUE(gpu->has_hessian_products());
    const MatS3 hc = cpu->distortion_hessian_direction_sum(), hg = gpu->distortion_hessian_direction_sum();
    EXPECT_LT((hc - hg).norm(), 1e-11 * hc.norm());
    const double cc = cpu->distortion_curvature(), cg = gpu->distortion_curvature();
    EXPECT_LT(rel(cc, cg), 1e-11) << cc << " vs " << cg;
    const double h = 1e-4;
    const double second =
        (gpu->distortion_sum(h) - 2 * gpu->distortion_sum(0) + gpu->distortion_sum(-h)) / (h * h);
    EXPECT_LT(rel(cg, second), 1e-5) << cg << " vs " << second;
    auto shifted = backend->energy_kernels(*r.energy);
    shifted->set_current(r.y + h * r.d);
    const MatS3 plus = shifted->distortion_gradient_sum();
    shifted->set_current(r.y - h * r.d);
    const MatS3 minus = shifted->distortion_gradient_sum();
    EXPECT_LT(((plus - minus) / (2 * h) - hg).norm(), 1e-6 * hg.norm());
    // The direction combined on the device from two directions equals the direction set at once.
    const MatS3 d2 = r.d.reverse();
    auto direct = backend->energy_kernels(*r.energy);
    direct->set_current(r.y);
    direct->set_direction(0.3 * r.d - 0.2 * d2);
    for (auto* k : {cpu.get(), gpu.get()}) {
      k->accumulate_direction(0.3, true);
      k->set_direction(d2);
      k->accumulate_direction(-0.2, false);
      k->use_accumulated_direction();
    }
    EXPECT_LT(rel(gpu->distortion_sum(0.6), direct->distortion_sum(0.6)), 1e-11);
    EXPECT_LT(rel(cpu->distortion_sum(0.6), gpu->distortion_sum(0.6)), 1e-11);
    EXPECT_GT(rel(gpu->distortion_sum(0.6), gpu->distortion_sum(0)), 1e-6);  // the direction matters
    for (auto* k : {cpu.get(), gpu.get()}) k->set_direction(r.d);
    // The accepted step.
    cpu->accept(0.5);
    gpu->accept(0.5);
    EXPECT_LT(rel(cpu->distortion_sum(0), gpu->distortion_sum(0)), 1e-11);
  }
  // The weights matter (else the weighted comparison above would prove nothing).
  const RandomEnergy uniform = random_energy(1500, 24, 3, 0.02);  // the same G, no weights
  auto plain = cpu_backend()->energy_kernels(*uniform.energy);
  auto weighted = cpu_backend()->energy_kernels(*r.energy);
  plain->set_current(r.y);
  weighted->set_current(r.y);
  EXPECT_GT(rel(plain->distortion_sum(0), weighted->distortion_sum(0)), 1e-3);
}

INSTANTIATE_TEST_SUITE_P(HostAndDeviceProduct, OpenCLEnergy, ::testing::Values(false, true));

TEST(OpenCL, EnergyBarrierIsInfiniteOnBothBackends) {
  REQUIRE_OPENCL();
  const RandomEnergy r = random_energy(400, 10, 5, 0.02);
  auto cpu = cpu_backend()->energy_kernels(*r.energy);
  auto gpu = opencl()->energy_kernels(*r.energy);
  MatS3 flip = r.y;
  flip.row(2) *= -1.0;  // J = diag(1, 1, −1) + noise: every det < 0
  for (auto* k : {cpu.get(), gpu.get()}) {
    k->set_current(r.y);
    k->set_direction(flip - r.y);
  }
  EXPECT_TRUE(std::isfinite(gpu->distortion_sum(0)));
  EXPECT_EQ(cpu->distortion_sum(1.0), std::numeric_limits<double>::infinity());
  EXPECT_EQ(gpu->distortion_sum(1.0), std::numeric_limits<double>::infinity());
}

// σ3 on the device for hand-made Jacobians (float-representable), through the certificate's base stage with
// stored rows = Jᵀ and Y = I: near-singular, repeated and clustered singular values, reflections.
TEST(OpenCL, SignedSigma3MatchesCpuOnHardMatrices) {
  REQUIRE_OPENCL();
  const Cage cage(lidef::test::icosphere(1));
  std::vector<Mat3> Js;
  std::mt19937 rng(11);
  std::normal_distribution<double> N01(0.0, 1.0);
  auto rotation = [&]() {
    Mat3 A;
    for (int q = 0; q < 9; ++q) A.data()[q] = N01(rng);
    Eigen::HouseholderQR<Mat3> qr(A);
    Mat3 Q = qr.householderQ();
    if (Q.determinant() < 0) Q.col(0) *= -1;
    return Q;
  };
  const double sigmas[][3] = {{1, 1, 1},        {1, 1, 1e-3},     {1, 1, 1e-7},      {2, 1e-4, 1e-5},
                              {1, 1 + 1e-9, 1}, {3, 2, 2 - 1e-8}, {1e3, 1, 1e-3},    {1, 0.5, -0.25},
                              {1, 1, -1e-6},    {5, 5, 5},        {1, 1e-12, 1e-12}, {2, 1, 0}};
  for (const auto& sg : sigmas)
    for (int rep = 0; rep < 20; ++rep) {
      const Mat3 U = rotation(), V = rotation();
      Mat3 J = U * Vec3(sg[0], sg[1], sg[2]).asDiagonal() * V.transpose();
      J = J.cast<float>().cast<double>();  // stored as float on the device
      Js.push_back(J);
    }
  for (int rep = 0; rep < 200; ++rep) {
    Mat3 J;
    for (int q = 0; q < 9; ++q) J.data()[q] = static_cast<float>(N01(rng));
    Js.push_back(J);
  }
  // Singular integer matrices (rank 2, rank 1; exact in float): det J = 0 exactly but not structurally, so
  // the sign is unresolved and σ3 = 0 on both backends (signed_svd.h).
  Js.push_back((Mat3() << 1, 2, 3, 4, 5, 6, 7, 8, 9).finished());
  Js.push_back((Mat3() << 2, -1, 3, 4, -2, 6, -6, 3, -9).finished());
  Js.push_back((Mat3() << 3, 1, 2, -1, 4, 1, 2, 5, 3).finished());
  const long N = static_cast<long>(Js.size()), m = 3;
  std::vector<float> GH(static_cast<size_t>(N) * 9 * m, 0.0f);
  for (long i = 0; i < N; ++i)
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a)
        GH[i * 9 * m + b * m + a] = static_cast<float>(Js[i](a, b));  // J(a,b) = Σ_k g_bk Y_ka
  MatX3d centers = MatX3d::Zero(N, 3);
  CertifierData data;
  data.cage = &cage;
  data.voxels = N;
  data.centers = &centers;
  data.m = m;
  data.GH = GH.data();
  for (const CageEdge& e : cage.edges) {
    data.edge_u.push_back(cage.V.row(e.v0));
    data.edge_w.push_back(cage.V.row(e.v1));
  }
  lidef::test::TempDir cache;
  for (const auto& backend : {opencl(), as_gpu_backend(cache.str())}) {
    auto k = backend->certifier_kernels(data);
    ASSERT_TRUE(k);
    const long E = cage.num_edges();
    std::vector<float> F(static_cast<size_t>(N) * E, 1.0f);
    k->set_factors(true, F.data(), E);
    const double Y[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    VecXd s3, s1, hn, T;
    std::vector<char> unresolved;
    const VecXd delta = VecXd::LinSpaced(E, 0.0, 1.0);
    k->base_stage(Y, true, delta, s3, s1, hn, T, unresolved);
    int worst = -1;
    double worst_err = 0;
    for (long i = 0; i < N; ++i) {
      bool resolved = true;
      const Vec3 ref = signed_singular_values(Js[i], &resolved);
      EXPECT_EQ(unresolved[i] != 0, !resolved) << "matrix " << i;
      if (!resolved) {
        EXPECT_EQ(s3(i), 0.0) << "matrix " << i;
      }
      const double err =
          std::max(std::abs(s3(i) - ref(2)), std::abs(s1(i) - ref(0))) / std::max(ref(0), 1e-300);
      if (err > worst_err) worst_err = err, worst = static_cast<int>(i);
      if (ref(2) != 0 && std::abs(ref(2)) > 1e-10 * ref(0)) {
        EXPECT_EQ(s3(i) < 0, ref(2) < 0) << "matrix " << i;
      }
      EXPECT_DOUBLE_EQ(hn(i), 0.0);
      EXPECT_NEAR(T(i), delta.sum(), 1e-12 * delta.sum());
    }
    EXPECT_LT(worst_err, 1e-14) << "worst matrix " << worst << ":\n" << Js[worst];
  }
}

// The node kernel (differential representation + own edge bound) against the CPU functions it mirrors.
TEST(OpenCL, NodeEvaluationMatchesCpu) {
  REQUIRE_OPENCL();
  const Cage cage(lidef::test::icosphere(2, 0.15, 4));
  const HarmonicBasis basis(cage);
  std::mt19937 rng(2);
  std::normal_distribution<double> N01(0.0, 1.0);
  MatX3d y = cage.identity_coefficients();
  for (int r = 0; r < y.rows(); ++r)
    for (int c = 0; c < 3; ++c) y(r, c) += 0.05 * N01(rng);
  const auto fm = basis.face_matrices(y);
  VecXd delta(cage.num_edges());
  for (int e = 0; e < cage.num_edges(); ++e)
    delta(e) = (fm.A[cage.edges[e].f0] - fm.A[cage.edges[e].f1]).norm() * (e % 5 == 0 ? 0.0 : 1.0);
  const MatX3d P = lidef::test::interior_points(cage, 300, 0.2, 9);
  VecXd rad(P.rows());
  for (long j = 0; j < P.rows(); ++j) rad(j) = 0.01 + 0.05 * (j % 4);
  MatX3d centers = MatX3d::Zero(1, 3);
  CertifierData data;
  data.cage = &cage;
  data.voxels = 1;
  data.centers = &centers;
  for (const CageEdge& e : cage.edges) {
    data.edge_u.push_back(cage.V.row(e.v0));
    data.edge_w.push_back(cage.V.row(e.v1));
  }
  auto k = opencl()->certifier_kernels(data);
  for (bool third : {true, false}) {
    std::vector<NodeValues> out;
    k->evaluate_nodes(fm.A, fm.AD, fm.A_abs, delta, third, P, rad, out);
    ASSERT_EQ(out.size(), static_cast<size_t>(P.rows()));
    for (long j = 0; j < P.rows(); ++j) {
      double sJ, sH;
      const MapJet jet = basis.differential_jet(fm, P.row(j).transpose(), third ? 2 : 1, &sJ, &sH);
      const Vec3 sv = signed_singular_values(jet.J);
      const double s3 = sv(2);
      double own = 0;
      for (int e = 0; e < cage.num_edges(); ++e)
        if (delta(e) != 0)
          own +=
              delta(e) *
              (third ? third_order_edge_factor(data.edge_u[e], data.edge_w[e], P.row(j).transpose(), rad(j))
                     : first_order_edge_factor(data.edge_u[e], data.edge_w[e], P.row(j).transpose(), rad(j)));
      EXPECT_LT(rel(out[j].sigma3, s3), 1e-12) << j;
      EXPECT_LT(rel(out[j].sigma1, sv(0)), 1e-12) << j;
      if (third) {
        EXPECT_LT(rel(out[j].hnorm, jet.hessian_norm()), 1e-12) << j;
        EXPECT_LT(rel(out[j].scale_H, sH), 1e-12) << j;
      }
      EXPECT_LT(rel(out[j].own_bound, own), 1e-12) << j;
      EXPECT_LT(rel(out[j].scale_J, sJ), 1e-12) << j;
    }
  }
}

namespace {

struct Beam {
  Model model;
  lidef::test::TempDir cache;
  MatX3d sources, targets;
};
const Beam& beam() {
  static const std::unique_ptr<Beam> b = [] {
    auto p =
        std::make_unique<Beam>(Beam{load_model(lidef::test::project_data() + "/models/beam"), {}, {}, {}});
    std::ifstream in(lidef::test::project_data() + "/scenarios/beam_bend.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    const auto& h = j.at("handles");
    p->sources.resize(h.size(), 3);
    p->targets.resize(h.size(), 3);
    for (size_t i = 0; i < h.size(); ++i)
      for (int c = 0; c < 3; ++c) {
        p->sources(i, c) = h[i]["source"][c].get<double>();
        p->targets(i, c) = h[i]["target"][c].get<double>();
      }
    return p;
  }();
  return *b;
}

// Compares two certificates leaf by leaf.
void expect_same_certificate(const Certificate& a, const Certificate& b, double tol) {
  EXPECT_EQ(a.certified, b.certified);
  EXPECT_EQ(a.refined, b.refined);
  ASSERT_EQ(a.leaves.size(), b.leaves.size());
  for (size_t i = 0; i < a.leaves.size(); ++i) {
    const CertLeaf &x = a.leaves[i], &y = b.leaves[i];
    ASSERT_EQ(x.certified, y.certified) << "leaf " << i;
    ASSERT_EQ(x.depth, y.depth) << "leaf " << i;
    EXPECT_EQ(x.center, y.center);
    EXPECT_LT(rel(x.sigma3, y.sigma3), tol) << "leaf " << i;
    // L of a (nearly) affine map is rounding noise of a cancelling sum: compare it on the scale of σ3.
    if (!(std::isinf(x.L) && std::isinf(y.L))) {
      EXPECT_LE(std::abs(x.L - y.L), tol * (std::abs(x.L) + 1.0)) << "leaf " << i;
    }
    if (std::isfinite(x.margin) || std::isfinite(y.margin)) {
      EXPECT_LT(std::abs(x.margin - y.margin), tol * (std::abs(x.sigma3) + x.L)) << "leaf " << i;
    }
    // The distortion bounds: σ1 comes from the device too (base stage and octree nodes).
    EXPECT_EQ(std::isfinite(x.sigma1_upper), std::isfinite(y.sigma1_upper)) << "leaf " << i;
    if (std::isfinite(x.sigma1_upper)) {
      EXPECT_LT(rel(x.sigma1_upper, y.sigma1_upper), tol) << "leaf " << i;
    }
  }
  EXPECT_LT(rel(a.min_lower_bound, b.min_lower_bound), tol);
}

// Solves on both backends (handles set) and compares the runs iteration by iteration; returns the relative
// difference of the final reduced coefficients.
double expect_same_solves(DeformationSolver& cpu, DeformationSolver& gpu, double tol) {
  const SolveResult rc = cpu.solve(), rg = gpu.solve();
  EXPECT_EQ(rc.reason, rg.reason);
  EXPECT_EQ(cpu.history().size(), gpu.history().size());
  for (size_t i = 0; i < std::min(cpu.history().size(), gpu.history().size()); ++i) {
    const IterationRecord &a = cpu.history()[i], &b = gpu.history()[i];
    EXPECT_EQ(a.accepted, b.accepted) << "iteration " << i + 1;
    EXPECT_EQ(a.step, b.step) << "iteration " << i + 1;
    EXPECT_EQ(a.certified, b.certified) << "iteration " << i + 1;
    EXPECT_EQ(a.certificate_rejections, b.certificate_rejections) << "iteration " << i + 1;
    EXPECT_EQ(a.armijo_rejections, b.armijo_rejections) << "iteration " << i + 1;
    EXPECT_LT(rel(a.terms.total, b.terms.total), tol) << "iteration " << i + 1;
  }
  EXPECT_EQ(cpu.certificate().certified, gpu.certificate().certified);
  EXPECT_TRUE(gpu.certificate().certified);
  std::cout << "[ parity   ] " << cpu.history().size() << " iterations (" << to_string(rc.reason)
            << "), solve " << rc.seconds << " s cpu, " << rg.seconds << " s opencl\n";
  return (cpu.reduced_coefficients() - gpu.reduced_coefficients()).norm() / cpu.reduced_coefficients().norm();
}

}  // namespace

// Whole certificates of deformed beams: full space (stored derivatives) and reduced space, third- and
// first-order bounds; maps that need refinement and one that folds.
TEST(OpenCL, CertificatesMatchCpu) {
  REQUIRE_OPENCL();
  const Cage& cage = beam().model.cage;
  SamplingParams sp;
  sp.target_count = 3000;
  const VoxelSampling sampling = sample_voxels(cage, sp);
  OctreeCertifier cpu(cage, sampling), gpu(cage, sampling), gpu_layout(cage, sampling);
  gpu.set_backend(*opencl());
  lidef::test::TempDir cache;
  gpu_layout.set_backend(*as_gpu_backend(cache.str()));  // the GPU kernels and layouts, whatever the device
  const MatX3d id = cage.identity_coefficients();
  // A bend (y = p + a x² e_y), strong enough to need refinement, and a fold.
  auto bent = [&](double a) {
    MatX3d y = id;
    for (int v = 0; v < cage.num_vertices(); ++v) y(v, 1) += a * id(v, 0) * id(v, 0);
    return y;
  };
  int refined_cases = 0;
  for (double a : {0.0, 0.4, 0.9, 3.0})
    for (auto bound : {LipschitzBound::kThirdOrder, LipschitzBound::kFirstOrder}) {
      CertifyParams cp;
      cp.bound = bound;
      cp.max_refined_voxels = 20000;
      // The CPU's exact refinement (the far field, the CPU default, refines differently: test_far_field.cpp).
      cp.refinement = RefinementEval::kPerEdgeBatched;
      // The device evaluates octree nodes per face (the differential representation), as the CPU's per-face
      // path does; the CPU's default per-edge path (edge_jet.h) sums other magnitudes into its rounding
      // allowance τ, so its margins differ by ~1e-9 of those sums: it is compared by verdicts only.
      CertifyParams per_face = cp;
      per_face.refinement = RefinementEval::kPerFace;
      const Certificate c = cpu.certify(bent(a), per_face), g = gpu.certify(bent(a), cp),
                        g2 = gpu_layout.certify(bent(a), cp), ce = cpu.certify(bent(a), cp);
      SCOPED_TRACE("a = " + std::to_string(a) + " bound " + to_string(bound));
      expect_same_certificate(c, g, 1e-10);
      expect_same_certificate(c, g2, 1e-10);
      EXPECT_EQ(ce.certified, c.certified);
      EXPECT_EQ(ce.refined, c.refined);
      EXPECT_EQ(ce.num_leaves, c.num_leaves);
      if (c.refined > 0) ++refined_cases;
    }
  EXPECT_GE(refined_cases, 2) << "the test maps should exercise the refinement";

  // Distortion targets: the device's σ1 (base stage and octree nodes) gives the CPU's bounds, so a target
  // just below the unconstrained bound is proven by the same refinement on both. The CPU's Taylor bounds
  // (Step 3d) need J and H on the host, which the device keeps: compared without them, and with them the
  // CPU proves the same target with no more refinement.
  CertifyParams per_face;
  per_face.refinement = RefinementEval::kPerFace;
  per_face.max_refined_voxels = 20000;
  per_face.taylor_bounds = false;
  CertifyParams cp = per_face;
  cp.refinement = RefinementEval::kPerEdgeBatched;
  const Certificate free = cpu.certify(bent(0.9), per_face);
  ASSERT_TRUE(free.certified) << free.reason;
  per_face.max_distortion = cp.max_distortion = 0.9 * free.max_distortion_upper_bound;
  per_face.max_sigma1 = cp.max_sigma1 = std::max(1.0, 0.95 * free.max_sigma1_upper_bound);
  const Certificate c = cpu.certify(bent(0.9), per_face), g = gpu.certify(bent(0.9), cp);
  EXPECT_TRUE(c.distortion_met) << c.reason;
  EXPECT_EQ(g.distortion_met, c.distortion_met) << g.reason;
  EXPECT_GT(c.refined, free.refined);
  expect_same_certificate(c, g, 1e-10);
  per_face.taylor_bounds = true;
  const Certificate t = cpu.certify(bent(0.9), per_face);
  EXPECT_TRUE(t.distortion_met) << t.reason;
  EXPECT_LE(t.refined, c.refined);
}

// The solver on both backends with double-precision Hessian products: the same accepted steps, the same
// certificate verdicts, coefficients equal to ~1e-9 relative. With single precision (the default) the
// directions differ by float rounding: the same verdicts, coefficients to ~1e-5.
TEST(OpenCL, SolverMatchesCpu) {
  REQUIRE_OPENCL();
  for (const HessianPrecision precision : {HessianPrecision::kDouble, HessianPrecision::kSingle}) {
    SCOPED_TRACE(to_string(precision));
    DeformParams p;
    p.samples = 4000;
    p.reduced_dof = 60;
    p.max_iterations = 12;
    p.hessian_precision = precision;
    p.kept_factor_cg_steps = 0;  // the device assembles every iteration's Hessian; so does the CPU here
    DeformationSolver cpu(beam().model.cage, p, beam().cache.str());
    DeformationSolver gpu(beam().model.cage, p, beam().cache.str(), {}, opencl());
    EXPECT_NE(gpu.backend().name().find("opencl"), std::string::npos);
    cpu.set_handles(beam().sources, beam().targets);
    gpu.set_handles(beam().sources, beam().targets);
    const double tol = precision == HessianPrecision::kDouble ? 1e-9 : 1e-5;
    const double diff = expect_same_solves(cpu, gpu, tol);
    EXPECT_LT(diff, tol);
    std::cout << "[ parity   ] " << to_string(precision) << ": " << cpu.history().size()
              << " iterations, relative "
              << "coefficient difference " << diff << "\n";
  }
}

// --- CLI

namespace {
std::string beam_scenario_args() {
  return lidef::test::project_data() + "/scenarios/beam_bend.json --models " + lidef::test::project_data() +
         "/models --samples 4000 --reduced-dof 60 --max-iterations 4 --grid 0";
}
}  // namespace

TEST(OpenCLCli, DeformWithOpenCLBackendWritesItsName) {
  REQUIRE_OPENCL();
  lidef::test::TempDir out;
  std::string log;
  const int rc = lidef::test::run_command(lidef::test::cli() + " deform " + beam_scenario_args() +
                                              " --backend opencl --quiet --out " + out.str() + "/r",
                                          &log);
  ASSERT_LE(rc, 1) << log;
  const nlohmann::json s = nlohmann::json::parse(lidef::test::read_text(out / "r/summary.json"));
  EXPECT_NE(s.at("backend").get<std::string>().find("opencl"), std::string::npos);
  EXPECT_NE(log.find("backend: opencl"), std::string::npos) << log;
  EXPECT_TRUE(s.at("certified").get<bool>()) << log;
}

TEST(OpenCLCli, BackendFailuresAreClearAndAutoFallsBack) {
  lidef::test::TempDir out;
  std::string log;
  // No device matches the filter: --backend opencl refuses (exit 2, nothing written) and says why ...
  int rc = lidef::test::run_command(lidef::test::cli() + " deform " + beam_scenario_args() +
                                        " --opencl-device no-such-device --backend opencl --quiet --out " +
                                        out.str() + "/a",
                                    &log);
  EXPECT_EQ(rc, 2) << log;
  EXPECT_NE(log.find("no-such-device"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(out / "a"));
  // ... and auto says so and runs on the CPU.
  rc = lidef::test::run_command(lidef::test::cli() + " deform " + beam_scenario_args() +
                                    " --opencl-device no-such-device --backend auto --quiet --out " +
                                    out.str() + "/b",
                                &log);
  EXPECT_LE(rc, 1) << log;
  EXPECT_NE(log.find("backend: cpu (auto: no usable OpenCL device"), std::string::npos) << log;
  // No OpenCL platform at all (the ICD loader finds no vendor files).
  rc = lidef::test::run_command("OCL_ICD_VENDORS=/nonexistent-lidef " + lidef::test::cli() + " deform " +
                                    beam_scenario_args() + " --backend opencl --quiet --out " + out.str() +
                                    "/c",
                                &log);
  EXPECT_EQ(rc, 2) << log;
  EXPECT_NE(log.find("OpenCL"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(out / "c"));
  // An unknown backend name.
  rc = lidef::test::run_command(lidef::test::cli() + " deform " + beam_scenario_args() +
                                    " --backend cuda --quiet --out " + out.str() + "/d",
                                &log);
  EXPECT_EQ(rc, 2) << log;
  EXPECT_NE(log.find("backend"), std::string::npos) << log;
}

TEST(OpenCLCli, KernelBuildFailureIsReportedWithTheCompilerLog) {
  REQUIRE_OPENCL();
  lidef::test::TempDir out;
  std::string log;
  // Test hook: appends a line that does not compile to the kernel source.
  const int rc = lidef::test::run_command(lidef::test::cli() + " deform " + beam_scenario_args() +
                                              " --test-break-kernels true --backend opencl --quiet --out " +
                                              out.str() + "/a",
                                          &log);
  EXPECT_EQ(rc, 2) << log;
  EXPECT_NE(log.find("building the kernels failed"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(out / "a"));
}

TEST(OpenCLCli, CertifyBackendsAgree) {
  REQUIRE_OPENCL();
  lidef::test::TempDir out;
  const std::string model = lidef::test::project_data() + "/models/beam";
  std::string log;
  for (const char* b : {"cpu", "opencl"}) {
    const int rc = lidef::test::run_command(lidef::test::cli() + " certify " + model +
                                                " --coeffs identity --samples 3000 --grid 0 --backend " + b +
                                                " --out " + out.str() + "/" + b,
                                            &log);
    ASSERT_EQ(rc, 0) << log;
  }
  const nlohmann::json a = nlohmann::json::parse(lidef::test::read_text(out / "cpu/certificate.json"));
  const nlohmann::json b = nlohmann::json::parse(lidef::test::read_text(out / "opencl/certificate.json"));
  for (const char* key : {"certified", "leaves", "refined", "voxels"}) EXPECT_EQ(a.at(key), b.at(key)) << key;
  EXPECT_LT(rel(a.at("min_lower_bound").get<double>(), b.at("min_lower_bound").get<double>()), 1e-10);
  const nlohmann::json t = nlohmann::json::parse(lidef::test::read_text(out / "opencl/timings.json"));
  EXPECT_NE(t.at("backend").get<std::string>().find("opencl"), std::string::npos);
  EXPECT_EQ(a.at("certified"), b.at("certified"));
}

// --- The paper's scenarios (../shared/data; ctest label "slow"): default parameters with double-precision
// Hessian products on both backends, the first 4 iterations of each solve (bar_twist180: 2): the same
// accepted steps and certificate verdicts, coefficients equal to ~1e-9 relative, the final maps certified
// alike.
class OpenCLShared : public ::testing::TestWithParam<const char*> {};

TEST_P(OpenCLShared, SameStepsVerdictsAndCoefficients) {
  REQUIRE_OPENCL();
  const std::string path = lidef::test::shared_data() + "/scenarios/" + GetParam() + ".json";
  if (lidef::test::shared_data().empty() || !std::filesystem::exists(path))
    GTEST_SKIP() << "shared data absent: " << path;
  static lidef::test::TempDir cache;
  const Scenario sc = read_scenario(path);
  const Model model = load_model(sc.model_dir);
  DeformParams p = sc.params;
  p.hessian_precision = HessianPrecision::kDouble;
  p.kept_factor_cg_steps = 0;  // the device assembles every iteration's Hessian; so does the CPU here
  // The first iterations only: on PoCL with 2 cores each costs up to seconds; docs/benchmarks.md has whole
  // solves (on the H100: every iteration of every scenario the same on both backends).
  p.max_iterations = std::string(GetParam()) == "bar_twist180" ? 2 : 4;
  DeformationSolver cpu(model.cage, p, cache.str());
  DeformationSolver gpu(model.cage, p, cache.str(), {}, opencl());
  cpu.set_handles(sc.sources, sc.targets, sc.path);
  gpu.set_handles(sc.sources, sc.targets, sc.path);
  const double diff = expect_same_solves(cpu, gpu, 1e-9);
  EXPECT_LT(diff, 1e-9);
  std::cout << "[ parity   ] " << GetParam() << ": relative coefficient difference " << diff << "\n";
}

INSTANTIATE_TEST_SUITE_P(Scenarios, OpenCLShared,
                         ::testing::Values("bar_bend", "bar_twist90", "bar_twist180", "horse_leg_lift",
                                           "spot_head_turn", "animal_tail_lift"));

TEST(OpenCLCli, DevicesListsWhatAutoPicks) {
  std::string log;
  ASSERT_EQ(lidef::test::run_command(lidef::test::cli() + " devices", &log), 0) << log;
  EXPECT_NE(log.find("--backend auto -> "), std::string::npos) << log;
  if (opencl()) {
    EXPECT_NE(log.find("double precision yes"), std::string::npos) << log;
  }
}

TEST(OpenCLCli, DeviceTooSmallIsClearAndAutoFallsBack) {
  REQUIRE_OPENCL();
  lidef::test::TempDir out;
  std::string log;
  // Test hook: the device allows at most 1 MB per buffer, less than the reduced basis gradients need.
  const std::string env = "";
  const std::string cap = " --test-opencl-max-alloc 1000000";
  int rc = lidef::test::run_command(env + lidef::test::cli() + " deform " + beam_scenario_args() + cap +
                                        " --backend opencl --quiet --out " + out.str() + "/a",
                                    &log);
  EXPECT_EQ(rc, 2) << log;
  EXPECT_NE(log.find("the device allows at most"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(out / "a"));
  rc = lidef::test::run_command(env + lidef::test::cli() + " deform " + beam_scenario_args() + cap +
                                    " --backend auto --quiet --out " + out.str() + "/b",
                                &log);
  EXPECT_LE(rc, 1) << log;
  EXPECT_NE(log.find("backend: cpu (auto: OpenCL"), std::string::npos) << log;
  const nlohmann::json s = nlohmann::json::parse(lidef::test::read_text(out / "b/summary.json"));
  EXPECT_EQ(s.at("backend"), "cpu");
}
