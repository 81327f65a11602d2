// Independence of position and units: translated and scaled copies of the shared models give the
// same check result, the same voxels, the same certificate and the same Newton iterations, with coefficients
// equal up to the transform. The truth is the untransformed model: the harmonic map is affine-covariant, so
// a copy moved by t and scaled by s must give f_copy(s p + t) = s f(p) + t exactly in exact arithmetic.
// Quick cases: suite Invariance (unit label). The full sweep with default parameters: InvarianceSlow (slow
// label, tests/CMakeLists.txt).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/normalization.h"
#include "lidef/projected_newton.h"
#include "lidef/sampling.h"
#include "lidef/scenario.h"
#include "test_support.h"

namespace lidef {
namespace {

// p ↦ s p + t, applied to the copies.
struct Transform {
  std::string name;
  double s = 1;
  Vec3 t = Vec3::Zero();
  MatX3d apply(const MatX3d& P) const { return (s * P).rowwise() + t.transpose(); }
  // Coefficients: vertex rows like points, face rows unchanged (normalization.h).
  MatX3d apply_coeffs(const MatX3d& y, int nv) const {
    MatX3d z = y;
    z.topRows(nv) = apply(y.topRows(nv));
    return z;
  }
};

// Translations along a direction with no symmetry of the models (a pure x shift keeps bar's symmetry).
Transform translated(double d) {
  return {"translated " + std::to_string(d), 1, d * Vec3(1, -0.7, 0.3)};
}
Transform scaled(double s) {
  return {"scaled " + std::to_string(s), s, Vec3::Zero()};
}
// The copies are not exact: s·p + t is rounded, so a copy's vertices differ from the transformed original's
// by up to an ulp of |t| + s·|p|, i.e. by `copy_eps` relative to the model's size (~1 for the shared models;
// 2.8e-8 for the 1e8 translation). Quantities computed from a copy may differ by a modest multiple of it (the
// tolerances below allow 20-50 times); anything from the normalization itself would show up as far larger.
double copy_eps(const Transform& T) {
  return 2.3e-16 * (1 + T.t.norm() / T.s);
}

std::vector<Transform> all_transforms() {
  return {translated(1e3), translated(1e6), translated(1e8), scaled(1e-6),
          scaled(1e-3),    scaled(1e3),     scaled(1e6)};
}

// A copy of a model folder's cage.obj and mesh.obj under `dir` (write_obj: shortest round-trip digits).
std::string write_copy(const std::string& model_dir, const Transform& T, const std::string& dir) {
  std::filesystem::create_directories(dir);
  for (const char* f : {"cage.obj", "mesh.obj"}) {
    const TriMesh m = read_mesh(model_dir + "/" + f);
    std::ofstream out(dir + "/" + f);
    write_obj(out, T.apply(m.V), m.F, "lidef test: " + T.name + " copy");
  }
  return dir;
}

TriMesh read_cage(const std::string& model) {
  return read_mesh(test::shared_model(model) + "/cage.obj");
}
TriMesh transformed(TriMesh m, const Transform& T) {
  m.V = T.apply(m.V);
  return m;
}

TEST(Invariance, FrameRules) {
  LIDEF_REQUIRE_SHARED();
  // The paper's bar spans [-1, 1] along z around the origin: its frame is the identity, so its runs are
  // bit-identical to what they were before normalization.
  const Cage bar(read_cage("bar"));
  EXPECT_TRUE(Frame::of(bar).is_identity());

  const Cage spot(read_cage("spot"));
  const Frame f = Frame::of(spot);
  const Cage n = f.normalized(spot);
  EXPECT_NEAR((n.bbox_max - n.bbox_min).maxCoeff(), 2.0, 1e-15);
  EXPECT_NEAR((n.bbox_max + n.bbox_min).norm(), 0.0, 1e-15);
  // The identity of the normalized cage is the identity of the cage: vertex rows map like points, face rows
  // (unit normals) are unchanged.
  const MatX3d y = f.coefficients_from_normalized(n.identity_coefficients(), spot.num_vertices());
  EXPECT_LT((y - spot.identity_coefficients()).cwiseAbs().maxCoeff(), 1e-14);
  // An affine map: y_v = A v + b, y_t = A n_t in both frames.
  Mat3 A;
  A << 1.1, 0.2, 0, -0.1, 0.9, 0.3, 0, 0.05, 1.2;
  const Vec3 b(0.3, -0.2, 0.1);
  const MatX3d ya = spot.affine_coefficients(A, b);
  // In the frame: f_n(q) = (A (s q + c) + b − c)/s = A q + (A c + b − c)/s.
  const MatX3d yna = n.affine_coefficients(A, (A * f.center + b - f.center) / f.scale);
  EXPECT_LT((f.coefficients_to_normalized(ya, spot.num_vertices()) - yna).cwiseAbs().maxCoeff(), 1e-13);
}

// `lidef check` (check_model_dir) on copies written to a temp dir: the same errors and warnings, element by
// element, and the summary numbers transformed.
TEST(Invariance, CheckResultIsTheSameForTranslatedAndScaledCopies) {
  LIDEF_REQUIRE_SHARED();
  test::TempDir tmp;
  for (const std::string model : {"bar", "spot", "animal"}) {
    const ValidationReport ref = check_model_dir(test::shared_model(model));
    for (const Transform& T : all_transforms()) {
      SCOPED_TRACE(model + " " + T.name);
      const std::string dir = write_copy(test::shared_model(model), T, tmp / (model + "_" + T.name));
      const ValidationReport r = check_model_dir(dir);
      ASSERT_EQ(r.errors.size(), ref.errors.size()) << (r.errors.empty() ? "" : r.errors[0].str());
      ASSERT_EQ(r.warnings.size(), ref.warnings.size());
      for (size_t k = 0; k < r.warnings.size(); ++k)
        EXPECT_EQ(r.warnings[k].element, ref.warnings[k].element);
      EXPECT_EQ(r.self_intersections, ref.self_intersections);
      EXPECT_EQ(r.genus, ref.genus);
      EXPECT_EQ(r.mesh_vertices_outside, ref.mesh_vertices_outside);
      EXPECT_EQ(r.mesh_vertices_on_cage, ref.mesh_vertices_on_cage);
      EXPECT_NEAR(r.cage_volume / std::pow(T.s, 3), ref.cage_volume,
                  (1e-12 + 20 * copy_eps(T)) * ref.cage_volume);
      EXPECT_NEAR(r.min_distance / T.s, ref.min_distance, 1e-12 + 20 * copy_eps(T));
      EXPECT_EQ(r.min_distance_vertex, ref.min_distance_vertex);
    }
  }
}

// Voxels and the identity's certificate: the same count, the same centers up to the transform, certified
// with the same number of leaves. Before normalization the bar moved by 1e8 gave "σ3 at centers −0.999989".
TEST(Invariance, SameVoxelsAndIdentityCertificateForCopies) {
  LIDEF_REQUIRE_SHARED();
  for (const std::string model : {"bar", "spot"}) {
    const Cage ref(read_cage(model));
    SamplingParams sp;
    sp.target_count = 3000;
    const VoxelSampling vs = sample_voxels(ref, sp);
    const Certificate cref = NormalizedCertifier(ref, vs).certify(ref.identity_coefficients());
    ASSERT_TRUE(cref.certified) << cref.reason;
    for (const Transform& T : all_transforms()) {
      SCOPED_TRACE(model + " " + T.name);
      const Cage c(transformed(read_cage(model), T));
      const VoxelSampling v = sample_voxels(c, sp);
      ASSERT_EQ(v.size(), vs.size());
      EXPECT_NEAR(v.side / T.s, vs.side, (1e-14 + 20 * copy_eps(T)) * vs.side);
      // Centers agree to rounding of the copy's own coordinates and of the normalization.
      EXPECT_LT((v.centers - T.apply(vs.centers)).cwiseAbs().maxCoeff() / T.s, 1e-14 + 20 * copy_eps(T));
      EXPECT_EQ(v.hessian_subset, vs.hessian_subset);
      const Certificate cc = NormalizedCertifier(c, v).certify(c.identity_coefficients());
      EXPECT_TRUE(cc.certified) << cc.reason;
      EXPECT_EQ(cc.num_leaves, cref.num_leaves);
      EXPECT_NEAR(cc.min_lower_bound, cref.min_lower_bound, 1e-10 + 50 * copy_eps(T));
    }
  }
}

// One bar_bend run on a copy and on the original: iteration count, stop reason, certificate and the
// coefficients mapped back. Tolerance of the coefficients: 1e-6 of the model size unless a test says
// otherwise. The copies' inputs differ from the original's by rounding (copy_eps: 2.8e-8 for the 1e8
// translation), and the Newton iterations (single-precision Hessians, CG steps, line-search decisions taken
// on energies) carry such differences along; measured: docs/benchmarks.md, "Invariance". A normalization
// error (a wrong frame rule, a parameter in absolute units) shows up as a different iteration count or
// differences of the size of the deformation (~0.1-1).
struct BendRun {
  int iterations = 0;
  StopReason reason = StopReason::kMaxIterations;
  MatX3d y;  // model units
  double max_handle_error = 0;
  long leaves = 0;
  bool certified = false;
};

BendRun run_bar_bend(const Transform& T, const DeformParams& p) {
  const Scenario sc = read_scenario(test::shared_data() + "/scenarios/bar_bend.json");
  const Cage cage(transformed(read_cage("bar"), T));
  DeformationSolver solver(cage, p, /*cache_dir=*/"");
  solver.set_handles(T.apply(sc.sources), T.apply(sc.targets), "bar_bend");
  const SolveResult r = solver.solve();
  BendRun b;
  b.iterations = r.iterations;
  b.reason = r.reason;
  b.y = solver.coefficients();
  b.max_handle_error = solver.handle_errors().maxCoeff();
  const Certificate c = solver.certify_current(false);
  b.leaves = c.num_leaves;
  b.certified = c.certified;
  return b;
}

void expect_same_run(const BendRun& ref, const BendRun& b, const Transform& T, int nv, double tol = 1e-6) {
  EXPECT_EQ(b.iterations, ref.iterations);
  EXPECT_EQ(b.reason, ref.reason);
  EXPECT_EQ(b.certified, ref.certified);
  EXPECT_EQ(b.leaves, ref.leaves);
  const MatX3d expected = T.apply_coeffs(ref.y, nv);
  const double err = (b.y - expected).cwiseAbs().maxCoeff() / T.s;  // in the original's units (size ~1)
  EXPECT_LT(err, tol);
  EXPECT_NEAR(b.max_handle_error / T.s, ref.max_handle_error, 1e-6);
  ::testing::Test::RecordProperty("coeff_err_" + T.name, std::to_string(err));
  std::printf("  %-22s iterations %d, max coefficient difference %.3g (model size 1)\n", T.name.c_str(),
              b.iterations, err);
}

// Quick: a coarse bar_bend (3,000 voxels, 40 reduced DOF per coordinate) on the extreme copies.
TEST(Invariance, BarBendSameIterationsOnExtremeCopies) {
  LIDEF_REQUIRE_SHARED();
  DeformParams p;
  p.samples = 3000;
  p.reduced_dof = 40;
  const BendRun ref = run_bar_bend({"original", 1, Vec3::Zero()}, p);
  ASSERT_TRUE(ref.certified);
  const int nv = Cage(read_cage("bar")).num_vertices();
  for (const Transform& T : {translated(1e8), scaled(1e-6), scaled(1e6)}) {
    SCOPED_TRACE(T.name);
    // 1e-4 like the full sweep below: the kept factor's CG steps (docs/solver.md, "The kept factor") carry
    // the copies' rounding differences further than a direct solve did, with the same decisions in every
    // iteration (measured 2026-11-30: 9.0e-6 on the 1e-6 scaling, 9.9e-8 on the 1e8 translation; with the
    // Hessian assembled every iteration 2.2e-8 and 9.9e-8).
    expect_same_run(ref, run_bar_bend(T, p), T, nv, 1e-4);
  }
}

// The full sweep with the default parameters (bar_bend: 6 iterations, docs/benchmarks.md).
TEST(InvarianceSlow, BarBendDefaultsSameIterationsOnAllCopies) {
  LIDEF_REQUIRE_SHARED();
  DeformParams p;
  const BendRun ref = run_bar_bend({"original", 1, Vec3::Zero()}, p);
  ASSERT_TRUE(ref.certified);
  EXPECT_EQ(ref.iterations, 6);
  const int nv = Cage(read_cage("bar")).num_vertices();
  for (const Transform& T : all_transforms()) {
    SCOPED_TRACE(T.name);
    // 1e-4, not 1e-6: with the default tolerances the run stops once an iteration lowers the energy by less
    // than energy_tolerance = 1e-5 (relative), so two runs whose line searches round differently stop at
    // points that agree only to about that accuracy (measured 2026-11-30: 5.1e-7 on the 1e-6 scaling, same 6
    // iterations; the others 1e-13 to 9e-8).
    expect_same_run(ref, run_bar_bend(T, p), T, nv, 1e-4);
  }
}

}  // namespace
}  // namespace lidef
