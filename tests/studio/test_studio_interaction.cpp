// Scripted interaction with the real window: mouse events go through the VTK interactor exactly as Qt
// delivers them (click on the mesh adds a handle, dragging the cyan sphere moves its target, right-click
// deletes), and the shown map must be certified with the handle moved. Also undo/redo, bad files, saved
// sessions.
#include <gtest/gtest.h>
#include <vtkCamera.h>
#include <vtkCommand.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkRendererCollection.h>

#include <QApplication>
#include <QProgressBar>
#include <QPushButton>
#include <QStatusBar>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <thread>

#include "lidef/scenario.h"
#include "studio_window.h"
#include "test_support.h"

namespace {
using namespace lidef;
using namespace lidef::test;
using lidef::studio::StudioWindow;

bool pump_until(const std::function<bool()>& cond, double seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < seconds) {
    QApplication::processEvents(QEventLoop::AllEvents, 20);
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return cond();
}

// The engine rests and the window shows its newest frame.
bool settled(StudioWindow& w, double seconds = 120) {
  return pump_until(
      [&] {
        if (!w.session().wait_until_resting(0.0)) return false;
        const auto f = w.session().latest_frame();
        const auto s = w.shown_frame();
        return f && s && f->serial == s->serial && f->mesh_V.rows() > 0;
      },
      seconds);
}

void display_of(StudioWindow& w, const Vec3& p, double xy[2]) {
  vtkRenderer* r = w.render_window()->GetRenderers()->GetFirstRenderer();
  r->SetWorldPoint(p.x(), p.y(), p.z(), 1.0);
  r->WorldToDisplay();
  xy[0] = r->GetDisplayPoint()[0];
  xy[1] = r->GetDisplayPoint()[1];
}

void mouse(StudioWindow& w, unsigned long event, double x, double y) {
  vtkRenderWindowInteractor* iren = w.render_window()->GetInteractor();
  iren->SetEventInformation(static_cast<int>(x), static_cast<int>(y), 0, 0, 0, 0);
  iren->InvokeEvent(event, nullptr);
  QApplication::processEvents();
}

DeformParams small_params() {
  DeformParams p;
  p.reduced_dof = 60;
  p.samples = 4000;
  return p;
}

struct Fixture {
  StudioWindow win;
  std::vector<std::string> errors;
  Fixture() {
    win.set_error_sink([this](const std::string& e) { errors.push_back(e); });
    win.resize(1100, 750);
    win.show();
    pump_until([] { return false; }, 0.3);
    win.set_params(small_params());
  }
};

TEST(StudioInteraction, AddDragDeleteUndoRedo) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win)) << "no frame";
  ASSERT_TRUE(fx.errors.empty()) << fx.errors.front();
  EXPECT_TRUE(win.shown_frame()->certified);
  win.render_window()->Render();

  // Two clicks on the beam's top face (+z, facing the camera), near both ends: two handles.
  const Vec3 a(-0.8, 0.0, 0.2), b(0.8, 0.0, 0.2);
  double xy[2];
  display_of(win, a, xy);
  mouse(win, vtkCommand::LeftButtonPressEvent, xy[0], xy[1]);
  mouse(win, vtkCommand::LeftButtonReleaseEvent, xy[0], xy[1]);
  ASSERT_EQ(win.num_handles(), 1) << win.caption();
  EXPECT_LT((win.sources().row(0).transpose() - a).norm(), 0.05);
  display_of(win, b, xy);
  mouse(win, vtkCommand::LeftButtonPressEvent, xy[0], xy[1]);
  mouse(win, vtkCommand::LeftButtonReleaseEvent, xy[0], xy[1]);
  ASSERT_EQ(win.num_handles(), 2);
  // A click off the model adds nothing.
  mouse(win, vtkCommand::LeftButtonPressEvent, 3, 3);
  mouse(win, vtkCommand::LeftButtonReleaseEvent, 3, 3);
  EXPECT_EQ(win.num_handles(), 2);
  ASSERT_TRUE(settled(win));
  const MatX3d targets0 = win.targets();
  const Vec3 image0 = win.shown_frame()->images.row(1).transpose();

  // Drag the second target sphere 90 pixels up on the screen, in steps, like a mouse.
  win.render_window()->Render();
  ASSERT_TRUE(win.target_display_position(1, xy));
  mouse(win, vtkCommand::MouseMoveEvent, xy[0], xy[1]);
  mouse(win, vtkCommand::LeftButtonPressEvent, xy[0], xy[1]);
  for (int k = 1; k <= 9; ++k) {
    mouse(win, vtkCommand::MouseMoveEvent, xy[0], xy[1] + 10 * k);
    pump_until([] { return false; }, 0.03);
  }
  mouse(win, vtkCommand::LeftButtonReleaseEvent, xy[0], xy[1] + 90);
  const Vec3 moved = win.targets().row(1).transpose();
  EXPECT_GT((moved - targets0.row(1).transpose()).norm(), 0.1) << "the drag did not move the target";
  EXPECT_EQ(win.targets().row(0), targets0.row(0));
  ASSERT_TRUE(settled(win));
  const auto f = win.shown_frame();
  EXPECT_TRUE(f->certified);
  EXPECT_GT(f->min_lower_bound, 0);
  const Vec3 image1 = f->images.row(1).transpose();
  EXPECT_GT((image1 - image0).norm(), 0.1) << "the handle's image did not move";
  EXPECT_LT((image1 - moved).norm(), 0.02) << f->status;
  EXPECT_TRUE(fx.errors.empty());

  // Undo restores the target, redo brings the drag back.
  win.undo();
  EXPECT_EQ(win.targets(), targets0);
  win.redo();
  EXPECT_EQ(win.targets().row(1).transpose(), moved);

  // Right-click on the first target deletes that handle (and is not a zoom).
  win.render_window()->Render();
  ASSERT_TRUE(win.target_display_position(0, xy));
  mouse(win, vtkCommand::RightButtonPressEvent, xy[0], xy[1]);
  mouse(win, vtkCommand::RightButtonReleaseEvent, xy[0], xy[1]);
  ASSERT_EQ(win.num_handles(), 1);
  EXPECT_EQ(win.targets().row(0).transpose(), moved);
  ASSERT_TRUE(settled(win));
  EXPECT_TRUE(win.shown_frame()->certified);
  win.undo();
  EXPECT_EQ(win.num_handles(), 2);
}

