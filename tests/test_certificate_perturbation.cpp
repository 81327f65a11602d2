// Certifying by perturbation (CertifyParams::previous_y / previous_lower; docs/certificate.md, Step 4e): base
// voxels certified from an earlier certified map without being evaluated. Checked against dense sampling of
// the true σ3 of the new map on every such voxel, against the certificate without the previous map (same
// verdict), and for large changes (nothing is taken over).
#include <gtest/gtest.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <memory>
#include <random>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/errors.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/subspace.h"
#include "test_cages.h"

using namespace lidef;

namespace {

using MatR = Eigen::Matrix<double, Eigen::Dynamic, 3>;

// A bent map in the subspace, in reduced coordinates.
MatR bent_reduced(const Cage& cage, const SpectralSubspace& sub, double amp, unsigned seed) {
  return sub.basis.transpose() * lidef::test::smooth_map(cage, sub, amp, seed);
}

// An icosphere cage (subdivisions, noise, seed), about `voxels` voxels and `dof` basis functions.
struct SphereCase {
  Cage cage;
  VoxelSampling sampling;
  SpectralSubspace sub;
  SphereCase(int subdivisions, double noise, unsigned seed, int voxels, double tolerance, int dof)
      : cage(lidef::test::icosphere(subdivisions, noise, seed)) {
    SamplingParams sp;
    sp.target_count = voxels;
    sp.count_tolerance = tolerance;
    sampling = sample_voxels(cage, sp);
    sub = compute_subspace(cage, dof);
  }
};

// The subdivided icosphere's ~1,460 voxels, 40 basis functions and a certified bent map y0.
struct BentCase : SphereCase {
  std::unique_ptr<OctreeCertifier> cert;
  MatR y0;
  BentCase() : SphereCase(2, 0.15, 8, 1500, 0.1, 40) {
    cert = std::make_unique<OctreeCertifier>(cage, sampling, &sub.basis);
    y0 = bent_reduced(cage, sub, 0.6, 14);
  }
};

// A coarse icosphere's ~300 voxels and 20 basis functions.
struct SmallCase : SphereCase {
  SmallCase() : SphereCase(1, 0.1, 3, 300, 0.2, 20) {}
};

// Checks every voxel of c taken over (σ3 = NaN, certified) by dense sampling of the map y: none has a sampled
// σ3 below its bound. At most `limit` voxels, spread over the list ordered by bound (the lowest included).
// Returns how many were checked.
long check_taken_over(const BentCase& b, const MatR& y, const Certificate& c, size_t limit) {
  std::vector<CertLeaf> taken;
  for (const CertLeaf& l : c.leaves)
    if (std::isnan(l.sigma3) && l.certified) taken.push_back(l);
  EXPECT_EQ(static_cast<long>(taken.size()), c.perturbed_voxels);
  std::sort(taken.begin(), taken.end(),
            [](const CertLeaf& a, const CertLeaf& l) { return a.margin < l.margin; });
  std::vector<CertLeaf> pick;
  for (size_t k = 0; k < taken.size(); k += std::max<size_t>(1, taken.size() / limit))
    pick.push_back(taken[k]);
  const VerificationResult v = verify_certificate(b.cert->basis(), b.sub.basis * y, pick, 24, 5);
  EXPECT_EQ(v.nonpositive_in_certified, 0);
  for (size_t k = 0; k < pick.size(); ++k)
    EXPECT_GE(v.voxels[k].min_sigma3, pick[k].margin) << "voxel at " << pick[k].center.transpose();
  return static_cast<long>(pick.size());
}

// The change a certificate subtracted from each voxel it took over, b_i(ỹ₀) − b_i(ỹ), against the sampled
// ‖J(ỹ)(q) − J(ỹ₀)(q)‖₂ on a 3×3×3 grid of the voxel (corners included): never below it. This checks the
// perturbation bound itself (a sound bound on loose base bounds can hide a wrong change). Returns how many
// voxels were checked.
long check_changes(const BentCase& b, const MatR& y0, const MatR& y, const Certificate& c0,
                   const Certificate& c) {
  std::vector<long> taken;
  for (const CertLeaf& l : c.leaves)
    if (std::isnan(l.sigma3) && l.certified) taken.push_back(l.base);
  MatX3d P(27 * taken.size(), 3);
  for (size_t k = 0; k < taken.size(); ++k) {
    const long i = taken[k];
    const double h = 0.5 * b.sampling.side_of(static_cast<int>(i));
    int q = 0;
    for (int x = -1; x <= 1; ++x)
      for (int yy = -1; yy <= 1; ++yy)
        for (int z = -1; z <= 1; ++z)
          P.row(27 * k + q++) = b.sampling.centers.row(i) + h * Eigen::RowVector3d(x, yy, z);
  }
  MatX3d f;
  MatXd JT;  // rows 3q..3q+2: J(δ)(p_q)ᵀ of the change δ = ỹ − ỹ₀ (J is linear in the map)
  b.cert->basis().map_jets(b.sub.basis * (y - y0), P, f, JT);
  double tightest = 0;
  for (size_t k = 0; k < taken.size(); ++k) {
    const long i = taken[k];
    const double change = c0.base_lower[i] - c.base_lower[i];
    double worst = 0;
    for (int q = 0; q < 27; ++q) {
      const Mat3 dJ = JT.middleRows(3 * (27 * k + q), 3);
      worst = std::max(worst, Eigen::JacobiSVD<Mat3>(dJ).singularValues()(0));
    }
    EXPECT_GE(change, worst) << "voxel " << i << " at " << b.sampling.centers.row(i);
    tightest = std::max(tightest, worst / change);
  }
  if (!taken.empty()) std::cout << "  largest sampled change / bound: " << tightest << "\n";
  return static_cast<long>(taken.size());
}

}  // namespace

