// How well does a Hessian-subset estimator stand in for the all-sample projected Hessian along a solve, and
// what does the conjugate-gradient correction (newton_cg_steps, docs/solver.md "Correcting the subset
// Hessian") have to make up? At every iterate of the scenario's solve (default parameters), for the exact
// Hessian H (all samples, volume weights, PSD-projected blocks, plus the quadratic terms) and an estimate H̃
// (the same with the distortion part from a subset), it prints the linear rate of Newton with H̃,
// rho = max |1 − λ| over the generalized eigenvalues λ of (H, H̃), for:
//   A  the solver's subset (select_hessian_subset: strata of equal volume along a Morton curve), weights
//   1/|H|; B  importance sampling ∝ w_i ‖G_i‖²_F (systematic, Horvitz–Thompson weights); C  importance
//   sampling ∝ the statistical leverage w_i tr(G_i M⁻¹ G_iᵀ), M = Σ w_i G_iᵀ G_i; D  importance sampling ∝
//   w_i ‖G_i‖²_F tr K_i, redrawn at every iterate (K_i the projected 9x9 block); E  A plus a control variate:
//   the exact all-sample Hessian of the subset's mean block K̄ minus its subset
//      estimate (exact wherever K_i is constant, e.g. at the identity); -1 when not positive definite.
// All subsets have the same size |H|. Double precision throughout; minutes per scenario (dense 3s x 3s
// generalized eigenproblems). Usage: bench_hessian_subset DATA_DIR|SCENARIO.json [--cache-dir DIR]; a folder
// (scripts/bench.sh passes the shared data folder) means its scenarios/bar_bend.json.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numeric>
#include <string>

#include "bench_util.h"
#include "lidef/blas_kernel.h"
#include "lidef/deformation_energy.h"
#include "lidef/errors.h"
#include "lidef/model_check.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"
#include "lidef/symmetric_dirichlet.h"

using namespace lidef;

