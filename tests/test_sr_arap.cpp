// PWL(Tri) / SR-ARAP (sr_arap.h): the energy never increases over local (Gauss-Seidel rotations) and global
// (positions) half-steps, and a rigid motion of all handles gives a rigid result.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "lidef/compare/sr_arap.h"
#include "lidef/procedural_models.h"
#include "lidef/scenario.h"
#include "test_support.h"

using namespace lidef;

TEST(PwlTri, EnergyDecreasesMonotonically) {
  const Model beam = make_beam();
  const Scenario sc = read_scenario(lidef::test::project_data() + "/scenarios/beam_bend.json");
  SrArapSolver s(beam.mesh);
  s.set_handles(sc.sources, sc.targets);
  double prev = s.energy(s.positions(), s.rotations());
  for (int it = 0; it < 40; ++it) {
    const PwlTriIteration r = s.step();
    EXPECT_LE(r.energy_after_local, prev * (1 + 1e-12) + 1e-15) << "local step, iteration " << it;
    EXPECT_LE(r.energy, r.energy_after_local * (1 + 1e-12) + 1e-15) << "global step, iteration " << it;
    prev = r.energy;
  }
  EXPECT_LT(s.handle_errors().maxCoeff(), 0.05);
}

TEST(PwlTri, RigidMotionOfAllHandlesGivesRigidResult) {
  BeamParams bp;  // a coarser beam mesh (~800 vertices): the iteration converges in a fraction of the time
  bp.mesh_segments_length = 30;
  bp.mesh_segments_section = 6;
  const Model beam = make_beam(bp);
  const Mat3 R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  const Vec3 t(0.3, -0.2, 0.5);
  // Handles spread over the mesh: every 75th vertex.
  MatX3d src(0, 3);
  for (Eigen::Index i = 0; i < beam.mesh.V.rows(); i += 75) {
    src.conservativeResize(src.rows() + 1, 3);
    src.row(src.rows() - 1) = beam.mesh.V.row(i);
  }
  const MatX3d dst = ((src * R.transpose()).rowwise() + t.transpose()).eval();
  PwlTriParams p;
  p.energy_tolerance = 1e-12;
  p.max_iterations = 4000;
  SrArapSolver s(beam.mesh, p);
  s.set_handles(src, dst);
  const PwlTriResult r = s.solve();
  EXPECT_TRUE(r.converged) << r.message;
  const MatX3d expected = ((beam.mesh.V * R.transpose()).rowwise() + t.transpose()).eval();
  EXPECT_LT((s.positions() - expected).cwiseAbs().maxCoeff(), 1e-4);
  for (const Mat3& Ri : s.rotations()) EXPECT_LT((Ri - R).norm(), 1e-3);
}