TEST(CertificatePerturbation, VoxelsTakenOverHoldUnderDenseSamplingAndTheVerdictIsUnchanged) {
  const BentCase b;
  const VoxelSampling& sampling = b.sampling;
  const SpectralSubspace& sub = b.sub;
  const OctreeCertifier& cert = *b.cert;
  const MatR& y0 = b.y0;
  CertifyParams p;
  p.max_depth = 4;
  const Certificate c0 = cert.certify_reduced(y0, p);
  ASSERT_TRUE(c0.certified) << c0.reason;
  ASSERT_EQ(static_cast<long>(c0.base_lower.size()), sampling.size());
  EXPECT_EQ(c0.perturbed_voxels, 0);
  // base_lower is a lower bound of σ3 on each base voxel: no sample below it.
  {
    std::vector<CertLeaf> base;
    for (long i = 0; i < sampling.size(); i += 7) {
      CertLeaf l;
      l.center = sampling.centers.row(i).transpose();
      l.side = sampling.side_of(static_cast<int>(i));
      l.certified = true;
      l.margin = c0.base_lower[i];
      base.push_back(l);
    }
    const VerificationResult v = verify_certificate(cert.basis(), sub.basis * y0, base, 16, 2);
    for (size_t k = 0; k < base.size(); ++k) EXPECT_GE(v.voxels[k].min_sigma3, base[k].margin);
  }
  std::mt19937 rng(3);
  std::normal_distribution<double> N01;
  MatR dir(y0.rows(), 3);
  for (long k = 0; k < dir.rows(); ++k)
    for (int a = 0; a < 3; ++a) dir(k, a) = N01(rng);
  dir *= y0.norm() / dir.norm();
  long taken_over_checked = 0;
  int some_taken = 0;
  for (double eps : {1e-5, 1e-4, 1e-3, 1e-2, 0.3}) {
    const MatR y = y0 + eps * dir;
    CertifyParams q = p;
    const Certificate plain = cert.certify_reduced(y, q);
    q.previous_y = &y0;
    q.previous_lower = &c0.base_lower;
    const Certificate c = cert.certify_reduced(y, q);
    SCOPED_TRACE("eps " + std::to_string(eps));
    std::cout << "change " << eps << " of |y0|: " << c.perturbed_voxels << " of " << sampling.size()
              << " voxels certified by perturbation\n";
    EXPECT_EQ(c.certified, plain.certified);
    if (eps >= 0.3) {
      EXPECT_EQ(c.perturbed_voxels, 0) << "a large change takes nothing over";
    }
    if (c.perturbed_voxels > 0) ++some_taken;
    // Every voxel taken over: its bound holds for the new map under dense sampling.
    taken_over_checked += check_taken_over(b, y, c, 400);
    // A map certified with voxels taken over passes its bounds on: a third map from it is still sound.
    if (c.certified) {
      EXPECT_EQ(static_cast<long>(c.base_lower.size()), sampling.size());
    }
  }
  std::cout << taken_over_checked << " voxels certified by perturbation checked by dense sampling\n";
  EXPECT_GE(some_taken, 3);
  EXPECT_GT(taken_over_checked, 500);
}

