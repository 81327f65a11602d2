// What the window says and draws about global injectivity (the badge's three verdicts and "checking", the
// overlap's red triangles and marker), and point clouds shown as points with their file's colours.
#include <gtest/gtest.h>
#include <vtkCellArray.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPNGReader.h>
#include <vtkPolyData.h>

#include <QCheckBox>
#include <array>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "lidef/mesh_io.h"
#include "lidef/point_cloud_io.h"
#include "studio_fixture.h"
#include "test_support.h"

namespace {
using namespace lidef;
using namespace lidef::test;
using lidef::studio::StudioWindow;
using Verdict = GlobalInjectivity::Verdict;

// The window's render as an image (VTK display coordinates: origin bottom left).
struct Shot {
  vtkNew<vtkPNGReader> reader;
  Shot(StudioWindow& win, const std::string& png) {
    EXPECT_TRUE(win.save_screenshot(png));
    reader->SetFileName(png.c_str());
    reader->Update();
  }
  std::array<int, 3> at(int x, int y) {
    const auto* p = static_cast<unsigned char*>(reader->GetOutput()->GetScalarPointer(x, y, 0));
    return {p[0], p[1], p[2]};
  }
  // Pixels for which `pred` holds, within `r` pixels of (x, y) (r < 0: the whole image).
  template <class Pred>
  long count(Pred pred, int x = 0, int y = 0, int r = -1) {
    const int* d = reader->GetOutput()->GetDimensions();
    long n = 0;
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        if (r >= 0 && (std::abs(i - x) > r || std::abs(j - y) > r)) continue;
        n += pred(at(i, j));
      }
    return n;
  }
};

// The overlap's colours: pure unshaded red (no heat-map colour has g = b = 0 at full red), and the marker's
// yellow (the heat map has g = b everywhere).
bool overlap_red(const std::array<int, 3>& c) {
  return c[0] >= 235 && c[1] <= 25 && c[2] <= 25;
}
bool marker_yellow(const std::array<int, 3>& c) {
  return c[0] >= 150 && c[1] >= 110 && c[2] + 80 < c[1];
}

// bar_fold_onto_itself with its shared model named by an absolute path (the scenario names "bar", which lives
// in the shared data).
std::string fold_scenario(const TempDir& dir) {
  std::ifstream in(project_data() + "/scenarios/bar_fold_onto_itself.json");
  nlohmann::json j = nlohmann::json::parse(in);
  j["model"] = shared_model("bar");
  const std::string path = dir / "fold.json";
  std::ofstream(path) << j.dump(1);
  return path;
}

QCheckBox* global_box(StudioWindow& win) {
  return win.findChild<QCheckBox*>("view_global_injectivity");
}

