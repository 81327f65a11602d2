// Opening a model while another is on screen: the window shows a model only once the engine holds it, so a
// cancel at any stage of the opening leaves the screen, the handles and every panel on the model before, and
// the badge, caption and plots always name the model they describe. Cancels land at chosen stages through
// test hooks (InteractiveSession::set_stage_hook, StudioWindow::set_cage_line_hook), never by timing.
#include <gtest/gtest.h>

#include <QLabel>
#include <QProgressBar>
#include <QProgressDialog>
#include <QPushButton>
#include <QStatusBar>
#include <QTimer>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>

#include "lidef/analysis/interactive_session.h"
#include "params_panel.h"
#include "plots_panel.h"
#include "studio_fixture.h"
#include "test_support.h"

namespace {
using namespace lidef;
using namespace lidef::test;
using lidef::studio::StudioWindow;

// Holds the engine thread at the first progress point of one stage until the test lets it go.
struct StageGate {
  std::mutex m;
  std::condition_variable cv;
  std::string target;
  bool arrived = false, released = false;
  void hook(const std::string& stage) {
    std::unique_lock<std::mutex> lk(m);
    if (arrived || stage != target) return;
    arrived = true;
    cv.notify_all();
    cv.wait(lk, [&] { return released; });
  }
  bool has_arrived() {
    std::lock_guard<std::mutex> lk(m);
    return arrived;
  }
  void release() {
    {
      std::lock_guard<std::mutex> lk(m);
      released = true;
    }
    cv.notify_all();
  }
};

// The stages an opening of `model_dir` goes through, in order, from a session of its own (no window).
std::vector<std::string> preparation_stages(const std::string& model_dir) {
  std::mutex m;
  std::vector<std::string> stages;
  InteractiveSession s([](std::shared_ptr<const SessionFrame>) {});
  s.set_cache("");
  s.set_stage_hook([&](const std::string& stage) {
    std::lock_guard<std::mutex> lk(m);
    if (stages.empty() || stages.back() != stage) stages.push_back(stage);
  });
  s.open_model(model_dir, small_params());
  EXPECT_TRUE(s.wait_until_resting(300));
  s.set_stage_hook({});
  std::lock_guard<std::mutex> lk(m);
  return stages;
}

QPushButton* cancel_button(StudioWindow& w) {
  return w.statusBar()->findChild<QPushButton*>("prepare_cancel");
}
std::string badge(StudioWindow& w) {
  return w.statusBar()->findChild<QLabel*>("badge")->text().toStdString();
}
// Equal sizes and entries (Eigen's == assumes equal sizes).
bool same(const MatX3d& a, const MatX3d& b) {
  return a.rows() == b.rows() && a == b;
}
bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// What is on screen is the engine's model: the shown frame's, the drawn mesh's, the handles', and the names
// in title, badge, caption and plots.
void expect_one_model(StudioWindow& w, const std::string& name, const std::string& when) {
  SCOPED_TRACE(when);
  const auto engine_model = w.session().solver_model();
  ASSERT_TRUE(engine_model);
  EXPECT_EQ(w.shown_model(), engine_model);
  ASSERT_TRUE(w.shown_frame());
  EXPECT_EQ(w.shown_frame()->model, engine_model);
  EXPECT_EQ(w.drawn_mesh_points(), engine_model->mesh.V.rows());
  EXPECT_EQ(w.shown_frame()->mesh_V.rows(), engine_model->mesh.V.rows());
  const auto latest = w.session().latest_frame();
  EXPECT_TRUE(same(w.sources(), latest->sources));
  EXPECT_TRUE(same(w.targets(), latest->targets));
  EXPECT_EQ(w.shown_name(), name);
  EXPECT_TRUE(has(w.windowTitle().toStdString(), name)) << w.windowTitle().toStdString();
  EXPECT_TRUE(has(badge(w), name)) << badge(w);
  EXPECT_TRUE(has(w.caption(), name)) << w.caption();
  auto* plots = w.findChild<studio::PlotsPanel*>();
  ASSERT_NE(plots, nullptr);
  EXPECT_TRUE(has(plots->history_title().toStdString(), name)) << plots->history_title().toStdString();
  EXPECT_FALSE(w.opening());
  EXPECT_FALSE(cancel_button(w)->isVisible());
}

TEST(StudioOpen, CancelAtEveryStageKeepsScreenAndEngineOnOneModel) {
  Fixture fx;
  StudioWindow& win = fx.win;
  win.session().set_cache("");  // every opening runs every stage
  const std::string ball = project_data() + "/models/ball";
  const std::vector<std::string> stages = preparation_stages(ball);
  ASSERT_GE(stages.size(), 3u) << "too few stages to test";
  // The last point is after the commit ("ready"): a cancel there comes too late.
  ASSERT_EQ(stages.back(), "ready");

  // The model before: the beam with two handles, one pulled.
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  ASSERT_TRUE(win.add_handle(Vec3(-0.8, 0.0, 0.1)));
  ASSERT_TRUE(win.add_handle(Vec3(0.8, 0.0, 0.1)));
  win.move_target(1, win.targets().row(1).transpose() + Vec3(0, 0, 0.5));
  ASSERT_TRUE(settled(win));
  const auto beam = win.session().solver_model();
  const MatX3d sources = win.sources(), targets = win.targets();
  expect_one_model(win, "beam", "before");

  for (const std::string& stage : stages) {
    SCOPED_TRACE("cancel at " + stage);
    // Shared with the hook and released on every way out of this scope, so that a failed assertion never
    // leaves the engine thread waiting (or the hook pointing at a gate that is gone).
    auto gate = std::make_shared<StageGate>();
    gate->target = stage;
    struct Release {
      std::shared_ptr<StageGate> g;
      ~Release() { g->release(); }
    } release{gate};
    win.session().set_stage_hook([gate](const std::string& s) { gate->hook(s); });  // the engine rests
    ASSERT_TRUE(win.open_path(ball));
    ASSERT_TRUE(pump_until([&] { return gate->has_arrived() && win.preparing_frame() != nullptr; }, 120))
        << "the engine never reached the stage";
    // Held at the stage: the beam is still what the window shows, and handle edits wait.
    EXPECT_EQ(win.shown_model(), beam);
    EXPECT_EQ(win.drawn_mesh_points(), beam->mesh.V.rows());
    EXPECT_TRUE(same(win.sources(), sources));
    EXPECT_TRUE(has(badge(win), "beam")) << badge(win);
    EXPECT_FALSE(win.add_handle(Vec3(0, 0, 0.1)));
    ASSERT_TRUE(cancel_button(win)->isVisible());
    cancel_button(win)->click();
    gate->release();
    ASSERT_TRUE(settled(win, 300));
    win.session().set_stage_hook({});
    if (stage != "ready") {
      expect_one_model(win, "beam", "after the cancel");
      EXPECT_EQ(win.shown_model(), beam);
      EXPECT_TRUE(same(win.sources(), sources));
      EXPECT_TRUE(same(win.targets(), targets));
      EXPECT_TRUE(win.shown_frame()->certified);
      EXPECT_TRUE(has(win.shown_frame()->status, "cancelled")) << win.shown_frame()->status;
    } else {
      expect_one_model(win, "ball", "a cancel after the commit");
      EXPECT_EQ(win.num_handles(), 0);
    }
  }
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

// Making a cage: its dialog shows at once, with Cancel; a cancel keeps the model before and leaves no cache
// entry. Then the same file opens (the dialog again), and a saved session names the mesh file, not the cache
// folder its cage lives in.
TEST(StudioOpen, CageDialogShowsCancelsAndSessionsNameTheMeshFile) {
  TempDir cache, dir;
  ::setenv("LIDEF_CACHE_DIR", cache.str().c_str(), 1);
  std::filesystem::copy_file(project_data() + "/models/ball/mesh.obj", dir / "ball.obj");
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  const auto beam = win.session().solver_model();

  // The cage maker's first line waits until the dialog was seen on screen (and, the first time, cancelled).
  for (const bool cancel : {true, false}) {
    SCOPED_TRACE(cancel ? "cancelled" : "made");
    std::promise<void> seen;
    std::future<void> seen_f = seen.get_future();
    bool visible = false;
    int lines = 0;
    win.set_cage_line_hook([&](const std::string&) {
      if (lines++ == 0) seen_f.wait_for(std::chrono::seconds(60));
    });
    QTimer::singleShot(0, &win, [&] {
      auto* dlg = win.findChild<QProgressDialog*>("cage_progress");
      visible = dlg && dlg->isVisible();
      if (dlg && cancel)
        for (QPushButton* b : dlg->findChildren<QPushButton*>())
          if (b->text() == "Cancel") b->click();
      seen.set_value();
    });
    const bool opened = win.open_path(dir / "ball.obj");
    win.set_cage_line_hook({});
    EXPECT_TRUE(visible) << "the cage dialog was not on screen";
    EXPECT_GE(lines, 1);
    if (cancel) {
      EXPECT_FALSE(opened);
      EXPECT_TRUE(has(win.statusBar()->findChild<QLabel*>("status")->text().toStdString(), "cancelled"));
      EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(cache.str()) / "cages") &&
                   !std::filesystem::is_empty(std::filesystem::path(cache.str()) / "cages"))
          << "a cancelled cage left a cache entry";
      ASSERT_TRUE(settled(win));
      EXPECT_EQ(win.session().solver_model(), beam);
      expect_one_model(win, "beam", "cage cancelled");
    } else {
      ASSERT_TRUE(opened) << (fx.errors.empty() ? "" : fx.errors.back());
      ASSERT_TRUE(settled(win));
      expect_one_model(win, "ball.obj", "cage made");
    }
  }
  ASSERT_TRUE(win.add_handle(Vec3(0, 0, 0)));
  ASSERT_TRUE(settled(win));
  ASSERT_TRUE(win.save_session(dir / "s.json"));
  std::ifstream in(dir / "s.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("model").get<std::string>(),
            std::filesystem::absolute(dir / "ball.obj").lexically_normal().string());
  // It reopens (the cage from the cache) with its handle.
  Fixture other;
  ASSERT_TRUE(other.win.open_path(dir / "s.json")) << (other.errors.empty() ? "" : other.errors.back());
  ASSERT_TRUE(settled(other.win));
  EXPECT_EQ(other.win.num_handles(), 1);
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
  ::unsetenv("LIDEF_CACHE_DIR");
}

