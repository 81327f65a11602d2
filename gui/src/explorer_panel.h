// The studio's σ3 explorer panel (docs/explorer.md): a harmonic map on a ball (an explorer map JSON, read
// with read_explorer_example), σ3 on three orthogonal slice planes through the ball in rest space, the ball's
// boundary sphere, the located interior minima of σ3 (find_sigma3_minima) and the comparison that makes the
// map a counterexample to a minimum principle: the lowest interior minimum against the minimum of σ3 sampled
// on the boundary sphere (sampled_sphere_min_sigma3).
//
// Self-contained: its own VTK view and controls. The computations run on one worker thread (a cage map takes
// seconds); results come back to the UI thread, and only the newest request is computed when several pile up.
#pragma once
#include <QWidget>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "lidef/types.h"

class QCheckBox;
class QLabel;
class QSlider;
class QSpinBox;
class QVTKOpenGLNativeWidget;
class vtkRenderWindow;

namespace lidef::studio {

class ExplorerPanel : public QWidget {
  Q_OBJECT
 public:
  // data_dir: the repository's data folder; the "Shipped counterexample" button opens
  // <data_dir>/explorer/sigma3_interior_min.json.
  explicit ExplorerPanel(std::string data_dir, QWidget* parent = nullptr);
  ~ExplorerPanel() override;  // waits for a running computation

  // Reads the map file now; on an error reports it (dialog, or the error sink) naming the file, keeps the
  // shown map and returns false. Otherwise starts computing minima, boundary minimum and slices and returns
  // true: the accessors below describe the new map once busy() is false (signal example_shown).
  bool open_example(const std::string& path);
  bool open_shipped_example();
  std::string shipped_example_path() const;
  // Pumps the Qt event loop until no computation is running or queued; false on timeout.
  bool wait_until_idle(double seconds = 60);
  bool busy() const;

  // Slice planes: x, y and z planes at center + t R e_axis, t in [-1, 1]; resolution: samples across the
  // ball's diameter (8 … 256, default 48).
  void set_slice_offset(double t);
  double slice_offset() const;
  void set_resolution(int n);
  int resolution() const;
  void set_show_minima(bool on);  // the minimum markers and their labels

  // The shown map (empty / 0 / NaN before the first one).
  std::string path() const;
  int num_minima() const;         // interior minima located (strict or not)
  int num_strict_minima() const;  // confirmed by the Hessian and the small-sphere check
  double interior_min() const;    // lowest σ3 among them (NaN when none)
  Vec3 interior_min_position() const;
  double boundary_min() const;  // σ3 sampled on the boundary sphere (icosphere, 2,562 points)
  Vec3 boundary_min_position() const;
  double analysis_ms() const;   // wall time of the last minima + boundary + colour range computation
  double slices_ms() const;     // wall time of the last slice evaluation
  std::string caption() const;  // the text shown above the view
  vtkRenderWindow* render_window() const;
  QVTKOpenGLNativeWidget* view_widget() const { return view_; }

  // Where error messages go: by default a modal dialog; tests collect them instead.
  void set_error_sink(std::function<void(const std::string&)> sink) { error_sink_ = std::move(sink); }

 signals:
  void example_shown();  // a computed result was drawn (new map, offset or resolution)

 private:
  struct Impl;
  struct Request;
  struct Result;
  void report_error(const std::string& title, const std::string& message);
  void kick();  // starts the worker on the wanted state when it differs from the shown one
  void finished(std::shared_ptr<Result> r);  // UI thread
  void draw(const Result& r, bool reset_camera);

  std::string data_dir_;
  std::unique_ptr<Impl> impl_;
  QVTKOpenGLNativeWidget* view_ = nullptr;
  QSlider* offset_slider_ = nullptr;
  QLabel* offset_label_ = nullptr;
  QSpinBox* resolution_box_ = nullptr;
  QCheckBox* minima_box_ = nullptr;
  QLabel* caption_label_ = nullptr;
  QLabel* status_ = nullptr;
  std::thread worker_;
  bool running_ = false;
  std::function<void(const std::string&)> error_sink_;
};

}  // namespace lidef::studio
