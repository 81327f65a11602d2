// What the window shows about the map on screen and around it: picked values that follow the map (and their
// marker), unreached handles and stop reasons in words, progress and Stop for long waits, the screenshot at a
// fixed size, the colour-range panel, and the View menu (panels, up axis, orientation axes, mesh edges),
// recent files and the tool bar.
#include <gtest/gtest.h>
#include <vtkDataArray.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPNGReader.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>

#include <QAction>
#include <QCheckBox>
#include <QComboBox>
#include <QDockWidget>
#include <QLabel>
#include <QMenu>
#include <QMenuBar>
#include <QProgressBar>
#include <QPushButton>
#include <QSettings>
#include <QStatusBar>
#include <QToolBar>
#include <QWheelEvent>
#include <array>
#include <atomic>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>

#include "lidef/analysis/interactive_session.h"
#include "lidef/number_format.h"
#include "pick.h"
#include "studio_common.h"
#include "studio_fixture.h"
#include "test_support.h"

namespace {
using namespace lidef;
using namespace lidef::test;
using lidef::studio::StudioWindow;

void open_beam_with_two_handles(Fixture& fx, double lift) {
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  ASSERT_TRUE(win.add_handle(Vec3(-0.8, 0.0, 0.1)));
  ASSERT_TRUE(win.add_handle(Vec3(0.8, 0.0, 0.1)));
  win.move_target(1, win.targets().row(1).transpose() + Vec3(0, 0, lift));
  ASSERT_TRUE(settled(win));
}

// A pixel of the window's render (RGB, VTK display coordinates).
std::array<int, 3> pixel(StudioWindow& win, const std::string& png, double x, double y) {
  EXPECT_TRUE(win.save_screenshot(png));
  vtkNew<vtkPNGReader> r;
  r->SetFileName(png.c_str());
  r->Update();
  const auto* p = static_cast<unsigned char*>(
      r->GetOutput()->GetScalarPointer(static_cast<int>(x), static_cast<int>(y), 0));
  return {p[0], p[1], p[2]};
}

TEST(StudioView, PickedValuesFollowTheMapAndAreMarked) {
  Fixture fx;
  StudioWindow& win = fx.win;
  open_beam_with_two_handles(fx, 0.4);
  win.set_hover(false);  // the scripted pointer must not replace the pick
  win.render_window()->Render();
  // Pick the image of a top-face point between the handles.
  const Vec3 rest(0.0, 0.0, win.shown_frame()->model->mesh.V.col(2).maxCoeff());
  const Vec3 image = studio::picked_values(*win.shown_frame(), rest, "").image;
  double xy[2];
  display_of(win, image, xy);
  ASSERT_TRUE(win.pick_at_display(static_cast<int>(xy[0]), static_cast<int>(xy[1])));
  const studio::PickedValues first = win.picked();
  ASSERT_TRUE(first.valid);
  // The marker: an orange sphere at f(p).
  pump_until([] { return false; }, 0.2);
  TempDir dir;
  display_of(win, first.image, xy);
  const auto c = pixel(win, dir / "a.png", xy[0], xy[1]);
  EXPECT_GT(c[0], 150) << c[0] << " " << c[1] << " " << c[2];
  EXPECT_GT(c[0], c[1] + 40);
  EXPECT_GT(c[1], c[2] + 40);
  // The map changes: the values are those of the new map at the same rest point.
  const long version = win.shown_frame()->map_version;
  win.move_target(1, win.targets().row(1).transpose() + Vec3(0, 0, 0.4));
  ASSERT_TRUE(settled(win));
  ASSERT_NE(win.shown_frame()->map_version, version);
  const studio::PickedValues now = win.picked();
  ASSERT_TRUE(now.valid);
  EXPECT_EQ(now.rest, first.rest);
  EXPECT_GT((now.image - first.image).norm(), 1e-3) << "the values did not follow the map";
  const studio::PickedValues fresh = studio::picked_values(*win.shown_frame(), first.rest, "");
  EXPECT_EQ(now.image, fresh.image);
  EXPECT_EQ(now.sigma3, fresh.sigma3);
  EXPECT_EQ(now.det_j, fresh.det_j);
  EXPECT_EQ(now.e_iso, fresh.e_iso);
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

TEST(StudioView, UnreachedHandlesMarkedAndStopReasonsInWords) {
  Fixture fx;
  StudioWindow& win = fx.win;
  open_beam_with_two_handles(fx, 0.2);
  EXPECT_EQ(win.unreached_handles(), 0) << win.shown_frame()->status;
  // A target 3 beam heights up, stopped at once: the image is far from it.
  win.move_target(1, win.targets().row(1).transpose() + Vec3(0, 0, 3.0));
  win.session().stop();
  ASSERT_TRUE(settled(win));
  const auto f = win.shown_frame();
  const double scale = 0.5 * (f->model->cage.bbox_max - f->model->cage.bbox_min).maxCoeff();
  int missing = 0;
  for (Eigen::Index i = 0; i < f->targets.rows(); ++i)
    missing += (f->images.row(i) - f->targets.row(i)).norm() > small_params().handle_tolerance * scale;
  ASSERT_GT(missing, 0) << "the handle reached its target: nothing to mark";
  EXPECT_EQ(win.unreached_handles(), missing);
  // The whole status line (cut by the badge on a narrow window) is its tooltip, with the unreached count.
  auto* status = win.statusBar()->findChild<QLabel*>("status");
  ASSERT_NE(status, nullptr);
  EXPECT_EQ(status->toolTip(), status->text());
  EXPECT_NE(status->toolTip().toStdString().find("not at the target"), std::string::npos)
      << status->toolTip().toStdString();
  // The engine's stop reasons in words.
  EXPECT_EQ(studio::stop_reason_in_words("targets_unreachable: residual 0.2 > 0.001")
                .rfind("targets unreachable (proven", 0),
            0u);
  EXPECT_NE(studio::stop_reason_in_words("blocked_by_certificate: x").find("blocked by the certificate"),
            std::string::npos);
  EXPECT_EQ(studio::stop_reason_in_words("stopped"), "stopped");
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

// A solver iteration with no frame for a while: busy bar and Stop; gone when the engine rests.
TEST(StudioView, LongIterationShowsStop) {
  Fixture fx;
  StudioWindow& win = fx.win;
  auto* bar = win.statusBar()->findChild<QProgressBar*>("wait_bar");
  auto* stop = win.statusBar()->findChild<QPushButton*>("wait_stop");
  ASSERT_TRUE(bar && stop);
  win.update_long_wait(SessionState::kIterating, 0.5);
  EXPECT_FALSE(bar->isVisible());
  win.update_long_wait(SessionState::kIterating, 3.2);
  EXPECT_TRUE(bar->isVisible());
  EXPECT_TRUE(stop->isVisible());
  EXPECT_NE(bar->format().toStdString().find("3 s"), std::string::npos) << bar->format().toStdString();
  win.update_long_wait(SessionState::kResting, 3.2);
  EXPECT_FALSE(bar->isVisible());
  EXPECT_FALSE(stop->isVisible());
}

// Verify certificate reports its progress in frames and stops at a cancel (the engine the window drives;
// the cancel lands from the frame callback, on the engine thread, at the first progress frame).
TEST(StudioView, VerificationReportsProgressAndCancels) {
  for (const bool cancel : {false, true}) {
    SCOPED_TRACE(cancel ? "cancelled" : "complete");
    std::mutex m;
    std::vector<double> progress;
    InteractiveSession* self = nullptr;
    InteractiveSession session([&](std::shared_ptr<const SessionFrame> f) {
      if (f->state == SessionState::kPreparing || f->progress < 0) return;
      std::lock_guard<std::mutex> lk(m);
      progress.push_back(f->progress);
      if (cancel && f->stage.rfind("verifying the certificate", 0) == 0) self->cancel_preparation();
    });
    self = &session;
    session.open_model(project_data() + "/models/beam", small_params());
    ASSERT_TRUE(session.wait_until_resting(300));
    session.verify(8);
    ASSERT_TRUE(session.wait_until_resting(300));
    const auto f = session.latest_frame();
    std::lock_guard<std::mutex> lk(m);
    ASSERT_GE(progress.size(), 2u) << "no progress frames";
    for (size_t i = 1; i < progress.size(); ++i) EXPECT_GE(progress[i], progress[i - 1]);
    EXPECT_LT(f->progress, 0);  // the last frame is final
    if (cancel) {
      EXPECT_FALSE(f->verification);
      EXPECT_EQ(f->status, "verification cancelled");
    } else {
      ASSERT_TRUE(f->verification && f->leaves);
      EXPECT_EQ(f->verification_version, f->map_version);
      EXPECT_EQ(f->verification->voxels.size(), f->leaves->leaves.size());
      EXPECT_EQ(f->verification->points, static_cast<long>(f->leaves->leaves.size()) * (9 + 8));
      for (size_t i = 0; i < f->verification->voxels.size(); ++i)
        ASSERT_EQ(f->verification->voxels[i].leaf, static_cast<long>(i));
      EXPECT_EQ(f->verification->nonpositive_in_certified, 0);
      EXPECT_EQ(f->verification->violations, 0);
    }
  }
}

TEST(StudioView, ScreenshotAt1920x1080RestoresTheWindow) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  pump_until([] { return false; }, 0.2);
  const QSize window = win.size(), view = win.view_widget()->size();
  const QRect geometry = win.geometry();
  auto* plots = win.findChild<QDockWidget*>("Plots");
  const QSize plots_size = plots->size();
  TempDir dir;
  ASSERT_TRUE(win.save_screenshot(dir / "big.png", 1920, 1080));
  pump_until([] { return false; }, 0.3);
  vtkNew<vtkPNGReader> r;
  r->SetFileName((dir / "big.png").c_str());
  r->Update();
  int dims[3];
  r->GetOutput()->GetDimensions(dims);
  EXPECT_EQ(dims[0], 1920);
  EXPECT_EQ(dims[1], 1080);
  auto text = [](const QRect& r) {
    return std::to_string(r.x()) + "," + std::to_string(r.y()) + " " + std::to_string(r.width()) + "x" +
           std::to_string(r.height());
  };
  EXPECT_EQ(text(win.geometry()), text(geometry));
  EXPECT_EQ(text(QRect(QPoint(0, 0), win.view_widget()->size())), text(QRect(QPoint(0, 0), view)));
  EXPECT_EQ(text(QRect(QPoint(0, 0), plots->size())), text(QRect(QPoint(0, 0), plots_size)));
  EXPECT_EQ(win.size(), window);
}

TEST(StudioView, ColourRangeShowsItsRangeAndIgnoresAStrayWheel) {
  Fixture fx;
  StudioWindow& win = fx.win;
  open_beam_with_two_handles(fx, 1.0);
  pump_until([] { return false; }, 0.3);
  auto* used = win.findChild<QLabel*>("range_used");
  ASSERT_NE(used, nullptr);
  const auto r = win.shown_color_range();
  EXPECT_EQ(used->text().toStdString(), "[" + format_g(r.first, 4) + ", " + format_g(r.second, 4) + "]");
  // A wheel turn over the mode box, which has no focus, leaves the mode alone.
  auto* mode = win.findChild<QComboBox*>("range_mode");
  ASSERT_NE(mode, nullptr);
  mode->clearFocus();
  const int before = mode->currentIndex();
  for (int delta : {-120, 120, 120}) {
    QWheelEvent wheel(QPointF(5, 5), mode->mapToGlobal(QPoint(5, 5)), QPoint(0, delta), QPoint(0, delta),
                      Qt::NoButton, Qt::NoModifier, Qt::NoScrollPhase, false);
    QApplication::sendEvent(mode, &wheel);
  }
  EXPECT_EQ(mode->currentIndex(), before);
  EXPECT_EQ(win.settings().range[0].mode, studio::ViewSettings{}.range[0].mode);
}

TEST(StudioView, ViewMenuUpAxisAxesEdgesRecentAndToolbar) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  // View menu: a closed panel comes back.
  auto* view_menu = win.findChild<QMenu*>("view_menu");
  ASSERT_NE(view_menu, nullptr);
  auto* plots = win.findChild<QDockWidget*>("Plots");
  plots->close();
  pump_until([] { return false; }, 0.1);
  ASSERT_FALSE(plots->isVisible());
  QAction* toggle = nullptr;
  for (QAction* a : view_menu->actions())
    if (a == plots->toggleViewAction()) toggle = a;
  ASSERT_NE(toggle, nullptr);
  toggle->trigger();
  pump_until([] { return false; }, 0.1);
  EXPECT_TRUE(plots->isVisible());
  // Up axis: z up, the camera's up vector is mostly +z (three-quarter view), and it is kept.
  win.set_up_axis(2);
  const auto cam = nlohmann::json::parse(win.camera_json()).at("camera");
  EXPECT_GT(cam.at("view_up")[2].get<double>(), 0.9);
  EXPECT_EQ(QSettings().value("view/up_axis").toInt(), 2);
  win.set_up_axis(1);
  EXPECT_GT(nlohmann::json::parse(win.camera_json()).at("camera").at("view_up")[1].get<double>(), 0.9);
  // Orientation axes: on, and off from the menu.
  EXPECT_TRUE(win.orientation_axes());
  win.findChild<QAction*>("orientation_axes")->trigger();
  EXPECT_FALSE(win.orientation_axes());
  // Mesh edges: the menu, the view settings and the saved session agree.
  win.findChild<QAction*>("mesh_edges")->trigger();
  EXPECT_TRUE(win.settings().mesh_edges);
  EXPECT_TRUE(studio::settings_to_json(win.settings()).at("mesh_edges").get<bool>());
  // Recent files: the newest first.
  const QStringList recent = win.recent_files();
  ASSERT_FALSE(recent.isEmpty());
  EXPECT_EQ(recent.front().toStdString(),
            std::filesystem::absolute(project_data() + "/models/beam").lexically_normal().string());
  // Open mesh is on the tool bar.
  auto* tb = win.findChild<QToolBar*>("Main");
  ASSERT_NE(tb, nullptr);
  bool mesh_on_toolbar = false;
  for (QAction* a : tb->actions()) mesh_on_toolbar = mesh_on_toolbar || a->text().contains("esh");
  EXPECT_TRUE(mesh_on_toolbar);
}

}  // namespace

