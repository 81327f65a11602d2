// Rotation-aware target paths (target_path.h) and the continuation driver (continuation.h): the path's ends
// are met exactly, a twist keeps the handles' distance to the axis where linear interpolation would collapse
// it, grouping, waypoints in scenarios; on the project's beam, a 180-degree twist reached through stages with
// every accepted iterate certified by an independent full-space certifier, determinism, and a pull that no
// certified map reaches ending "blocked" with the solver's map the last certified one.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>

#include "lidef/continuation.h"
#include "lidef/errors.h"
#include "lidef/model_check.h"
#include "lidef/octree_certifier.h"
#include "lidef/projected_newton.h"
#include "lidef/scenario.h"
#include "lidef/target_path.h"
#include "test_support.h"

using namespace lidef;

namespace {

constexpr double kPi = 3.14159265358979323846;

Vec3 rotate_x(const Vec3& p, double deg) {
  const double t = deg * kPi / 180, c = std::cos(t), s = std::sin(t);
  return {p.x(), c * p.y() - s * p.z(), s * p.y() + c * p.z()};
}

// The beam's end faces: 4 corners and the center at x = -1 (fixed) and x = +1.
MatX3d beam_sources() {
  MatX3d s(10, 3);
  const double c[5][2] = {{-0.2, -0.2}, {0.2, -0.2}, {0.2, 0.2}, {-0.2, 0.2}, {0, 0}};
  for (int e = 0; e < 2; ++e)
    for (int k = 0; k < 5; ++k) s.row(5 * e + k) << (e ? 1.0 : -1.0), c[k][0], c[k][1];
  return s;
}

MatX3d twisted(const MatX3d& sources, double deg) {
  MatX3d t = sources;
  for (Eigen::Index i = 5; i < t.rows(); ++i)
    t.row(i) = rotate_x(sources.row(i).transpose(), deg).transpose();
  return t;
}

}  // namespace

TEST(TargetPath, GroupsHandlesByProximity) {
  const std::vector<int> g = group_handles(beam_sources(), 0.5);
  EXPECT_EQ(g, (std::vector<int>{0, 0, 0, 0, 0, 1, 1, 1, 1, 1}));
  // Chains count (single linkage): three points 0.4 apart in a row are one group at link 0.5.
  MatX3d chain(3, 3);
  chain << 0, 0, 0, 0.4, 0, 0, 0.8, 0, 0;
  EXPECT_EQ(group_handles(chain, 0.5), (std::vector<int>{0, 0, 0}));
  EXPECT_EQ(group_handles(chain, 0.3), (std::vector<int>{0, 1, 2}));
}

TEST(TargetPath, TwistTurnsTheHandlesInsteadOfCollapsingThem) {
  const MatX3d a = beam_sources(), b = twisted(a, 180);
  const TargetPath path({a, b}, group_handles(a, 0.5));
  ASSERT_EQ(path.segments(), 1);
  EXPECT_NEAR(path.max_angle(0), kPi, 1e-9);
  // Ends exactly.
  EXPECT_EQ(path.at(0), a);
  EXPECT_EQ(path.at(1), b);
  // Halfway: the twisted end turned by 90 degrees (either way: 180 degrees has no preferred sense), each
  // corner still 0.2*sqrt(2) from the axis; linear interpolation would put all four on the axis.
  const MatX3d mid = path.at(0.5);
  for (int i = 5; i < 9; ++i) {
    const Vec3 p = mid.row(i).transpose();
    EXPECT_NEAR(std::hypot(p.y(), p.z()), 0.2 * std::sqrt(2.0), 1e-12) << i;
    EXPECT_NEAR(p.x(), 1.0, 1e-12);
    const Vec3 plus = rotate_x(a.row(i).transpose(), 90), minus = rotate_x(a.row(i).transpose(), -90);
    EXPECT_LT(std::min((p - plus).norm(), (p - minus).norm()), 1e-12) << i;
  }
  // The fixed end does not move at all along the way.
  for (double s : {0.1, 0.5, 0.9})
    for (int i = 0; i < 5; ++i) EXPECT_LT((path.at(s).row(i) - a.row(i)).norm(), 1e-15);
}