TEST(StudioView, FoldedBarShowsTheOverlapBadgeRedTrianglesAndMarker) {
  LIDEF_REQUIRE_SHARED();
  Fixture fx;
  StudioWindow& win = fx.win;
  win.set_hover(false);
  win.set_orientation_axes(false);  // its x axis is red
  ASSERT_TRUE(global_box(win));
  EXPECT_TRUE(global_box(win)->isChecked()) << "the check is on by default";
  TempDir dir;
  ASSERT_TRUE(
      win.open_path(fold_scenario(dir), project_data() + "/scenarios/bar_fold_onto_itself.coefficients.txt"));
  ASSERT_TRUE(settled(win, 600));
  ASSERT_TRUE(fx.errors.empty()) << fx.errors.front();
  const auto f = win.shown_frame();
  ASSERT_TRUE(f->certified) << f->not_certified_reason;
  ASSERT_TRUE(f->global);
  ASSERT_EQ(f->global_version, f->map_version) << "the verdict is of the map on screen";
  const GlobalInjectivity& g = *f->global;
  ASSERT_EQ(g.verdict, Verdict::kOverlap) << g.reason;
  EXPECT_NE(win.badge_text().find("locally injective — overlaps itself"), std::string::npos)
      << win.badge_text();
  EXPECT_EQ(win.badge_text().find("CERTIFIED injective"), std::string::npos);
  // The red faces: the two triangles' neighbourhoods, no more than a few rings.
  const std::vector<int>& red = win.overlap_faces();
  EXPECT_TRUE(std::binary_search(red.begin(), red.end(), g.overlap_face_a));
  EXPECT_TRUE(std::binary_search(red.begin(), red.end(), g.overlap_face_b));
  EXPECT_EQ(
      red, studio::faces_near(f->model->mesh.F, {g.overlap_face_a, g.overlap_face_b}, studio::kOverlapRings));
  EXPECT_LT(red.size(), static_cast<size_t>(f->model->mesh.F.rows()) / 10);
  ASSERT_TRUE(win.overlap_marker_shown());
  EXPECT_EQ(win.overlap_marker_at(), g.overlap_point);
  // On screen: red pixels, and the marker's yellow at the overlap point.
  double xy[2];
  display_of(win, g.overlap_point, xy);
  const int mx = static_cast<int>(xy[0]), my = static_cast<int>(xy[1]);
  {
    Shot shot(win, dir / "on.png");
    EXPECT_GT(shot.count(overlap_red), 100);
    EXPECT_GT(shot.count(marker_yellow, mx, my, 4), 10) << "no marker at the overlap point";
  }
  // Unchecked: the local badge only, nothing red or yellow drawn.
  global_box(win)->setChecked(false);
  pump_until([&] { return win.badge_text().find("CERTIFIED locally injective") != std::string::npos; }, 30);
  ASSERT_TRUE(settled(win));
  win.render_window()->Render();
  EXPECT_NE(win.badge_text().find("CERTIFIED locally injective"), std::string::npos) << win.badge_text();
  EXPECT_TRUE(win.overlap_faces().empty());
  EXPECT_FALSE(win.overlap_marker_shown());
  Shot off(win, dir / "off.png");
  EXPECT_EQ(off.count(overlap_red), 0);
  EXPECT_EQ(off.count(marker_yellow, mx, my, 4), 0);
}

