// VHM (vhm.h): handles at rest reproduce the identity; the local/global iteration never increases the energy;
// and lidef's certificate on a VHM result agrees with dense sampling (Fig. 11): no sample inside a certified
// leaf has σ3 ≤ 0, and a verdict "not locally injective" comes with a point where σ3 ≤ 0 really holds.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/compare/vhm.h"
#include "lidef/green_coordinates.h"
#include "lidef/octree_certifier.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"
#include "lidef/scenario.h"
#include "lidef/signed_svd.h"
#include "test_support.h"

using namespace lidef;

namespace {

struct BeamVhm {
  Model beam = make_beam();
  Cage& cage = beam.cage;
  HarmonicBasis basis{beam.cage};
  VoxelSampling sampling;
  MatX3d anchors, boundary;
  BeamVhm() {
    SamplingParams sp;
    sp.target_count = 3000;
    sampling = sample_voxels(cage, sp);
    const std::vector<int> pick = select_hessian_subset(sampling, 150.0 / sampling.size());
    anchors.resize(static_cast<Eigen::Index>(pick.size()), 3);
    for (size_t k = 0; k < pick.size(); ++k)
      anchors.row(static_cast<Eigen::Index>(k)) = sampling.centers.row(pick[k]);
    boundary.resize((beam.mesh.V.rows() + 9) / 10, 3);
    for (Eigen::Index i = 0; i < beam.mesh.V.rows(); i += 10) boundary.row(i / 10) = beam.mesh.V.row(i);
  }
};

}  // namespace

TEST(Vhm, HandlesAtRestReproduceTheIdentity) {
  BeamVhm s;
  VhmSolver vhm(s.cage, s.basis, s.anchors, s.boundary);
  const MatX3d src = s.beam.mesh.V.topRows(6);
  vhm.set_handles(src, src);
  const VhmResult r = vhm.solve();
  EXPECT_TRUE(r.converged) << r.message;
  const MatX3d f = s.basis.map_values(vhm.coefficients(), s.beam.mesh.V);
  EXPECT_LT((f - s.beam.mesh.V).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT(vhm.handle_errors().maxCoeff(), 1e-8);
}

TEST(Vhm, EnergyNeverIncreasesAndHandlesMove) {
  BeamVhm s;
  const Scenario sc = read_scenario(lidef::test::project_data() + "/scenarios/beam_bend.json");
  VhmSolver vhm(s.cage, s.basis, s.anchors, s.boundary);
  vhm.set_handles(sc.sources, sc.targets);
  double prev = vhm.energy(vhm.coefficients(), vhm.best_rotations(vhm.coefficients()));
  for (int it = 0; it < 30; ++it) {
    const VhmIteration r = vhm.step();
    EXPECT_LE(r.energy, prev * (1 + 1e-12)) << "iteration " << it;
    prev = r.energy;
  }
  const double initial_err = (sc.targets - sc.sources).rowwise().norm().maxCoeff();
  EXPECT_LT(vhm.handle_errors().maxCoeff(), 0.1 * initial_err);
}

TEST(Vhm, CertificateAgreesWithDenseSampling) {
  BeamVhm s;
  for (const char* name : {"beam_bend.json", "beam_twist150.json"}) {
    const Scenario sc = read_scenario(lidef::test::project_data() + "/scenarios/" + name);
    VhmParams p;
    p.max_iterations = 200;
    VhmSolver vhm(s.cage, s.basis, s.anchors, s.boundary, p);
    vhm.set_handles(sc.sources, sc.targets);
    vhm.solve();
    const MatX3d& y = vhm.coefficients();
    OctreeCertifier certifier(s.cage, s.sampling);
    CertifyParams cp;
    cp.max_refined_voxels = 4000;
    cp.keep_leaves = true;
    const Certificate cert = certifier.certify(y, cp);
    std::vector<CertLeaf> certified;
    for (const CertLeaf& l : cert.leaves)
      if (l.certified) certified.push_back(l);
    const VerificationResult v = verify_certificate(s.basis, y, certified, 4);
    std::cout << name << ": " << (cert.certified ? "certified" : "not certified: " + cert.reason) << ", "
              << certified.size() << " certified leaves, " << v.points << " dense samples\n";
    EXPECT_EQ(v.nonpositive_in_certified, 0) << name;
    EXPECT_EQ(v.violations, 0) << name;
    if (!cert.certified) {
      // The certificate says no: dense evidence of σ3 ≤ 0 should exist wherever it saw σ3 ≤ 0 at a center.
      for (const CertLeaf& l : cert.failing)
        if (l.sigma3 <= 0) {
          EXPECT_LE(signed_singular_values(s.basis.map_jet(y, l.center, 1).J)(2), 0) << name;
        }
    }
  }
}
