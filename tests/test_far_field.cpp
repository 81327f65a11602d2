// The far-field refinement (RefinementEval::kFarField; docs/certificate.md, Step 4d) against independent
// truths: the patch representation of a subset of faces (finite differences of its J, linearity), its
// third-derivative bound against sampled Taylor remainders on random balls, the near-face test against exact
// point-triangle distances, and certificates against the batched (exact) refinement, the exact σ3 at every
// leaf center, dense sampling, and thread counts.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/geometry.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/edge_jet.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"
#include "test_cages.h"

using namespace lidef;
using lidef::test::perturbed_map;

namespace {

double frob(const std::array<Mat3, 3>& H) {
  return std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
}

// Distance from p to the closed triangle (a, b, c) (geometry.h's exact closest point; independent of the
// bounding spheres faces_near uses).
double point_triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return std::sqrt(point_triangle_dist2(p, a, b, c));
}

// A random point inside the icosphere cage at least `clear` from its surface, with its ball radius.
struct Ball {
  Vec3 c;
  double r;
};
std::vector<Ball> random_balls(const Cage& cage, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-0.85, 0.85), R(0, 1);
  std::vector<Ball> out;
  while (static_cast<int>(out.size()) < count) {
    const Vec3 c(U(rng), U(rng), U(rng));
    double d = 1e300;
    for (int t = 0; t < cage.num_faces(); ++t)
      d = std::min(d, point_triangle_distance(c, cage.V.row(cage.F(t, 0)).transpose(),
                                              cage.V.row(cage.F(t, 1)).transpose(),
                                              cage.V.row(cage.F(t, 2)).transpose()));
    if (c.norm() > 0.9 || d < 0.02) continue;
    // Radii from 2% to 50% of the clearance: both small balls near the cage and large ones.
    out.push_back({c, d * (0.02 + 0.48 * R(rng))});
  }
  return out;
}

}  // namespace

// A patch's J and H are those of Σ_{t∈S} f_t: J of S plus J of its complement is the whole J (the
// representation is linear in the faces), and the patch's H is the derivative of its J (central differences),
// for random subsets S.
TEST(FarField, PatchJacobianAndHessianAreThoseOfTheSubset) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  const HarmonicBasis basis(cage);
  const EdgeJet jet(cage);
  const MatX3d y = perturbed_map(cage, 0.05, 3);
  const HarmonicBasis::FaceMatrices fm = basis.face_matrices(y);
  const EdgeJet::MapData full = jet.prepare(fm);
  std::mt19937 rng(5);
  double worst_sum = 0, worst_fd = 0;
  for (const Ball& b : random_balls(cage, 30, 11)) {
    std::vector<int> s, rest;
    for (int t = 0; t < cage.num_faces(); ++t) (rng() % 3 == 0 ? s : rest).push_back(t);
    EdgeJet::Patch ps, pr;
    jet.make_patch(fm, s, ps);
    jet.make_patch(fm, rest, pr);
    EdgeJet::Values vs, vr, vf;
    jet.evaluate(ps, b.c, b.r, true, false, false, vs);
    jet.evaluate(pr, b.c, b.r, true, false, false, vr);
    jet.evaluate(full, b.c, b.r, true, false, false, vf);
    const double scale = vf.scale_J + vf.scale_H;
    worst_sum = std::max(worst_sum, (vs.J + vr.J - vf.J).norm() / scale);
    for (int a = 0; a < 3; ++a) worst_sum = std::max(worst_sum, (vs.H[a] + vr.H[a] - vf.H[a]).norm() / scale);
    // ∂J_S/∂p_c by central differences (step 1e-5, error O(h²)) against H_S[a](b, c).
    const double h = 1e-5;
    for (int c = 0; c < 3; ++c) {
      EdgeJet::Values plus, minus;
      Vec3 e = Vec3::Zero();
      e(c) = h;
      jet.evaluate(ps, b.c + e, b.r, false, false, false, plus);
      jet.evaluate(ps, b.c - e, b.r, false, false, false, minus);
      const Mat3 fd = (plus.J - minus.J) / (2 * h);
      for (int a = 0; a < 3; ++a)
        for (int bb = 0; bb < 3; ++bb)
          worst_fd = std::max(worst_fd, std::abs(fd(a, bb) - vs.H[a](bb, c)) / (1 + frob(vs.H)));
    }
    // The lanes evaluate the same function.
    EdgeJet::Values lanes[1];
    jet.evaluate_lanes(ps, &b.c, &b.r, 1, true, false, true, lanes);
    EXPECT_LE((lanes[0].J - vs.J).norm(), 1e-12 * (vs.scale_J + 1));
  }
  std::cout << "J_S + J_rest − J: " << worst_sum << " of the scales; H_S vs differences of J_S: " << worst_fd
            << "\n";
  EXPECT_LE(worst_sum, 1e-13);
  EXPECT_LE(worst_fd, 1e-5);
}