// The distortion view: σ1/σ3 at the mesh vertices equal to the map's at those points (evaluated apart, by the
// pick), never above the certified bound the caption states; the Lipschitz view colours leaves by that bound;
// the σ3 view's slices by σ1/σ3. The setting is saved with the view settings.
TEST(StudioView, DistortionViewShowsSigma1OverSigma3UnderItsCertifiedBound) {
  Fixture fx;
  StudioWindow& win = fx.win;
  open_beam_with_two_handles(fx, 0.6);
  auto* box = win.findChild<QCheckBox*>("view_distortion");
  ASSERT_NE(box, nullptr);
  box->setChecked(true);
  ASSERT_TRUE(win.settings().distortion);
  ASSERT_TRUE(pump_until(
      [&] {
        const auto f = win.shown_frame();
        return settled(win, 0.1) && f->mesh_distortion.size() == f->mesh_V.rows() && f->leaves &&
               f->leaves_version == f->map_version;
      },
      120));
  const auto frame = win.shown_frame();
  ASSERT_TRUE(frame->certified);
  vtkDataArray* shown = win.mesh_data()->GetPointData()->GetScalars();
  ASSERT_NE(shown, nullptr);
  EXPECT_STREQ(shown->GetName(), "sigma1/sigma3");
  const MatX3d& V = frame->model->mesh.V;
  double max_vertex = 0;
  for (Eigen::Index i = 0; i < V.rows(); ++i) max_vertex = std::max(max_vertex, shown->GetTuple1(i));
  EXPECT_GT(max_vertex, 1.01) << "the pulled beam is not conformal";
  for (Eigen::Index i = 0; i < V.rows(); i += std::max<Eigen::Index>(1, V.rows() / 25)) {
    const studio::PickedValues p = studio::picked_values(*frame, V.row(i).transpose(), "");
    EXPECT_NEAR(shown->GetTuple1(i), p.sigma1 / p.sigma3, 1e-9 * p.sigma1 / p.sigma3) << "vertex " << i;
  }
  const double bound = frame->leaves->max_distortion_upper_bound;
  EXPECT_GE(bound, max_vertex) << "the certified bound is below a vertex's distortion";
  // Printed rounded up (format_bound): the 4 digits shown are never below the bound.
  EXPECT_NE(win.caption().find("sigma1/sigma3 <= " + format_bound(bound, true, 4)), std::string::npos)
      << win.caption();
  EXPECT_GE(std::stod(format_bound(bound, true, 4)), bound);

  auto settings = win.settings();
  settings.view = studio::View::kLipschitz;
  win.set_settings(settings);
  ASSERT_TRUE(settled(win));
  pump_until([] { return false; }, 0.2);
  EXPECT_NE(win.caption().find("certified upper bound of sigma1/sigma3"), std::string::npos) << win.caption();
  const auto leaf_range = win.shown_color_range();
  EXPECT_GE(leaf_range.first, 1.0);
  EXPECT_LE(leaf_range.second, bound * (1 + 1e-12));

  settings.view = studio::View::kSigma3;
  win.set_settings(settings);
  ASSERT_TRUE(pump_until(
      [&] {
        const auto f = win.shown_frame();
        return settled(win, 0.1) && f->field && f->field_version == f->map_version;
      },
      120));
  pump_until([] { return false; }, 0.2);
  EXPECT_NE(win.caption().find("distortion sigma1/sigma3"), std::string::npos) << win.caption();
  EXPECT_GE(win.shown_color_range().first, 1.0);

  studio::ViewSettings back;
  studio::settings_from_json(studio::settings_to_json(win.settings()), back, "test");
  EXPECT_TRUE(back.distortion);
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}
