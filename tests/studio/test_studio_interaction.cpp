// Scripted interaction with the real window: mouse events go through the VTK interactor exactly as Qt
// delivers them (click on the mesh adds a handle, dragging the cyan sphere moves its target, right-click
// deletes), and the shown map must be certified with the handle moved. Also undo/redo, bad files, saved
// sessions.
#include <QVTKOpenGLNativeWidget.h>
#include <gtest/gtest.h>
#include <vtkCamera.h>
#include <vtkCommand.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPNGReader.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkRendererCollection.h>

#include <QAction>
#include <QApplication>
#include <QCheckBox>
#include <QClipboard>
#include <QDockWidget>
#include <QMessageBox>
#include <QProgressBar>
#include <QPushButton>
#include <QStatusBar>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "lidef/analysis/certificate_report.h"
#include "lidef/scenario.h"
#include "studio_fixture.h"
#include "studio_window.h"
#include "test_support.h"

namespace {
using namespace lidef;
using namespace lidef::test;
using lidef::studio::StudioWindow;

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
// from the cache the next time; a scenario whose "model" is a mesh file opens the same way.
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

// ---------------------------------------------------------------- inspect, camera, colour, layout

// The beam with two handles, the second pulled up: a bent map with some E_iso − 6 spread.
void open_bent_beam(Fixture& fx) {
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win)) << "no frame";
  ASSERT_TRUE(win.add_handle(Vec3(-0.8, 0.0, 0.1)));
  ASSERT_TRUE(win.add_handle(Vec3(0.8, 0.0, 0.1)));
  win.move_target(1, win.targets().row(1).transpose() + Vec3(0, 0, 1.0));
  ASSERT_TRUE(settled(win));
  ASSERT_TRUE(win.shown_frame()->certified);
  ASSERT_TRUE(fx.errors.empty()) << fx.errors.front();
}

nlohmann::json camera_of(StudioWindow& w) {
  return nlohmann::json::parse(w.camera_json()).at("camera");
}

TEST(StudioInteraction, CameraPresetsOrthographicAndCopyPasteRoundTrip) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  win.camera_preset(2, true);  // from +z
  auto c = camera_of(win);
  const auto pos = c.at("position").get<std::vector<double>>();
  const auto fp = c.at("focal_point").get<std::vector<double>>();
  EXPECT_NEAR(pos[0], fp[0], 1e-9);
  EXPECT_NEAR(pos[1], fp[1], 1e-9);
  EXPECT_GT(pos[2], fp[2]);
  win.camera_preset(0, false);  // from -x: the camera sits at smaller x
  c = camera_of(win);
  EXPECT_LT(c.at("position")[0].get<double>(), c.at("focal_point")[0].get<double>());
  win.set_orthographic(true);
  EXPECT_TRUE(win.orthographic());
  const nlohmann::json copied = camera_of(win);
  EXPECT_TRUE(copied.at("parallel_projection").get<bool>());
  win.copy_camera();
  EXPECT_EQ(QApplication::clipboard()->text().toStdString(), win.camera_json());

  // Change everything, paste, and the camera is back (numbers exactly: JSON keeps 17 digits).
  win.reset_camera();
  win.set_orthographic(false);
  EXPECT_NE(camera_of(win), copied);
  ASSERT_TRUE(win.paste_camera());
  EXPECT_EQ(camera_of(win), copied);
  EXPECT_TRUE(win.orthographic());

  // Not a camera in the clipboard: refused with a message, the camera unchanged.
  QApplication::clipboard()->setText("{\"camera\": {\"position\": [1, 2]}}");
  EXPECT_FALSE(win.paste_camera());
  ASSERT_FALSE(fx.errors.empty());
  EXPECT_EQ(camera_of(win), copied);
  QApplication::clipboard()->setText("not json");
  EXPECT_FALSE(win.paste_camera());
  EXPECT_EQ(camera_of(win), copied);

  // A saved session keeps the projection.
  TempDir dir;
  ASSERT_TRUE(win.add_handle(Vec3(-0.8, 0.0, 0.1)));
  ASSERT_TRUE(win.save_session(dir / "s.json"));
  Fixture other;
  ASSERT_TRUE(other.win.open_path(dir / "s.json"));
  ASSERT_TRUE(settled(other.win));
  EXPECT_EQ(camera_of(other.win), copied);
}