namespace {

constexpr int kPairs[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};

// Σ_k wk G_kᵀ K_k G_k over the samples idx (3s by 3s, vec(ỹ) column-major), K_k the projected block at JT or
// the given fixed blocks.
MatXd distortion_estimate(const MatXfR& G, const MatJT& JT, const std::vector<int>& idx, const VecXd& wk,
                          const std::vector<Mat9>* fixed = nullptr) {
  const int s = static_cast<int>(G.cols()), m = static_cast<int>(idx.size());
  MatXd Gd(3 * m, s);
  for (int k = 0; k < m; ++k) Gd.middleRows(3 * k, 3) = G.middleRows(3 * idx[k], 3).cast<double>();
  MatXd H = MatXd::Zero(3 * s, 3 * s);
  for (const auto& pair : kPairs) {
    const int a = pair[0], a2 = pair[1];
    MatXd W(3 * m, s);
#pragma omp parallel for
    for (int k = 0; k < m; ++k) {
      const Mat9 K = fixed ? (*fixed)[k] : sd_hessian_psd(JT.middleRows<3>(3 * idx[k]).transpose());
      Mat3 Ht;
      for (int b = 0; b < 3; ++b)
        for (int b2 = 0; b2 < 3; ++b2) Ht(b, b2) = wk(k) * K(a + 3 * b, a2 + 3 * b2);
      W.middleRows(3 * k, 3) = Ht * Gd.middleRows(3 * k, 3);
    }
    const MatXd B = Gd.transpose() * W;
    H.block(a * s, a2 * s, s, s) = B;
    if (a != a2) H.block(a2 * s, a * s, s, s) = B.transpose();
  }
  return 0.5 * (H + H.transpose());
}

double rate(const MatXd& H, const MatXd& Hest) {
  const Eigen::GeneralizedSelfAdjointEigenSolver<MatXd> es(H, Hest);
  const VecXd& l = es.eigenvalues();
  return std::max(std::abs(1 - l.minCoeff()), std::abs(1 - l.maxCoeff()));
}

// Systematic sampling of m picks with inclusion probabilities π_i ∝ q_i (capped at 1), in index order, at
// golden-ratio offsets; weights v_i / π_i estimate Σ_i v_i X_i.
void systematic(const VecXd& q, const VecXd& v, int m, std::vector<int>& idx, VecXd& wk) {
  const int n = static_cast<int>(q.size());
  VecXd pi = (q * (m / q.sum())).cwiseMin(1.0);
  for (int it = 0; it < 20; ++it) {  // redistribute what the cap removed
    const double full = static_cast<double>((pi.array() >= 1.0).count());
    double rest = 0;
    for (int i = 0; i < n; ++i)
      if (pi(i) < 1) rest += q(i);
    if (rest <= 0) break;
    for (int i = 0; i < n; ++i)
      if (pi(i) < 1) pi(i) = std::min(1.0, q(i) * (m - full) / rest);
  }
  idx.clear();
  std::vector<double> w;
  double cum = 0;
  int k = 0;
  for (int i = 0; i < n; ++i) {
    const double c0 = cum;
    cum += pi(i);
    for (;;) {
      const double t = k + std::fmod(0.5 + k * 0.6180339887498949, 1.0);
      if (!(t >= c0 && t < cum)) break;
      idx.push_back(i);
      w.push_back(v(i) / pi(i));
      ++k;
    }
  }
  wk = Eigen::Map<const VecXd>(w.data(), static_cast<Eigen::Index>(w.size()));
}

}  // namespace

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  std::string path, cache = "/tmp/lidef-bench-cache";
  CLI::App app{
      "bench_hessian_subset: the linear rate of Newton with each Hessian-subset estimate against the "
      "all-sample Hessian, at every iterate of a scenario's solve; a markdown table on stdout"};
  app.option_defaults()->always_capture_default();
  app.add_option(
         "DATA_DIR", path,
         "a scenario JSON, or a data folder (its scenarios/bar_bend.json: scripts/bench.sh passes the "
         "shared data folder)")
      ->required();
  app.add_option("--cache-dir", cache, "subspace cache folder");
  if (const int rc = bench::parse_command_line(app, argc, argv); rc >= 0) return rc;
  if (std::filesystem::is_directory(path)) path += "/scenarios/bar_bend.json";
  try {
    const Scenario sc = read_scenario(path);
    const Model model = load_model(sc.model_dir);
    DeformationSolver solver(model.cage, model.mesh, sc.params, cache);
    solver.set_handles(sc.sources, sc.targets);
    std::vector<MatS3> ys{solver.reduced_coefficients()};
    std::vector<EnergyWeights> ws{solver.weights()};
    solver.solve([&](const IterationRecord&) {
      ys.push_back(solver.reduced_coefficients());
      ws.push_back(solver.weights());
      return true;
    });
    const DeformationEnergy& E = solver.energy_function();
    const MatXfR& G = E.gradient_matrix();
    const int n = E.num_samples(), s = E.reduced_size();
    const std::vector<int>& subset = E.hessian_subset();
    const int m = static_cast<int>(subset.size());
    const VecXd v =
        E.weighted() ? VecXd(E.sample_weights() / E.sample_weights().sum()) : VecXd::Constant(n, 1.0 / n);
    std::printf("%s: %d samples, s = %d, |H| = %d, %zu iterations (newton_cg_steps %d)\n", sc.name.c_str(), n,
                s, m, ys.size() - 1, sc.params.newton_cg_steps);
    // Per-sample norms and leverages.
    const MatXd Gd = G.cast<double>();
    MatXd M = MatXd::Zero(s, s);
    for (int i = 0; i < n; ++i) M += v(i) * Gd.middleRows(3 * i, 3).transpose() * Gd.middleRows(3 * i, 3);
    const Eigen::LLT<MatXd> Ml(M + 1e-9 * M.trace() / s * MatXd::Identity(s, s));
    VecXd norm2(n), leverage(n);
    for (int i = 0; i < n; ++i) {
      norm2(i) = v(i) * Gd.middleRows(3 * i, 3).squaredNorm();
      leverage(i) = v(i) * (Gd.middleRows(3 * i, 3) * Ml.solve(Gd.middleRows(3 * i, 3).transpose())).trace();
    }
    std::vector<int> idxB, idxC, all(n);
    std::iota(all.begin(), all.end(), 0);
    VecXd wB, wC;
    systematic(norm2, v, m, idxB, wB);
    systematic(leverage, v, m, idxC, wC);
    const VecXd wA = VecXd::Constant(m, 1.0 / m);
    std::printf(
        "| iterate | A: solver's subset | B: ∝ ‖G_i‖² | C: ∝ leverage | D: ∝ ‖G_i‖² tr K_i | E: A + control "
        "variate |\n");
    std::printf("|---:|---:|---:|---:|---:|---:|\n");
    for (size_t it = 0; it < ys.size(); ++it) {
      const MatJT JT = E.jacobians(ys[it]);
      auto with_quadratic = [&](MatXd H) {
        for (int a = 0; a < 3; ++a) {
          auto blk = H.block(a * s, a * s, s, s);
          blk += (2.0 * ws[it].p2p) * E.handle_matrix().transpose() * E.handle_matrix();
          blk.diagonal() += (2.0 * ws[it].smooth / E.num_edges()) * E.smooth_eigenvalues();
        }
        return H;
      };
      const MatXd H = with_quadratic(distortion_estimate(G, JT, all, v));
      VecXd qD(n);
      for (int i = 0; i < n; ++i)
        qD(i) = norm2(i) * sd_hessian_psd(JT.middleRows<3>(3 * i).transpose()).trace();
      std::vector<int> idxD;
      VecXd wD;
      systematic(qD, v, m, idxD, wD);
      Mat9 mean = Mat9::Zero();
      for (int k = 0; k < m; ++k) mean += wA(k) * sd_hessian_psd(JT.middleRows<3>(3 * subset[k]).transpose());
      const std::vector<Mat9> mean_all(n, mean), mean_subset(m, mean);
      const MatXd HA = distortion_estimate(G, JT, subset, wA);
      const MatXd HE = with_quadratic(HA + distortion_estimate(G, JT, all, v, &mean_all) -
                                      distortion_estimate(G, JT, subset, wA, &mean_subset));
      const bool E_pd = Eigen::LLT<MatXd>(HE).info() == Eigen::Success;
      std::printf("| %zu | %.3f | %.3f | %.3f | %.3f | %.3f |\n", it, rate(H, with_quadratic(HA)),
                  rate(H, with_quadratic(distortion_estimate(G, JT, idxB, wB))),
                  rate(H, with_quadratic(distortion_estimate(G, JT, idxC, wC))),
                  rate(H, with_quadratic(distortion_estimate(G, JT, idxD, wD))), E_pd ? rate(H, HE) : -1.0);
      std::fflush(stdout);
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_hessian_subset: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
