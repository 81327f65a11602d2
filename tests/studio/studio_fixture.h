// What the studio's window tests share: pumping the Qt event loop until a condition holds, waiting until the
// window shows the engine's newest frame, scripted mouse events through the VTK interactor, and a shown
// window with small solver parameters whose errors are collected instead of shown in dialogs.
#pragma once
#include <QVTKOpenGLNativeWidget.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkRendererCollection.h>

#include <QApplication>
#include <chrono>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "lidef/internal/stopwatch.h"
#include "studio_window.h"

namespace lidef::test {

inline bool pump_until(const std::function<bool()>& cond, double seconds) {
  const auto t0 = Clock::now();
  while (seconds_since(t0) < seconds) {
    QApplication::processEvents(QEventLoop::AllEvents, 20);
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return cond();
}

// The engine rests and the window shows its newest frame.
inline bool settled(lidef::studio::StudioWindow& w, double seconds = 120) {
  return pump_until(
      [&] {
        if (!w.session().wait_until_resting(0.0)) return false;
        const auto f = w.session().latest_frame();
        const auto s = w.shown_frame();
        return f && s && f->serial == s->serial && f->mesh_V.rows() > 0;
      },
      seconds);
}

inline void display_of(lidef::studio::StudioWindow& w, const Vec3& p, double xy[2]) {
  vtkRenderer* r = w.render_window()->GetRenderers()->GetFirstRenderer();
  r->SetWorldPoint(p.x(), p.y(), p.z(), 1.0);
  r->WorldToDisplay();
  xy[0] = r->GetDisplayPoint()[0];
  xy[1] = r->GetDisplayPoint()[1];
}

inline void mouse(lidef::studio::StudioWindow& w, unsigned long event, double x, double y) {
  vtkRenderWindowInteractor* iren = w.render_window()->GetInteractor();
  iren->SetEventInformation(static_cast<int>(x), static_cast<int>(y), 0, 0, 0, 0);
  iren->InvokeEvent(event, nullptr);
  QApplication::processEvents();
}

inline DeformParams small_params() {
  DeformParams p;
  p.reduced_dof = 60;
  p.samples = 4000;
  return p;
}

struct Fixture {
  lidef::studio::StudioWindow win;
  std::vector<std::string> errors;
  Fixture() {
    win.set_error_sink([this](const std::string& e) { errors.push_back(e); });
    win.resize(1100, 750);
    win.show();
    pump_until([] { return false; }, 0.3);
    win.set_params(small_params());
  }
};

}  // namespace lidef::test