// The bound the far field rests on: for S = the faces far from a ball (EdgeJet::faces_near's complement),
// T_S (the patch's third-order factor sum over the ball) bounds the Taylor remainders of J_S and H_S:
//   ‖J_S(q) − J_S(c) − H_S(c)[q − c]‖_F ≤ ½|q − c|² T_S,   ‖H_S(q) − H_S(c)‖_F ≤ |q − c| T_S,
// at 200 points of each of 40 random balls (half on the sphere), on maps with bends of several sizes.
TEST(FarField, FarPartRemaindersStayBelowTheirBound) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  const HarmonicBasis basis(cage);
  const EdgeJet jet(cage);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> U(-1, 1), R(0, 1);
  double worst_j = 0, worst_h = 0;
  long checked = 0;
  for (double amp : {0.02, 0.1}) {
    const HarmonicBasis::FaceMatrices fm = basis.face_matrices(perturbed_map(cage, amp, 17));
    for (const Ball& b : random_balls(cage, 20, static_cast<unsigned>(amp * 1000))) {
      for (double reach : {1.5, 4.0}) {
        std::vector<int> near, far;
        jet.faces_near(b.c, reach * b.r, nullptr, near);
        for (int t = 0, k = 0; t < cage.num_faces(); ++t) {
          if (k < static_cast<int>(near.size()) && near[k] == t)
            ++k;
          else
            far.push_back(t);
        }
        EdgeJet::Patch pf;
        jet.make_patch(fm, far, pf);
        EdgeJet::Values c0;
        jet.evaluate(pf, b.c, b.r, true, false, true, c0);
        ASSERT_TRUE(std::isfinite(c0.T_third));
        if (far.empty()) continue;  // every face near this ball: no far part
        for (int k = 0; k < 200; ++k) {
          Vec3 d(U(rng), U(rng), U(rng));
          d *= b.r / d.norm() * (k % 2 ? 1.0 : std::cbrt(R(rng)));
          EdgeJet::Values q;
          jet.evaluate(pf, b.c + d, b.r, true, false, false, q);
          Mat3 taylor = c0.J;
          for (int a = 0; a < 3; ++a) taylor.row(a) += (c0.H[a] * d).transpose();
          const double dn = d.norm();
          const double rj = (q.J - taylor).norm() / (0.5 * dn * dn * c0.T_third);
          std::array<Mat3, 3> dh{q.H[0] - c0.H[0], q.H[1] - c0.H[1], q.H[2] - c0.H[2]};
          const double rh = frob(dh) / (dn * c0.T_third);
          worst_j = std::max(worst_j, rj);
          worst_h = std::max(worst_h, rh);
          ++checked;
          ASSERT_LE(rj, 1.0) << "ball " << b.c.transpose() << " r " << b.r << " reach " << reach;
          ASSERT_LE(rh, 1.0) << "ball " << b.c.transpose() << " r " << b.r << " reach " << reach;
        }
      }
    }
  }
  std::cout << checked << " points; largest remainder / bound: J " << worst_j << ", H " << worst_h << "\n";
  EXPECT_GT(worst_h, 1e-3);  // the check is not vacuous
}

// faces_near misses no face closer than the radius (exact point-triangle distances), and filtering the faces
// near a larger ball that contains the smaller one gives the same list as searching all faces.
TEST(FarField, FacesNearMissesNoCloseFaceAndInherits) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  const EdgeJet jet(cage);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> U(-1.2, 1.2), R(0.01, 0.8);
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 c(U(rng), U(rng), U(rng));
    const double radius = R(rng);
    std::vector<int> near;
    jet.faces_near(c, radius, nullptr, near);
    EXPECT_TRUE(std::is_sorted(near.begin(), near.end()));
    for (int t = 0, k = 0; t < cage.num_faces(); ++t) {
      if (k < static_cast<int>(near.size()) && near[k] == t) {
        ++k;
        continue;
      }
      const double d =
          point_triangle_distance(c, cage.V.row(cage.F(t, 0)).transpose(),
                                  cage.V.row(cage.F(t, 1)).transpose(), cage.V.row(cage.F(t, 2)).transpose());
      ASSERT_GT(d, radius) << "face " << t << " missed";
    }
    // A ball inside: its center at distance ≤ radius/2, its radius ≤ radius − that distance.
    Vec3 off(U(rng), U(rng), U(rng));
    off *= 0.5 * radius * R(rng) / off.norm();
    const double inner = (radius - off.norm()) * 0.999;
    std::vector<int> from_all, inherited;
    jet.faces_near(c + off, inner, nullptr, from_all);
    jet.faces_near(c + off, inner, &near, inherited);
    EXPECT_EQ(from_all, inherited);
  }
}