// Parameters > Defaults, Apply after the Interactive preset rebuilds the solver (a precomputation parameter
// changed) with no handles to iterate: the progress must still end, the engine rest, Cancel go away.
TEST(StudioOpen, ParameterRebuildWithoutHandlesEndsInAFinalState) {
  Fixture fx;
  StudioWindow& win = fx.win;
  auto* params = win.findChild<studio::ParamsPanel*>();
  ASSERT_NE(params, nullptr);
  params->load_interactive_preset();
  ASSERT_TRUE(params->apply());
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  ASSERT_EQ(win.num_handles(), 0);
  const auto before = win.session().solver_model();
  params->load_defaults();
  ASSERT_TRUE(params->apply());
  ASSERT_TRUE(pump_until(
      [&] {
        const auto f = win.session().latest_frame();
        return win.session().wait_until_resting(0.0) && f && f->state != SessionState::kPreparing &&
               win.shown_frame() && win.shown_frame()->serial == f->serial;
      },
      300))
      << "the engine never reached a final state; last status: " << win.session().latest_frame()->status;
  EXPECT_EQ(win.session().state(), SessionState::kResting);
  EXPECT_FALSE(win.preparing_frame());
  EXPECT_FALSE(win.statusBar()->findChild<QProgressBar*>("prepare_bar")->isVisible());
  EXPECT_FALSE(cancel_button(win)->isVisible());
  EXPECT_TRUE(has(win.shown_frame()->status, "parameters applied")) << win.shown_frame()->status;
  EXPECT_EQ(win.session().solver_model(), before);  // the same model, a new solver
  EXPECT_EQ(win.session().scenario().params.reduced_dof, DeformParams{}.reduced_dof);
  expect_one_model(win, "beam", "after the rebuild");
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

}  // namespace