TEST(StudioInteraction, ColorRangeAutoPercentileManual) {
  Fixture fx;
  StudioWindow& win = fx.win;
  open_bent_beam(fx);
  const auto f = win.shown_frame();
  double e_max = 0;
  for (Eigen::Index i = 0; i < f->mesh_e_iso.size(); ++i)
    if (std::isfinite(f->mesh_e_iso(i))) e_max = std::max(e_max, f->mesh_e_iso(i));
  ASSERT_GT(e_max, 0.05) << "the bent beam must be bent more than the colour floor (0.05)";
  // Default for E_iso − 6: the 99th percentile, below the largest value (the outlier no longer sets it).
  auto r = win.shown_color_range();
  EXPECT_EQ(r.first, 0);
  EXPECT_LT(r.second, e_max);
  EXPECT_GT(r.second, 0);
  using studio::ColorRange;
  using studio::Field;
  auto pump = [&] { pump_until([] { return false; }, 0.3); };
  win.set_color_range(Field::kEiso, {ColorRange::Mode::kAuto, 99, 0, 1});
  pump();
  r = win.shown_color_range();
  EXPECT_EQ(r.first, 0);
  EXPECT_DOUBLE_EQ(r.second, std::max(e_max, 0.05));
  win.set_color_range(Field::kEiso, {ColorRange::Mode::kManual, 99, 0.1, 0.3});
  pump();
  r = win.shown_color_range();
  EXPECT_DOUBLE_EQ(r.first, 0.1);
  EXPECT_DOUBLE_EQ(r.second, 0.3);
  // Manual min above max is refused.
  win.set_color_range(Field::kEiso, {ColorRange::Mode::kManual, 99, 0.5, 0.2});
  EXPECT_FALSE(fx.errors.empty());
  pump();
  EXPECT_DOUBLE_EQ(win.shown_color_range().second, 0.3);
  // det J: symmetric around 1 on a log scale (auto); manual as given.
  studio::ViewSettings s = win.settings();
  s.mesh_volume_ratio = true;
  win.set_settings(s);
  pump();
  r = win.shown_color_range();
  EXPECT_NEAR(r.first * r.second, 1.0, 1e-9);
  // The ranges are part of the saved view settings.
  const nlohmann::json j = studio::settings_to_json(win.settings());
  studio::ViewSettings back;
  studio::settings_from_json(j, back, "test");
  EXPECT_EQ(back.range[0].mode, ColorRange::Mode::kManual);
  EXPECT_EQ(back.range[0].min, 0.1);
  EXPECT_EQ(back.range[0].max, 0.3);
  nlohmann::json bad = j;
  bad["ranges"]["e_iso"]["mode"] = "rainbow";
  EXPECT_THROW(studio::settings_from_json(bad, back, "test"), InputError);
}

// Reads `lidef eval`'s CSV (header + rows of numbers).
std::vector<std::vector<double>> read_eval_csv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) row.push_back(std::stod(cell));
    rows.push_back(row);
  }
  return rows;
}