// A previous map of another shape (wrong row count) or bounds of another sampling are ignored, not trusted.
TEST(CertificatePerturbation, MismatchedPreviousDataIsIgnored) {
  const SmallCase small;
  const Cage& cage = small.cage;
  const VoxelSampling& sampling = small.sampling;
  const SpectralSubspace& sub = small.sub;
  const OctreeCertifier cert(cage, sampling, &sub.basis);
  const MatR y0 = bent_reduced(cage, sub, 0.2, 5);
  const Certificate c0 = cert.certify_reduced(y0);
  ASSERT_TRUE(c0.certified);
  CertifyParams q;
  const MatR other = MatR::Zero(y0.rows() - 1, 3);
  q.previous_y = &other;
  q.previous_lower = &c0.base_lower;
  EXPECT_EQ(cert.certify_reduced(y0, q).perturbed_voxels, 0);
  const std::vector<double> short_lower(c0.base_lower.begin(), c0.base_lower.end() - 1);
  q.previous_y = &y0;
  q.previous_lower = &short_lower;
  EXPECT_EQ(cert.certify_reduced(y0, q).perturbed_voxels, 0);
  q.previous_lower = &c0.base_lower;
  EXPECT_EQ(cert.certify_reduced(y0, q).perturbed_voxels, sampling.size()) << "the same map: every voxel";
  // The floor: no voxel whose bound would be below it is taken over (all are, here, below 1e9).
  q.perturbation_floor = 1e9;
  EXPECT_EQ(cert.certify_reduced(y0, q).perturbed_voxels, 0);
  double lowest = 1e300;
  for (double b : c0.base_lower) lowest = std::min(lowest, b);
  q.perturbation_floor = lowest;  // the voxel(s) at the lowest bound stay evaluated
  const Certificate c = cert.certify_reduced(y0, q);
  EXPECT_LT(c.perturbed_voxels, sampling.size());
  EXPECT_GT(c.perturbed_voxels, 0);
  EXPECT_EQ(c.min_lower_bound, c0.min_lower_bound) << "the lowest bound is an evaluated one";
}

namespace {

// D = G̃ d at every base center from the certifier's stored float rows (JT layout, 3N by 3), in double as
// DeformationEnergy::jacobians computes it.
MatR direction_jacobians(const OctreeCertifier& cert, long voxels, const MatR& d) {
  const OctreeCertifier::ReducedDerivativesRef r = cert.reduced_derivatives();
  MatR D(3 * voxels, 3);
  for (long i = 0; i < voxels; ++i)
    for (int row = 0; row < 3; ++row)
      for (int a = 0; a < 3; ++a) {
        double acc = 0;
        for (long k = 0; k < r.m; ++k) acc += double((*r.GH)[(9 * i + row) * r.m + k]) * d(k, a);
        D(3 * i + row, a) = acc;
      }
  return D;
}

// p with the previous map y0 and its certificate c0, and the trial y0 + t·dir with the direction's Jacobians
// D.
CertifyParams along_direction(const CertifyParams& p, const MatR& y0, const Certificate& c0, const MatR& dir,
                              const MatR& D, double t) {
  CertifyParams q = p;
  q.previous_y = &y0;
  q.previous_lower = &c0.base_lower;
  q.direction = &dir;
  q.direction_jacobians = &D;
  q.direction_step = t;
  q.direction_scale = dir.norm();
  return q;
}

}  // namespace

