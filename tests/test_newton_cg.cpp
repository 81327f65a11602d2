// truncated_newton_cg (newton_cg.h) on explicit matrices: exact at n steps, the error in the operator's norm
// never grows from one iterate to the next, the first iterate is the exact model's minimum along p0, and at
// non-positive curvature it stops with a descent direction.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <random>

#include "lidef/internal/newton_cg.h"

using namespace lidef;

namespace {

MatXd random_spd(int n, double cond_spread, std::mt19937& rng) {
  std::normal_distribution<double> N01;
  MatXd A(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) A(i, j) = N01(rng);
  MatXd S = A * A.transpose() / n;
  S.diagonal().array() += 1.0 / cond_spread;
  return S;
}

struct Problem {
  MatXd H, M;  // operator, preconditioner
  VecXd g;
  int curvature_calls = 0, product_calls = 0;
  NewtonCgOperators ops() {
    NewtonCgOperators o;
    o.curvature = [this](const VecXd& p) {
      ++curvature_calls;
      return p.dot(H * p);
    };
    o.hessian_times = [this](const VecXd& p) {
      ++product_calls;
      return VecXd(H * p);
    };
    o.precondition = [this](VecXd& r) {
      r = M.llt().solve(r);
      return true;
    };
    return o;
  }
  VecXd p0() const { return M.llt().solve(-g); }
};

Problem make_problem(int n, double perturbation, unsigned seed) {
  std::mt19937 rng(seed);
  Problem P;
  P.H = random_spd(n, 100, rng);
  // The preconditioner: H with a relative random perturbation, as the subset Hessian is.
  MatXd E = random_spd(n, 1, rng);
  P.M = P.H + perturbation * E * (P.H.norm() / E.norm());
  std::normal_distribution<double> N01;
  P.g.resize(n);
  for (int i = 0; i < n; ++i) P.g(i) = N01(rng);
  return P;
}

double error_in_h_norm(const Problem& P, const VecXd& d) {
  const VecXd e = d - P.H.llt().solve(-P.g);
  return std::sqrt(e.dot(P.H * e));
}

}  // namespace

TEST(NewtonCg, ReachesTheNewtonStepAndNeverIncreasesTheError) {
  for (unsigned seed : {1u, 2u, 3u}) {
    Problem P = make_problem(30, 0.5, seed);
    const VecXd p0 = P.p0();
    double previous = error_in_h_norm(P, p0);
    for (int k = 1; k <= 30; ++k) {
      const NewtonCgResult r = truncated_newton_cg(P.g, p0, k, P.ops());
      ASSERT_EQ(r.steps, k);
      const double e = error_in_h_norm(P, r.d);
      EXPECT_LE(e, previous * (1 + 1e-9) + 1e-12) << "seed " << seed << ", " << k << " steps";
      EXPECT_LT(P.g.dot(r.d), 0) << "a descent direction";
      previous = e;
    }
    const NewtonCgResult full = truncated_newton_cg(P.g, p0, 30, P.ops());
    const VecXd exact = P.H.llt().solve(-P.g);
    EXPECT_LT((full.d - exact).norm(), 1e-8 * exact.norm()) << "seed " << seed;
  }
}

TEST(NewtonCg, FirstIterateIsTheExactModelsMinimumAlongP0) {
  Problem P = make_problem(20, 0.8, 7);
  const VecXd p0 = P.p0();
  const NewtonCgResult r = truncated_newton_cg(P.g, p0, 1, P.ops());
  ASSERT_EQ(r.steps, 1);
  const double alpha = -P.g.dot(p0) / p0.dot(P.H * p0);  // argmin_α gᵀ(α p0) + ½ α² p0ᵀ H p0
  EXPECT_NEAR(r.scale, alpha, 1e-12 * std::abs(alpha));
  EXPECT_LT((r.d - alpha * p0).norm(), 1e-12 * p0.norm() * std::abs(alpha));
  EXPECT_EQ(P.product_calls, 0) << "one iterate needs no Hessian-vector product";
  EXPECT_EQ(P.curvature_calls, 1);
  // With a perfect preconditioner p0 is the Newton step and the scale is 1.
  Problem Q = make_problem(20, 0.0, 7);
  EXPECT_NEAR(truncated_newton_cg(Q.g, Q.p0(), 1, Q.ops()).scale, 1.0, 1e-10);
}

