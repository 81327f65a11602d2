// The proof that a certificate's leaves cover the domain it claims (leaf_coverage.h), the half of `lidef
// verify
// --interval` that the per-leaf re-proof cannot give. Truths: the certifier's own leaves on the mesh domain
// and on the paper's grid (proven), and the same leaves tampered with — a leaf dropped, the table cut short,
// a leaf moved off the grid, a leaf marked not certified (each must fail, naming the gap); far from the
// origin the rounding of the model-unit leaves is absorbed by the radius slack, which stays tiny.
#include <gtest/gtest.h>

#include <algorithm>

#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/leaf_coverage.h"
#include "lidef/domain_sampling.h"
#include "lidef/normalization.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"

using namespace lidef;

namespace {

struct Certified {
  Model model;
  CertificateReport report;
};

// The ball (small) moved by `offset`, a mild bend of it certified on `domain`, as `lidef certify` reports it.
Certified certified_ball(const std::string& domain, const Vec3& offset = Vec3::Zero()) {
  BallParams bp;
  bp.cage_subdivisions = 1;
  bp.mesh_subdivisions = 2;
  Certified c{make_ball(bp), {}};
  if (!offset.isZero()) {
    Model& m = c.model;
    m.cage = Cage(TriMesh{m.cage.V.rowwise() + offset.transpose(), m.cage.F, ""});
    m.mesh.V = m.mesh.V.rowwise() + offset.transpose();
  }
  SamplingParams sp;
  sp.target_count = 300;
  sp.count_tolerance = 0.3;
  const VoxelSampling sampling = sample_for_domain(domain, c.model.cage, c.model.mesh.V, c.model.mesh.F, sp);
  MatX3d y = c.model.cage.identity_coefficients();
  for (int v = 0; v < c.model.cage.num_vertices(); ++v) {
    const Vec3 p = c.model.cage.V.row(v).transpose() - offset;
    y.row(v) += 0.03 * Vec3(std::sin(2 * p.y()), std::sin(2 * p.z()), std::cos(2 * p.x())).transpose();
  }
  const NormalizedCertifier certifier(c.model.cage, sampling);
  CertifyParams params;
  params.keep_leaves = true;
  const Certificate cert = certifier.certify(y, params);
  EXPECT_TRUE(cert.certified) << cert.reason;
  c.report =
      make_certificate_report(cert, c.model.cage, c.model.mesh, y, "ball", "bend", sp, sampling, params);
  return c;
}

// The index of a leaf that meets the mesh domain (the first one in the table).
long leaf_meeting_domain(const Certified& c) {
  const auto& leaves = c.report.cert.leaves;
  MatX3d C(leaves.size(), 3);
  VecXd S(leaves.size());
  for (size_t i = 0; i < leaves.size(); ++i) {
    C.row(i) = leaves[i].center.transpose();
    S(i) = leaves[i].side;
  }
  const std::vector<char> meets = cubes_meeting_mesh_domain(c.model.mesh.V, c.model.mesh.F, C, S);
  return static_cast<long>(std::find(meets.begin(), meets.end(), 1) - meets.begin());
}

}  // namespace

TEST(LeafCoverage, TheCertifiersLeavesCoverTheMeshDomainAndThePapersGrid) {
  for (const std::string domain : {"mesh", "voxels"}) {
    const Certified c = certified_ball(domain);
    ASSERT_EQ(c.report.domain, domain);
    const LeafCoverage cov = prove_leaf_coverage(c.report, c.model.mesh);
    EXPECT_TRUE(cov.proven) << domain << ": " << cov.reason;
    if (domain == "voxels") {
      EXPECT_EQ(cov.base_cells, c.report.cert.voxels);
    }
    EXPECT_GT(cov.cells_checked, 0);
    // The slack covers only rounding: far below a leaf's size.
    EXPECT_LT(cov.radius_slack, 1e-12) << domain;
  }
}

TEST(LeafCoverage, DroppedCutMovedOrUncertifiedLeavesFailTheProof) {
  const Certified c = certified_ball("mesh");
  const long n = leaf_meeting_domain(c);
  ASSERT_LT(n, static_cast<long>(c.report.cert.leaves.size()));
  {  // One leaf meeting D dropped: a gap where it was.
    CertificateReport r = c.report;
    const Vec3 where = r.cert.leaves[n].center;
    r.cert.leaves.erase(r.cert.leaves.begin() + n);
    const LeafCoverage cov = prove_leaf_coverage(r, c.model.mesh);
    EXPECT_FALSE(cov.proven);
    EXPECT_NE(cov.reason.find("meets the domain and no leaf covers it"), std::string::npos) << cov.reason;
    EXPECT_LE((cov.gap - where).norm(), r.cert.voxel_side) << cov.reason;
  }
  {  // The paper's grid: a leaf dropped leaves its base voxel untiled, or one base voxel fewer than claimed.
    const Certified g = certified_ball("voxels");
    CertificateReport r = g.report;
    r.cert.leaves.erase(r.cert.leaves.begin() + r.cert.leaves.size() / 2);
    const LeafCoverage cov = prove_leaf_coverage(r, g.model.mesh);
    EXPECT_FALSE(cov.proven);
    EXPECT_TRUE(cov.reason.find("no leaf covers it") != std::string::npos ||
                cov.reason.find("base voxels, the certificate claims") != std::string::npos)
        << cov.reason;
  }
  {  // The table cut to its first 20 rows, the claimed leaf count rewritten to match: the gap is found.
    CertificateReport r = c.report;
    r.cert.leaves.resize(20);
    r.cert.num_leaves = 20;
    const LeafCoverage cov = prove_leaf_coverage(r, c.model.mesh);
    EXPECT_FALSE(cov.proven);
    EXPECT_NE(cov.reason.find("meets the domain and no leaf covers it"), std::string::npos) << cov.reason;
  }
  {  // A leaf moved by a tenth of its side: not a cell of the grid.
    CertificateReport r = c.report;
    r.cert.leaves[n].center.x() += 0.1 * r.cert.leaves[n].side;
    const LeafCoverage cov = prove_leaf_coverage(r, c.model.mesh);
    EXPECT_FALSE(cov.proven);
    EXPECT_NE(cov.reason.find("is not a cell center of the grid"), std::string::npos) << cov.reason;
  }
  {  // A leaf meeting D marked not certified.
    CertificateReport r = c.report;
    r.cert.leaves[n].certified = false;
    const LeafCoverage cov = prove_leaf_coverage(r, c.model.mesh);
    EXPECT_FALSE(cov.proven);
    EXPECT_NE(cov.reason.find("not certified"), std::string::npos) << cov.reason;
  }
  {  // A leaf duplicated.
    CertificateReport r = c.report;
    r.cert.leaves.push_back(r.cert.leaves[n]);
    EXPECT_FALSE(prove_leaf_coverage(r, c.model.mesh).proven);
  }
}

TEST(LeafCoverage, FarFromTheOriginTheRoundedLeavesAreStillCellsWithinTheSlack) {
  const Certified c = certified_ball("mesh", Vec3(1e8, -3e7, 2e8));
  const LeafCoverage cov = prove_leaf_coverage(c.report, c.model.mesh);
  EXPECT_TRUE(cov.proven) << cov.reason;
  // Coordinates of 2e8 carry ulps of 3e-8: the slack is of that order, far below a leaf's side.
  EXPECT_GT(cov.radius_slack, 0);
  EXPECT_LT(cov.radius_slack, 1e-4 * c.report.cert.voxel_side);
}