namespace {

struct FarFieldCase {
  double amp;
  unsigned seed;
};

// Exact σ3 at a point from the full coefficients.
double exact_sigma3(const HarmonicBasis& basis, const MatX3d& y, const Vec3& p) {
  return signed_singular_values(basis.map_jet(y, p, 1).J)(2);
}

}  // namespace

// Far-field certificates of refined maps: the same verdict as the exact batched refinement on every case; at
// every leaf center the reported σ3 lies within its sigma3_error of the exact σ3; dense sampling finds no σ3
// below a certified leaf's lower bound; the same leaves (bit for bit) at 1 and 2 threads. Both base-stage
// paths: stored derivatives (reduced and full) and on the fly.
TEST(FarField, CertificatesAgreeWithExactRefinementAndHoldUnderDenseSampling) {
  const Cage cage(lidef::test::icosphere(2, 0.15, 8));
  SamplingParams sp;
  sp.target_count = 800;
  sp.count_tolerance = 0.1;
  const VoxelSampling sampling = sample_voxels(cage, sp);
  const OctreeCertifier stored(cage, sampling);
  const OctreeCertifier on_the_fly(cage, sampling, nullptr, 0.0);
  int refined_certified = 0, far_leaves = 0;
  double worst_err_ratio = 0;
  for (const OctreeCertifier* cert : {&stored, &on_the_fly})
    for (const FarFieldCase& fc :
         {FarFieldCase{0.008, 21}, FarFieldCase{0.012, 21}, FarFieldCase{0.016, 4}, FarFieldCase{0.03, 4}}) {
      const MatX3d y = perturbed_map(cage, fc.amp, fc.seed);
      CertifyParams p;
      p.max_depth = 4;
      p.refinement = RefinementEval::kPerEdgeBatched;
      const Certificate exact = cert->certify(y, p);
      p.refinement = RefinementEval::kFarField;
      omp_set_num_threads(1);
      const Certificate one = cert->certify(y, p);
      omp_set_num_threads(2);
      const Certificate c = cert->certify(y, p);
      EXPECT_EQ(c.certified, exact.certified) << "amp " << fc.amp;
      ASSERT_EQ(one.leaves.size(), c.leaves.size());
      for (size_t i = 0; i < c.leaves.size(); ++i) {
        EXPECT_EQ(one.leaves[i].margin, c.leaves[i].margin);
        EXPECT_EQ(one.leaves[i].sigma3, c.leaves[i].sigma3);
      }
      std::vector<CertLeaf> refined;
      for (const CertLeaf& l : c.leaves)
        if (l.depth > 0 && std::isfinite(l.sigma3)) refined.push_back(l);
      // Base voxels: σ3 from the stored float derivatives is within the reported sigma3_error of the exact
      // σ3 (0 only where the base stage evaluated in double precision).
      int base_checked = 0;
      for (const CertLeaf& l : c.leaves) {
        if (l.depth != 0 || !std::isfinite(l.sigma3) || base_checked >= 64) continue;
        ++base_checked;
        const double s3 = exact_sigma3(cert->basis(), y, l.center);
        EXPECT_LE(std::abs(l.sigma3 - s3), l.sigma3_error + 1e-9 * (1 + std::abs(s3)))
            << "base leaf at " << l.center.transpose();
      }
      for (const CertLeaf& l : refined) {
        const double s3 = exact_sigma3(cert->basis(), y, l.center);
        if (l.sigma3_error > 0) {
          ++far_leaves;
          worst_err_ratio = std::max(worst_err_ratio, std::abs(l.sigma3 - s3) / l.sigma3_error);
        }
        EXPECT_LE(std::abs(l.sigma3 - s3), l.sigma3_error + 1e-9 * (1 + std::abs(s3)))
            << "leaf at " << l.center.transpose() << " depth " << l.depth;
      }
      if (!c.certified || c.refined == 0) continue;
      ++refined_certified;
      const VerificationResult v = verify_certificate(cert->basis(), y, refined, 64, 5);
      EXPECT_EQ(v.nonpositive_in_certified, 0);
      EXPECT_EQ(v.violations, 0);  // L is a Lipschitz constant of the exact σ3 on the leaf
      for (size_t i = 0; i < refined.size(); ++i)
        EXPECT_GE(v.voxels[i].min_sigma3, refined[i].margin) << "leaf " << i;
    }
  std::cout << far_leaves << " far-field leaves; largest |σ3 − exact| / sigma3_error " << worst_err_ratio
            << "\n";
  EXPECT_GE(refined_certified, 4);
  EXPECT_GT(far_leaves, 100);
}
