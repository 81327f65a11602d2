// The σ3 explorer panel (gui/src/explorer_panel.h) on the shipped counterexample
// data/explorer/sigma3_interior_min.json: the interior minimum σ3 = 0.6 at the center (J = diag(2.2, 1.8,
// 0.6), docs/explorer.md) against an independent evaluation, the boundary minimum above it, the rendered
// slices (colours of the σ3 map, nothing red) and the minimum marker; a malformed file goes to the error sink
// and keeps the shown map. Needs a display (the studio test main; run under xvfb-run).
#include <QVTKOpenGLNativeWidget.h>
#include <gtest/gtest.h>
#include <vtkCamera.h>
#include <vtkImageData.h>
#include <vtkPointData.h>
#include <vtkRenderWindow.h>
#include <vtkRenderer.h>
#include <vtkRendererCollection.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkWindowToImageFilter.h>

#include <Eigen/Eigenvalues>
#include <QApplication>
#include <chrono>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "explorer_panel.h"
#include "lidef/explorer/explorer_example.h"
#include "lidef/internal/stopwatch.h"
#include "test_support.h"

namespace {
using namespace lidef;
using namespace lidef::test;
using lidef::studio::ExplorerPanel;

void pump(double seconds) {
  const auto t0 = Clock::now();
  while (seconds_since(t0) < seconds) {
    QApplication::processEvents(QEventLoop::AllEvents, 20);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

// σ3 from the eigenvalues of JᵀJ and the sign of det J (not the project's signed SVD).
double sigma3_by_eigen(const Mat3& J) {
  const Eigen::SelfAdjointEigenSolver<Mat3> es(J.transpose() * J, Eigen::EigenvaluesOnly);
  return (J.determinant() < 0 ? -1 : 1) * std::sqrt(std::max(0.0, es.eigenvalues()(0)));
}

struct Image {
  int w = 0, h = 0;
  std::vector<unsigned char> rgb;  // bottom row first, like VTK display coordinates
  const unsigned char* at(int x, int y) const { return &rgb[3 * (static_cast<size_t>(y) * w + x)]; }
};

Image grab(ExplorerPanel& panel) {
  vtkRenderWindow* win = panel.render_window();
  win->Render();
  auto f = vtkSmartPointer<vtkWindowToImageFilter>::New();
  f->SetInput(win);
  f->ReadFrontBufferOff();
  f->ShouldRerenderOn();
  f->Update();
  Image img;
  int dims[3];
  f->GetOutput()->GetDimensions(dims);
  img.w = dims[0];
  img.h = dims[1];
  auto* a = vtkUnsignedCharArray::SafeDownCast(f->GetOutput()->GetPointData()->GetScalars());
  const int nc = a ? a->GetNumberOfComponents() : 0;
  if (nc < 3) return img;
  img.rgb.resize(static_cast<size_t>(img.w) * img.h * 3);
  for (long i = 0; i < static_cast<long>(img.w) * img.h; ++i)
    for (int c = 0; c < 3; ++c) img.rgb[3 * i + c] = a->GetValue(nc * i + c);
  return img;
}

vtkRenderer* main_renderer(ExplorerPanel& panel) {
  return panel.render_window()->GetRenderers()->GetFirstRenderer();
}

void to_display(vtkRenderer* r, const Vec3& p, double xy[2]) {
  r->SetWorldPoint(p.x(), p.y(), p.z(), 1.0);
  r->WorldToDisplay();
  xy[0] = r->GetDisplayPoint()[0];
  xy[1] = r->GetDisplayPoint()[1];
}

// Waits for the computation, then lets the layout settle (the caption's height changes with its text) and
// resizes the panel so that its 3D view is 400x400.
bool settle(ExplorerPanel& panel) {
  const bool idle = panel.wait_until_idle(60);
  for (int i = 0; i < 4; ++i) {
    pump(0.15);
    const QWidget* v = panel.view_widget();
    if (v->width() == 400 && v->height() == 400) break;
    panel.resize(panel.width() + 400 - v->width(), panel.height() + 400 - v->height());
  }
  pump(0.15);
  return idle;
}

struct Fixture {
  ExplorerPanel panel{project_data()};
  std::vector<std::string> errors;
  Fixture() {
    panel.set_error_sink([this](const std::string& e) { errors.push_back(e); });
    panel.resize(400, 400);
    panel.show();
    pump(0.2);
  }
};

TEST(ExplorerPanel, ShippedCounterexampleHasAnInteriorMinimumBelowTheBoundary) {
  Fixture fx;
  ExplorerPanel& panel = fx.panel;
  EXPECT_EQ(panel.resolution(), 48);
  EXPECT_TRUE(std::isnan(panel.interior_min()));
  const auto t0 = Clock::now();
  ASSERT_TRUE(panel.open_shipped_example());
  ASSERT_TRUE(panel.wait_until_idle(60));
  const double open_ms = 1000 * seconds_since(t0);
  ASSERT_TRUE(settle(panel));
  ASSERT_TRUE(fx.errors.empty()) << fx.errors.front();
  std::printf(
      "open, compute and draw: %.0f ms (minima, boundary, range %.0f ms; slices %.0f ms), %d minima\n",
      open_ms, panel.analysis_ms(), panel.slices_ms(), panel.num_minima());
  EXPECT_EQ(panel.path(), panel.shipped_example_path());

  // The file states σ = (2.2, 1.8, 0.6) at the center: J(0) = diag(2.2, 1.8, 0.6), so σ3(0) = 0.6.
  const ExplorerExample ex = read_explorer_example(panel.shipped_example_path());
  EXPECT_NE(ex.note.find("sigma = (2.2, 1.8, 0.6)"), std::string::npos) << ex.note;
  EXPECT_LT((ex.map->jet(ex.ball.center).J - Vec3(2.2, 1.8, 0.6).asDiagonal().toDenseMatrix()).norm(), 1e-12);

  ASSERT_GE(panel.num_minima(), 1);
  EXPECT_GE(panel.num_strict_minima(), 1);
  EXPECT_NEAR(panel.interior_min(), 0.6, 1e-9);
  const Vec3 x = panel.interior_min_position();
  EXPECT_LT((x - ex.ball.center).norm(), 1e-6) << x.transpose();
  EXPECT_NEAR(sigma3_by_eigen(ex.map->jet(x).J), panel.interior_min(), 1e-9);
  // A strict local minimum: σ3 larger on a small sphere around it.
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01;
  for (int i = 0; i < 100; ++i) {
    const Vec3 u = Vec3(n01(rng), n01(rng), n01(rng)).normalized();
    EXPECT_GT(sigma3_by_eigen(ex.map->jet(x + 0.02 * u).J), panel.interior_min());
  }

  // The boundary: its sampled minimum is a value of σ3 on the sphere, no random sphere point is much lower,
  // and it lies above the interior minimum (docs: 0.80 sampled, > 0.6009 certified).
  const Vec3 b = panel.boundary_min_position();
  EXPECT_NEAR((b - ex.ball.center).norm(), ex.ball.radius, 1e-9);
  EXPECT_NEAR(sigma3_by_eigen(ex.map->jet(b).J), panel.boundary_min(), 1e-9);
  EXPECT_NEAR(panel.boundary_min(), 0.80, 0.01);
  EXPECT_GT(panel.boundary_min(), panel.interior_min() + 0.1);
  for (int i = 0; i < 500; ++i) {
    const Vec3 u = Vec3(n01(rng), n01(rng), n01(rng)).normalized();
    const double s = sigma3_by_eigen(ex.map->jet(ex.ball.center + ex.ball.radius * u).J);
    EXPECT_GT(s, panel.boundary_min() - 0.01);
    EXPECT_GT(s, 0.6009);
  }
  const std::string cap = panel.caption();
  EXPECT_NE(cap.find("sigma3_interior_min.json"), std::string::npos) << cap;
  EXPECT_NE(cap.find("interior minimum 0.600 < boundary minimum 0.80"), std::string::npos) << cap;
  EXPECT_NE(cap.find("no minimum principle"), std::string::npos) << cap;

  // Rendering: the slices in the σ3 colours, nothing red (σ3 > 0 everywhere), the marker at the minimum.
  const Image with = grab(panel);
  ASSERT_EQ(with.w, 400);
  ASSERT_EQ(with.h, 400);
  long red = 0, coloured = 0;
  for (int y = 0; y < with.h; ++y)
    for (int xx = 0; xx < with.w; ++xx) {
      const unsigned char* p = with.at(xx, y);
      const int hi = std::max({p[0], p[1], p[2]}), lo = std::min({p[0], p[1], p[2]});
      if (p[0] > 150 && p[1] < 90 && p[2] < 90) ++red;
      if (xx < 0.85 * with.w && hi - lo > 60) ++coloured;  // left of the colour bar
    }
  EXPECT_EQ(red, 0);
  EXPECT_GT(coloured, static_cast<long>(0.08 * with.w * with.h)) << with.w << "x" << with.h;
  // A visible point of the x = 0 slice has the colour of σ3 there (up to shading).
  vtkRenderer* ren = main_renderer(panel);
  {
    const Vec3 q = ex.ball.center + ex.ball.radius * Vec3(0, 0.45, 0.45);
    double xy[2];
    to_display(ren, q, xy);
    const unsigned char* p =
        with.at(static_cast<int>(std::lround(xy[0])), static_cast<int>(std::lround(xy[1])));
    // The σ3 colour map: dark purple at the minimum, through teal and green, to yellow at the maximum.
    const double s = sigma3_by_eigen(ex.map->jet(q).J);
    EXPECT_GT(s, 0.6);
    const Vec3 px(p[0], p[1], p[2]);
    EXPECT_GT(px.maxCoeff() - px.minCoeff(), 40) << px.transpose();  // coloured, not background or grey
    EXPECT_LT(px(0), 0.6 * std::max(px(1), px(2)) + 10) << px.transpose();  // no red component to speak of
  }
  // The marker: a sphere of radius 0.035 R at the minimum with a white halo out to 1.5 times that. Hiding the
  // minima turns the halo's ring back into the dark slices around the center.
  panel.set_show_minima(false);
  const Image without = grab(panel);
  panel.set_show_minima(true);
  ASSERT_EQ(without.w, with.w);
  ASSERT_EQ(without.h, with.h);
  double c[2], e[2];
  to_display(ren, x, c);
  const double* n = ren->GetActiveCamera()->GetViewPlaneNormal();
  const Vec3 side = Vec3(n[0], n[1], n[2]).cross(Vec3(0, 0, 1)).normalized();  // ⊥ to the view direction
  to_display(ren, x + 0.035 * ex.ball.radius * side, e);
  const double r_px = std::hypot(e[0] - c[0], e[1] - c[1]);
  EXPECT_GT(r_px, 2.5);
  long ring = 0, white_with = 0, white_without = 0, core = 0, core_marker = 0;
  auto white = [](const unsigned char* p) { return p[0] > 200 && p[1] > 200 && p[2] > 200; };
  for (int y = 0; y < with.h; ++y)
    for (int xx = 0; xx < with.w; ++xx) {
      const double d = std::hypot(xx - c[0], y - c[1]) / r_px;
      const unsigned char *p = with.at(xx, y), *q = without.at(xx, y);
      if (d > 1.15 && d < 1.4) {
        ++ring;
        white_with += white(p);
        white_without += white(q);
      }
      if (d < 0.6) {  // the body: σ3 = 0.6 is the bottom of the colour map, dark purple (0.18, 0, 0.33)
        ++core;
        core_marker += p[2] > p[1] + 20 && p[0] > p[1] && !white(p);
      }
    }
  EXPECT_GT(ring, 8);
  EXPECT_GT(white_with, ring * 3 / 4)
      << "marker at display (" << c[0] << ", " << c[1] << "), radius " << r_px;
  EXPECT_EQ(white_without, 0);
  EXPECT_GT(core_marker, core / 3) << core;
}

TEST(ExplorerPanel, ControlsRecomputeOnlyTheSlices) {
  Fixture fx;
  ExplorerPanel& panel = fx.panel;
  ASSERT_TRUE(panel.open_shipped_example());
  ASSERT_TRUE(settle(panel));
  const double analysis_ms = panel.analysis_ms();
  const std::string cap = panel.caption();
  const Image before = grab(panel);
  panel.set_slice_offset(0.5);
  panel.set_resolution(20);
  panel.set_slice_offset(-0.3);  // requests pile up: the newest one is shown
  ASSERT_TRUE(settle(panel));
  EXPECT_EQ(panel.slice_offset(), -0.3);
  EXPECT_EQ(panel.resolution(), 20);
  EXPECT_EQ(panel.analysis_ms(), analysis_ms);  // the same analysis, reused
  EXPECT_EQ(panel.caption(), cap);
  const Image after = grab(panel);
  ASSERT_EQ(after.rgb.size(), before.rgb.size());
  long differ = 0;
  for (size_t i = 0; i < after.rgb.size(); ++i) differ += std::abs(after.rgb[i] - before.rgb[i]) > 30;
  EXPECT_GT(differ, 1000);
  panel.set_slice_offset(7);  // clamped; the planes vanish at |t| = 1
  ASSERT_TRUE(settle(panel));
  EXPECT_EQ(panel.slice_offset(), 1);
  EXPECT_TRUE(fx.errors.empty());
}

TEST(ExplorerPanel, ClosingWhileComputingIsSafe) {
  for (int i = 0; i < 3; ++i) {
    auto panel = std::make_unique<ExplorerPanel>(project_data());
    panel->show();
    ASSERT_TRUE(panel->open_shipped_example());
    EXPECT_TRUE(panel->busy());
    if (i == 1) pump(0.01);
    panel.reset();  // joins the worker; its posted result is dropped with the panel
  }
  pump(0.2);
}

TEST(ExplorerPanel, MalformedFileGoesToTheErrorSinkAndKeepsTheMap) {
  Fixture fx;
  ExplorerPanel& panel = fx.panel;
  ASSERT_TRUE(panel.open_shipped_example());
  ASSERT_TRUE(settle(panel));
  const std::string cap = panel.caption();
  const int minima = panel.num_minima();
  TempDir dir;
  const std::string bad = dir / "broken_map.json";
  write_text(bad, "{\"format\": \"lidef-explorer-map\", \"type\": \"harmonic_polynomial\", \"degree\": ");
  EXPECT_FALSE(panel.open_example(bad));
  ASSERT_EQ(fx.errors.size(), 1u);
  EXPECT_NE(fx.errors[0].find("broken_map.json"), std::string::npos) << fx.errors[0];
  // A well-formed file with the wrong number of coefficient rows, and a missing file.
  const std::string rows = dir / "wrong_rows.json";
  write_text(rows,
             "{\"format\": \"lidef-explorer-map\", \"type\": \"harmonic_polynomial\", \"degree\": 1, "
             "\"coefficients\": [[0, 0, 0], [1, 0, 0]]}");
  EXPECT_FALSE(panel.open_example(rows));
  EXPECT_FALSE(panel.open_example(dir / "missing.json"));
  ASSERT_EQ(fx.errors.size(), 3u);
  EXPECT_NE(fx.errors[1].find("wrong_rows.json"), std::string::npos) << fx.errors[1];
  EXPECT_NE(fx.errors[2].find("missing.json"), std::string::npos) << fx.errors[2];
  EXPECT_FALSE(panel.busy());
  EXPECT_EQ(panel.path(), panel.shipped_example_path());
  EXPECT_EQ(panel.caption(), cap);
  EXPECT_EQ(panel.num_minima(), minima);
  EXPECT_NEAR(panel.interior_min(), 0.6, 1e-9);
}

}  // namespace
