// The studio's engine (interactive_session.h) without a display: frames against independent evaluations of
// the same map, certificates of every published frame, the drag path, extras, bad input, stop, saved
// sessions.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>
#include <vector>

#include "lidef/analysis/interactive_session.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/octree_certifier.h"
#include "lidef/scenario.h"
#include "lidef/symmetric_dirichlet.h"
#include "test_support.h"

namespace lidef {
namespace {
using namespace lidef::test;

// Small enough for a unit test (a few seconds): the beam with 60 DOF per coordinate and ~4000 voxels.
DeformParams small_params() {
  DeformParams p;
  p.reduced_dof = 60;
  p.samples = 4000;
  p.max_iterations = 30;
  return p;
}

struct Recorder {
  std::mutex m;
  std::vector<std::shared_ptr<const SessionFrame>> frames;
  std::vector<std::string> errors;
  InteractiveSession::FrameCallback frame_cb() {
    return [this](std::shared_ptr<const SessionFrame> f) {
      std::lock_guard<std::mutex> lk(m);
      frames.push_back(f);
    };
  }
  InteractiveSession::ErrorCallback error_cb() {
    return [this](const std::string& e) {
      std::lock_guard<std::mutex> lk(m);
      errors.push_back(e);
    };
  }
};

// The beam's end face x = +1 (5 points) pulled, the end x = -1 fixed.
void beam_handles(MatX3d& S, MatX3d& T, double pull_y) {
  const double c[5][2] = {{-0.2, -0.2}, {0.2, -0.2}, {0.2, 0.2}, {-0.2, 0.2}, {0, 0}};
  S.resize(10, 3);
  for (int i = 0; i < 5; ++i) {
    S.row(i) << -0.95, c[i][0] * 0.9, c[i][1] * 0.9;
    S.row(5 + i) << 0.95, c[i][0] * 0.9, c[i][1] * 0.9;
  }
  T = S;
  for (int i = 5; i < 10; ++i) T(i, 1) += pull_y;
}

TEST(InteractiveSession, FramesMatchIndependentEvaluationAndAreCertified) {
  Recorder rec;
  InteractiveSession session(rec.frame_cb(), rec.error_cb());
  session.open_model(project_data() + "/models/beam", small_params());
  ASSERT_TRUE(session.wait_until_resting(300));
  MatX3d S, T;
  beam_handles(S, T, 0.3);
  session.set_handles(S, T);
  ASSERT_TRUE(session.wait_until_resting(300));
  const auto f = session.latest_frame();
  ASSERT_TRUE(f && f->model);
  EXPECT_TRUE(rec.errors.empty()) << rec.errors.front();
  EXPECT_EQ(f->state, SessionState::kResting);
  EXPECT_TRUE(f->certified);
  EXPECT_GT(f->min_lower_bound, 0);
  ASSERT_FALSE(f->history.empty());
  EXPECT_LT(f->max_handle_error, 0.02) << f->status;

  // Geometry against the full-space basis evaluated point by point (no reduced matrices involved).
  const Model& model = *f->model;
  const HarmonicBasis basis(model.cage);
  ASSERT_EQ(f->mesh_V.rows(), model.mesh.V.rows());
  const MatX3d images = basis.map_values(f->coefficients, S);
  EXPECT_LT((images - f->images).cwiseAbs().maxCoeff(), 1e-9);
  double max_dv = 0, max_de = 0, max_dd = 0;
  for (Eigen::Index i = 0; i < model.mesh.V.rows(); i += 37) {
    const MapJet jet = basis.map_jet(f->coefficients, model.mesh.V.row(i).transpose(), 1);
    max_dv = std::max(max_dv, (jet.f.transpose() - f->mesh_V.row(i)).cwiseAbs().maxCoeff());
    max_de = std::max(max_de, std::abs(sd_energy(jet.J) - 6 - f->mesh_e_iso(i)));
    max_dd = std::max(max_dd, std::abs(jet.J.determinant() - f->mesh_det(i)));
  }
  EXPECT_LT(max_dv, 1e-9);
  EXPECT_LT(max_de, 1e-7);
  EXPECT_LT(max_dd, 1e-9);
  EXPECT_EQ((f->cage_V - f->coefficients.topRows(model.cage.num_vertices())).cwiseAbs().maxCoeff(), 0.0);
  // Every published frame with a map is certified (the studio shows only certified maps); preparing frames
  // show the model at rest before any certificate and say so (state kPreparing, not certified).
  std::lock_guard<std::mutex> lk(rec.m);
  int with_map = 0;
  for (const auto& fr : rec.frames)
    if (fr->mesh_V.rows() > 0 && fr->state != SessionState::kPreparing) {
      ++with_map;
      EXPECT_TRUE(fr->certified) << "frame " << fr->serial;
    }
  EXPECT_GT(with_map, 2);
}

TEST(InteractiveSession, ExtrasAndVerificationOfTheShownMap) {
  Recorder rec;
  InteractiveSession session(rec.frame_cb(), rec.error_cb());
  session.open_model(project_data() + "/models/beam", small_params());
  MatX3d S, T;
  beam_handles(S, T, 0.4);
  session.set_handles(S, T);
  ExtrasRequest ex;
  ex.leaves = true;
  ex.field = true;
  ex.field_resolution = 24;
  session.set_extras(ex);
  session.verify(16);
  ASSERT_TRUE(session.wait_until_resting(300));
  const auto f = session.latest_frame();
  ASSERT_TRUE(f->leaves && f->field && f->field_deformed && f->verification);
  EXPECT_EQ(f->leaves_version, f->map_version);
  EXPECT_EQ(f->field_version, f->map_version);
  EXPECT_EQ(f->verification_version, f->map_version);
  EXPECT_TRUE(f->leaves->certified);
  EXPECT_EQ(static_cast<long>(f->leaves->leaves.size()), f->leaves->num_leaves);
  // Ground truth by dense sampling: no sampled point of a certified leaf has σ3 <= 0, and L bounds the
  // slopes.
  EXPECT_EQ(f->verification->nonpositive_in_certified, 0);
  EXPECT_EQ(f->verification->violations, 0);
  EXPECT_EQ(f->verification->voxels.size(), f->leaves->leaves.size());
  // The field's deformed positions are f at the grid points inside the cage.
  const FieldGrid& g = *f->field;
  EXPECT_EQ(g.dims[0], 24);
  const HarmonicBasis basis(f->model->cage);
  long checked = 0;
  for (long i = 0; i < g.points(); i += 7) {
    const float* q = &(*f->field_deformed)[3 * static_cast<size_t>(i)];
    if (!g.inside_cage[static_cast<size_t>(i)]) {
      EXPECT_TRUE(std::isnan(q[0]));
      continue;
    }
    const Vec3 p = g.origin + g.spacing * Vec3(i % g.dims[0], (i / g.dims[0]) % g.dims[1],
                                               i / (static_cast<long>(g.dims[0]) * g.dims[1]));
    const MapJet jet = basis.map_jet(f->coefficients, p, 1);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(q[a], jet.f(a), 1e-5);
    ++checked;
  }
  EXPECT_GT(checked, 20);
}

TEST(InteractiveSession, DragPathKeepsEveryFrameCertifiedAndReachesTheLastTarget) {
  Recorder rec;
  InteractiveSession session(rec.frame_cb(), rec.error_cb());
  session.open_model(project_data() + "/models/beam", small_params());
  MatX3d S, T;
  beam_handles(S, T, 0.0);
  session.set_handles(S, T);
  ASSERT_TRUE(session.wait_until_resting(300));
  // A drag: 20 target updates without waiting (the engine keeps only the newest of a burst).
  for (int k = 1; k <= 20; ++k) {
    for (int i = 5; i < 10; ++i) T(i, 2) = S(i, 2) + 0.02 * k;
    session.set_targets(T);
    std::this_thread::sleep_for(std::chrono::milliseconds(15));
  }
  ASSERT_TRUE(session.wait_until_resting(300));
  const auto f = session.latest_frame();
  EXPECT_TRUE(f->certified);
  EXPECT_EQ((f->targets - T).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_LT(f->max_handle_error, 0.02) << f->status;
  EXPECT_GT(f->images(7, 2) - S(7, 2), 0.35);  // the pulled end moved up by ~0.4
  std::lock_guard<std::mutex> lk(rec.m);
  for (const auto& fr : rec.frames) {
    if (fr->mesh_V.rows() > 0 && fr->state != SessionState::kPreparing) {
      EXPECT_TRUE(fr->certified) << "frame " << fr->serial;
    }
  }
  EXPECT_TRUE(rec.errors.empty());
}

// Dragging the beam's end around a full turn keeps following the cursor. The studio's window only
// forwards the dragged targets to this engine (tests/studio drag the same way with mouse events); here the
// end face's targets turn about the beam axis in 10-degree updates 40 ms apart, as a drag does, and at every
// quarter turn the engine must come to rest with the handles on their targets and a certified map. Slow label
// (DeformSlow.*): four solves to rest, ~1 min on 2 idle cores, several on a loaded machine.
// Drags the beam's far end around a full turn in 10° steps, as fast as a hand would (40 ms apart); at every
// quarter turn the engine must come to rest certified with the handles following within 0.02.
void drag_around_a_full_turn(const DeformParams& p) {
  Recorder rec;
  InteractiveSession session(rec.frame_cb(), rec.error_cb());
  session.open_model(project_data() + "/models/beam", p);
  MatX3d S, T;
  beam_handles(S, T, 0.0);
  session.set_handles(S, T);
  ASSERT_TRUE(session.wait_until_resting(300));
  for (int deg = 10; deg <= 360; deg += 10) {
    const double t = deg * 3.14159265358979323846 / 180, c = std::cos(t), sn = std::sin(t);
    for (int i = 5; i < 10; ++i) {
      T(i, 1) = c * S(i, 1) - sn * S(i, 2);
      T(i, 2) = sn * S(i, 1) + c * S(i, 2);
    }
    session.set_targets(T);
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
    if (deg % 90 != 0) continue;
    ASSERT_TRUE(session.wait_until_resting(300)) << deg;
    const auto f = session.latest_frame();
    EXPECT_TRUE(f->certified) << deg << " degrees: " << f->status;
    EXPECT_EQ((f->targets - T).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_LT(f->max_handle_error, 0.02) << deg << " degrees: " << f->status;
  }
  std::lock_guard<std::mutex> lk(rec.m);
  for (const auto& fr : rec.frames) {
    if (fr->mesh_V.rows() > 0 && fr->state != SessionState::kPreparing) {
      EXPECT_TRUE(fr->certified) << "frame " << fr->serial;
    }
  }
  EXPECT_TRUE(rec.errors.empty());
}

TEST(DeformSlow, StudioEngineFollowsADragAroundAFullTurn) {
  DeformParams p = small_params();
  p.samples = 2000;
  p.reduced_dof = 40;
  // The paper's grid: on the mesh domain (the default) this small subspace (40 DOF per coordinate) is blocked
  // by the certificate at 270° (max handle error 0.27; measured 2026-11-23) — the surface layer the grid
  // leaves out is where the twist folds first. The mesh-domain drag runs below, at the studio's preset.
  p.domain = DomainKind::kVoxels;
  drag_around_a_full_turn(p);
}

TEST(DeformSlow, StudioEngineFollowsAFullTurnOnTheWholeMeshAtTheInteractivePreset) {
  // The studio's interactive preset (100 DOF per coordinate, 10,000 samples) on the default domain: the whole
  // mesh and its solid certified in every frame, the end dragged around a full turn.
  DeformParams p;
  p.reduced_dof = 100;
  p.samples = 10000;
  p.max_iterations = 30;
  ASSERT_EQ(p.domain, DomainKind::kMesh);
  drag_around_a_full_turn(p);
}

TEST(InteractiveSession, BadInputThrowsAndKeepsTheSession) {
  Recorder rec;
  InteractiveSession session(rec.frame_cb(), rec.error_cb());
  session.open_model(project_data() + "/models/beam", small_params());
  ASSERT_TRUE(session.wait_until_resting(300));
  const auto before = session.latest_frame();
  TempDir dir;
  const std::string bad = dir.str() + "/bad.json";
  write_text(bad, "{\"model\": \"beam\", \"handles\": [ {\"source\": [0,0,0], \"target\": [0,0]} ]}");
  const std::string msg = input_error_message([&] { session.open_scenario(bad); });
  EXPECT_NE(msg.find("bad.json"), std::string::npos) << msg;
  EXPECT_THROW(session.open_model(dir.str() + "/no_such_model"), InputError);
  // A handle outside the cage is refused before anything is queued.
  MatX3d S(1, 3), T(1, 3);
  S << 5, 0, 0;
  T = S;
  const std::string out = input_error_message([&] { session.set_handles(S, T); });
  EXPECT_NE(out.find("outside the cage"), std::string::npos) << out;
  EXPECT_NE(session.check_source(Vec3(5, 0, 0)), "");
  EXPECT_EQ(session.check_source(Vec3(0, 0, 0)), "");
  ASSERT_TRUE(session.wait_until_resting(60));
  EXPECT_EQ(session.latest_frame()->model_version, before->model_version);
  EXPECT_EQ(session.model()->dir, before->model->dir);
  // Mismatched target count.
  MatX3d T2(3, 3);
  T2.setZero();
  EXPECT_THROW(session.set_targets(T2), InputError);
}

TEST(InteractiveSession, StopInterruptsAndKeepsACertifiedMap) {
  Recorder rec;
  InteractiveSession session(rec.frame_cb(), rec.error_cb());
  DeformParams p = small_params();
  p.max_iterations = 1000;
  session.open_model(project_data() + "/models/beam", p);
  // Prepared first: reopened from the precomputation cache the preparation may take only milliseconds, and
  // the stop below must interrupt iterations, not the preparation.
  ASSERT_TRUE(session.wait_until_resting(300));
  MatX3d S, T;
  // Far beyond what a certified map reaches quickly: the center of the end face pulled 3 away from its four
  // corners (pulling the whole end face is a shear, which one Newton step reaches).
  beam_handles(S, T, 0.0);
  T(9, 1) += 3.0;
  session.set_handles(S, T);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  session.stop();
  ASSERT_TRUE(session.wait_until_resting(60));
  const auto f = session.latest_frame();
  EXPECT_EQ(f->state, SessionState::kResting);
  EXPECT_TRUE(f->certified);
  EXPECT_GT(f->max_handle_error, 0.1)  // stopped long before reaching the target
      << f->status << "; " << f->history.size() << " iterations";
  // solve() continues from there.
  const size_t n = f->history.size();
  session.solve();
  // Until at least one more iteration (or a minute), then stop.
  for (int k = 0; k < 6000 && session.latest_frame()->history.size() <= n; ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  session.stop();
  ASSERT_TRUE(session.wait_until_resting(60));
  EXPECT_GT(session.latest_frame()->history.size(), n);
}

TEST(InteractiveSession, ScenarioWithStudioSettingsRoundTrips) {
  TempDir dir;
  Scenario s = read_scenario(project_data() + "/scenarios/beam_bend.json");
  s.studio = R"({"camera": {"position": [1, 2, 3], "focal_point": [0, 0, 0]}, "view": "mesh"})";
  s.model = "";  // written as the resolved folder
  const std::string path = dir.str() + "/session.json";
  write_scenario(path, s);
  const Scenario r = read_scenario(path);
  EXPECT_EQ(nlohmann::json::parse(r.studio), nlohmann::json::parse(s.studio));
  EXPECT_EQ(r.sources, s.sources);
  EXPECT_EQ(r.targets, s.targets);
  write_text(dir.str() + "/bad_studio.json",
             "{\"model\": \"" + s.model_dir +
                 "\", \"handles\": [{\"source\": [0,0,0], \"target\": [0,0,0]}], "
                 "\"studio\": 3}");
  const std::string msg = input_error_message([&] { read_scenario(dir.str() + "/bad_studio.json"); });
  EXPECT_NE(msg.find("\"studio\" must be a JSON object"), std::string::npos) << msg;
  // The session the engine reports is a scenario that `lidef deform` reads.
  InteractiveSession session({}, {});
  session.open_scenario(path);
  Scenario back = session.scenario();
  back.studio = s.studio;
  write_scenario(dir.str() + "/again.json", back);
  EXPECT_EQ(read_scenario(dir.str() + "/again.json").sources, s.sources);
}

}  // namespace
}  // namespace lidef