TEST(StudioInteraction, BadFilesShowTheLoaderMessageAndKeepTheSession) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/scenarios/beam_bend.json"));
  ASSERT_TRUE(settled(win));
  const long version = win.shown_frame()->model_version;
  const int handles = win.num_handles();
  TempDir dir;
  write_text(dir / "broken.json", "{\"model\": \"beam\", \"handles\": [ {\"source\": [0,0,0]");
  EXPECT_FALSE(win.open_path(dir / "broken.json"));
  ASSERT_EQ(fx.errors.size(), 1u);
  EXPECT_NE(fx.errors[0].find("broken.json"), std::string::npos) << fx.errors[0];
  std::filesystem::create_directories(dir / "not_a_model");
  write_text(dir / "not_a_model/cage.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");  // open, no mesh.obj
  EXPECT_FALSE(win.open_path(dir / "not_a_model"));
  ASSERT_EQ(fx.errors.size(), 2u);
  EXPECT_NE(fx.errors[1].find("not_a_model"), std::string::npos) << fx.errors[1];
  // Still the same session, and still responsive.
  ASSERT_TRUE(settled(win));
  EXPECT_EQ(win.shown_frame()->model_version, version);
  EXPECT_EQ(win.num_handles(), handles);
  EXPECT_TRUE(win.shown_frame()->certified);
}

TEST(StudioInteraction, SavedSessionReopensWithHandlesCameraAndView) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/scenarios/beam_bend.json"));
  ASSERT_TRUE(settled(win));
  vtkCamera* cam = win.render_window()->GetRenderers()->GetFirstRenderer()->GetActiveCamera();
  cam->Azimuth(40);
  auto s = win.settings();
  s.view = lidef::studio::View::kOctree;
  s.min_depth = 1;
  win.set_settings(s);
  const Vec3 pos(cam->GetPosition());
  TempDir dir;
  ASSERT_TRUE(win.save_session(dir / "session.json")) << (fx.errors.empty() ? "" : fx.errors.back());
  // `lidef deform` reads it (the "studio" object is part of the scenario format).
  const Scenario sc = read_scenario(dir / "session.json");
  EXPECT_EQ(sc.sources.rows(), win.num_handles());
  const auto j = nlohmann::json::parse(sc.studio);
  EXPECT_EQ(j.at("views").at("view"), "octree");
  // Reopen in a fresh window: handles, view settings and camera come back.
  Fixture fx2;
  ASSERT_TRUE(fx2.win.open_path(dir / "session.json"));
  ASSERT_TRUE(settled(fx2.win));
  EXPECT_EQ(fx2.win.sources(), win.sources());
  EXPECT_EQ(fx2.win.targets(), win.targets());
  EXPECT_EQ(fx2.win.settings().view, lidef::studio::View::kOctree);
  EXPECT_EQ(fx2.win.settings().min_depth, 1);
  vtkCamera* cam2 = fx2.win.render_window()->GetRenderers()->GetFirstRenderer()->GetActiveCamera();
  EXPECT_LT((Vec3(cam2->GetPosition()) - pos).norm(), 1e-9);
  EXPECT_TRUE(fx2.errors.empty());
}

