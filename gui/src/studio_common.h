// Small pieces the studio's views and panels share.
#pragma once
#include <functional>
#include <string>

class QLabel;
class QWidget;
class vtkColorTransferFunction;
class vtkLookupTable;
class vtkScalarBarActor;
class vtkRenderWindow;

namespace lidef::studio {

// σ3 colours of every studio view: red below 0 (not injective), then a perceptual ramp (dark blue → yellow)
// on [max(lo, 0), hi]. (scene.cpp)
void sigma3_colors(vtkColorTransferFunction* ctf, double lo, double hi);

// Heat map for E_iso − 6 on [0, hi] (0 = isometry): white to dark red, like the paper's figures; NaN dark
// grey. (scene.cpp)
void heat_lut(vtkLookupTable* lut, double hi);

// The studio's colour-bar look: right edge, dark text, `height` of the view. (scene.cpp)
void style_scalar_bar(vtkScalarBarActor* bar, double height);

// The one way the studio tells the user about a problem: the message in `status` and, unless a sink is set
// (tests, headless runs), a modal error dialog titled "lidef-studio: <title>". (studio_window.cpp)
void report_to_user(QWidget* parent, QLabel* status, const std::function<void(const std::string&)>& sink,
                    const std::string& title, const std::string& message);

// Renders `window` and writes it as PNG: temporary file in the same folder, then rename. Returns "" or the
// reason it failed (nothing is left behind then). rgba: 4 channels, the alpha of the frame buffer (a
// transparent background needs renderers with background alpha 0 and alpha bit planes). (studio_window.cpp)
std::string write_window_png(vtkRenderWindow* window, const std::string& path, bool rgba = false);

// An engine status line with its stop reason in words ("targets_unreachable: ..." → "targets unreachable
// (proven: ...): ..."); other lines unchanged. (studio_window.cpp)
std::string stop_reason_in_words(const std::string& status);

}  // namespace lidef::studio