TEST(TargetPath, TranslationsAndNonRigidRestAreLinear) {
  // One handle alone (no rotation defined) and a stretched group: the rigid part is interpolated, the rest
  // linearly, and both ends are met exactly.
  MatX3d a(4, 3), b(4, 3);
  a << 0, 0, 0, 1, 0, 0, 0, 1, 0, 5, 5, 5;
  b << 0, 0, 0, 2, 0, 0, 0, 1, 0, 6, 5, 5;  // handle 1 stretched; handle 3 translated
  const TargetPath path({a, b}, {0, 0, 0, 1});
  EXPECT_EQ(path.at(1), b);
  EXPECT_LT((path.at(0.5).row(3) - Eigen::RowVector3d(5.5, 5, 5)).norm(), 1e-12);
  // Collinear group: no rotation is defined, so the move is linear.
  MatX3d c(3, 3), d(3, 3);
  c << 0, 0, 0, 1, 0, 0, 2, 0, 0;
  d << 0, 0, 0, 0, 1, 0, 0, 2, 0;
  const TargetPath line({c, d}, {0, 0, 0});
  EXPECT_EQ(line.max_angle(0), 0);
  EXPECT_LT((line.at(0.5) - 0.5 * (c + d)).norm(), 1e-12);
}

TEST(TargetPath, WaypointsMakeSegments) {
  const MatX3d a = beam_sources();
  const TargetPath path({a, twisted(a, 120), twisted(a, 240), twisted(a, 360)}, group_handles(a, 0.5));
  ASSERT_EQ(path.segments(), 3);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(path.max_angle(k), 2 * kPi / 3, 1e-9);
  EXPECT_LT((path.at(1) - twisted(a, 120)).norm(), 1e-15);
  EXPECT_LT((path.at(1.5) - twisted(a, 180)).norm(), 1e-12);
  EXPECT_LT((path.at(2.5) - twisted(a, 300)).norm(), 1e-12);
  EXPECT_LT((path.at(3) - a).norm(), 1e-12);  // a full turn ends where it started
}

TEST(Scenario, HandlePathsAndGroupsReadAndWriteBack) {
  lidef::test::TempDir tmp;
  const Scenario s = read_scenario(lidef::test::project_data() + "/scenarios/beam_twist360.json");
  ASSERT_EQ(s.waypoints.size(), 2u);
  EXPECT_LT((s.waypoints[0] - twisted(beam_sources(), 120)).norm(), 1e-12);
  EXPECT_LT((s.targets - beam_sources()).norm(), 1e-12);
  Scenario g = s;
  g.groups = {0, 0, 0, 0, 0, 1, 1, 1, 1, 1};
  write_scenario(tmp.str() + "/s.json", g);
  // Written next to nothing: the model is resolved through the scenario folder, so point it at the beam.
  Scenario back = read_scenario(tmp.str() + "/s.json", lidef::test::project_data() + "/models");
  EXPECT_EQ(back.waypoints.size(), 2u);
  EXPECT_EQ(back.waypoints[1], g.waypoints[1]);
  EXPECT_EQ(back.groups, g.groups);
}

TEST(Scenario, BadHandlePathsAndGroupsAreRefusedWithAReason) {
  lidef::test::TempDir tmp;
  const std::string models = lidef::test::project_data() + "/models";
  auto refuse = [&](const std::string& handles) {
    const std::string path = tmp.str() + "/bad.json";
    lidef::test::write_text(path, "{\"model\": \"beam\", \"handles\": [" + handles + "]}");
    return lidef::test::input_error_message([&] { read_scenario(path, models); });
  };
  const std::string h1 = "{\"source\": [0,0,0], \"target\": [0,0,0]}";
  EXPECT_NE(refuse(h1 + ", {\"source\": [0.5,0,0], \"path\": [[0.5,0,0]], \"target\": [0.6,0,0]}")
                .find("\"path\" has 1 waypoints but handle 1 has 0"),
            std::string::npos);
  EXPECT_NE(refuse("{\"source\": [0,0,0], \"path\": [], \"target\": [0,0,0]}").find("non-empty array"),
            std::string::npos);
  EXPECT_NE(refuse("{\"source\": [0,0,0], \"path\": [[0,\"x\",0]], \"target\": [0,0,0]}")
                .find("path[0][1] (y) is not a finite number"),
            std::string::npos);
  EXPECT_NE(refuse("{\"source\": [0,0,0], \"target\": [0,0,0], \"group\": 0}, " +
                   std::string("{\"source\": [0.5,0,0], \"target\": [0.5,0,0]}"))
                .find("has no \"group\" but handle 1 has one"),
            std::string::npos);
  EXPECT_NE(refuse("{\"source\": [0,0,0], \"target\": [0,0,0], \"group\": -1}").find("\"group\" must be"),
            std::string::npos);
}