// A mesh file opens like a model folder: its automatic cage is made once (with a progress dialog) and reused
// from the cache the next time; a scenario whose "model" is a mesh file opens the same way (issue 17).
TEST(StudioInteraction, MeshFileOpensWithAnAutomaticCage) {
  TempDir cache, dir;
  ::setenv("LIDEF_CACHE_DIR", cache.str().c_str(), 1);
  std::filesystem::copy_file(project_data() + "/models/ball/mesh.obj", dir / "ball.obj");
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(dir / "ball.obj")) << (fx.errors.empty() ? "" : fx.errors.back());
  ASSERT_TRUE(settled(win)) << "no frame";
  EXPECT_TRUE(win.shown_frame()->certified);
  EXPECT_EQ(win.shown_frame()->mesh_V.rows(), 2562);  // the file's vertices, unchanged
  EXPECT_EQ(win.model_note().find("reused"), std::string::npos) << win.model_note();
  EXPECT_FALSE(win.model_note().empty());
  // Opened again: the cached cage.
  ASSERT_TRUE(win.open_path(dir / "ball.obj"));
  EXPECT_NE(win.model_note().find("reused cached cage"), std::string::npos) << win.model_note();
  ASSERT_TRUE(settled(win));
  // A scenario naming the mesh file: one handle at the center pulled a little.
  {
    std::ofstream out(dir / "pull.json");
    out << R"({"model": ")" << (dir / "ball.obj") << R"(",
  "handles": [{"source": [0, 0, 0], "target": [0.02, 0, 0]}],
  "parameters": {"reduced_dof": 60, "samples": 4000}})";
  }
  ASSERT_TRUE(win.open_path(dir / "pull.json")) << (fx.errors.empty() ? "" : fx.errors.back());
  ASSERT_TRUE(settled(win));
  EXPECT_EQ(win.num_handles(), 1);
  EXPECT_TRUE(win.shown_frame()->certified);
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
  ::unsetenv("LIDEF_CACHE_DIR");
}

}  // namespace

namespace {

// Opening shows the model at rest at once with a progress bar and Cancel; Cancel stops the preprocessing and
// the window returns to the model before (here: none).
TEST(StudioInteraction, PreprocessingShowsProgressAndCancelReturnsToACleanState) {
  Fixture fx;
  StudioWindow& win = fx.win;
  win.session().set_cache("");  // every opening computes: there is a preprocessing to watch and cancel
  DeformParams p;               // the defaults: several seconds of preprocessing
  win.set_params(p);
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  QProgressBar* bar = nullptr;
  QPushButton* cancel = nullptr;
  for (QPushButton* b : win.findChildren<QPushButton*>())
    if (b->text() == "Cancel") cancel = b;
  bar = win.statusBar()->findChild<QProgressBar*>();
  ASSERT_TRUE(cancel && bar);
  ASSERT_TRUE(pump_until(
      [&] {
        const auto s = win.shown_frame();
        return s && s->state == SessionState::kPreparing && s->progress > 0.05;
      },
      120));
  // The rest mesh is on screen while preparing, with the stage on the bar.
  EXPECT_GT(win.shown_frame()->mesh_V.rows(), 0);
  EXPECT_TRUE(bar->isVisible());
  EXPECT_TRUE(cancel->isVisible());
  EXPECT_FALSE(bar->format().isEmpty());
  cancel->click();
  ASSERT_TRUE(pump_until(
      [&] {
        const auto s = win.shown_frame();
        return win.session().wait_until_resting(0.0) && s && s->state != SessionState::kPreparing &&
               s->serial == win.session().latest_frame()->serial;
      },
      120));
  EXPECT_EQ(win.session().state(), SessionState::kEmpty);
  EXPECT_FALSE(win.session().model());
  EXPECT_NE(win.shown_frame()->status.find("cancelled"), std::string::npos) << win.shown_frame()->status;
  EXPECT_FALSE(bar->isVisible());
  EXPECT_FALSE(cancel->isVisible());
  EXPECT_TRUE(fx.errors.empty());  // a cancel is not an error
}

}  // namespace