// With the direction's Jacobians (CertifyParams::direction_jacobians, Step 4e's center term t ‖G d‖ instead
// of ‖G‖₂ ‖ỹ − ỹ₀‖): more voxels taken over, each still holding under dense sampling of the new map, the
// verdict unchanged; a direction that does not match the change (a wrong step) is covered by the residual,
// and Jacobians of another size are ignored.
TEST(CertificatePerturbation, TheDirectionsJacobiansTakeOverMoreAndStaySound) {
  const BentCase b;
  const long N = b.sampling.size();
  const OctreeCertifier& cert = *b.cert;
  const MatR& y0 = b.y0;
  CertifyParams p;
  p.max_depth = 4;
  const Certificate c0 = cert.certify_reduced(y0, p);
  ASSERT_TRUE(c0.certified) << c0.reason;
  // A smooth direction (the difference of two bent maps), as a Newton step would be.
  MatR dir = bent_reduced(b.cage, b.sub, 0.6, 15) - y0;
  const MatR D = direction_jacobians(cert, N, dir);
  long more = 0, checked = 0;
  for (double t : {1e-3, 1e-2, 0.05, 0.2}) {
    SCOPED_TRACE("t " + std::to_string(t));
    const MatR y = y0 + t * dir;
    CertifyParams q = p;
    const Certificate plain = cert.certify_reduced(y, q);
    q.previous_y = &y0;
    q.previous_lower = &c0.base_lower;
    const Certificate norm_only = cert.certify_reduced(y, q);
    q.direction = &dir;
    q.direction_jacobians = &D;
    q.direction_step = t;
    q.direction_scale = dir.norm();
    const Certificate c = cert.certify_reduced(y, q);
    std::cout << "step " << t << ": " << c.perturbed_voxels << " taken over with the direction, "
              << norm_only.perturbed_voxels << " with ‖G‖‖δ‖ alone, of " << N << "\n";
    EXPECT_EQ(c.certified, plain.certified);
    EXPECT_GE(c.perturbed_voxels, norm_only.perturbed_voxels);
    if (c.perturbed_voxels > norm_only.perturbed_voxels) ++more;
    // A wrong step (the change is t d, the step says 2t): the residual ‖ỹ − ỹ₀ − 2t d‖ is then large, the
    // direction's term loose, and what is taken over must still hold.
    CertifyParams wrong = q;
    wrong.direction_step = 2 * t;
    const Certificate cw = cert.certify_reduced(y, wrong);
    for (const Certificate* cc : {&c, &cw}) checked += check_taken_over(b, y, *cc, 250);
    // Jacobians of another size: ignored (the norm-only test decides).
    const MatR short_D = D.topRows(D.rows() - 3);
    CertifyParams bad = q;
    bad.direction_jacobians = &short_D;
    EXPECT_EQ(cert.certify_reduced(y, bad).perturbed_voxels, norm_only.perturbed_voxels);
  }
  std::cout << checked << " voxels taken over checked by dense sampling\n";
  EXPECT_GE(more, 2) << "the direction's center term takes over more voxels at some steps";
  EXPECT_GT(checked, 500);
}

