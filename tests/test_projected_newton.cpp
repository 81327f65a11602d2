// DeformationSolver (projected_newton.h) on the project's beam model with small, fast parameters and the
// handles of data/scenarios/beam_bend.json: the identity as a fixed point, monotone energy, every accepted
// iterate certified by an independent full-space certifier, dense sampling of the final certificate,
// convergence to the handles, interruption and determinism (bitwise), handle errors, and dynamic weighting.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/model_check.h"
#include "lidef/octree_certifier.h"
#include "lidef/projected_newton.h"
#include "lidef/signed_svd.h"
#include "test_support.h"

using namespace lidef;

namespace {

struct BeamData {
  explicit BeamData(Model m) : model(std::move(m)) {}
  Model model;
  MatX3d sources, targets;     // beam_bend.json's 10 handles
  lidef::test::TempDir cache;  // subspace cache shared by every solver of this file
};

MatX3d json_points(const nlohmann::json& handles, const char* key) {
  MatX3d P(handles.size(), 3);
  for (size_t i = 0; i < handles.size(); ++i)
    for (int c = 0; c < 3; ++c) P(i, c) = handles[i].at(key).at(c).get<double>();
  return P;
}

const BeamData& beam() {
  static const std::unique_ptr<BeamData> B = [] {
    auto b = std::make_unique<BeamData>(load_model(lidef::test::project_data() + "/models/beam"));
    // Parsed directly (not through scenario.h) so that this file depends only on the solver.
    std::ifstream in(lidef::test::project_data() + "/scenarios/beam_bend.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    b->sources = json_points(j.at("handles"), "source");
    b->targets = json_points(j.at("handles"), "target");
    return b;
  }();
  return *B;
}

// Small and fast: about 4000 voxels, 60 reduced coefficients per coordinate, 15 iterations.
DeformParams fast_params() {
  DeformParams p;
  p.samples = 4000;
  p.reduced_dof = 60;
  p.max_iterations = 15;
  return p;
}

std::unique_ptr<DeformationSolver> make_solver(const DeformParams& p = fast_params()) {
  return std::make_unique<DeformationSolver>(beam().model.cage, p, beam().cache.str());
}

bool bitwise_equal(const MatS3& a, const MatS3& b) {
  return a.rows() == b.rows() && std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

// One beam_bend run with dynamic weighting off, shared by the tests that only read it. Every accepted iterate
// is certified in the callback by a fresh full-space certifier (no reduction).
struct BendRun {
  std::unique_ptr<DeformationSolver> solver;
  SolveResult result;
  std::vector<IterationRecord> records;        // as passed to the callback
  std::vector<Certificate> full_certificates;  // one per accepted iterate, full space
  double seconds = 0;
};

const BendRun& bend_run() {
  static const std::unique_ptr<BendRun> R = [] {
    auto r = std::make_unique<BendRun>();
    const auto t0 = Clock::now();
    DeformParams p = fast_params();
    p.dynamic_weighting = false;
    p.max_iterations =
        30;  // converges in 11-17 iterations depending on the build (measured); 30 leaves margin
    r->solver = make_solver(p);
    DeformationSolver& s = *r->solver;
    s.set_handles(beam().sources, beam().targets, "beam_bend.json");
    const OctreeCertifier full(beam().model.cage, s.sampling());  // full space: no reduction matrix
    r->result = s.solve([&](const IterationRecord& rec) {
      r->records.push_back(rec);
      if (rec.accepted)
        r->full_certificates.push_back(full.certify(s.coefficients(), s.certify_params(false, false)));
      return true;
    });
    r->seconds = seconds_since(t0);
    for (const IterationRecord& rec : r->records)
      std::printf("  it %2d  E %.10e -> %.10e  t %.4g  |step| %.3e  armijo %d  cert %d  handle err %.3e\n",
                  rec.iteration, rec.energy_before, rec.terms.total, rec.step, rec.step_norm,
                  rec.armijo_rejections, rec.certificate_rejections, rec.max_handle_error);
    std::printf("beam_bend (fixed weights): %s after %d iterations, %s, max handle error %.3e, %.2f s\n",
                to_string(r->result.reason), r->result.iterations, r->result.message.c_str(),
                s.handle_errors().maxCoeff(), r->seconds);
    return r;
  }();
  return *R;
}

}  // namespace

TEST(ProjectedNewton, IdentityIsAFixedPoint) {
  // Targets at the sources: the identity (certified, E ≈ 0, ∇E ≈ 0) is the minimiser. The solver must stop
  // within 2 iterations with energy ≈ 0 (1e-12: E_dis is quadratic in J − I) and the handles where they are.
  // How far it may move ỹ from Ξᵀ y_id depends on the storage of the reduced gradient matrix G: in double the
  // gradient at the identity is ~1e-15 and ỹ stays within 1e-9; the energy now keeps G in single precision
  // (deformation_energy.h, "Storage"), which puts the discrete minimiser ~H⁻¹∇E ≈ 2e-7 away (∇E_dis ≈ 3e-8
  // and E_dis is flat in the local-rotation directions), so the bound here is 1e-6 on ỹ and 1e-6 (relative to
  // the cage size) on the map at the voxel centers.
  auto s = make_solver();
  s->set_handles(beam().sources, beam().sources);
  const MatS3 y0 = s->reduced_coefficients();
  const MatS3 yid = s->subspace().basis.transpose() * s->normalized_cage().identity_coefficients();
  EXPECT_LT((y0 - yid).cwiseAbs().maxCoeff(), 1e-14);
  const SolveResult r = s->solve();
  EXPECT_TRUE(r.converged()) << to_string(r.reason) << ": " << r.message;
  EXPECT_LE(r.iterations, 2);
  const double dy = (s->reduced_coefficients() - yid).cwiseAbs().maxCoeff();
  EXPECT_LT(dy, 1e-6);
  const MatX3d& C = s->sampling().centers;
  const double df = (s->basis().map_values(s->coefficients(), C) - C).cwiseAbs().maxCoeff();
  EXPECT_LT(df, 1e-6 * (beam().model.cage.bbox_max - beam().model.cage.bbox_min).norm());
  const EnergyTerms e = s->energy();
  EXPECT_LT(std::abs(e.total), 1e-12);
  EXPECT_LT(s->handle_errors().maxCoeff(), 1e-9);
  EXPECT_TRUE(s->certificate().certified);
  std::printf("identity: %s, %d iterations, %s, E = %.3e, max |dy| = %.3e, max |f(c) - c| = %.3e\n",
              to_string(r.reason), r.iterations, r.message.c_str(), e.total, dy, df);
}

TEST(ProjectedNewton, EnergyIsNonIncreasingWithFixedWeights) {
  // With dynamic_weighting = false the weights never change, so within an accepted iteration the Armijo test
  // gives terms.total ≤ energy_before, and the next iteration starts exactly (bitwise: same ỹ, same JT, same
  // deterministic evaluate) at the previous accepted energy.
  const BendRun& run = bend_run();
  ASSERT_FALSE(run.records.empty());
  const DeformParams& p = run.solver->params();
  double prev = std::numeric_limits<double>::quiet_NaN();
  for (const IterationRecord& rec : run.records) {
    EXPECT_EQ(rec.lambda_p2p, p.lambda_p2p);
    EXPECT_EQ(rec.lambda_smooth, p.lambda_smooth);
    if (rec.iteration > 1) {
      EXPECT_EQ(rec.energy_before, prev) << "iteration " << rec.iteration;
    }
    if (rec.accepted) {
      EXPECT_LE(rec.terms.total, rec.energy_before) << "iteration " << rec.iteration;
      EXPECT_LE(rec.terms.total, rec.energy_before + p.armijo * rec.step * -rec.newton_decrement)
          << rec.iteration;
      EXPECT_EQ(rec.terms.total,
                rec.terms.dis + p.lambda_p2p * rec.terms.p2p + p.lambda_smooth * rec.terms.smooth);
    }
    prev = rec.terms.total;
  }
  // The solver's energy() is the last accepted one.
  EXPECT_EQ(run.solver->energy().total, run.records.back().terms.total);
}

TEST(ProjectedNewton, EveryAcceptedIterateIsCertifiedInFullSpace) {
  const BendRun& run = bend_run();
  int accepted = 0;
  for (const IterationRecord& rec : run.records) {
    EXPECT_TRUE(rec.certified) << "iteration " << rec.iteration;
    accepted += rec.accepted;
  }
  ASSERT_GT(accepted, 0);
  ASSERT_EQ(static_cast<int>(run.full_certificates.size()), accepted);
  for (size_t k = 0; k < run.full_certificates.size(); ++k)
    EXPECT_TRUE(run.full_certificates[k].certified)
        << "accepted iterate " << k + 1 << ": " << run.full_certificates[k].reason;
}

TEST(ProjectedNewton, FinalCertificateSurvivesDenseSampling) {
  // ≥ 20 random points (plus the 8 corners and the center) in every leaf of the final map's certificate, σ3
  // from the exact double-precision basis (verify_certificate): no σ3 ≤ 0 in a certified leaf, and no sample
  // below the certified lower bound σ3(c) − |p − c| L.
  const BendRun& run = bend_run();
  const DeformationSolver& s = *run.solver;
  const Certificate c = s.certify_current(true);
  ASSERT_TRUE(c.certified) << c.reason;
  ASSERT_EQ(static_cast<long>(c.leaves.size()), c.num_leaves);
  const MatX3d y = s.coefficients();
  const VerificationResult v = verify_certificate(s.basis(), y, c.leaves, 20, 9);
  EXPECT_EQ(v.nonpositive_in_certified, 0);
  EXPECT_EQ(v.violations, 0);
  EXPECT_GT(v.min_sigma3, 0);
  EXPECT_GE(v.min_sigma3, c.min_lower_bound - 1e-9);
  // An independent spot check of the same thing without verify_certificate: 20 points in each of 200 leaves,
  // σ3 via signed_singular_values of map_jet(y, p, 1).J.
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> U(-0.5, 0.5);
  double min_s3 = std::numeric_limits<double>::infinity();
  const long stride = std::max<long>(1, static_cast<long>(c.leaves.size()) / 200);
  for (size_t li = 0; li < c.leaves.size(); li += stride) {
    const CertLeaf& lf = c.leaves[li];
    for (int k = 0; k < 20; ++k) {
      const Vec3 p = lf.center + lf.side * Vec3(U(rng), U(rng), U(rng));
      min_s3 = std::min(min_s3, signed_singular_values(s.basis().map_jet(y, p, 1).J)(2));
    }
  }
  EXPECT_GT(min_s3, 0);
  std::printf(
      "dense sampling: %ld leaves, %ld points, min sigma3 %.4f (certified lower bound %.4f), spot check "
      "%.4f\n",
      static_cast<long>(c.leaves.size()), v.points, v.min_sigma3, c.min_lower_bound, min_s3);
}

TEST(ProjectedNewton, ConvergesOnBeamBend) {
  // λ1 = 1e5 makes the P2P residual tiny: at the minimiser ∇E_dis + λ1 ∇E_P2P = 0 gives handle errors of
  // order |∇E_dis| / λ1 ~ 1e-5; the project's handle_tolerance of 1e-3 (0.05% of the beam's length) is the
  // bound.
  const BendRun& run = bend_run();
  EXPECT_TRUE(run.result.converged()) << to_string(run.result.reason) << ": " << run.result.message;
  const double err = run.solver->handle_errors().maxCoeff();
  EXPECT_LE(err, 1e-3);
  EXPECT_EQ(run.records.back().max_handle_error, err);
  EXPECT_TRUE(run.solver->certificate().certified);
  EXPECT_EQ(static_cast<int>(run.solver->history().size()), run.result.iterations);
}

TEST(ProjectedNewton, InterruptionEqualsIterationLimit) {
  // A callback that returns false after k = 3 iterations, and a stop flag set from the callback, must both
  // leave exactly (bitwise) the coefficients of a run limited to 3 iterations.
  const int k = 3;
  DeformParams p3 = fast_params();
  p3.max_iterations = k;
  auto a = make_solver(p3);
  a->set_handles(beam().sources, beam().targets);
  const SolveResult ra = a->solve();
  EXPECT_EQ(ra.reason, StopReason::kMaxIterations) << ra.message;
  EXPECT_EQ(ra.iterations, k);

  auto b = make_solver();
  b->set_handles(beam().sources, beam().targets);
  int calls = 0;
  const SolveResult rb = b->solve([&](const IterationRecord&) { return ++calls < k; });
  EXPECT_EQ(rb.reason, StopReason::kInterrupted) << rb.message;
  EXPECT_EQ(rb.iterations, k);
  EXPECT_EQ(calls, k);
  EXPECT_TRUE(bitwise_equal(a->reduced_coefficients(), b->reduced_coefficients()));

  auto c = make_solver();
  c->set_handles(beam().sources, beam().targets);
  std::atomic<bool> stop{false};
  int calls_c = 0;
  const SolveResult rc = c->solve(
      [&](const IterationRecord&) {
        if (++calls_c == k) stop = true;
        return true;
      },
      &stop);
  EXPECT_EQ(rc.reason, StopReason::kInterrupted) << rc.message;
  EXPECT_EQ(rc.iterations, k);
  EXPECT_EQ(static_cast<int>(c->history().size()), k);
  EXPECT_TRUE(bitwise_equal(a->reduced_coefficients(), c->reduced_coefficients()));
  EXPECT_TRUE(c->certificate().certified);

  // A stop flag set before solve() changes nothing.
  auto d = make_solver();
  d->set_handles(beam().sources, beam().targets);
  std::atomic<bool> stop_now{true};
  const SolveResult rd = d->solve({}, &stop_now);
  EXPECT_EQ(rd.reason, StopReason::kInterrupted);
  EXPECT_EQ(rd.iterations, 0);
  EXPECT_TRUE(bitwise_equal(d->reduced_coefficients(), MatS3(d->subspace().basis.transpose() *
                                                             d->normalized_cage().identity_coefficients())));
}

TEST(ProjectedNewton, FreshSolversAreBitwiseDeterministic) {
  DeformParams p = fast_params();
  p.max_iterations = 5;
  MatX3d coeffs[2];
  std::vector<IterationRecord> hist[2];
  for (int r = 0; r < 2; ++r) {
    auto s = make_solver(p);
    s->set_handles(beam().sources, beam().targets);
    s->solve();
    coeffs[r] = s->coefficients();
    hist[r] = s->history();
  }
  ASSERT_EQ(coeffs[0].rows(), coeffs[1].rows());
  EXPECT_EQ(std::memcmp(coeffs[0].data(), coeffs[1].data(), sizeof(double) * coeffs[0].size()), 0);
  ASSERT_EQ(hist[0].size(), hist[1].size());
  for (size_t i = 0; i < hist[0].size(); ++i) {
    EXPECT_EQ(hist[0][i].terms.total, hist[1][i].terms.total);
    EXPECT_EQ(hist[0][i].step, hist[1][i].step);
  }
}

TEST(ProjectedNewton, SetHandlesRejectsBadInput) {
  auto s = make_solver();
  const MatS3 y0 = s->reduced_coefficients();
  auto message = [](auto&& f) { return lidef::test::input_error_message(f); };
  MatX3d src = beam().sources, tgt = beam().targets;
  // A source outside the cage (the cage spans x in [-1.04, 1.04]).
  MatX3d out = src;
  out.row(3) << 1.5, 0.0, 0.0;
  std::string m = message([&] { s->set_handles(out, tgt, "my_handles.json"); });
  EXPECT_NE(m.find("outside the cage"), std::string::npos) << m;
  EXPECT_NE(m.find("handle 4"), std::string::npos) << m;
  EXPECT_NE(m.find("my_handles.json"), std::string::npos) << m;
  // A NaN target.
  MatX3d nan = tgt;
  nan(2, 1) = std::numeric_limits<double>::quiet_NaN();
  m = message([&] { s->set_handles(src, nan); });
  EXPECT_NE(m.find("not a finite number"), std::string::npos) << m;
  EXPECT_NE(m.find("handle 3"), std::string::npos) << m;
  // An infinite source.
  MatX3d inf = src;
  inf(0, 0) = std::numeric_limits<double>::infinity();
  m = message([&] { s->set_handles(inf, tgt); });
  EXPECT_NE(m.find("not a finite number"), std::string::npos) << m;
  // No handles at all.
  m = message([&] { s->set_handles(MatX3d(0, 3), MatX3d(0, 3)); });
  EXPECT_NE(m.find("no handles"), std::string::npos) << m;
  // Mismatched counts.
  m = message([&] { s->set_handles(src, tgt.topRows(3)); });
  EXPECT_FALSE(m.empty());
  // solve() before any valid set_handles.
  m = message([&] { s->solve(); });
  EXPECT_NE(m.find("no handles"), std::string::npos) << m;
  // A NaN in set_targets after valid handles.
  s->set_handles(src, tgt);
  m = message([&] { s->set_targets(nan); });
  EXPECT_NE(m.find("not a finite number"), std::string::npos) << m;
  // A target at 1e300: finite, but its squared distance is not a double (it used to run).
  MatX3d far = tgt;
  far(1, 0) = 1e300;
  m = message([&] { s->set_handles(src, far, "far.json"); });
  EXPECT_NE(m.find("handle 2"), std::string::npos) << m;
  EXPECT_NE(m.find("cage diagonals"), std::string::npos) << m;
  m = message([&] { s->set_targets(far); });
  EXPECT_NE(m.find("cage diagonals"), std::string::npos) << m;
  // One source with two different targets (it used to run and average them).
  MatX3d dup_src = src, dup_tgt = tgt;
  dup_src.row(1) = dup_src.row(0);
  dup_tgt.row(1) = dup_tgt.row(0) + Eigen::RowVector3d(0.1, 0, 0);
  m = message([&] { s->set_handles(dup_src, dup_tgt, "dup.json"); });
  EXPECT_NE(m.find("handles 1 and 2 have the same source but different targets"), std::string::npos) << m;
  // The same source with the same target is only redundant: accepted.
  dup_tgt.row(1) = dup_tgt.row(0);
  EXPECT_NO_THROW(s->set_handles(dup_src, dup_tgt));
  // ... and moving one of its targets away later is refused like the rest.
  dup_tgt(1, 0) += 0.1;
  m = message([&] { s->set_targets(dup_tgt); });
  EXPECT_NE(m.find("same source but different targets"), std::string::npos) << m;
  // None of the refusals changed the map.
  EXPECT_TRUE(bitwise_equal(s->reduced_coefficients(), y0));
}

TEST(ProjectedNewton, DynamicWeightingOnAndOffBothEndCertified) {
  // Off: the shared run. On: a fresh run with the defaults (κ1 = 0.5, κ2 = 2). Both end certified; with
  // weighting on, a converged run ends at the user's weights (the reset/relax logic of solve()). On beam_bend
  // with the fast parameters no weight change is triggered (measured), so the weights are also driven away on
  // purpose below.
  const BendRun& off = bend_run();
  EXPECT_TRUE(off.solver->certificate().certified);
  EXPECT_TRUE(off.solver->certify_current(false).certified);
  EXPECT_EQ(off.solver->weights().p2p, fast_params().lambda_p2p);
  EXPECT_EQ(off.solver->weights().smooth, fast_params().lambda_smooth);

  DeformParams p = fast_params();
  p.dynamic_weighting = true;
  p.max_iterations = 30;
  auto on = make_solver(p);
  on->set_handles(beam().sources, beam().targets);
  const SolveResult r = on->solve();
  EXPECT_TRUE(on->certificate().certified);
  EXPECT_TRUE(on->certify_current(false).certified);
  for (const IterationRecord& rec : on->history()) EXPECT_TRUE(rec.certified) << rec.iteration;
  EXPECT_TRUE(r.converged()) << to_string(r.reason) << ": " << r.message;
  EXPECT_EQ(on->weights().p2p, p.lambda_p2p);
  EXPECT_EQ(on->weights().smooth, p.lambda_smooth);
  EXPECT_LE(on->handle_errors().maxCoeff(), 1e-3);
  // Same map as with weighting off when no weight ever changed (same arithmetic).
  bool changed = false;
  for (const IterationRecord& rec : on->history()) changed |= !rec.weight_action.empty();
  if (!changed) {
    EXPECT_TRUE(bitwise_equal(on->reduced_coefficients(), off.solver->reduced_coefficients()));
  }
}

TEST(ProjectedNewton, DynamicWeightingRelaxesBackToTheUserWeights) {
  // Phase 1: E0 = 1e-13 · diag² (below every E_P2P reached) makes each accepted step raise λ2 (κ2 = 2) and,
  // while the certified margin min(σ3 − rL) < ε = 0.05, lower λ1 (κ1 = 0.5): 4 iterations, stopped by the
  // callback. Phase 2: the default E0 again (set_params keeps the changed weights: λ1, λ2 are the same
  // parameters) — now E_P2P < E0 and no certificate rejection, so every step relaxes the weights toward the
  // user's, and the run must converge exactly at them (relax, or a reset at convergence), certified, with the
  // handles reached (1e-3).
  DeformParams p = fast_params();
  p.max_iterations = 40;
  p.e0 = 1e-13;
  auto s = make_solver(p);
  s->set_handles(beam().sources, beam().targets);
  int calls = 0;
  const SolveResult r1 = s->solve([&](const IterationRecord&) { return ++calls < 4; });
  EXPECT_EQ(r1.reason, StopReason::kInterrupted) << r1.message;
  EXPECT_GT(s->weights().smooth, p.lambda_smooth);
  EXPECT_LT(s->weights().p2p, p.lambda_p2p);
  for (const IterationRecord& rec : s->history()) {
    EXPECT_TRUE(rec.certified);
    EXPECT_NE(rec.weight_action.find("smooth+"), std::string::npos)
        << rec.iteration << ": " << rec.weight_action;
  }
  const EnergyWeights changed = s->weights();

  p.e0 = DeformParams().e0;
  s->set_params(p);
  EXPECT_EQ(s->weights().p2p, changed.p2p);
  EXPECT_EQ(s->weights().smooth, changed.smooth);
  std::vector<IterationRecord> recs;
  const SolveResult r2 = s->solve([&](const IterationRecord& rec) {
    recs.push_back(rec);
    return true;
  });
  std::string actions;
  int relax = 0, reset = 0;
  for (const IterationRecord& rec : recs) {
    EXPECT_TRUE(rec.certified) << rec.iteration;
    relax += rec.weight_action == "relax";
    reset += rec.weight_action == "reset";
    if (!rec.weight_action.empty()) actions += " " + std::to_string(rec.iteration) + ":" + rec.weight_action;
  }
  std::printf("relax phase: %s after %d iterations, weights %g %g, max handle error %.3e, actions:%s\n",
              to_string(r2.reason), r2.iterations, s->weights().p2p, s->weights().smooth,
              s->handle_errors().maxCoeff(), actions.c_str());
  EXPECT_GT(relax + reset, 0);
  EXPECT_TRUE(r2.converged()) << to_string(r2.reason) << ": " << r2.message;
  EXPECT_EQ(s->weights().p2p, p.lambda_p2p);
  EXPECT_EQ(s->weights().smooth, p.lambda_smooth);
  EXPECT_TRUE(s->certificate().certified);
  EXPECT_LE(s->handle_errors().maxCoeff(), 1e-3);
}

// Reproducer of a contract mismatch (see the report): with E0 below every E_P2P reached, weighting changes
// the weights after every step; convergence resets them max_weight_resets (2) times, and the third
// convergence is reported as StopReason::kConverged with λ1 = 781.25, λ2 = 100 (handle error 5e-4) although
// kConverged is documented as "... at the user's weights". Disabled because it fails on purpose; enable to
// reproduce. With a tiny E0 the weights keep changing; once max_weight_resets is used up the run may converge
// at adjusted weights, and then the result must say so (kConverged alone promises the user's weights).
TEST(ProjectedNewton, ConvergedAtAdjustedWeightsSaysSo) {
  DeformParams p = fast_params();
  p.max_iterations = 60;
  p.e0 = 1e-13;
  auto s = make_solver(p);
  s->set_handles(beam().sources, beam().targets);
  const SolveResult r = s->solve();
  std::printf("%s (%s) after %d iterations, weights %g %g, max handle error %.3e\n", to_string(r.reason),
              r.message.c_str(), r.iterations, s->weights().p2p, s->weights().smooth,
              s->handle_errors().maxCoeff());
  EXPECT_TRUE(s->certificate().certified);
  if (r.converged()) {
    const bool user = s->weights().p2p == p.lambda_p2p && s->weights().smooth == p.lambda_smooth;
    EXPECT_EQ(!user, r.message.find("adjusted weights") != std::string::npos) << r.message;
  }
}

// The line search stops halving once t‖δ‖ ≤ step_tolerance · max(1, ‖ỹ‖): a shorter step would end the solve
// anyway (converged, or blocked when a trial was refused). A distortion target just above 1 refuses every
// long step of beam_bend's first direction; with a step tolerance of 0.05 the trials stop while still long
// (no step, the map unchanged), without one the halving goes on until a short step is certified.
TEST(ProjectedNewton, LineSearchStopsAtTheStepTolerance) {
  auto first_iteration = [](double step_tolerance) {
    DeformParams p = fast_params();
    p.dynamic_weighting = false;
    p.max_distortion = 1.001;
    p.step_tolerance = step_tolerance;
    p.max_iterations = 1;
    auto s = make_solver(p);
    s->set_handles(beam().sources, beam().targets);
    const MatS3 y0 = s->reduced_coefficients();
    const IterationRecord rec = s->step();
    std::printf(
        "step_tolerance %g: accepted %d, t %g, |t delta| %.3e, %d certificate and %d energy rejections\n",
        step_tolerance, rec.accepted ? 1 : 0, rec.step, rec.step_norm, rec.certificate_rejections,
        rec.armijo_rejections);
    return std::make_tuple(rec, bitwise_equal(y0, s->reduced_coefficients()),
                           p.step_tolerance * std::max(1.0, y0.norm()));
  };
  const auto [cut, unchanged, shortest] = first_iteration(0.05);
  EXPECT_FALSE(cut.accepted);
  EXPECT_TRUE(unchanged);
  EXPECT_GE(cut.certificate_rejections, 1);
  const int trials = cut.certificate_rejections + cut.armijo_rejections;
  EXPECT_LT(trials, fast_params().max_halvings + 1);

  const auto [full, moved, unused] = first_iteration(0);
  (void)unused;
  ASSERT_TRUE(full.accepted) << "the target must allow a short step, else the first run proves nothing";
  EXPECT_FALSE(moved);
  // The same direction and trials up to the cut: the certified step is one the cut skipped, after the same
  // refusals and more.
  EXPECT_LE(full.step_norm, shortest);
  EXPECT_GT(full.certificate_rejections + full.armijo_rejections, trials);
}

// Dragging (set_dragging, DeformParams::drag_hessian_reuse): the first step after new targets may solve with
// the previous step's Hessian factor. The targets move along the beam_bend path in 12 increments, one step
// each, as the studio's engine does; every accepted map must be certified by an independent full-space
// certifier, at most drag_hessian_reuse steps in a row reuse, the reused directions descend, and once the
// targets rest, the solve ends where a solver that never reused ends.
TEST(ProjectedNewton, DraggingReusesTheHessianFactorAndKeepsEveryMapCertified) {
  struct Drag {
    std::vector<IterationRecord> drag, rest;
    EnergyTerms final_energy;
    std::vector<bool> full_certified;
  };
  auto run = [](bool dragging, int reuse) {
    Drag d;
    DeformParams p = fast_params();
    p.dynamic_weighting = false;
    p.max_iterations = 40;
    p.drag_hessian_reuse = reuse;
    p.kept_factor_cg_steps = 0;  // the drag's reuse alone (a kept factor's CG steps also count as reused)
    auto s = make_solver(p);
    s->set_handles(beam().sources, beam().sources, "drag");
    s->set_dragging(dragging);
    const OctreeCertifier full(beam().model.cage, s->sampling());
    for (int k = 1; k <= 12; ++k) {
      const double f = k / 12.0;
      s->set_targets(beam().sources + f * (beam().targets - beam().sources), "drag");
      const IterationRecord rec = s->step();
      d.drag.push_back(rec);
      if (rec.accepted)
        d.full_certified.push_back(
            full.certify(s->coefficients(), s->certify_params(false, false)).certified);
    }
    s->solve([&](const IterationRecord& rec) {
      d.rest.push_back(rec);
      return true;
    });
    d.final_energy = s->energy();
    return d;
  };
  const Drag reused = run(true, 2);
  int n_reused = 0, in_a_row = 0, accepted = 0;
  for (const IterationRecord& rec : reused.drag) {
    accepted += rec.accepted;
    if (rec.hessian_reused) {
      ++n_reused;
      ++in_a_row;
      EXPECT_LE(in_a_row, 2) << "iteration " << rec.iteration;
      EXPECT_GT(rec.newton_decrement, 0) << "iteration " << rec.iteration;
      EXPECT_EQ(rec.ms_hessian, 0) << "a reused step assembles no Hessian";
    } else {
      in_a_row = 0;
    }
    EXPECT_TRUE(rec.certified) << "iteration " << rec.iteration;
  }
  EXPECT_FALSE(reused.drag.front().hessian_reused) << "no factor before the first step";
  EXPECT_GE(n_reused, 6) << "of 12 drag steps, with at most 2 reuses after each assembled factor";
  EXPECT_EQ(accepted, 12);
  for (size_t k = 0; k < reused.full_certified.size(); ++k)
    EXPECT_TRUE(reused.full_certified[k]) << "accepted drag step " << k + 1;
  for (const IterationRecord& rec : reused.rest)
    EXPECT_FALSE(rec.hessian_reused) << "targets at rest: iteration " << rec.iteration;

  const Drag fresh = run(false, 2), zero = run(true, 0);
  for (const Drag* d : {&fresh, &zero})
    for (const IterationRecord& rec : d->drag)
      EXPECT_FALSE(rec.hessian_reused) << "iteration " << rec.iteration;
  // Both end at rest at the same minimum (the solves stop at a relative energy decrease of 1e-5).
  EXPECT_NEAR(reused.final_energy.total, fresh.final_energy.total, 1e-5 * fresh.final_energy.total);
  std::printf(
      "drag: %d of 12 steps reused a factor; at rest E %.8e (reused) vs %.8e (never), %zu vs %zu "
      "iterations\n",
      n_reused, reused.final_energy.total, fresh.final_energy.total, reused.rest.size(), fresh.rest.size());
}

namespace {
// A beam_bend solve with every accepted map certified by an independent full-space certifier (no reduction):
// the records, the final energy and how many accepted maps that certifier certified.
struct FullyCertifiedRun {
  std::vector<IterationRecord> records;
  EnergyTerms energy;
  int full_certified = 0, accepted = 0;
};
FullyCertifiedRun fully_certified_run(const DeformParams& p) {
  FullyCertifiedRun r;
  auto s = make_solver(p);
  s->set_handles(beam().sources, beam().targets, "fully certified run");
  const OctreeCertifier full(beam().model.cage, s->sampling());
  s->solve([&](const IterationRecord& rec) {
    r.records.push_back(rec);
    if (rec.accepted) {
      ++r.accepted;
      r.full_certified += full.certify(s->coefficients(), s->certify_params(false, false)).certified;
    }
    return true;
  });
  r.energy = s->energy();
  return r;
}
}  // namespace

// The kept factor (kept_factor_cg_steps): after the first iteration the subset Hessian's system is solved by
// CG steps preconditioned with an earlier factor, to the relative residual kept_factor_tolerance, instead of
// being assembled. The solve must end where the assembling solve ends (energy within its own stopping
// tolerance, iterations within one), every accepted map certified by an independent full-space certifier; the
// records say which iterations took the kept factor and how many steps they needed.
TEST(ProjectedNewton, KeptFactorReachesTheAssemblingSolvesMinimumWithEveryMapCertified) {
  using Run = FullyCertifiedRun;
  auto run = [](int steps) {
    DeformParams p = fast_params();
    p.max_iterations = 40;
    p.kept_factor_cg_steps = steps;
    return fully_certified_run(p);
  };
  const Run assembling = run(0), kept = run(DeformParams().kept_factor_cg_steps);
  ASSERT_GT(DeformParams().kept_factor_cg_steps, 0) << "the default keeps the factor";
  for (const Run* r : {&assembling, &kept}) {
    EXPECT_EQ(r->full_certified, r->accepted);
    EXPECT_TRUE(r->records.back().certified);
  }
  for (const IterationRecord& rec : assembling.records) {
    EXPECT_FALSE(rec.hessian_reused) << "iteration " << rec.iteration;
    EXPECT_EQ(rec.kept_factor_steps, 0) << "iteration " << rec.iteration;
  }
  int took = 0;
  for (const IterationRecord& rec : kept.records) {
    if (rec.iteration == 1) {
      EXPECT_EQ(rec.kept_factor_steps, 0) << "no factor before the first iteration";
    }
    if (rec.hessian_reused) {
      ++took;
      EXPECT_GE(rec.kept_factor_steps, 1) << "iteration " << rec.iteration;
      EXPECT_LE(rec.kept_factor_steps, DeformParams().kept_factor_cg_steps) << "iteration " << rec.iteration;
    }
    EXPECT_GT(rec.newton_decrement, 0) << "a descent direction, iteration " << rec.iteration;
  }
  EXPECT_GE(took, 1) << "some iteration solved with the kept factor";
  EXPECT_LE(std::abs(static_cast<int>(kept.records.size()) - static_cast<int>(assembling.records.size())), 1);
  EXPECT_NEAR(kept.energy.total, assembling.energy.total, 1e-5 * assembling.energy.total);
  std::printf(
      "kept factor: %d of %zu iterations took it; iterations %zu (assembling %zu); E %.10e vs %.10e\n", took,
      kept.records.size(), kept.records.size(), assembling.records.size(), kept.energy.total,
      assembling.energy.total);
}

// The conjugate-gradient correction (newton_cg_steps, newton_cg.h): with a deliberately poor Hessian subset
// (20 of 4,000 samples) the plain subset direction converges slowly; CG iterates on the exact Hessian take
// fewer iterations to a minimum at least as low, and every accepted map stays certified (independent
// full-space certifier). The records say what CG did.
TEST(ProjectedNewton, ConjugateGradientCorrectionNeedsFewerIterationsWithAPoorSubset) {
  using Run = FullyCertifiedRun;
  auto run = [](int cg) {
    DeformParams p = fast_params();
    p.hessian_fraction = 0.005;
    p.max_iterations = 40;
    p.newton_cg_steps = cg;
    return fully_certified_run(p);
  };
  const Run plain = run(0), one = run(1), three = run(3);
  for (const Run* r : {&plain, &one, &three}) {
    EXPECT_EQ(r->full_certified, r->accepted);
    EXPECT_TRUE(r->records.back().certified);
  }
  for (const IterationRecord& rec : plain.records) EXPECT_EQ(rec.cg_steps, 0);
  for (const IterationRecord& rec : three.records) {
    EXPECT_GE(rec.cg_steps, 1) << "iteration " << rec.iteration;
    EXPECT_LE(rec.cg_steps, 3) << "iteration " << rec.iteration;
    EXPECT_GT(rec.cg_scale, 0) << "iteration " << rec.iteration;
    EXPECT_GT(rec.newton_decrement, 0) << "a descent direction, iteration " << rec.iteration;
  }
  // The plain direction is 3-7x too long here (cg_scale 0.13-0.45): halving steps, a slow decrease, and a
  // stop at the relative-decrease tolerance above the minimum. Scaling alone (one iterate) zigzags like a
  // gradient method and is not asserted to be faster; three iterates are.
  EXPECT_LT(three.records.size(), plain.records.size());
  EXPECT_LE(three.energy.total, plain.energy.total * (1 + 1e-6));
  std::printf(
      "iterations with a 0.5%% subset: plain %zu, 1 CG iterate %zu, 3 CG iterates %zu; E %.8e / %.8e / "
      "%.8e\n",
      plain.records.size(), one.records.size(), three.records.size(), plain.energy.total, one.energy.total,
      three.energy.total);
}