// Picking: the values at a picked point are what `lidef eval` gives there for the exported map (and the
// export writes what the CLI writes). Mesh view by Ctrl+click through the interactor; Lipschitz view by
// click, with the leaf that holds the point.
TEST(StudioInteraction, PickedValuesEqualLidefEval) {
  Fixture fx;
  StudioWindow& win = fx.win;
  open_bent_beam(fx);
  win.render_window()->Render();
  // Ctrl+click on the image of the centroid of a top-face triangle (+z faces the camera): the rendered
  // triangle is the deformed one, so the centroid of its deformed corners is the image of the rest centroid
  // under the barycentric pull-back.
  const auto f = win.shown_frame();
  const MatX3d& V = f->model->mesh.V;
  const MatX3i& F = f->model->mesh.F;
  const double zmax = V.col(2).maxCoeff();
  Eigen::Index tri = -1;
  Vec3 rest_c = Vec3::Zero(), image_c = Vec3::Zero();
  for (Eigen::Index t = 0; t < F.rows(); ++t) {
    Vec3 c = Vec3::Zero(), ci = Vec3::Zero();
    bool top = true;
    for (int k = 0; k < 3; ++k) {
      top = top && V(F(t, k), 2) > zmax - 1e-9;
      c += V.row(F(t, k)).transpose() / 3;
      ci += f->mesh_V.row(F(t, k)).transpose() / 3;
    }
    if (top && (tri < 0 || (c - Vec3(0.3, 0, zmax)).norm() < (rest_c - Vec3(0.3, 0, zmax)).norm())) {
      tri = t;
      rest_c = c;
      image_c = ci;
    }
  }
  ASSERT_GE(tri, 0);
  double xy[2];
  display_of(win, image_c, xy);
  vtkRenderWindowInteractor* iren = win.render_window()->GetInteractor();
  for (unsigned long ev : {vtkCommand::LeftButtonPressEvent, vtkCommand::LeftButtonReleaseEvent}) {
    iren->SetEventInformation(static_cast<int>(xy[0]), static_cast<int>(xy[1]), 1, 0, 0, 0);
    iren->InvokeEvent(ev, nullptr);
    QApplication::processEvents();
  }
  EXPECT_EQ(win.num_handles(), 2) << "Ctrl+click must pick, not add a handle";
  ASSERT_TRUE(win.picked().valid);
  const studio::PickedValues on_mesh = win.picked();
  EXPECT_LT((on_mesh.rest - rest_c).norm(), 0.02);
  EXPECT_LT((on_mesh.image - image_c).norm(), 0.02);

  // The Lipschitz view: click where a leaf is drawn.
  studio::ViewSettings s = win.settings();
  s.view = studio::View::kLipschitz;
  s.clip = 1.0;
  win.set_settings(s);
  ASSERT_TRUE(pump_until(
      [&] {
        const auto g = win.shown_frame();
        return g && g->leaves && g->leaves_version == g->map_version;
      },
      120));
  win.render_window()->Render();
  const auto g = win.shown_frame();
  display_of(win, Vec3(0.3, 0.0, 0.0), xy);
  ASSERT_TRUE(win.pick_at_display(static_cast<int>(xy[0]), static_cast<int>(xy[1])));
  const studio::PickedValues on_leaf = win.picked();
  ASSERT_TRUE(on_leaf.has_leaf);
  const Vec3 off = (on_leaf.rest - on_leaf.leaf.center).cwiseAbs();
  EXPECT_LE(off.maxCoeff(), 0.5 * on_leaf.leaf.side * (1 + 1e-6)) << "the point is not in its leaf";
  bool found = false;
  for (const CertLeaf& l : g->leaves->leaves)
    found = found ||
            (l.center == on_leaf.leaf.center && l.L == on_leaf.leaf.L && l.margin == on_leaf.leaf.margin);
  EXPECT_TRUE(found) << "the picked leaf is not one of the certificate's";

  // Hover: scripted mouse moves (no button) over another leaf; the throttled pick fills the same panel.
  ASSERT_TRUE(win.hover_enabled());
  auto move_to = [&](const Vec3& p) {
    double m[2];
    display_of(win, p, m);
    iren->SetEventInformation(static_cast<int>(m[0]), static_cast<int>(m[1]), 0, 0, 0, 0);
    iren->InvokeEvent(vtkCommand::MouseMoveEvent, nullptr);
  };
  move_to(Vec3(-0.5, 0.02, 0.0));
  move_to(Vec3(0.6, 0.02, 0.0));  // the newest position is the one picked
  ASSERT_TRUE(pump_until([&] { return win.picked().where.rfind("hover", 0) == 0; }, 5)) << win.picked().where;
  const studio::PickedValues on_hover = win.picked();
  ASSERT_TRUE(on_hover.has_leaf);
  EXPECT_GT(on_hover.rest.x(), 0.3) << "not the newest hover position";
  EXPECT_LE((on_hover.rest - on_hover.leaf.center).cwiseAbs().maxCoeff(),
            0.5 * on_hover.leaf.side * (1 + 1e-6));
  // Turned off (the panel's checkbox), moves no longer change the panel.
  auto* hover_box = win.findChild<QCheckBox*>("hover");
  ASSERT_NE(hover_box, nullptr);
  hover_box->setChecked(false);
  EXPECT_FALSE(win.hover_enabled());
  move_to(Vec3(-0.3, 0.02, 0.0));
  pump_until([] { return false; }, 0.3);
  EXPECT_EQ(win.picked().rest, on_hover.rest) << "hover is off";

  // Export the map as the CLI writes it, and evaluate both points with lidef eval.
  TempDir dir;
  ASSERT_TRUE(win.export_current(dir / "export"));
  for (const char* name :
       {"coefficients.txt", "deformed.vtp", "leaves.vtu", "certificate.json", "voxels.csv"})
    EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(dir / "export") / name)) << name;
  // The exported certificate is what lidef deform writes for its map (the solver's certificate of it, the
  // same writers). lidef certify of the exported coefficients (same sampling and certifier parameters) must
  // agree: the same voxels, leaves and verdicts. The numbers differ slightly because deform's solver
  // certifies from the reduced coordinates (certify_reduced) and certify from the full coefficients (measured
  // here: σ3 at the centers within 1.3e-7, L within 2.3e-6 relative); both L are upper bounds of the same
  // map's constant.
  {
    std::string clog;
    ASSERT_EQ(
        run_command(cli() + " certify " + project_data() + "/models/beam --coeffs " +
                        (dir / "export/coefficients.txt") + " --samples 4000 --grid 0 --out " + (dir / "cli"),
                    &clog),
        0)
        << clog;
    const auto a = read_voxels_csv(dir / "export/voxels.csv"), b = read_voxels_csv(dir / "cli/voxels.csv");
    ASSERT_EQ(a.size(), b.size());
    ASSERT_GT(a.size(), 1000u);
    double worst_l = 0, worst_s = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      ASSERT_EQ(a[i].center, b[i].center) << "leaf " << i;
      ASSERT_EQ(a[i].side, b[i].side) << "leaf " << i;
      ASSERT_EQ(a[i].depth, b[i].depth) << "leaf " << i;
      ASSERT_EQ(a[i].certified, b[i].certified) << "leaf " << i;
      worst_s = std::max(worst_s, std::abs(a[i].sigma3 - b[i].sigma3));
      worst_l = std::max(worst_l, std::abs(a[i].L - b[i].L) / b[i].L);
    }
    EXPECT_LT(worst_s, 1e-6) << "sigma3 at the leaf centers";
    EXPECT_LT(worst_l, 1e-4) << "Lipschitz bounds of the two certifiers";
    std::printf(
        "export vs lidef certify: %zu leaves, max |sigma3 difference| %.3g, max relative L difference "
        "%.3g\n",
        a.size(), worst_s, worst_l);
    auto slurp = [](const std::string& path) {
      std::ifstream in(path);
      return nlohmann::json::parse(in);
    };
    auto studio_json = slurp(dir / "export/certificate.json"), cli_json = slurp(dir / "cli/certificate.json");
    EXPECT_NEAR(studio_json.at("min_lower_bound").get<double>(), cli_json.at("min_lower_bound").get<double>(),
                1e-4);
    // The distortion bounds follow σ1 and L (relative 1e-5 above) and divide by the leaves' σ3 lower bounds.
    EXPECT_NEAR(studio_json.at("max_sigma1_upper_bound").get<double>(),
                cli_json.at("max_sigma1_upper_bound").get<double>(),
                1e-4 * cli_json.at("max_sigma1_upper_bound").get<double>());
    EXPECT_NEAR(studio_json.at("max_distortion_upper_bound").get<double>(),
                cli_json.at("max_distortion_upper_bound").get<double>(),
                1e-2 * cli_json.at("max_distortion_upper_bound").get<double>());
    // Input paths, the L-dependent minima and maxima and the CSV's hash aside, certificate.json is the same.
    for (auto* j : {&studio_json, &cli_json})
      for (const char* k : {"model", "coefficients", "min_lower_bound", "min_margin", "min_sigma3_center",
                            "max_sigma1_upper_bound", "max_distortion_upper_bound", "voxels_csv_fnv1a64"}) {
        EXPECT_TRUE(j->contains(k)) << k;
        j->erase(k);
      }
    EXPECT_EQ(studio_json, cli_json);
  }
  {
    std::ofstream pts(dir / "p.xyz");
    pts.precision(17);
    for (const auto* v : {&on_mesh, &on_leaf, &on_hover})
      pts << v->rest.x() << " " << v->rest.y() << " " << v->rest.z() << "\n";
  }
  std::string log;
  ASSERT_EQ(run_command(cli() + " eval " + project_data() + "/models/beam --coeffs " +
                            (dir / "export/coefficients.txt") + " --points " + (dir / "p.xyz") + " --out " +
                            (dir / "e.csv"),
                        &log),
            0)
      << log;
  const auto rows = read_eval_csv(dir / "e.csv");
  ASSERT_EQ(rows.size(), 3u);
  int k = 0;
  for (const auto* v : {&on_mesh, &on_leaf, &on_hover}) {
    const auto& row = rows[k++];
    ASSERT_EQ(row.size(), 19u);
    // x,y,z,fx,fy,fz,J00..J22,s1,s2,s3,detJ
    EXPECT_NEAR(v->image.x(), row[3], 1e-12);
    EXPECT_NEAR(v->sigma1, row[15], 1e-12 * std::abs(row[15]));
    EXPECT_NEAR(v->sigma3, row[17], 1e-12 * std::abs(row[17]) + 1e-15);
    EXPECT_NEAR(v->det_j, row[18], 1e-12 * std::abs(row[18]));
    // E_iso − 6 = ||J||_F^2 + ||J^-1||_F^2 − 6 from eval's J.
    Mat3 J;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) J(a, b) = row[6 + 3 * a + b];
    const double e = J.squaredNorm() + J.inverse().squaredNorm() - 6;
    EXPECT_NEAR(v->e_iso, e, 1e-9 * std::max(1.0, std::abs(e)));
  }
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