TEST(NewtonCg, StopsAtNonPositiveCurvatureWithADescentDirection) {
  Problem P = make_problem(12, 0.3, 11);
  // An indefinite operator: one strongly negative eigenvalue.
  Eigen::SelfAdjointEigenSolver<MatXd> es(P.H);
  VecXd lambda = es.eigenvalues();
  lambda(0) = -50 * lambda.maxCoeff();
  P.H = es.eigenvectors() * lambda.asDiagonal() * es.eigenvectors().transpose();
  const VecXd p0 = P.p0();
  const NewtonCgResult r = truncated_newton_cg(P.g, p0, 12, P.ops());
  EXPECT_LT(r.steps, 12) << "the negative direction is met before n steps";
  EXPECT_LT(P.g.dot(r.d), 0) << "every iterate before it descends";
  // Negative curvature along p0 itself: no iterate, the plain direction is returned.
  P.H = -MatXd::Identity(12, 12);
  const NewtonCgResult none = truncated_newton_cg(P.g, p0, 5, P.ops());
  EXPECT_EQ(none.steps, 0);
  EXPECT_EQ((none.d - p0).norm(), 0.0);
}

// preconditioned_cg (the kept factor's solve): it stops as soon as the residual (in the preconditioner's
// norm) meets the tolerance, and the residual it reports is the true one; an exact preconditioner solves in
// one step; with too few steps for a poor preconditioner it gives up early and says so.
TEST(PreconditionedCg, MeetsTheToleranceWithATrueResidual) {
  for (const double perturbation : {0.05, 0.3, 1.0}) {
    Problem P = make_problem(40, perturbation, 21);
    int products = 0;
    const auto A = [&](const VecXd& p) {
      ++products;
      return VecXd(P.H * p);
    };
    const auto M = [&](VecXd& r) {
      r = P.M.llt().solve(r);
      return true;
    };
    const VecXd b = -P.g;
    // Room enough that the early give-up (a geometric rate; CG's end is faster) does not stop it.
    const PcgResult r = preconditioned_cg(b, A, M, 400, 1e-6);
    ASSERT_TRUE(r.converged) << perturbation;
    EXPECT_EQ(r.steps, products);
    const auto m_norm = [&](const VecXd& v) { return std::sqrt(v.dot(P.M.llt().solve(v))); };
    const double true_residual = m_norm(b - P.H * r.x) / m_norm(b);
    EXPECT_LE(true_residual, 1.01e-6) << perturbation;
    EXPECT_NEAR(true_residual, r.relative_residual, 1e-9) << perturbation;
    // A tolerance met one step earlier would have stopped there.
    const PcgResult one_less = preconditioned_cg(b, A, M, r.steps - 1, 1e-6);
    EXPECT_FALSE(one_less.converged) << perturbation;
    EXPECT_LE(one_less.steps, r.steps - 1) << perturbation;
  }
}

TEST(PreconditionedCg, ExactPreconditionerSolvesInOneStep) {
  Problem P = make_problem(30, 0.0, 5);
  const auto A = [&](const VecXd& p) { return VecXd(P.H * p); };
  const auto M = [&](VecXd& r) {
    r = P.H.llt().solve(r);
    return true;
  };
  const PcgResult r = preconditioned_cg(-P.g, A, M, 10, 1e-9);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(r.steps, 1);
  EXPECT_LT((r.x - P.H.llt().solve(-P.g)).norm(), 1e-9 * r.x.norm());
}

TEST(PreconditionedCg, GivesUpEarlyWhenTheStepsCannotReachTheTolerance) {
  // The identity as the preconditioner of a badly conditioned operator: 12 steps cannot reach 1e-10.
  std::mt19937 rng(3);
  const MatXd H = random_spd(60, 1e6, rng);
  const VecXd b = VecXd::Ones(60);
  int products = 0;
  const auto A = [&](const VecXd& p) {
    ++products;
    return VecXd(H * p);
  };
  const auto M = [](VecXd&) { return true; };
  const PcgResult r = preconditioned_cg(b, A, M, 12, 1e-10);
  EXPECT_FALSE(r.converged);
  EXPECT_LT(r.steps, 12) << "the rate after four steps predicts the failure";
  EXPECT_GE(r.steps, 4);
  EXPECT_GT(r.relative_residual, 1e-10);
  // A zero right side is solved by x = 0 at once.
  const PcgResult zero = preconditioned_cg(VecXd::Zero(60), A, M, 12, 1e-10);
  EXPECT_TRUE(zero.converged);
  EXPECT_EQ(zero.steps, 0);
}