// The rest from a direction (Step 4e): with the first-order factors built, the H and third-order parts of Γ_i
// (Cauchy–Schwarz over the basis) are replaced where that helps by t r Σ_e Θ¹_e ‖δ_e(Ξ d)‖ + rest_i ‖ρ‖: more
// voxels taken over at large steps, each holding under dense sampling of the new map, also with a wrong step
// or a direction unrelated to the change; the verdict unchanged; the per-direction cache gives the same bits
// as a fresh certifier, also after another direction replaced it.
TEST(CertificatePerturbation, TheRestFromADirectionTakesOverMoreAndStaysSound) {
  const BentCase b;
  const long N = b.sampling.size();
  const OctreeCertifier& plain_cert = *b.cert;
  const OctreeCertifier along(b.cage, b.sampling, &b.sub.basis);
  const std::vector<char>* finite = nullptr;
  EXPECT_EQ(along.built_factors(false, &finite), nullptr);
  along.factor_matrix(false);
  ASSERT_NE(along.built_factors(false, &finite), nullptr);
  const MatR& y0 = b.y0;
  CertifyParams p;
  p.max_depth = 4;
  const Certificate c0 = plain_cert.certify_reduced(y0, p);
  ASSERT_TRUE(c0.certified) << c0.reason;
  const MatR dir = bent_reduced(b.cage, b.sub, 0.6, 15) - y0;
  const MatR D = direction_jacobians(plain_cert, N, dir);
  // Another smooth direction, unrelated to the change.
  const MatR other = bent_reduced(b.cage, b.sub, 0.6, 16) - y0;
  const MatR D_other = direction_jacobians(plain_cert, N, other);
  long more = 0, checked = 0, changes = 0;
  for (double t : {1e-2, 0.05, 0.2, 0.5}) {
    SCOPED_TRACE("t " + std::to_string(t));
    const MatR y = y0 + t * dir;
    const Certificate plain = plain_cert.certify_reduced(y, p);
    const CertifyParams q = along_direction(p, y0, c0, dir, D, t);
    const Certificate center_only = plain_cert.certify_reduced(y, q);
    const Certificate c = along.certify_reduced(y, q);
    std::cout << "step " << t << ": " << c.perturbed_voxels
              << " taken over with the rest from the direction, " << center_only.perturbed_voxels
              << " with its center term alone, of " << N << "\n";
    EXPECT_EQ(c.certified, plain.certified);
    EXPECT_GE(c.perturbed_voxels, center_only.perturbed_voxels);
    if (c.perturbed_voxels > center_only.perturbed_voxels) ++more;
    // The cache: the same direction again, then another direction, then this one again: the same bits as
    // the first time.
    EXPECT_EQ(along.certify_reduced(y, q).base_lower, c.base_lower);
    CertifyParams wrong_direction = q;  // the change is t·dir, the direction says `other`: ρ is large
    wrong_direction.direction = &other;
    wrong_direction.direction_jacobians = &D_other;
    wrong_direction.direction_scale = other.norm();
    const Certificate co = along.certify_reduced(y, wrong_direction);
    EXPECT_EQ(co.certified, plain.certified);
    EXPECT_EQ(along.certify_reduced(y, q).base_lower, c.base_lower);
    CertifyParams wrong_step = q;  // the step says 2t
    wrong_step.direction_step = 2 * t;
    const Certificate cw = along.certify_reduced(y, wrong_step);
    EXPECT_EQ(cw.certified, plain.certified);
    for (const Certificate* cc : {&c, &co, &cw}) {
      checked += check_taken_over(b, y, *cc, 250);
      changes += check_changes(b, y0, y, c0, *cc);
    }
  }
  std::cout << checked << " voxels taken over checked by dense sampling, " << changes
            << " changes checked against the sampled change of J\n";
  EXPECT_GE(more, 2) << "the rest from the direction takes over more voxels at some steps";
  EXPECT_GT(checked, 800);
  EXPECT_GT(changes, 2000);

  // Adopted factors (what the precomputation cache does) give the same certificates; other shapes throw.
  OctreeCertifier adopted(b.cage, b.sampling, &b.sub.basis);
  OctreeCertifier::FactorMatrix f = *along.built_factors(false, &finite);
  EXPECT_THROW(adopted.adopt_factors(false, f.topRows(N - 1), *finite), Error);
  adopted.adopt_factors(false, f, *finite);
  const MatR y = y0 + 0.2 * dir;
  const CertifyParams q = along_direction(p, y0, c0, dir, D, 0.2);
  EXPECT_EQ(adopted.certify_reduced(y, q).base_lower, along.certify_reduced(y, q).base_lower);
}

// The voxel groups of the rest from a direction (Step 4e, "Voxel groups"): a partition of the voxels into
// blocks of 2 x 2 x 2 base cells, each group's factor row and radius bounding every member's (so its rest
// bounds theirs), formed alike when the factors are built and when they are adopted.
TEST(CertificatePerturbation, TheVoxelGroupsBoundTheirMembers) {
  const BentCase b;
  const long N = b.sampling.size(), E = b.cage.num_edges();
  ASSERT_EQ(b.sampling.grid_index.rows(), N);
  const OctreeCertifier along(b.cage, b.sampling, &b.sub.basis);
  EXPECT_TRUE(along.voxel_groups().start.empty());
  const OctreeCertifier::FactorMatrix& f = along.factor_matrix(false);
  const std::vector<char>* finite = nullptr;
  ASSERT_NE(along.built_factors(false, &finite), nullptr);
  const OctreeCertifier::VoxelGroups g = along.voxel_groups();
  const long G = static_cast<long>(g.start.size()) - 1;
  ASSERT_GT(G, 0);
  EXPECT_EQ(g.start.front(), 0);
  EXPECT_EQ(g.start.back(), N);
  EXPECT_EQ(g.factors.rows(), G);
  EXPECT_EQ(g.factors.cols(), E);
  std::vector<int> seen(N, 0);
  long violations = 0;
  for (long q = 0; q < G; ++q) {
    ASSERT_LT(g.start[q], g.start[q + 1]);
    Eigen::Vector3i lo = Eigen::Vector3i::Constant(1 << 30), hi = -lo;
    bool all_finite = true;
    for (long k = g.start[q]; k < g.start[q + 1]; ++k) {
      const long i = g.voxels[k];
      ++seen[i];
      lo = lo.cwiseMin(b.sampling.grid_index.row(i).transpose());
      hi = hi.cwiseMax(b.sampling.grid_index.row(i).transpose());
      all_finite = all_finite && (*finite)[i];
      if (b.sampling.radius_of(static_cast<int>(i)) > g.radius(q)) ++violations;
      for (long e = 0; e < E; ++e)
        if (!(f(i, e) <= g.factors(q, e))) ++violations;
    }
    EXPECT_LE((hi - lo).maxCoeff(), 1) << "group " << q << " spans more than 2 cells";
    EXPECT_EQ(g.finite[q] != 0, all_finite);
  }
  EXPECT_EQ(violations, 0);
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int c) { return c == 1; }));
  EXPECT_GT(static_cast<double>(N) / static_cast<double>(G), 3.0) << "groups of several voxels";
  OctreeCertifier adopted(b.cage, b.sampling, &b.sub.basis);
  adopted.adopt_factors(false, f, *finite);
  const OctreeCertifier::VoxelGroups ga = adopted.voxel_groups();
  EXPECT_EQ(ga.start, g.start);
  EXPECT_EQ(ga.voxels, g.voxels);
  EXPECT_TRUE(ga.factors == g.factors);
}