TEST(StudioInteraction, LayoutDominantViewDocksSavedAndCheatSheet) {
  StudioWindow win;
  win.show();
  pump_until([] { return false; }, 0.5);
  // The 3D view takes most of the window's width at the first-run size.
  EXPECT_GT(win.view_widget()->width(), 0.6 * win.width())
      << win.view_widget()->width() << " of " << win.width();
  EXPECT_GT(win.width(), 1000);
  auto* plots = win.findChild<QDockWidget*>("Plots");
  ASSERT_NE(plots, nullptr);
  EXPECT_TRUE(plots->features() & QDockWidget::DockWidgetClosable);
  plots->hide();
  win.resize(1111, 777);
  pump_until([] { return false; }, 0.3);
  win.save_layout();
  {
    StudioWindow again;
    ASSERT_TRUE(again.restore_layout());
    again.show();
    pump_until([] { return false; }, 0.3);
    EXPECT_FALSE(again.findChild<QDockWidget*>("Plots")->isVisible());
    EXPECT_EQ(again.size(), QSize(1111, 777));
  }
  // F1 and H open the cheat sheet, which names the camera keys.
  QAction* cheat = nullptr;
  for (QAction* a : win.findChildren<QAction*>())
    if (a->shortcuts().contains(QKeySequence(Qt::Key_F1))) cheat = a;
  ASSERT_NE(cheat, nullptr);
  EXPECT_TRUE(cheat->shortcuts().contains(QKeySequence(Qt::Key_H)));
  cheat->trigger();
  pump_until([] { return false; }, 0.2);
  auto* box = win.findChild<QMessageBox*>("cheat_sheet");
  ASSERT_NE(box, nullptr);
  EXPECT_TRUE(box->isVisible());
  for (const char* key : {"reset the camera", "orthographic", "copy / paste the camera", "pick"})
    EXPECT_NE(StudioWindow::cheat_sheet().find(key), std::string::npos) << key;
  box->close();
}

