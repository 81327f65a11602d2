// lidef-studio: interactive certified deformation (Qt5 + VTK). With --screenshot it solves, renders one view,
// writes a PNG and exits (docs, render tests).
#include <QVTKOpenGLNativeWidget.h>

#include <CLI/CLI.hpp>
#include <QApplication>
#include <QSurfaceFormat>
#include <QTimer>
#include <chrono>
#include <clocale>
#include <iostream>
#include <regex>

#include "compare_view.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "omp_wait.h"
#include "scene.h"
#include "studio_common.h"
#include "studio_window.h"

int main(int argc, char** argv) {
  using namespace lidef;
  using namespace lidef::studio;
  ensure_studio_environment(argv);
  CLI::App app{
      "lidef-studio: drag handles, watch the certified deformation, inspect sigma3, Lipschitz bounds and "
      "the octree"};
  std::string scenario, model, compare, view = "mesh", screenshot, size = "1024x768";
  double timeout = 600;
  int multisamples = -1;
  bool transparent = false;
  app.add_option(
      "PATH", scenario,
      "A scenario/session JSON, a model folder, or a mesh file (.obj/.off/.ply/.stl: automatic cage)");
  app.add_option("--scenario", scenario, "Scenario or saved session JSON to open");
  app.add_option("--model", model, "Model folder or mesh file to open (no handles)");
  std::string coefficients;
  app.add_option("--coefficients", coefficients,
                 "With a scenario: start from this map (a coefficients.txt of `lidef deform` with the same "
                 "parameters) instead of solving");
  app.add_option(
      "--compare", compare,
      "A `lidef compare --out` folder: every method's mesh side by side (with --screenshot: that picture)");
  app.add_option("--view", view, "View: mesh, sigma3, lipschitz, octree")->capture_default_str();
  bool distortion = false;
  app.add_flag("--distortion", distortion,
               "Colour the view by sigma1/sigma3 (the Lipschitz view: its certified upper bound per leaf)");
  bool global = ViewSettings{}.global_injectivity;
  app.add_flag("--global-injectivity,!--no-global-injectivity", global,
               "Check global injectivity when the solver rests (badge; an overlap drawn red with a yellow "
               "marker); on by default");
  app.add_option(
      "--screenshot", screenshot,
      "Solve until the solver rests, render --view, write this PNG and exit (0 written, 1 timed out, "
      "2 error)");
  app.add_option("--size", size, "Size of the rendered view for --screenshot, WxH")->capture_default_str();
  app.add_flag("--transparent", transparent,
               "With --screenshot: an RGBA PNG whose background is transparent");
  app.add_option("--multisamples", multisamples,
                 "MSAA samples of the 3D view (default: 0 interactive, 4 for --screenshot)");
  app.add_option("--timeout", timeout, "Seconds to wait for the solver in --screenshot mode")
      ->capture_default_str();
  app.footer(
      "Mouse: click on the mesh adds a handle (Ctrl+click picks values); drag a cyan target sphere;\n"
      "right-click on it deletes it. Keys: F1 or H in the window lists them all. Docs: docs/studio.md.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  int w = 0, h = 0;
  {
    std::smatch m;
    if (!std::regex_match(size, m, std::regex(R"((\d{2,5})x(\d{2,5}))"))) {
      std::cerr << "lidef-studio: --size: expected WxH (e.g. 1024x768), got \"" << size << "\"\n";
      return 2;
    }
    w = std::stoi(m[1]);
    h = std::stoi(m[2]);
  }
  ViewSettings settings;
  try {
    settings.view = view_from_string(view);
    settings.distortion = distortion;
    settings.global_injectivity = global;
  } catch (const std::exception& e) {
    std::cerr << "lidef-studio: " << e.what() << "\n";
    return 2;
  }
  if (!screenshot.empty() && scenario.empty() && model.empty() && compare.empty()) {
    std::cerr << "lidef-studio: --screenshot needs --scenario, --model or --compare\n";
    return 2;
  }

  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication qapp(argc, argv);
  // QSettings (the window layout) under ~/.config/lidef/lidef-studio.conf.
  QApplication::setOrganizationName("lidef");
  QApplication::setApplicationName("lidef-studio");
  // QApplication adopts the user's locale (setlocale(LC_ALL, "")); numbers in captions and files are written
  // with printf (format_g), which must keep the '.' of the C locale.
  std::setlocale(LC_NUMERIC, "C");
  const bool headless = !screenshot.empty();
  if (!compare.empty() && headless) {
    std::string caption;
    QVTKOpenGLNativeWidget* cw = nullptr;
    try {
      cw = open_compare_widget(compare, multisamples >= 0 ? multisamples : 4, &caption, w, h);
    } catch (const std::exception& e) {
      std::cerr << "lidef-studio: " << e.what() << "\n";
      return 2;
    }
    cw->setFixedSize(w, h);
    cw->show();
    QApplication::processEvents();
    const std::string why = write_window_png(cw->renderWindow(), screenshot);
    cw->close();
    if (!why.empty()) {
      std::cerr << "lidef-studio: " << why << "\n";
      return 2;
    }
    std::cout << "lidef-studio: comparison " << compare << " written to " << screenshot << "; " << caption
              << "\n";
    return 0;
  }
  StudioWindow win;
  win.set_multisamples(multisamples >= 0 ? multisamples : headless ? 4 : 0);
  int exit_code = 0;
  if (headless) {
    win.set_error_sink([&](const std::string& e) {
      std::cerr << "lidef-studio: " << e << "\n";
      exit_code = 2;
      qapp.exit(2);
    });
    win.set_view_only(true);
    win.view_widget()->setFixedSize(w, h);
    win.adjustSize();
  }
  if (!headless) win.restore_layout();
  win.show();
  win.set_settings(settings);
  const std::string path = !scenario.empty() ? scenario : model;
  if (!coefficients.empty() && scenario.empty()) {
    std::cerr << "lidef-studio: --coefficients needs a scenario (PATH or --scenario)\n";
    return 2;
  }
  if (!path.empty() && !win.open_path(path, coefficients)) {
    if (headless) return 2;
  }
  if (!compare.empty() && !win.open_comparison(compare) && headless) return 2;
  if (!headless) return qapp.exec();

  // Headless: wait until the engine rests with the view's extras for the final map, then grab.
  const auto t0 = lidef::Clock::now();
  QTimer poll;
  QObject::connect(&poll, &QTimer::timeout, [&] {
    const double waited = lidef::seconds_since(t0);
    if (waited > timeout) {
      std::cerr << "lidef-studio: timed out after " << timeout << " s waiting for the solver\n";
      exit_code = 1;
      qapp.exit(1);
      return;
    }
    if (!win.session().wait_until_resting(0.0)) return;
    const auto f = win.session().latest_frame();
    const auto shown = win.shown_frame();
    if (!f || !shown || shown->serial != f->serial || f->mesh_V.rows() == 0) return;
    const ExtrasRequest ex = extras_for(win.settings());
    if (ex.leaves && f->leaves_version != f->map_version) return;
    if (ex.field && f->field_version != f->map_version) return;
    if (ex.mesh_distortion && f->mesh_distortion.size() != f->mesh_V.rows()) return;
    if (ex.global_injectivity && f->global_version != f->map_version) return;
    poll.stop();
    if (!win.save_screenshot(screenshot, 0, 0, transparent)) {
      exit_code = 2;
      qapp.exit(2);
      return;
    }
    std::cout << "lidef-studio: " << to_string(win.settings().view) << " view of " << path << " written to "
              << screenshot << " (" << w << "x" << h << "); " << win.caption() << "\n"
              << "badge:" << win.badge_text() << "\n";
    qapp.exit(0);
  });
  poll.start(50);
  const int rc = qapp.exec();
  return exit_code ? exit_code : rc;
}