// The per-voxel constants of Step 4e: built once, bounded by the stored rows' true norms (Eigen's SVD in
// double), and adopted by another certifier (what the precomputation cache does) with the same certificates.
TEST(CertificatePerturbation, ConstantsBoundTheStoredRowsAndAdoptingThemChangesNothing) {
  const SmallCase small;
  const Cage& cage = small.cage;
  const VoxelSampling& sampling = small.sampling;
  const SpectralSubspace& sub = small.sub;
  const OctreeCertifier built(cage, sampling, &sub.basis);
  EXPECT_EQ(built.perturbation_constants_if_built(), nullptr);
  const OctreeCertifier::PerturbationConstants pc = built.perturbation_constants();
  ASSERT_NE(built.perturbation_constants_if_built(), nullptr);
  const long N = sampling.size();
  ASSERT_EQ(pc.g2.size(), N);
  const OctreeCertifier::ReducedDerivativesRef r = built.reduced_derivatives();
  for (long i = 0; i < N; ++i) {
    Eigen::MatrixXd G(3, r.m);
    for (int row = 0; row < 3; ++row)
      for (long k = 0; k < r.m; ++k) G(row, k) = (*r.GH)[(9 * i + row) * r.m + k];
    const double two = Eigen::JacobiSVD<Eigen::MatrixXd>(G).singularValues()(0);
    EXPECT_GE(pc.g2(i), two) << "voxel " << i;
    EXPECT_LE(pc.g2(i), std::pow(3.0, 0.25) * two * (1 + 1e-9)) << "Gershgorin is within 3^(1/4)";
    EXPECT_GE(pc.gF(i), G.norm());
    EXPECT_LE(pc.gF(i), G.norm() * (1 + 1e-9));
    EXPECT_GT(pc.rest(i), 0);
  }

  OctreeCertifier fresh(cage, sampling, &sub.basis);
  OctreeCertifier::PerturbationConstants wrong = pc;
  wrong.rest.conservativeResize(N - 1);
  EXPECT_THROW(fresh.adopt_perturbation_constants(wrong), Error);
  fresh.adopt_perturbation_constants(pc);
  const OctreeCertifier::PerturbationConstants* got = fresh.perturbation_constants_if_built();
  ASSERT_NE(got, nullptr);
  EXPECT_EQ(got->g2, pc.g2);
  EXPECT_EQ(got->rest, pc.rest);
  EXPECT_EQ(got->gF, pc.gF);

  const MatR y0 = bent_reduced(cage, sub, 0.2, 5);
  const Certificate c0 = built.certify_reduced(y0);
  ASSERT_TRUE(c0.certified);
  const MatR y1 = bent_reduced(cage, sub, 0.201, 5);
  CertifyParams q;
  q.previous_y = &y0;
  q.previous_lower = &c0.base_lower;
  const Certificate a = built.certify_reduced(y1, q), b = fresh.certify_reduced(y1, q);
  EXPECT_GT(a.perturbed_voxels, 0);
  EXPECT_EQ(a.perturbed_voxels, b.perturbed_voxels);
  EXPECT_EQ(a.min_lower_bound, b.min_lower_bound);
  EXPECT_EQ(a.base_lower, b.base_lower);

  // A certifier without a reduction has none.
  const OctreeCertifier full(cage, sampling);
  EXPECT_THROW(full.perturbation_constants(), Error);
}