TEST(StudioInteraction, ScreenshotAtSizeWithTransparentBackground) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  TempDir dir;
  ASSERT_TRUE(win.save_screenshot(dir / "t.png", 320, 240, true));
  vtkNew<vtkPNGReader> r;
  r->SetFileName((dir / "t.png").c_str());
  r->Update();
  int dims[3];
  r->GetOutput()->GetDimensions(dims);
  EXPECT_EQ(dims[0], 320);
  EXPECT_EQ(dims[1], 240);
  ASSERT_EQ(r->GetOutput()->GetNumberOfScalarComponents(), 4);
  auto alpha = [&](int x, int y) {
    return static_cast<unsigned char*>(r->GetOutput()->GetScalarPointer(x, y, 0))[3];
  };
  EXPECT_EQ(alpha(2, 2), 0) << "background not transparent";
  long opaque = 0;
  for (int y = 0; y < dims[1]; y += 4)
    for (int x = 0; x < dims[0]; x += 4) opaque += alpha(x, y) == 255;
  EXPECT_GT(opaque, 100) << "the model is missing";
  // The view is back to its size afterwards.
  EXPECT_NE(win.view_widget()->size(), QSize(320, 240));
}

}  // namespace

namespace {

// Opening shows a progress bar and Cancel while the engine prepares; the view keeps what it showed before
// (here: nothing) until the model is ready. Cancel stops the preprocessing and the window stays as it was.
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
  bar = win.statusBar()->findChild<QProgressBar*>("prepare_bar");
  ASSERT_TRUE(cancel && bar);
  ASSERT_TRUE(pump_until(
      [&] {
        const auto s = win.preparing_frame();
        return s && s->state == SessionState::kPreparing && s->progress > 0.05;
      },
      120));
  // Nothing was open: nothing is drawn while preparing, the stage is on the bar.
  EXPECT_FALSE(win.shown_model());
  EXPECT_EQ(win.drawn_mesh_points(), 0);
  EXPECT_TRUE(win.opening());
  EXPECT_TRUE(bar->isVisible());
  EXPECT_TRUE(cancel->isVisible());
  EXPECT_FALSE(bar->format().isEmpty());
  EXPECT_NE(bar->format().toStdString().find("beam"), std::string::npos) << bar->format().toStdString();
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
  EXPECT_FALSE(win.opening());
  EXPECT_FALSE(win.shown_model());
  EXPECT_FALSE(win.preparing_frame());
  EXPECT_TRUE(fx.errors.empty());  // a cancel is not an error
}

}  // namespace