// A benign drag of the beam: "checking" while the map is new, then "CERTIFIED injective" — and never a
// verdict on screen that belongs to another map than the one shown.
TEST(StudioView, BenignDragIsCertifiedInjectiveAndNeverShowsAStaleVerdict) {
  Fixture fx;
  StudioWindow& win = fx.win;
  ASSERT_TRUE(win.open_path(project_data() + "/models/beam"));
  ASSERT_TRUE(settled(win));
  long stale = 0, checking = 0, injective = 0;
  QObject::connect(&win, &StudioWindow::frame_shown, [&] {
    const auto f = win.shown_frame();
    if (!f || f->mesh_V.rows() == 0) return;
    const std::string b = win.badge_text();
    if (b.find("CERTIFIED injective") != std::string::npos) {
      ++injective;
      stale += !f->global || f->global_version != f->map_version;
    }
    checking += b.find("global: checking") != std::string::npos;
  });
  ASSERT_TRUE(win.add_handle(Vec3(-0.8, 0.0, 0.1)));
  ASSERT_TRUE(win.add_handle(Vec3(0.8, 0.0, 0.1)));
  ASSERT_TRUE(settled(win));
  win.move_target(1, win.targets().row(1).transpose() + Vec3(0, 0, 0.3));
  ASSERT_TRUE(settled(win));
  const auto f = win.shown_frame();
  ASSERT_TRUE(f->global);
  EXPECT_EQ(f->global_version, f->map_version);
  EXPECT_EQ(f->global->verdict, Verdict::kInjective) << f->global->reason;
  EXPECT_NE(win.badge_text().find("CERTIFIED injective"), std::string::npos) << win.badge_text();
  EXPECT_TRUE(win.overlap_faces().empty());
  EXPECT_FALSE(win.overlap_marker_shown());
  EXPECT_GT(checking, 0) << "a new map was never announced as being checked";
  EXPECT_GT(injective, 0);
  EXPECT_EQ(stale, 0) << "a verdict was shown with a map it was not computed for";
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

// A point cloud (a PLY without faces, green from its red green blue) opened as the CLI opens it (automatic
// cage): drawn as points where they are, in the file's colour, with handles that drag it.
TEST(StudioView, PointCloudLoadsRendersPointsAndDrags) {
  Fixture fx;
  StudioWindow& win = fx.win;
  win.set_hover(false);
  TempDir dir;
  PlyCloud cloud;
  cloud.names = {"x", "y", "z", "red", "green", "blue"};
  cloud.types = {"float", "float", "float", "uchar", "uchar", "uchar"};
  const TriMesh beam = read_mesh(project_data() + "/models/beam/mesh.obj");
  const Eigen::Index n = beam.V.rows();
  cloud.values.resize(n, 6);
  cloud.values.leftCols(3) = beam.V.cast<float>().cast<double>();
  cloud.values.col(3).setConstant(30);
  cloud.values.col(4).setConstant(170);
  cloud.values.col(5).setConstant(60);
  const std::string ply = dir / "beam_points.ply";
  {
    std::ofstream out(ply, std::ios::binary);
    write_ply_cloud(out, cloud);
  }
  ASSERT_TRUE(win.open_path(ply));
  ASSERT_TRUE(settled(win, 300));
  ASSERT_TRUE(fx.errors.empty()) << fx.errors.front();
  const auto f = win.shown_frame();
  ASSERT_EQ(f->model->mesh.F.rows(), 0);
  ASSERT_EQ(f->mesh_V.rows(), n);
  EXPECT_EQ(win.mesh_data()->GetNumberOfVerts(), n);
  EXPECT_EQ(win.mesh_data()->GetNumberOfPolys(), 0);
  EXPECT_TRUE(win.has_point_colors());
  EXPECT_NE(win.badge_text().find("global: not decided — a point cloud has no surface"), std::string::npos)
      << win.badge_text();
  // Every 97th point's pixel shows the file's green (points are drawn there, nothing else is green).
  auto green = [](const std::array<int, 3>& c) { return c[1] > c[0] + 50 && c[1] > c[2] + 40; };
  {
    Shot shot(win, dir / "points.png");
    long hits = 0, tried = 0;
    for (Eigen::Index i = 0; i < n; i += 97, ++tried) {
      double xy[2];
      display_of(win, f->mesh_V.row(i).transpose(), xy);
      hits += shot.count(green, static_cast<int>(xy[0]), static_cast<int>(xy[1]), 1) > 0;
    }
    EXPECT_GE(hits, tried * 9 / 10) << hits << " of " << tried;
  }
  // Handles on two points; the far one is dragged up: the cloud follows, certified.
  const Vec3 a = beam.V.row(0).transpose();
  Eigen::Index far = 0;
  for (Eigen::Index i = 0; i < n; ++i)
    if ((beam.V.row(i).transpose() - a).norm() > (beam.V.row(far).transpose() - a).norm()) far = i;
  ASSERT_TRUE(win.add_handle(0.95 * a + 0.05 * beam.V.colwise().mean().transpose()));
  ASSERT_TRUE(
      win.add_handle(0.95 * Vec3(beam.V.row(far).transpose()) + 0.05 * beam.V.colwise().mean().transpose()));
  ASSERT_TRUE(settled(win));
  const MatX3d before = win.shown_frame()->mesh_V;
  const Vec3 lift(0, 0, 0.3);
  win.move_target(1, win.targets().row(1).transpose() + lift);
  ASSERT_TRUE(settled(win, 300));
  const auto g = win.shown_frame();
  EXPECT_TRUE(g->certified);
  EXPECT_LT((g->images.row(1) - win.targets().row(1)).norm(), 0.05);
  EXPECT_GT((g->mesh_V.row(far) - before.row(far)).norm(), 0.2) << "the far point did not follow";
  EXPECT_LT((g->mesh_V.row(0) - before.row(0)).norm(), 0.05) << "the held point moved";
  EXPECT_TRUE(fx.errors.empty()) << fx.errors.front();
}

}  // namespace