namespace {

struct Beam {
  Beam() : model(load_model(lidef::test::project_data() + "/models/beam")) {}
  Model model;
  lidef::test::TempDir cache;
};
const Beam& beam() {
  static const Beam b;
  return b;
}

DeformParams fast_params() {
  DeformParams p;
  p.samples = 4000;
  p.reduced_dof = 60;
  p.max_iterations = 40;
  return p;
}

struct TwistRun {
  std::unique_ptr<DeformationSolver> solver;
  SolveResult result;
  PathSolveReport report;
  std::vector<IterationRecord> records;
  std::vector<std::string> stages;
  int accepted = 0, fully_certified = 0;
};

// The beam twisted by `deg` (through `waypoint_degs`) with fast parameters; every accepted iterate certified
// again in the callback by a full-space certifier (no reduction matrix: an independent check).
std::unique_ptr<TwistRun> twist_run(double deg, const std::vector<double>& waypoint_degs, bool continuation) {
  auto r = std::make_unique<TwistRun>();
  DeformParams p = fast_params();
  p.continuation = continuation;
  r->solver = std::make_unique<DeformationSolver>(beam().model.cage, p, beam().cache.str());
  DeformationSolver& s = *r->solver;
  const MatX3d src = beam_sources();
  s.set_handles(src, twisted(src, deg), "twist");
  std::vector<MatX3d> waypoints;
  for (double w : waypoint_degs) waypoints.push_back(twisted(src, w));
  const OctreeCertifier full(beam().model.cage, s.sampling());
  r->result = solve_to_targets(
      s, waypoints, twisted(src, deg), {},
      [&](const IterationRecord& rec) {
        r->records.push_back(rec);
        if (rec.accepted) {
          ++r->accepted;
          if (full.certify(s.coefficients(), s.certify_params(false, false)).certified) ++r->fully_certified;
        }
        return true;
      },
      nullptr, [&](const std::string& line) { r->stages.push_back(line); }, &r->report);
  std::printf("twist %.0f (continuation %s): %s after %d iterations (%s), max handle error %.3e, %d stages\n",
              deg, continuation ? "on" : "off", to_string(r->result.reason), r->result.iterations,
              r->result.message.c_str(), s.handle_errors().maxCoeff(), r->report.stages);
  for (const std::string& l : r->stages) std::printf("  %s\n", l.c_str());
  return r;
}

}  // namespace

TEST(Continuation, BeamTwist180IsReachedThroughStagesWithEveryIterateCertified) {
  const auto run = twist_run(180, {}, true);
  const DeformationSolver& s = *run->solver;
  ASSERT_EQ(run->report.strategies.size(), 1u);
  EXPECT_EQ(run->report.strategies[0], "planned continuation");
  EXPECT_NEAR(run->report.max_angle_deg, 180, 1e-6);
  EXPECT_GE(run->report.stages, 1);  // 180 / 90: one intermediate stage at least
  EXPECT_TRUE(run->result.converged()) << run->result.message;
  EXPECT_LE(s.handle_errors().maxCoeff(), s.params().handle_tolerance);
  EXPECT_TRUE(s.certificate().certified);
  EXPECT_GT(run->accepted, 0);
  EXPECT_EQ(run->fully_certified, run->accepted);
  // The end face really turned: its corner (1, -0.2, -0.2) went to (1, 0.2, 0.2), which a linear pull could
  // only reach by collapsing the beam; the map at the face center, halfway along the axis, is no fold.
  const MatX3d h = s.handle_positions();
  EXPECT_LT((h.row(5) - Eigen::RowVector3d(1, 0.2, 0.2)).norm(), 1e-3);
  // Deterministic: the same run again gives the same coefficients bit for bit.
  const auto again = twist_run(180, {}, true);
  EXPECT_EQ(std::memcmp(s.reduced_coefficients().data(), again->solver->reduced_coefficients().data(),
                        sizeof(double) * s.reduced_coefficients().size()),
            0);
}

TEST(Continuation, AFullTurnFollowsItsWaypoints) {
  const auto run = twist_run(360, {120, 240}, true);
  const DeformationSolver& s = *run->solver;
  EXPECT_EQ(run->report.segments, 3);
  EXPECT_TRUE(run->result.converged()) << run->result.message;
  EXPECT_LE(s.handle_errors().maxCoeff(), s.params().handle_tolerance);
  EXPECT_EQ(run->fully_certified, run->accepted);
  // Targets equal sources, yet the map is a full twist, not the identity: the middle of the beam's top edge
  // (0, 0.2, 0.2)... is turned by about 180 degrees about the axis.
  const HarmonicBasis& basis = s.basis();
  MatX3d p(1, 3);
  p << 0, 0.15, 0.15;
  const MatX3d q = basis.value_matrix(p) * s.coefficients();
  EXPECT_LT(q(0, 1), 0) << q;  // y changed sign: turned half a turn at mid length
  EXPECT_LT(q(0, 2), 0) << q;
}
