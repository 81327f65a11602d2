#include "studio_window.h"

#include <QVTKOpenGLNativeWidget.h>
#include <vtkAxesActor.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCellPicker.h>
#include <vtkCommand.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkHandleWidget.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkObjectFactory.h>
#include <vtkOpenGLRenderer.h>
#include <vtkOrientationMarkerWidget.h>
#include <vtkPNGWriter.h>
#include <vtkPolyData.h>
#include <vtkPropPicker.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkSphereHandleRepresentation.h>
#include <vtkWindowToImageFilter.h>

#include <QAction>
#include <QActionGroup>
#include <QApplication>
#include <QButtonGroup>
#include <QCheckBox>
#include <QClipboard>
#include <QCloseEvent>
#include <QComboBox>
#include <QDockWidget>
#include <QDoubleSpinBox>
#include <QDragEnterEvent>
#include <QDropEvent>
#include <QFileDialog>
#include <QFileInfo>
#include <QFormLayout>
#include <QGroupBox>
#include <QGuiApplication>
#include <QLabel>
#include <QMenuBar>
#include <QMessageBox>
#include <QMimeData>
#include <QProgressBar>
#include <QProgressDialog>
#include <QPushButton>
#include <QRadioButton>
#include <QScreen>
#include <QScrollArea>
#include <QScrollBar>
#include <QSettings>
#include <QSlider>
#include <QSpinBox>
#include <QStatusBar>
#include <QTimer>
#include <QToolBar>
#include <QVBoxLayout>
#include <QWheelEvent>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "compare_view.h"
#include "explorer_panel.h"
#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/deform_outputs.h"
#include "lidef/analysis/mesh_export.h"
#include "lidef/analysis/vtk_export.h"
#include "lidef/atomic_file.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_fields.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/subspace.h"
#include "params_panel.h"
#include "plots_panel.h"
#include "studio_common.h"

namespace lidef::studio {

// A renderer that draws translucent geometry with plain alpha blending instead of vtkOpenGLRenderer's
// order-independent transparency (extra full-viewport passes; ~9% of a Lipschitz-view frame under Mesa's
// software renderer, CHANGELOG.md, 2026-11-23). The only translucent prop is the faint context mesh: one
// colour at one opacity, for which the blending order changes little.
// clang-format off
class PlainBlendRenderer : public vtkOpenGLRenderer {
 public:
  static PlainBlendRenderer* New();
  vtkTypeMacro(PlainBlendRenderer, vtkOpenGLRenderer)
  void DeviceRenderTranslucentPolygonalGeometry(vtkFrameBufferObjectBase* fbo) override {
    vtkRenderer::DeviceRenderTranslucentPolygonalGeometry(fbo);  // UpdateTranslucentPolygonalGeometry()
  }
};
vtkStandardNewMacro(PlainBlendRenderer)

// The camera style with the studio's clicks: a left click (press and release within 3 pixels) adds a handle,
// a right press on a target deletes it instead of zooming. It lives in the style because the style grabs the
// interactor's focus on a press, so observers of the interactor never see the matching release.
class StudioStyle : public vtkInteractorStyleTrackballCamera {
  // clang-format on
 public:
  static StudioStyle* New();
  vtkTypeMacro(StudioStyle, vtkInteractorStyleTrackballCamera)
      std::function<void(int, int, bool)> on_click;  // x, y, Ctrl held
  std::function<bool(int, int)> on_right_press;      // true = consumed
  std::function<void(int, int)> on_hover;            // x, y of a move with no button held
  void OnLeftButtonDown() override {
    this->Interactor->GetEventPosition(press_);
    vtkInteractorStyleTrackballCamera::OnLeftButtonDown();
  }
  void OnLeftButtonUp() override {
    vtkInteractorStyleTrackballCamera::OnLeftButtonUp();
    int xy[2];
    this->Interactor->GetEventPosition(xy);
    if (std::abs(xy[0] - press_[0]) <= 3 && std::abs(xy[1] - press_[1]) <= 3 && on_click)
      on_click(xy[0], xy[1], this->Interactor->GetControlKey() != 0);
  }
  // Mouse moves with no button held (the style is not rotating, panning or zooming) are hover positions.
  void OnMouseMove() override {
    vtkInteractorStyleTrackballCamera::OnMouseMove();
    if (this->State != VTKIS_NONE || !on_hover) return;
    int xy[2];
    this->Interactor->GetEventPosition(xy);
    on_hover(xy[0], xy[1]);
  }
  void OnRightButtonDown() override {
    int xy[2];
    this->Interactor->GetEventPosition(xy);
    if (on_right_press && on_right_press(xy[0], xy[1])) return;
    vtkInteractorStyleTrackballCamera::OnRightButtonDown();
  }

 private:
  int press_[2] = {0, 0};
};
vtkStandardNewMacro(StudioStyle)

    // One draggable target: a cyan sphere (vtkHandleWidget + sphere representation) and its drag observer.
    struct StudioWindow::Widget {
  vtkSmartPointer<vtkHandleWidget> widget = vtkSmartPointer<vtkHandleWidget>::New();
  vtkSmartPointer<vtkSphereHandleRepresentation> rep = vtkSmartPointer<vtkSphereHandleRepresentation>::New();
  vtkSmartPointer<vtkCallbackCommand> cb = vtkSmartPointer<vtkCallbackCommand>::New();
  int index = 0;
  StudioWindow* owner = nullptr;
};

// Passes a wheel event to the scroll area instead of a widget that has no focus.
class WheelGuard : public QObject {
 public:
  using QObject::QObject;
  bool eventFilter(QObject* o, QEvent* e) override {
    auto* w = qobject_cast<QWidget*>(o);
    if (e->type() != QEvent::Wheel || !w || w->hasFocus()) return false;
    for (QWidget* p = w->parentWidget(); p; p = p->parentWidget())
      if (auto* scroll = qobject_cast<QScrollArea*>(p)) {
        QApplication::sendEvent(scroll->verticalScrollBar(), e);
        break;
      }
    return true;
  }
};

StudioWindow::StudioWindow(QWidget* parent) : QMainWindow(parent) {
  wheel_guard_ = new WheelGuard(this);
  sources_.resize(0, 3);
  targets_.resize(0, 3);
  setAcceptDrops(true);
  build_ui();
  // Frames arrive on the engine thread; errors too.
  session_ = std::make_unique<InteractiveSession>(
      [this](std::shared_ptr<const SessionFrame> f) { on_frame(std::move(f)); },
      [this](const std::string& e) {
        QMetaObject::invokeMethod(
            this, [this, e] { report_error("Solver", e); }, Qt::QueuedConnection);
      },
      opencl_backend_factory(default_cache_dir()));
  session_->set_extras(extras_for(settings_));
  // A scenario whose "model" is a mesh file opens its automatic cage, with the same progress dialog.
  session_->set_model_resolver([this](const std::string& p) { return resolve_model(p); });
}

StudioWindow::~StudioWindow() {
  session_.reset();  // joins the engine thread before the widgets go
  for (auto& w : widgets_) w->widget->Off();
}

vtkRenderWindow* StudioWindow::render_window() const {
  return window_;
}

void StudioWindow::build_ui() {
  setWindowTitle("lidef-studio");
  view_ = new QVTKOpenGLNativeWidget(this);
  auto win = vtkSmartPointer<vtkGenericOpenGLRenderWindow>::New();
  view_->setRenderWindow(win);
  window_ = win;
  // No MSAA while interacting: under Mesa's software renderer (Xvfb, this 2-core machine) 4x MSAA doubles the
  // render time and the renderer shares the cores with the solver (CHANGELOG.md, 2026-11-22).
  window_->SetMultiSamples(0);
  auto ren = vtkSmartPointer<PlainBlendRenderer>::New();
  ren->SetBackground(1, 1, 1);
  ren->SetBackground2(0.86, 0.89, 0.94);
  ren->GradientBackgroundOn();
  window_->AddRenderer(ren);
  renderer_ = ren;
  // The colour bar lives in its own strip at the right edge, so it never covers the model.
  auto bar_ren = vtkSmartPointer<vtkRenderer>::New();
  bar_ren->SetBackground(1, 1, 1);
  bar_ren->SetBackground2(0.86, 0.89, 0.94);
  bar_ren->GradientBackgroundOn();
  bar_ren->InteractiveOff();
  ren->SetViewport(0, 0, 0.84, 1);
  bar_ren->SetViewport(0.84, 0, 1, 1);
  window_->AddRenderer(bar_ren);
  bar_renderer_ = bar_ren;
  scene_ = std::make_unique<Scene>(renderer_, bar_renderer_);
  setCentralWidget(view_);

  // Click on the mesh adds a handle; right-click on a target deletes it. The handle widgets (observer
  // priority 0.5) see a press before the style and keep it when they grab a sphere.
  auto style = vtkSmartPointer<StudioStyle>::New();
  // In the mesh view a click adds a handle and Ctrl+click picks; in the other views a click picks.
  style->on_click = [this](int x, int y, bool ctrl) {
    if (dragging_ >= 0) return;
    if (settings_.view == View::kMesh && !ctrl)
      add_handle_at_display(x, y);
    else
      pick_at_display(x, y);
  };
  style->on_right_press = [this](int x, int y) { return delete_handle_at_display(x, y); };
  // Hover: the newest position is picked at most once per kHoverMs, from the event loop (never inside the
  // mouse event, never while a handle is dragged), so moving the mouse does not hold up rendering.
  hover_timer_ = new QTimer(this);
  hover_timer_->setSingleShot(true);
  hover_timer_->setInterval(kHoverMs);
  connect(hover_timer_, &QTimer::timeout, this, [this] {
    if (hover_enabled_ && dragging_ < 0) hover_at_display(hover_xy_[0], hover_xy_[1]);
  });
  style->on_hover = [this](int x, int y) {
    if (!hover_enabled_) return;
    hover_xy_[0] = x;
    hover_xy_[1] = y;
    if (!hover_timer_->isActive()) hover_timer_->start();
  };
  window_->GetInteractor()->SetInteractorStyle(style);
  // Orientation axes in the lower-left corner (x red, y yellow, z green), turning with the camera.
  auto axes = vtkSmartPointer<vtkAxesActor>::New();
  axes_widget_ = vtkSmartPointer<vtkOrientationMarkerWidget>::New();
  axes_widget_->SetOrientationMarker(axes);
  axes_widget_->SetInteractor(window_->GetInteractor());
  axes_widget_->SetViewport(0.0, 0.0, 0.13, 0.2);
  axes_widget_->SetEnabled(1);
  axes_widget_->InteractiveOff();
  QSettings st;
  up_axis_ = std::clamp(st.value("view/up_axis", 1).toInt(), 0, 2);

  // Menus and tool bar.
  QMenu* file = menuBar()->addMenu("&File");
  QAction* open_model = file->addAction("Open &model folder...", this, [this] {
    const QString d = QFileDialog::getExistingDirectory(this, "Open model folder (cage.obj, mesh.obj)");
    if (!d.isEmpty()) open_path(d.toStdString());
  });
  QAction* open_mesh = file->addAction("Open m&esh (automatic cage)...", this, [this] {
    const QString f =
        QFileDialog::getOpenFileName(this, "Open a mesh: lidef makes its cage", {},
                                     "Meshes (*.obj *.off *.ply *.stl *.OBJ *.OFF *.PLY *.STL)");
    if (!f.isEmpty()) open_path(f.toStdString());
  });
  QAction* open_sc = file->addAction("&Open scenario or session...", this, [this] {
    const QString f = QFileDialog::getOpenFileName(this, "Open scenario", {}, "Scenario JSON (*.json)");
    if (!f.isEmpty()) open_path(f.toStdString());
  });
  open_sc->setShortcut(QKeySequence::Open);
  QMenu* recent = file->addMenu("Open &recent");
  recent->setObjectName("recent_menu");
  connect(recent, &QMenu::aboutToShow, this, [this, recent] { fill_recent_menu(recent); });
  QAction* save = file->addAction("&Save session...", this, [this] {
    const QString f = QFileDialog::getSaveFileName(this, "Save session", {}, "Scenario JSON (*.json)");
    if (!f.isEmpty()) save_session(f.toStdString());
  });
  save->setShortcut(QKeySequence::Save);
  file->addAction("Open &comparison folder (lidef compare --out)...", this, [this] {
    const QString d = QFileDialog::getExistingDirectory(this, "Open a lidef compare output folder");
    if (!d.isEmpty()) open_comparison(d.toStdString());
  });
  file->addAction("Save &screenshot...", this, [this] {
    const QString f = QFileDialog::getSaveFileName(this, "Save screenshot", {}, "PNG (*.png)");
    if (!f.isEmpty()) save_screenshot(f.toStdString());
  });
  file->addAction("Save screenshot, transparent &background...", this, [this] {
    const QString f = QFileDialog::getSaveFileName(this, "Save screenshot (RGBA)", {}, "PNG (*.png)");
    if (!f.isEmpty()) save_screenshot(f.toStdString(), 0, 0, true);
  });
  file->addAction("Save screenshot at &1920x1080...", this, [this] {
    const QString f = QFileDialog::getSaveFileName(this, "Save screenshot (1920x1080)", {}, "PNG (*.png)");
    if (!f.isEmpty()) save_screenshot(f.toStdString(), 1920, 1080, false);
  });
  file->addAction("&Export map, certificate and fields (as the CLI writes them)...", this, [this] {
    const QString d = QFileDialog::getExistingDirectory(this, "Export into folder");
    if (!d.isEmpty()) export_current(d.toStdString());
  });
  file->addSeparator();
  file->addAction("&Quit", this, [this] { close(); })->setShortcut(QKeySequence::Quit);
  QMenu* edit = menuBar()->addMenu("&Edit");
  QAction* undo_a = edit->addAction("&Undo handle edit", this, [this] { undo(); });
  undo_a->setShortcut(QKeySequence::Undo);
  QAction* redo_a = edit->addAction("&Redo handle edit", this, [this] { redo(); });
  redo_a->setShortcut(QKeySequence::Redo);
  edit->addAction("Delete all handles", this, [this] {
    if (!edits_allowed()) return;
    push_undo();
    sources_.resize(0, 3);
    targets_.resize(0, 3);
    send_handles();
  });
  QMenu* solver = menuBar()->addMenu("&Solver");
  QAction* solve_a = solver->addAction("&Solve", this, [this] { session_->solve(); });
  QAction* stop_a = solver->addAction("S&top", this, [this] { session_->stop(); });
  stop_a->setShortcut(Qt::Key_Escape);
  QAction* reset_a = solver->addAction("&Reset to identity", this, [this] { session_->reset(); });
  QAction* verify_a = solver->addAction("&Verify certificate (dense sampling, Fig. 5)", this,
                                        [this] { session_->verify(32); });
  QMenu* camera = menuBar()->addMenu("&Camera");
  camera->addAction("&Reset", this, [this] { reset_camera(); })->setShortcut(Qt::Key_R);
  const char* preset_names[6] = {"From +X", "From -X", "From +Y", "From -Y", "From +Z", "From -Z"};
  for (int k = 0; k < 6; ++k)
    camera->addAction(preset_names[k], this, [this, k] { camera_preset(k / 2, k % 2 == 0); })
        ->setShortcut(Qt::Key_1 + k);
  QAction* ortho = camera->addAction("&Orthographic projection");
  ortho->setCheckable(true);
  ortho->setObjectName("orthographic");
  ortho->setShortcut(Qt::Key_O);
  connect(ortho, &QAction::toggled, this, [this](bool on) { set_orthographic(on); });
  camera->addSeparator();
  camera->addAction("&Copy camera (JSON)", this, [this] { copy_camera(); })
      ->setShortcut(QKeySequence("Ctrl+Shift+C"));
  camera->addAction("&Paste camera (JSON)", this, [this] { paste_camera(); })
      ->setShortcut(QKeySequence("Ctrl+Shift+V"));
  QMenu* help = menuBar()->addMenu("&Help");
  QAction* cheat = help->addAction("&Keyboard and mouse (cheat sheet)", this, [this] { show_cheat_sheet(); });
  cheat->setShortcuts({QKeySequence(Qt::Key_F1), QKeySequence(Qt::Key_H)});
  QToolBar* tb = addToolBar("Main");
  tb->setObjectName("Main");
  tb->addAction(open_model);
  tb->addAction(open_mesh);
  tb->addAction(open_sc);
  tb->addAction(save);
  tb->addSeparator();
  tb->addAction(undo_a);
  tb->addAction(redo_a);
  tb->addSeparator();
  tb->addAction(solve_a);
  tb->addAction(stop_a);
  tb->addAction(reset_a);
  tb->addAction(verify_a);
  chrome_.push_back(tb);
  chrome_.push_back(menuBar());

  // Panels: one column of dock widgets on the right (collapsible, movable; the layout is saved with
  // QSettings), so the 3D view keeps most of the window.
  auto dock = [&](const char* title, QWidget* w) {
    auto* d = new QDockWidget(title, this);
    d->setObjectName(title);
    d->setWidget(w);
    addDockWidget(Qt::RightDockWidgetArea, d);
    chrome_.push_back(d);
    return d;
  };
  view_panel_ = build_view_panel();
  auto* view_scroll = new QScrollArea;
  view_scroll->setObjectName("view_scroll");
  view_scroll->setWidgetResizable(true);
  view_scroll->setWidget(view_panel_);
  auto* vd = dock("View", view_scroll);
  params_ = new ParamsPanel(this);
  auto* pd = dock("Parameters", params_);
  tabifyDockWidget(vd, pd);
  vd->raise();
  connect(params_, &ParamsPanel::params_applied, this, [this](const DeformParams& p, bool) {
    try {
      session_->set_params(p);
      plots_->set_bound_tolerance(p.bound_tolerance);
    } catch (const std::exception& e) {
      report_error("Parameters", e.what());
    }
  });
  picked_label_ = new QLabel(QString::fromStdString(to_text(picked_)));
  picked_label_->setObjectName("picked");
  picked_label_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  picked_label_->setWordWrap(true);
  picked_label_->setAlignment(Qt::AlignTop | Qt::AlignLeft);
  picked_label_->setMargin(4);
  auto* picked_box = new QWidget;
  auto* picked_layout = new QVBoxLayout(picked_box);
  picked_layout->setContentsMargins(0, 0, 0, 0);
  hover_check_ = new QCheckBox("Values under the cursor (hover)");
  hover_check_->setObjectName("hover");
  hover_check_->setChecked(hover_enabled_);
  hover_check_->setToolTip(
      "Show the values at the point under the mouse as it moves (click or Ctrl+click picks)");
  connect(hover_check_, &QCheckBox::toggled, this, [this](bool on) { set_hover(on); });
  picked_layout->addWidget(hover_check_);
  picked_layout->addWidget(picked_label_, 1);
  auto* picked_dock = dock("Picked values", picked_box);
  plots_ = new PlotsPanel(this);
  auto* plots_dock = dock("Plots", plots_);
  // The σ3 counterexample explorer (docs/explorer.md): its own map and view, beside the plots.
  const char* data_env = std::getenv("LIDEF_DATA");
  auto* explorer = new ExplorerPanel(data_env ? data_env : LIDEF_STUDIO_DATA_DIR, this);
  explorer->set_error_sink([this](const std::string& e) { report_error("Explorer", e); });
  tabifyDockWidget(plots_dock, dock("sigma3 explorer", explorer));
  plots_dock->raise();
  splitDockWidget(vd, picked_dock, Qt::Vertical);
  splitDockWidget(picked_dock, plots_dock, Qt::Vertical);
  resizeDocks({vd, picked_dock, plots_dock}, {330, 150, 330}, Qt::Vertical);
  resizeDocks({vd}, {360}, Qt::Horizontal);
  build_view_menu(help);

  badge_ = new QLabel(" no map ");
  badge_->setObjectName("badge");
  status_ = new QLabel("File > Open a model folder or a scenario; click on the mesh to add a handle");
  status_->setObjectName("status");
  statusBar()->addWidget(status_, 1);
  prepare_bar_ = new QProgressBar;
  prepare_bar_->setObjectName("prepare_bar");
  prepare_bar_->setRange(0, 1000);
  prepare_bar_->setMinimumWidth(320);
  prepare_bar_->setVisible(false);
  prepare_cancel_ = new QPushButton("Cancel");
  prepare_cancel_->setObjectName("prepare_cancel");
  prepare_cancel_->setToolTip("Stop preprocessing this model (the model before stays open)");
  prepare_cancel_->setVisible(false);
  connect(prepare_cancel_, &QPushButton::clicked, this, [this] { cancel_opening(); });
  statusBar()->addPermanentWidget(prepare_bar_);
  statusBar()->addPermanentWidget(prepare_cancel_);
  // A solver iteration that runs for seconds (a large model, a long line search): a busy bar and Stop.
  wait_bar_ = new QProgressBar;
  wait_bar_->setObjectName("wait_bar");
  wait_bar_->setRange(0, 0);
  wait_bar_->setMinimumWidth(200);
  wait_bar_->setVisible(false);
  wait_stop_ = new QPushButton("Stop");
  wait_stop_->setObjectName("wait_stop");
  wait_stop_->setToolTip(
      "Interrupt the solver after its current line-search trial (Esc); the map stays certified");
  wait_stop_->setVisible(false);
  connect(wait_stop_, &QPushButton::clicked, this, [this] { session_->stop(); });
  statusBar()->addPermanentWidget(wait_bar_);
  statusBar()->addPermanentWidget(wait_stop_);
  auto* wait_timer = new QTimer(this);
  wait_timer->setInterval(250);
  connect(wait_timer, &QTimer::timeout, this, [this] {
    const auto now = std::chrono::steady_clock::now().time_since_epoch().count();
    const double idle =
        std::chrono::duration<double>(std::chrono::steady_clock::duration(now - last_frame_ns_.load()))
            .count();
    update_long_wait(session_->state(), idle);
  });
  wait_timer->start();
  statusBar()->addPermanentWidget(badge_);
  chrome_.push_back(statusBar());
  // First run: most of the screen (the saved geometry replaces it, restore_layout()).
  QSize size(1280, 800);
  if (const QScreen* screen = QGuiApplication::primaryScreen()) {
    const QRect avail = screen->availableGeometry();
    size = QSize(std::max(1024, static_cast<int>(0.85 * avail.width())),
                 std::max(700, static_cast<int>(0.85 * avail.height())));
    size = size.boundedTo(avail.size());
  }
  resize(size);
}

// View menu: the panels (closed ones come back here), the up axis, orientation axes, mesh edges.
void StudioWindow::build_view_menu(QMenu* before) {
  QMenu* view = new QMenu("&View", this);
  view->setObjectName("view_menu");
  menuBar()->insertMenu(before->menuAction(), view);
  for (QDockWidget* d : findChildren<QDockWidget*>()) view->addAction(d->toggleViewAction());
  for (QToolBar* t : findChildren<QToolBar*>()) view->addAction(t->toggleViewAction());
  view->addSeparator();
  QMenu* up = view->addMenu("&Up axis");
  auto* group = new QActionGroup(this);
  const char* names[3] = {"+X up", "+Y up", "+Z up"};
  for (int a = 0; a < 3; ++a) {
    QAction* act = up->addAction(names[a]);
    act->setObjectName(QString("up_") + "xyz"[a]);
    act->setCheckable(true);
    act->setChecked(a == up_axis_);
    group->addAction(act);
    connect(act, &QAction::triggered, this, [this, a] { set_up_axis(a); });
  }
  QAction* axes = view->addAction("&Orientation axes");
  axes->setObjectName("orientation_axes");
  axes->setCheckable(true);
  axes->setChecked(true);
  connect(axes, &QAction::toggled, this, [this](bool on) { set_orientation_axes(on); });
  QAction* edges = view->addAction("Mesh &edges");
  edges->setObjectName("mesh_edges");
  edges->setCheckable(true);
  edges->setShortcut(Qt::Key_E);
  edges->setChecked(settings_.mesh_edges);
  connect(edges, &QAction::toggled, this, [this](bool on) {
    if (settings_.mesh_edges == on) return;
    settings_.mesh_edges = on;
    refresh_view_panel();
    settings_changed();
  });
}

void StudioWindow::set_up_axis(int axis) {
  up_axis_ = std::clamp(axis, 0, 2);
  QSettings().setValue("view/up_axis", up_axis_);
  if (auto* a = findChild<QAction*>(QString("up_") + "xyz"[up_axis_])) {
    const QSignalBlocker block(a);
    a->setChecked(true);
  }
  reset_camera();
}

void StudioWindow::set_orientation_axes(bool on) {
  axes_widget_->SetEnabled(on ? 1 : 0);
  if (on) axes_widget_->InteractiveOff();
  if (auto* a = findChild<QAction*>("orientation_axes")) {
    const QSignalBlocker block(a);
    a->setChecked(on);
  }
  window_->Render();
}

bool StudioWindow::orientation_axes() const {
  return axes_widget_->GetEnabled() != 0;
}

QStringList StudioWindow::recent_files() const {
  return QSettings().value("recent/files").toStringList();
}

void StudioWindow::add_recent(const std::string& path) {
  const QString p = QString::fromStdString(std::filesystem::absolute(path).lexically_normal().string());
  QStringList list = recent_files();
  list.removeAll(p);
  list.prepend(p);
  while (list.size() > kRecentFiles) list.removeLast();
  QSettings().setValue("recent/files", list);
}

void StudioWindow::fill_recent_menu(QMenu* menu) {
  menu->clear();
  const QStringList list = recent_files();
  if (list.isEmpty()) menu->addAction("(none yet)")->setEnabled(false);
  for (const QString& f : list) menu->addAction(f, this, [this, f] { open_path(f.toStdString()); });
}

QWidget* StudioWindow::build_view_panel() {
  auto* w = new QWidget;
  auto* lay = new QVBoxLayout(w);
  auto* views = new QGroupBox("View");
  auto* vl = new QVBoxLayout(views);
  auto* group = new QButtonGroup(w);
  const char* names[4] = {"Deformed mesh", "sigma3 field", "Lipschitz bound", "Octree leaves"};
  for (int i = 0; i < 4; ++i) {
    auto* r = new QRadioButton(names[i]);
    r->setObjectName(QString("view_") + to_string(static_cast<View>(i)));
    r->setChecked(i == static_cast<int>(settings_.view));
    group->addButton(r, i);
    vl->addWidget(r);
  }
  connect(group, &QButtonGroup::idClicked, this, [this](int id) {
    settings_.view = static_cast<View>(id);
    settings_changed();
    // The colour-range group shows the new view's field.
    QMetaObject::invokeMethod(
        this, [this] { refresh_view_panel(); }, Qt::QueuedConnection);
  });
  auto* dist = new QCheckBox("Distortion sigma1/sigma3");
  dist->setObjectName("view_distortion");
  dist->setChecked(settings_.distortion);
  dist->setToolTip(
      "Colour by sigma1/sigma3 instead: at the mesh vertices, on the slices, and in the Lipschitz view the "
      "certified upper bound per leaf; the caption gives the certified bound over the whole domain");
  connect(dist, &QCheckBox::toggled, this, [this](bool on) {
    settings_.distortion = on;
    settings_changed();
    QMetaObject::invokeMethod(
        this, [this] { refresh_view_panel(); }, Qt::QueuedConnection);
  });
  vl->addWidget(dist);
  auto* global = new QCheckBox("Check global injectivity");
  global->setObjectName("view_global_injectivity");
  global->setChecked(settings_.global_injectivity);
  global->setToolTip(
      "When the solver rests, prove or refute that the deformed shape does not pass through itself (one "
      "check takes seconds; while it runs the badge says 'checking'). An overlap is drawn: the two touching "
      "parts of the surface red, a yellow sphere where they meet");
  connect(global, &QCheckBox::toggled, this, [this](bool on) {
    settings_.global_injectivity = on;
    settings_changed();
  });
  vl->addWidget(global);
  lay->addWidget(views);
  lay->addWidget(build_range_controls());
  auto check = [&](QLayout* l, const char* text, bool* field, const char* tip) {
    auto* c = new QCheckBox(text);
    c->setChecked(*field);
    c->setToolTip(tip);
    connect(c, &QCheckBox::toggled, this, [this, field](bool on) {
      *field = on;
      settings_changed();
    });
    l->addWidget(c);
    return c;
  };
  auto* mesh = new QGroupBox("Mesh");
  auto* ml = new QVBoxLayout(mesh);
  check(ml, "Colour by local volume ratio (det J)", &settings_.mesh_volume_ratio,
        "Otherwise by E_iso - 6, the symmetric Dirichlet density above its minimum (0 at rotations)");
  check(ml, "Rest cage", &settings_.rest_cage, "Wireframe of the cage");
  check(ml, "Deformed cage", &settings_.deformed_cage, "Wireframe of the vertex coefficients y_v");
  check(ml, "Triangle edges", &settings_.mesh_edges,
        "The mesh's edges over its colours (View > Mesh edges, E)");
  check(ml, "Point colours of the file", &settings_.point_colors,
        "A point cloud or Gaussian splats: the colours of the PLY file (a splat's f_dc, red green blue) "
        "instead of the field");
  lay->addWidget(mesh);
  auto* sig = new QGroupBox("sigma3 field");
  auto* sl = new QVBoxLayout(sig);
  check(sl, "Deformed space", &settings_.sigma_deformed_space, "Draw the slices at f(p) instead of p");
  check(sl, "Volume rendering (rest space)", &settings_.sigma_volume,
        "Ray-cast volume of sigma3; low values opaque");
  check(sl, "Whole cage interior", &settings_.sigma_whole_cage,
        "Also show sigma3 between the voxels and the cage, where the certificate says nothing");
  const char* axes[3] = {"x slice", "y slice", "z slice"};
  for (int a = 0; a < 3; ++a) {
    auto* row = new QWidget;
    auto* rl = new QHBoxLayout(row);
    rl->setContentsMargins(0, 0, 0, 0);
    check(rl, axes[a], &settings_.slice[a], "Show this slice plane");
    auto* s = new QSlider(Qt::Horizontal);
    s->setRange(0, 100);
    s->setValue(static_cast<int>(settings_.slice_pos[a] * 100));
    connect(s, &QSlider::valueChanged, this, [this, a](int v) {
      settings_.slice_pos[a] = v / 100.0;
      settings_changed();
    });
    rl->addWidget(s);
    sl->addWidget(row);
  }
  lay->addWidget(sig);
  auto* leaves = new QGroupBox("Lipschitz / octree");
  auto* ll = new QFormLayout(leaves);
  auto* lcol = new QVBoxLayout;
  check(lcol, "Lipschitz: colour by margin sigma3 - rL", &settings_.lipschitz_margin,
        "Otherwise by L; a leaf is certified when the margin exceeds the rounding allowance");
  check(lcol, "Lipschitz: only refined or failed leaves", &settings_.only_refined_or_failed,
        "Hide base voxels that passed at once");
  check(lcol, "Octree: colour by status", &settings_.octree_by_status, "Otherwise by depth");
  ll->addRow(lcol);
  auto* clip = new QSlider(Qt::Horizontal);
  clip->setRange(0, 100);
  clip->setValue(static_cast<int>(settings_.clip * 100));
  clip->setToolTip("Keep leaves whose center lies below this fraction of the longest axis (see inside)");
  connect(clip, &QSlider::valueChanged, this, [this](int v) {
    settings_.clip = v / 100.0;
    settings_changed();
  });
  ll->addRow("Clip plane", clip);
  auto* depth = new QSpinBox;
  depth->setRange(0, 12);
  depth->setValue(settings_.min_depth);
  depth->setToolTip("Show only leaves at least this deep (0 = all)");
  connect(depth, QOverload<int>::of(&QSpinBox::valueChanged), this, [this](int v) {
    settings_.min_depth = v;
    settings_changed();
  });
  ll->addRow("Min depth", depth);
  lay->addWidget(leaves);
  lay->addStretch(1);
  // The panel scrolls: a wheel turn over a box or slider the user did not click must scroll, never change
  // its value (a mode or slice jumping under a passing wheel).
  for (QWidget* c : w->findChildren<QWidget*>())
    if (qobject_cast<QComboBox*>(c) || qobject_cast<QAbstractSpinBox*>(c) || qobject_cast<QSlider*>(c)) {
      c->setFocusPolicy(Qt::StrongFocus);
      c->installEventFilter(wheel_guard_);
    }
  return w;
}

void StudioWindow::set_multisamples(int n) {
  window_->SetMultiSamples(n);
}

void StudioWindow::set_view_only(bool on) {
  view_only_ = on;
  for (QWidget* c : chrome_) c->setVisible(!on);
  set_orientation_axes(!on);  // pictures for papers and docs: the model alone
}

void StudioWindow::set_settings(const ViewSettings& s) {
  settings_ = s;
  refresh_view_panel();
  settings_changed();
}

void StudioWindow::refresh_view_panel() {
  // The panel's widgets are bound to settings_ fields; rebuilding it is the simplest way to show new values.
  auto* scroll = findChild<QScrollArea*>("view_scroll");
  if (!scroll) return;
  QWidget* old = scroll->takeWidget();
  view_panel_ = build_view_panel();
  scroll->setWidget(view_panel_);
  if (old) old->deleteLater();
}

void StudioWindow::set_params(const DeformParams& p) {
  params_->set_params(p);
  plots_->set_bound_tolerance(p.bound_tolerance);
  try {
    session_->set_params(p);
  } catch (const std::exception& e) {
    report_error("Parameters", e.what());
  }
}

void StudioWindow::settings_changed() {
  if (auto* a = findChild<QAction*>("mesh_edges"); a && a->isChecked() != settings_.mesh_edges) {
    const QSignalBlocker block(a);
    a->setChecked(settings_.mesh_edges);
  }
  session_->set_extras(extras_for(settings_));
  sync_widgets();  // the target spheres belong to the mesh view
  if (shown_) {
    std::lock_guard<std::mutex> lk(pending_mutex_);
    if (!pending_) pending_ = shown_;
  }
  QMetaObject::invokeMethod(
      this, [this] { render_pending(); }, Qt::QueuedConnection);
}

void report_to_user(QWidget* parent, QLabel* status, const std::function<void(const std::string&)>& sink,
                    const std::string& title, const std::string& message) {
  if (status) status->setText(QString::fromStdString(title + ": " + message));
  if (sink) {
    sink(message);
    return;
  }
  QMessageBox::critical(parent, QString::fromStdString("lidef-studio: " + title),
                        QString::fromStdString(message));
}

void StudioWindow::report_error(const std::string& title, const std::string& message) {
  report_to_user(this, status_, error_sink_, title, message);
}

std::string StudioWindow::resolve_model(const std::string& path) {
  if (!is_mesh_file(path)) return path;
  // Making a cage takes seconds: a worker thread makes it while this (UI) thread shows its stages in a
  // dialog at once (a minimum duration would hide it: a range of 0..0 never calls setValue), with Cancel.
  QProgressDialog progress(QString::fromStdString("Making a cage for " + path), "Cancel", 0, 0, this);
  progress.setObjectName("cage_progress");
  progress.setWindowTitle("Automatic cage");
  progress.setWindowModality(Qt::WindowModal);
  progress.setMinimumDuration(0);
  progress.setAutoClose(false);
  progress.setAutoReset(false);
  connect(&progress, &QProgressDialog::canceled, this, [this] { cancel_opening(); });
  std::mutex m;
  std::string last_line, folder;
  std::exception_ptr failure;
  std::atomic<bool> done{false};
  cage_cancel_.store(false);
  cage_running_.store(true);
  // The cage maker reports a line between its steps; a cancel is honoured there (it cannot stop inside a
  // step, so the dialog says it waits for the step to end).
  std::thread worker([&] {
    try {
      folder = resolve_model_path(path, [&](const std::string& line) {
        if (cage_line_hook_) cage_line_hook_(line);
        if (cage_cancel_.load()) throw Cancelled();
        std::lock_guard<std::mutex> lk(m);
        last_line = line;
      });
      if (cage_cancel_.load()) throw Cancelled();
    } catch (...) {
      failure = std::current_exception();
    }
    done.store(true);
  });
  progress.show();
  while (!done.load()) {
    {
      std::lock_guard<std::mutex> lk(m);
      if (cage_cancel_.load())
        progress.setLabelText("Cancelling: waiting for the cage maker's current step to end...");
      else if (!last_line.empty())
        progress.setLabelText(QString::fromStdString(last_line));
      model_note_ = last_line;
    }
    QApplication::processEvents(QEventLoop::AllEvents, 30);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  worker.join();
  cage_running_.store(false);
  if (failure) std::rethrow_exception(failure);
  model_note_ = last_line;
  return folder;
}

void StudioWindow::cancel_opening() {
  if (cage_running_.load())
    cage_cancel_.store(true);
  else
    session_->cancel_preparation();
}

bool StudioWindow::open_path(const std::string& path, const std::string& coefficients) {
  model_note_.clear();
  OpenRecord rec;
  rec.path = path;
  try {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec) || is_mesh_file(path)) {
      if (!coefficients.empty())
        throw InputError(coefficients, "a map to start from needs a scenario, and " + path + " is a model");
      const std::string dir = resolve_model(path);
      session_->open_model(dir, params_->params());
      rec.name = std::filesystem::path(path).filename().string();
      rec.source = std::filesystem::absolute(path).lexically_normal().string();
      rec.params = params_->params();
    } else {
      // Read first: its views are checked before anything is opened, and the model as the file names it
      // (before the resolver replaces a mesh file by its cage folder) is what a saved session names.
      const Scenario file = read_scenario(path);
      rec.source = std::filesystem::absolute(file.model_dir).lexically_normal().string();
      if (!file.studio.empty()) {
        const auto j = nlohmann::json::parse(file.studio);
        if (j.contains("views")) {
          rec.views = settings_;
          settings_from_json(j.at("views"), rec.views, path);
          rec.has_views = true;
        }
      }
      session_->open_scenario(path, "", coefficients);
      const Scenario sc = session_->scenario();
      rec.name = sc.name;
      rec.camera = sc.studio;
      rec.params = sc.params;
    }
  } catch (const Cancelled&) {
    status_->setText(QString::fromStdString("opening " + path + " cancelled" +
                                            (shown_model_ ? "; " + shown_name_ + " stays open" : "")));
    return false;
  } catch (const std::exception& e) {
    report_error("Cannot open " + path, e.what());
    return false;
  }
  rec.model = session_->model();
  rec.note = model_note_;
  opens_.push_back(rec);
  add_recent(path);
  sync_widgets();  // no handle drags while the model before is only on show
  status_->setText(QString::fromStdString(
      "opening " + path + (model_note_.empty() ? "" : " (" + model_note_ + ")") +
      (shown_model_ ? ": " + shown_name_ + " stays on screen until it is ready" : "")));
  return true;
}

// Openings the engine no longer prepares: it names another model now (a cancel or a failure restored the
// one before, or a newer opening replaced it). Their model never reaches the screen.
void StudioWindow::forget_dropped_opens() {
  if (opens_.empty()) return;
  const auto current = session_->model();
  std::string dropped;
  for (auto it = opens_.begin(); it != opens_.end();) {
    if (it->model == current) {
      ++it;
      continue;
    }
    dropped = it->name;
    it = opens_.erase(it);
  }
  if (!dropped.empty() && opens_.empty()) {
    status_->setText(
        QString::fromStdString("opening " + dropped + " did not complete (cancelled or failed); " +
                               (shown_model_ ? shown_name_ + " stays open" : "no model is open")));
    sync_widgets();
  }
}

// The engine holds a model the window does not show yet: adopt everything of it at once.
void StudioWindow::adopt_shown_model(const SessionFrame& f) {
  OpenRecord rec;
  bool found = false;
  for (size_t k = 0; k < opens_.size(); ++k)
    if (opens_[k].model == f.model) {
      rec = opens_[k];
      opens_.erase(opens_.begin(), opens_.begin() + static_cast<long>(k) + 1);  // older ones were replaced
      found = true;
      break;
    }
  if (!found && f.model) {
    rec.name = std::filesystem::path(f.model->dir).filename().string();
    rec.source = f.model->dir;
    rec.params = session_->scenario().params;
  }
  shown_model_ = f.model;
  shown_name_ = f.model ? rec.name : "";
  shown_source_ = f.model ? rec.source : "";
  scenario_name_ = shown_name_;
  setWindowTitle(QString::fromStdString(f.model ? "lidef-studio — " + shown_name_ : "lidef-studio"));
  if (rec.has_views) {
    settings_ = rec.views;
    refresh_view_panel();
    session_->set_extras(extras_for(settings_));
  }
  if (found) {
    params_->set_params(rec.params);
    plots_->set_bound_tolerance(rec.params.bound_tolerance);
  }
  sources_ = f.sources;
  targets_ = f.targets;
  undo_.clear();
  redo_.clear();
  picked_ = PickedValues{};
  picked_map_version_ = -1;
  picked_label_->setText(QString::fromStdString(to_text(picked_)));
  scene_->set_picked(false, Vec3::Zero(), Vec3::Zero());
  plots_->clear_verification();
  plots_->set_model_name(QString::fromStdString(shown_name_));
  scene_->set_model_name(shown_name_);
  if (f.model) load_point_colors(*f.model);
  shown_verification_version_ = -1;
  pending_camera_ = rec.camera;
  camera_to_reset_ = f.model != nullptr;
  if (found)
    status_->setText(
        QString::fromStdString("opened " + rec.path + (rec.note.empty() ? "" : " (" + rec.note + ")")));
}

bool StudioWindow::edits_allowed() {
  if (opens_.empty()) return true;
  status_->setText(QString::fromStdString("handles are locked while " + opens_.back().name +
                                          " is being prepared (Cancel keeps " +
                                          (shown_model_ ? shown_name_ : std::string("no model")) + ")"));
  return false;
}

long StudioWindow::drawn_mesh_points() const {
  vtkPolyData* pd = scene_->mesh_data();
  return pd && pd->GetPoints() ? static_cast<long>(pd->GetNumberOfPoints()) : 0;
}

std::string StudioWindow::camera_json() const {
  vtkCamera* cam = renderer_->GetActiveCamera();
  const double* p = cam->GetPosition();
  const double* fp = cam->GetFocalPoint();
  const double* up = cam->GetViewUp();
  nlohmann::json j;
  j["camera"] = {{"position", {p[0], p[1], p[2]}},
                 {"focal_point", {fp[0], fp[1], fp[2]}},
                 {"view_up", {up[0], up[1], up[2]}},
                 {"view_angle", cam->GetViewAngle()},
                 {"parallel_projection", cam->GetParallelProjection() != 0},
                 {"parallel_scale", cam->GetParallelScale()}};
  return j.dump();
}

std::string StudioWindow::studio_json() const {
  nlohmann::json j = nlohmann::json::parse(camera_json());
  j["views"] = settings_to_json(settings_);
  return j.dump();
}

void StudioWindow::apply_camera_object(const nlohmann::json& c) {
  auto v = [&](const char* k) {
    const auto x = c.at(k).get<std::vector<double>>();
    if (x.size() != 3) throw InputError("camera", std::string("\"") + k + "\" needs 3 numbers");
    return x;
  };
  const auto p = v("position"), fp = v("focal_point"), up = v("view_up");
  const double angle = c.at("view_angle").get<double>();
  const bool parallel = c.value("parallel_projection", false);
  const double scale = c.value("parallel_scale", 1.0);
  vtkCamera* cam = renderer_->GetActiveCamera();
  cam->SetPosition(p[0], p[1], p[2]);
  cam->SetFocalPoint(fp[0], fp[1], fp[2]);
  cam->SetViewUp(up[0], up[1], up[2]);
  cam->SetViewAngle(angle);
  cam->SetParallelProjection(parallel ? 1 : 0);
  cam->SetParallelScale(scale);
  renderer_->ResetCameraClippingRange();
  if (auto* a = findChild<QAction*>("orthographic")) {
    const QSignalBlocker block(a);
    a->setChecked(parallel);
  }
}

void StudioWindow::apply_camera_json(const std::string& text) {
  if (text.empty()) return;
  try {
    const auto j = nlohmann::json::parse(text);
    if (!j.contains("camera")) return;
    apply_camera_object(j.at("camera"));
  } catch (const std::exception& e) {
    report_error("Session camera", e.what());
  }
}

void StudioWindow::set_camera_json(const std::string& text) {
  try {
    const auto j = nlohmann::json::parse(text);
    if (!j.is_object() || !j.contains("camera"))
      throw InputError("camera", "expected {\"camera\": {...}} as Camera > Copy writes it");
    apply_camera_object(j.at("camera"));
  } catch (const nlohmann::json::exception& e) {
    throw InputError("camera", e.what());
  }
  window_->Render();
}

void StudioWindow::copy_camera() {
  QGuiApplication::clipboard()->setText(QString::fromStdString(camera_json()));
  status_->setText("camera copied to the clipboard (JSON)");
}

bool StudioWindow::paste_camera() {
  try {
    set_camera_json(QGuiApplication::clipboard()->text().toStdString());
  } catch (const std::exception& e) {
    report_error("Paste camera", e.what());
    return false;
  }
  status_->setText("camera pasted");
  return true;
}

void StudioWindow::reset_camera() {
  reset_camera_pose(false);
  renderer_->GetActiveCamera()->OrthogonalizeViewUp();
  renderer_->ResetCamera();
  window_->Render();
}

// A three-quarter view (it shows depth) with the chosen up axis pointing up, of what is drawn or (rest_cage)
// of the shown model's rest cage: an opened model gets the same view whichever of its frames comes first.
void StudioWindow::reset_camera_pose(bool rest_cage) {
  vtkCamera* cam = renderer_->GetActiveCamera();
  double up[3] = {0, 0, 0}, eye[3] = {0, 0, 0};
  up[up_axis_] = 1;
  eye[(up_axis_ + 1) % 3] = 1;  // y up: from +z; z up: from +x; x up: from +y
  cam->SetFocalPoint(0, 0, 0);
  cam->SetPosition(eye);
  cam->SetViewUp(up);
  double bounds[6];
  const bool fit_cage = rest_cage && shown_model_;
  if (fit_cage)
    for (int a = 0; a < 3; ++a) {
      bounds[2 * a] = shown_model_->cage.bbox_min(a);
      bounds[2 * a + 1] = shown_model_->cage.bbox_max(a);
    }
  auto fit = [&] {
    if (fit_cage)
      renderer_->ResetCamera(bounds);
    else
      renderer_->ResetCamera();
  };
  fit();
  cam->Azimuth(25);
  cam->Elevation(20);
  fit();
}

void StudioWindow::camera_preset(int axis, bool positive) {
  vtkCamera* cam = renderer_->GetActiveCamera();
  double dir[3] = {0, 0, 0};
  dir[axis] = positive ? 1 : -1;
  const double up[3][3] = {{0, 0, 1}, {0, 0, 1}, {0, 1, 0}};  // z up when looking along x or y
  cam->SetFocalPoint(0, 0, 0);
  cam->SetPosition(dir);
  cam->SetViewUp(up[axis][0], up[axis][1], up[axis][2]);
  renderer_->ResetCamera();
  window_->Render();
}

void StudioWindow::set_orthographic(bool on) {
  vtkCamera* cam = renderer_->GetActiveCamera();
  cam->SetParallelProjection(on ? 1 : 0);
  if (on) {  // the same apparent size at the focal point
    const double d = cam->GetDistance();
    cam->SetParallelScale(d * std::tan(0.5 * cam->GetViewAngle() * M_PI / 180));
  }
  renderer_->ResetCameraClippingRange();
  if (auto* a = findChild<QAction*>("orthographic")) {
    const QSignalBlocker block(a);
    a->setChecked(on);
  }
  window_->Render();
}

bool StudioWindow::orthographic() const {
  return renderer_->GetActiveCamera()->GetParallelProjection() != 0;
}

std::string StudioWindow::cheat_sheet() {
  return "Mouse\n"
         "  left click on the mesh (mesh view)   add a handle\n"
         "  Ctrl+left click (mesh view)          pick: sigma1, sigma3, det J, E_iso there\n"
         "  left click (sigma3, Lipschitz, octree views)  pick (with the leaf's depth, L, margin, status)\n"
         "  move the mouse (no button)           hover: the same values under the cursor (Picked values\n"
         "                                       panel; its checkbox turns hover off)\n"
         "  drag a cyan sphere                   move that handle's target\n"
         "  right click on a cyan sphere         delete the handle\n"
         "  left drag / middle drag / wheel      rotate / pan / zoom\n"
         "Keys\n"
         "  R                 reset the camera\n"
         "  1 2 / 3 4 / 5 6   look from +X -X / +Y -Y / +Z -Z\n"
         "  O                 orthographic projection on/off\n"
         "  E                 mesh edges on/off\n"
         "  Ctrl+Shift+C / V  copy / paste the camera as JSON\n"
         "  Ctrl+Z / Ctrl+Shift+Z  undo / redo handle edits\n"
         "  Esc               stop the solver\n"
         "  Ctrl+O / Ctrl+S   open / save a session\n"
         "  F1 or H           this sheet\n"
         "Panels (right): View (colour range per field), Parameters, Picked values, Plots, sigma3 explorer;\n"
         "drag a panel's title to move it, double-click to float it; the layout is kept between runs.\n"
         "View menu: bring back a closed panel, up axis (X/Y/Z), orientation axes, mesh edges.";
}

void StudioWindow::show_cheat_sheet() {
  auto* box = new QMessageBox(QMessageBox::NoIcon, "lidef-studio: keys and mouse",
                              QString::fromStdString(cheat_sheet()), QMessageBox::Close, this);
  box->setObjectName("cheat_sheet");
  box->setAttribute(Qt::WA_DeleteOnClose);
  QFont mono("Monospace");
  mono.setStyleHint(QFont::TypeWriter);
  box->setFont(mono);
  box->setModal(false);
  box->show();
}

bool StudioWindow::restore_layout() {
  QSettings st;
  const QByteArray geometry = st.value("window/geometry").toByteArray();
  const QByteArray state = st.value("window/state").toByteArray();
  if (geometry.isEmpty() || state.isEmpty()) return false;
  restoreGeometry(geometry);
  return restoreState(state, 1);
}

void StudioWindow::save_layout() {
  QSettings st;
  st.setValue("window/geometry", saveGeometry());
  st.setValue("window/state", saveState(1));
  st.sync();
}

bool StudioWindow::save_session(const std::string& path) {
  try {
    Scenario sc = session_->scenario();
    if (sc.model_dir.empty()) throw InputError(path, "nothing to save: no model is loaded");
    if (sc.sources.rows() == 0) throw InputError(path, "nothing to save: add at least one handle first");
    sc.sources = sources_;
    sc.targets = targets_;
    sc.studio = studio_json();
    if (!opens_.empty()) throw InputError(path, "wait until " + opens_.back().name + " is ready (or Cancel)");
    // The file the shown model came from (a mesh file, not the cage cache folder it was caged into), as an
    // absolute path: a relative name only resolves next to the original scenario.
    sc.model = shown_source_.empty() ? std::filesystem::absolute(sc.model_dir).lexically_normal().string()
                                     : shown_source_;
    if (sc.name.empty()) sc.name = scenario_name_;
    write_scenario(path, sc);
  } catch (const std::exception& e) {
    report_error("Cannot save", e.what());
    return false;
  }
  status_->setText(QString::fromStdString("saved " + path));
  return true;
}

std::string write_window_png(vtkRenderWindow* window, const std::string& path, bool rgba) {
  window->Render();
  auto grab = vtkSmartPointer<vtkWindowToImageFilter>::New();
  grab->SetInput(window);
  if (rgba) grab->SetInputBufferTypeToRGBA();
  grab->ReadFrontBufferOff();
  grab->ShouldRerenderOn();
  grab->Update();
  auto writer = vtkSmartPointer<vtkPNGWriter>::New();
  writer->SetInputConnection(grab->GetOutputPort());
  try {
    write_file_atomic_via_path(path, ".png", [&](const std::string& tmp) {
      writer->SetFileName(tmp.c_str());
      writer->Write();
      if (writer->GetErrorCode() != 0) throw InputError(path, "write failed");
    });
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

bool StudioWindow::save_screenshot(const std::string& path, int width, int height, bool transparent) {
  // A size larger than the window's view (1920x1080) grows the whole window: everything about the window
  // (geometry, maximized state, dock sizes, the view's size limits) is put back afterwards.
  const QSize min = view_->minimumSize(), max = view_->maximumSize();
  const QByteArray state = saveState(1);
  const Qt::WindowStates window_state = windowState();
  const QSize window_size = size();
  const QPoint position = pos();
  const bool resize_view = width > 0 && height > 0 && QSize(width, height) != view_->size();
  if (resize_view) {
    view_->setFixedSize(width, height);
    adjustSize();
    QApplication::processEvents();
  }
  if (transparent) {
    window_->SetAlphaBitPlanes(1);
    for (vtkRenderer* r : {renderer_, bar_renderer_}) {
      r->GradientBackgroundOff();
      r->SetBackgroundAlpha(0.0);
    }
  }
  const std::string why = write_window_png(window_, path, transparent);
  if (transparent)
    for (vtkRenderer* r : {renderer_, bar_renderer_}) {
      r->GradientBackgroundOn();
      r->SetBackgroundAlpha(1.0);
    }
  if (resize_view) {
    view_->setMinimumSize(min);
    view_->setMaximumSize(max);
    // Position and size as they were (restoreGeometry would shift the window by a frame offset when no
    // window manager reports one), then the docks.
    setWindowState(window_state);
    restoreState(state, 1);
    QApplication::processEvents();
    if (!(window_state & (Qt::WindowMaximized | Qt::WindowFullScreen))) {
      resize(window_size);
      move(position);
      QApplication::processEvents();
    }
  }
  window_->Render();
  if (!why.empty()) report_error("Cannot save screenshot", why);
  return why.empty();
}

bool StudioWindow::export_current(const std::string& dir) {
  const auto f = shown_;
  try {
    if (!f || !f->model || f->coefficients.rows() == 0) throw InputError(dir, "no map to export yet");
    std::filesystem::create_directories(dir);
    const std::filesystem::path d(dir);
    // The files lidef deform writes for a map, with its writers (coefficients.h, mesh_export.h,
    // vtk_export.h).
    write_file_atomic((d / "coefficients.txt").string(),
                      [&](std::ostream& s) { write_coefficients(s, f->coefficients); });
    const MeshFields mf =
        mesh_fields(HarmonicBasis(f->model->cage), f->coefficients, f->model->mesh.V, {true});
    write_mesh_vtp((d / "deformed.vtp").string(), mf.V, f->model->mesh.F,
                   {{"E_iso_minus_6", mf.e_iso},
                    {"detJ", mf.det_j},
                    {"sigma3", mf.sigma3},
                    {"sigma1", mf.sigma1},
                    {"distortion", mf.distortion}});
    std::string also;
    if (f->leaves && f->leaves_version == f->map_version && f->leaves_sampling) {
      // certificate.json and voxels.csv as lidef deform writes them for its map (certificate_report.h): the
      // leaves are the solver's certify_current(true) of this map, as there.
      CertificateReport report = make_certificate_report(
          *f->leaves, f->model->cage, f->model->mesh, f->coefficients, session_->scenario().model_dir,
          "coefficients.txt", f->leaves_sampling_params, *f->leaves_sampling, f->leaves_certify_params);
      write_certificate_files(dir, report);
      write_leaves_vtu((d / "leaves.vtu").string(), f->leaves->leaves);
      also += ", certificate.json, voxels.csv, leaves.vtu";
    }
    if (f->field && f->field_version == f->map_version) {
      write_field_vti((d / "field.vti").string(), *f->field);
      also += ", field.vti";
    }
    status_->setText(QString::fromStdString("exported coefficients.txt, deformed.vtp" + also + " to " + dir +
                                            (also.empty() ? " (show the Lipschitz/octree or sigma3 view "
                                                            "for the certificate files / field.vti)"
                                                          : "")));
  } catch (const std::exception& e) {
    report_error("Cannot export", e.what());
    return false;
  }
  return true;
}

void StudioWindow::show_range_used() {
  if (!range_used_) return;
  const auto r = scene_->shown_range();
  const QString text =
      r.first == r.second
          ? QString("(no map shown)")
          : QString::fromStdString("[" + format_g(r.first, 4) + ", " + format_g(r.second, 4) + "]");
  if (range_used_->text() != text) range_used_->setText(text);
}

void StudioWindow::set_color_range(Field f, const ColorRange& r) {
  if (r.mode == ColorRange::Mode::kManual && !(r.min < r.max)) {
    report_error("Colour range", "min must be below max");
    return;
  }
  settings_.range[static_cast<int>(f)] = r;
  refresh_view_panel();
  settings_changed();
}

QWidget* StudioWindow::build_range_controls() {
  auto* box = new QGroupBox("Colour range");
  auto* form = new QFormLayout(box);
  range_used_ = nullptr;
  if (!has_range(settings_)) {
    form->addRow(new QLabel("(the octree view colours by depth or status)"));
    return box;
  }
  const Field fld = shown_field(settings_);
  const ColorRange cur = settings_.range[static_cast<int>(fld)];
  form->addRow(new QLabel(QString("field: ") + to_string(fld)));
  auto* mode = new QComboBox;
  mode->setObjectName("range_mode");
  mode->addItems({"auto (data min/max)", "percentile clamp", "manual min/max"});
  mode->setCurrentIndex(static_cast<int>(cur.mode));
  auto* pct = new QDoubleSpinBox;
  pct->setObjectName("range_percentile");
  pct->setRange(50, 100);
  pct->setDecimals(1);
  pct->setSuffix(" %");
  pct->setValue(cur.percentile);
  pct->setToolTip("The range spans the (100 - p)-th to the p-th percentile of the shown values");
  auto make_edit = [](const char* name, double v) {
    auto* e = new QDoubleSpinBox;
    e->setObjectName(name);
    e->setRange(-1e12, 1e12);
    e->setDecimals(6);
    e->setValue(v);
    return e;
  };
  const auto shown = scene_->shown_range();
  auto* lo = make_edit("range_min", cur.mode == ColorRange::Mode::kManual ? cur.min : shown.first);
  auto* hi = make_edit("range_max", cur.mode == ColorRange::Mode::kManual ? cur.max : shown.second);
  form->addRow("Mode", mode);
  form->addRow("Percentile", pct);
  form->addRow("Min", lo);
  form->addRow("Max", hi);
  auto* apply = new QPushButton("Apply range");
  apply->setObjectName("range_apply");
  form->addRow(apply);
  // What the colour bar spans now (auto and percentile ranges follow the data, frame by frame).
  range_used_ = new QLabel;
  range_used_->setObjectName("range_used");
  form->addRow("In use", range_used_);
  show_range_used();
  connect(apply, &QPushButton::clicked, this, [this, fld, mode, pct, lo, hi] {
    ColorRange r;
    r.mode = static_cast<ColorRange::Mode>(mode->currentIndex());
    r.percentile = pct->value();
    r.min = lo->value();
    r.max = hi->value();
    set_color_range(fld, r);
  });
  return box;
}

bool StudioWindow::pick_at_display(int x, int y) {
  Vec3 rest;
  std::string where;
  if (!rest_point_at_display(x, y, rest, where, false)) return false;
  picked_ = picked_values(*shown_, rest, where);
  picked_map_version_ = shown_->map_version;
  show_picked(true);
  status_->setText(QString::fromStdString("picked " + where));
  return picked_.valid;
}

bool StudioWindow::hover_at_display(int x, int y) {
  Vec3 rest;
  std::string where;
  // Nothing under the cursor: the panel keeps the last values.
  if (!rest_point_at_display(x, y, rest, where, true)) return false;
  const PickedValues v = picked_values(*shown_, rest, "hover: " + where);
  if (!v.valid) return false;
  picked_ = v;
  picked_map_version_ = shown_->map_version;
  show_picked(true);
  return true;
}

void StudioWindow::refresh_picked(const SessionFrame& f) {
  if (!picked_.valid || f.map_version == picked_map_version_ || !f.model || f.coefficients.rows() == 0)
    return;
  const std::string where = picked_.where;
  picked_ = picked_values(f, picked_.rest, where);
  picked_map_version_ = f.map_version;
  show_picked(false);  // the frame being rendered draws the marker
}

void StudioWindow::show_picked(bool render) {
  std::string text = to_text(picked_);
  if (picked_.valid && shown_) text += "\n(of the map on screen; recomputed when it changes)";
  picked_label_->setText(QString::fromStdString(text));
  scene_->set_picked(picked_.valid, picked_.rest, picked_.image);
  if (!render) return;
  if (shown_) {
    std::lock_guard<std::mutex> lk(pending_mutex_);
    if (!pending_) pending_ = shown_;
  }
  QMetaObject::invokeMethod(
      this, [this] { render_pending(); }, Qt::QueuedConnection);
}

void StudioWindow::set_hover(bool on) {
  hover_enabled_ = on;
  if (!on) hover_timer_->stop();
  if (hover_check_ && hover_check_->isChecked() != on) {
    const QSignalBlocker block(hover_check_);
    hover_check_->setChecked(on);
  }
}

bool StudioWindow::rest_point_at_display(int x, int y, Vec3& rest, std::string& where, bool quiet) {
  if (!shown_ || !shown_->model) return false;
  vtkActor* actor = nullptr;
  if (settings_.view == View::kMesh) {
    actor = scene_->mesh_actor();
    where = "mesh surface";
  } else if (settings_.view == View::kSigma3) {
    if (settings_.sigma_deformed_space) {
      if (!quiet)
        status_->setText("picking on sigma3 slices works in rest space only (untick \"Deformed space\")");
      return false;
    }
    actor = scene_->slices_actor();
    where = "sigma3 slice";
  } else {
    actor = scene_->leaves_actor();
    where = "leaf voxel";
  }
  if (settings_.view == View::kMesh) {
    // The deformed mesh: the picked point pulled back to rest space (the same barycentric combination of the
    // rest triangle), as a handle's source.
    if (!mesh_rest_point_at_display(x, y, rest)) return false;
  } else if (settings_.view == View::kSigma3) {
    // The slices are drawn in rest space: the picked world point (depth buffer) is the rest point.
    actor->PickableOn();
    auto picker = vtkSmartPointer<vtkPropPicker>::New();
    picker->PickFromListOn();
    picker->AddPickList(actor);
    const int hit = picker->Pick(x, y, 0, renderer_);
    actor->PickableOff();
    if (!hit) return false;
    const double* w = picker->GetPickPosition();
    rest = Vec3(w[0], w[1], w[2]);
  } else {
    // Leaves: the nearest drawn cube along the ray through the pixel (exact, unlike the depth buffer, whose
    // precision is coarser than the gap between neighbouring cubes).
    if (!shown_->leaves) return false;
    double ends[2][3];
    for (int k = 0; k < 2; ++k) {
      renderer_->SetDisplayPoint(x, y, k);
      renderer_->DisplayToWorld();
      const double* w = renderer_->GetWorldPoint();
      for (int a = 0; a < 3; ++a) ends[k][a] = w[a] / w[3];
    }
    const Vec3 o(ends[0][0], ends[0][1], ends[0][2]);
    const Vec3 d = Vec3(ends[1][0], ends[1][1], ends[1][2]) - o;
    double best = std::numeric_limits<double>::infinity();
    for (const CertLeaf& l : shown_->leaves->leaves) {
      if (!leaf_shown(l, *shown_->model, settings_)) continue;
      const double h = 0.5 * kLeafDrawnSide * l.side;
      double t0 = 0, t1 = best;
      for (int a = 0; a < 3 && t0 <= t1; ++a) {
        if (std::abs(d(a)) < 1e-300) {
          if (std::abs(o(a) - l.center(a)) > h) t0 = t1 + 1;
          continue;
        }
        double ta = (l.center(a) - h - o(a)) / d(a), tb = (l.center(a) + h - o(a)) / d(a);
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
      }
      if (t0 <= t1 && t0 < best) best = t0;
    }
    if (!std::isfinite(best)) return false;
    rest = o + best * d;  // on a drawn cube: strictly inside that leaf's voxel
  }
  return true;
}

bool StudioWindow::open_comparison(const std::string& dir) {
  try {
    std::string caption;
    QVTKOpenGLNativeWidget* w = open_compare_widget(dir, 0, &caption);
    w->setToolTip(QString::fromStdString(caption));
    w->show();
    status_->setText(QString::fromStdString("comparison: " + caption));
  } catch (const std::exception& e) {
    report_error("Cannot open comparison " + dir, e.what());
    return false;
  }
  return true;
}

// ------------------------------------------------------------------------------------------------- frames

void StudioWindow::on_frame(std::shared_ptr<const SessionFrame> f) {
  last_frame_ns_.store(std::chrono::steady_clock::now().time_since_epoch().count());
  {
    std::lock_guard<std::mutex> lk(pending_mutex_);
    pending_ = std::move(f);  // a frame not yet rendered is replaced: only the newest is worth drawing
    if (render_scheduled_) return;
    render_scheduled_ = true;
  }
  QMetaObject::invokeMethod(
      this, [this] { render_pending(); }, Qt::QueuedConnection);
}

void StudioWindow::render_pending() {
  std::shared_ptr<const SessionFrame> f;
  {
    std::lock_guard<std::mutex> lk(pending_mutex_);
    f = std::move(pending_);
    pending_.reset();
    render_scheduled_ = false;
  }
  if (!f) return;
  // A preparing frame is progress only: the view, badge and panels keep the model the engine's solver holds
  // until the preparation succeeds (then a frame of the new model follows) or is cancelled.
  if (f->state == SessionState::kPreparing) {
    preparing_ = f;
    update_status(*f);
    emit frame_shown();
    return;
  }
  preparing_.reset();
  forget_dropped_opens();
  const bool new_model = f->model != shown_model_;
  if (new_model) adopt_shown_model(*f);
  refresh_picked(*f);
  scene_->set_handle_tolerance(params_->params().handle_tolerance);
  const auto t0 = Clock::now();
  scene_->set_certified_domain(session_->scenario().params.domain);
  scene_->show(*f, settings_);
  if (camera_to_reset_ && f->mesh_V.rows() > 0) {
    camera_to_reset_ = false;
    shown_model_version_ = f->model_version;
    reset_camera_pose(true);
    apply_camera_json(pending_camera_);
    pending_camera_.clear();
  }
  if (new_model) sync_widgets();
  shown_ = f;
  window_->Render();
  last_render_ms_ = ms_since(t0);
  ++rendered_;
  show_range_used();
  update_status(*f);
  plots_->set_history(f->history);
  if (f->verification && f->verification_version != shown_verification_version_) {
    shown_verification_version_ = f->verification_version;
    plots_->set_verification(*f->verification);
  }
  emit frame_shown();
}

std::string stop_reason_in_words(const std::string& status) {
  static const std::pair<const char*, const char*> words[] = {
      {"targets_unreachable", "targets unreachable (proven: no map of the subspace reaches them)"},
      {"blocked_by_certificate", "blocked by the certificate (at the injectivity boundary)"},
      {"no_certified_step", "no certified step"},
      {"reached_not_converged", "targets reached (energy not stationary)"},
      {"max_iterations", "iteration limit reached (Solver > Solve continues)"},
  };
  for (const auto& [key, text] : words)
    if (status.rfind(key, 0) == 0) return text + status.substr(std::string(key).size());
  return status;
}

void StudioWindow::update_long_wait(SessionState state, double seconds_since_frame) {
  const bool show = state == SessionState::kIterating && seconds_since_frame >= kLongWaitSeconds;
  if (show) {
    wait_bar_->setFormat(
        QString("solver iteration running for %1 s").arg(static_cast<int>(seconds_since_frame)));
    wait_bar_->setToolTip(
        "No new iterate for a while: the Newton step or its certified line search takes long");
  }
  if (wait_bar_->isVisible() != show) {
    wait_bar_->setVisible(show);
    wait_stop_->setVisible(show);
  }
}

void StudioWindow::set_status_line(const std::string& text) {
  // The status line is cut where the badge begins: the whole text is its tooltip.
  status_->setText(QString::fromStdString(text));
  status_->setToolTip(QString::fromStdString(text));
}

namespace {
// The first `n` characters of a reason (at a word boundary), for the badge; the tooltip has all of it.
std::string shortened(const std::string& s, size_t n) {
  if (s.size() <= n) return s;
  const size_t cut = s.rfind(' ', n);
  return s.substr(0, cut == std::string::npos || cut < n / 2 ? n : cut) + "…";
}
}  // namespace

// The badge says what is proven about the map on screen: the local certificate, and with the global check its
// verdict for this map ("checking" until the engine has it: never an earlier map's verdict).
void StudioWindow::update_badge(const SessionFrame& f, const std::string& name) {
  const std::string about = "the map of " + shown_name_ + " on screen";
  std::string text, tip, style;
  const char* green = "background:#2e7d32; color:white; font-weight:bold";
  const char* red = "background:#c62828; color:white; font-weight:bold";
  const char* amber = "background:#f9a825; color:black; font-weight:bold";
  const char* orange = "background:#e65100; color:white; font-weight:bold";
  if (!f.certified) {
    text = "NOT certified";
    tip = "the certificate of " + about + ": " + f.not_certified_reason;
    style = red;
  } else if (!settings_.global_injectivity) {
    text = "CERTIFIED locally injective";
    tip = "the certificate of " + about + " (global injectivity is not checked: View panel)";
    style = green;
  } else if (!f.global || f.global_version != f.map_version) {
    text = "locally injective (global: checking…)";
    tip = "the local certificate of " + about + " holds; global injectivity is checked when the solver rests";
    style = amber;
  } else if (f.global->verdict == GlobalInjectivity::Verdict::kInjective) {
    text = "CERTIFIED injective";
    tip = "the local certificate of " + about +
          " holds and the map is globally injective on the mesh's solid: " + no_overlap_words(*f.global) +
          " (checked in " + format_g(f.global->ms / 1000, 2) + " s)";
    style = green;
  } else if (f.global->verdict == GlobalInjectivity::Verdict::kOverlap) {
    text = "locally injective — overlaps itself";
    tip = "the local certificate of " + about + " holds, but " + f.global->reason +
          " (red: the two parts that meet; yellow sphere: where)";
    style = orange;
  } else {
    text = "locally injective (global: not decided — " + shortened(f.global->reason, 60) + ")";
    tip = "the local certificate of " + about + " holds; global injectivity not decided: " + f.global->reason;
    style = amber;
  }
  badge_->setText(QString::fromStdString(" " + name + text + " "));
  badge_->setToolTip(QString::fromStdString(tip));
  badge_->setStyleSheet(QString::fromStdString(style));
}

// A point cloud made from a PLY file shows that file's colours (when it has some and its points are the
// model's, in order); anything else shows the field.
void StudioWindow::load_point_colors(const Model& model) {
  std::vector<unsigned char> rgb;
  if (model.mesh.F.rows() == 0) {
    try {
      // The file opened (or named by the scenario) first: a cached automatic cage's model.json names the file
      // it was first made from, which may be gone.
      Scenario sc = session_->scenario();
      sc.model_dir = shown_source_;
      const std::string ply = source_points_file(model, sc);
      if (lowercase_extension(ply) == ".ply") {
        const PlyCloud cloud = read_ply_cloud(ply);
        if (cloud.points() == model.mesh.V) rgb = point_cloud_colors(cloud);
      }
    } catch (const std::exception& e) {  // the model itself is fine: its points show the field
      status_->setText(QString::fromStdString(std::string("point colours not shown: ") + e.what()));
    }
  }
  has_point_colors_ = !rgb.empty();
  scene_->set_point_colors(std::move(rgb));
}

std::string StudioWindow::badge_text() const {
  return badge_->text().toStdString();
}

void StudioWindow::update_status(const SessionFrame& f) {
  const bool preparing = f.state == SessionState::kPreparing;
  const bool busy = preparing || f.progress >= 0;  // preparing, or verifying the map on screen
  prepare_bar_->setVisible(busy);
  prepare_cancel_->setVisible(busy);
  if (busy && !preparing) {
    prepare_bar_->setValue(static_cast<int>(1000 * f.progress));
    prepare_bar_->setFormat(QString::fromStdString(f.stage) + " %p%");
  }
  if (preparing) {
    // The badge stays as it is: it describes the map on screen, which the engine still holds.
    const std::string what = opens_.empty() ? shown_name_ + " (new parameters)" : opens_.back().name;
    prepare_bar_->setValue(static_cast<int>(1000 * std::max(0.0, f.progress)));
    prepare_bar_->setFormat(QString::fromStdString("preparing " + what + ": " + f.stage) + " %p%");
    set_status_line(
        "preparing " + what + ": " + f.status +
        (shown_model_ ? " | on screen until it is ready: " + shown_name_ + " and its certified map" : ""));
    return;
  }
  const std::string name = shown_name_.empty() ? "" : shown_name_ + ": ";
  if (f.mesh_V.rows() == 0) {
    badge_->setText(" no map ");
    badge_->setStyleSheet("");
    badge_->setToolTip("");
    set_status_line(f.status);
    return;
  }
  update_badge(f, name);
  std::ostringstream s;
  s << name << to_string(f.state) << " | " << stop_reason_in_words(f.status) << " | iteration "
    << f.history.size() << " | energy " << format_g(f.energy.total, 4) << " | min sigma3 LB "
    << format_bound(f.min_lower_bound, false, 4) << " | handle error " << format_g(f.max_handle_error, 3);
  const int unreached = scene_->unreached_handles();
  if (unreached > 0)
    s << " | " << unreached << " handle" << (unreached > 1 ? "s" : "")
      << " not at the target (red line: image to target)";
  set_status_line(s.str());
}

// ------------------------------------------------------------------------------------------------ handles

void StudioWindow::sync_widgets() {
  vtkRenderWindowInteractor* iren = window_->GetInteractor();
  const auto& m = shown_model_;
  const double diag = m ? (m->cage.bbox_max - m->cage.bbox_min).norm() : 1.0;
  while (static_cast<int>(widgets_.size()) > num_handles()) {
    widgets_.back()->widget->Off();
    widgets_.pop_back();
  }
  while (static_cast<int>(widgets_.size()) < num_handles()) {
    auto w = std::make_unique<Widget>();
    w->index = static_cast<int>(widgets_.size());
    w->owner = this;
    w->rep->GetProperty()->SetColor(0.0, 0.85, 0.9);
    w->rep->GetSelectedProperty()->SetColor(0.0, 1.0, 1.0);
    w->rep->SetTranslationMode(1);
    w->widget->SetInteractor(iren);
    w->widget->SetRepresentation(w->rep);
    w->widget->SetAllowHandleResize(0);
    w->cb->SetClientData(w.get());
    w->cb->SetCallback([](vtkObject*, unsigned long ev, void* data, void*) {
      auto* self = static_cast<Widget*>(data);
      StudioWindow* o = self->owner;
      double p[3];
      self->rep->GetWorldPosition(p);
      if (ev == vtkCommand::StartInteractionEvent) {
        o->push_undo();
        o->dragging_ = self->index;
      } else if (ev == vtkCommand::InteractionEvent) {
        o->targets_.row(self->index) << p[0], p[1], p[2];
        o->session_->set_targets(o->targets_);
      } else if (ev == vtkCommand::EndInteractionEvent) {
        o->targets_.row(self->index) << p[0], p[1], p[2];
        o->session_->set_targets(o->targets_);
        o->dragging_ = -1;
      }
    });
    w->widget->AddObserver(vtkCommand::StartInteractionEvent, w->cb);
    w->widget->AddObserver(vtkCommand::InteractionEvent, w->cb);
    w->widget->AddObserver(vtkCommand::EndInteractionEvent, w->cb);
    widgets_.push_back(std::move(w));
  }
  for (int i = 0; i < num_handles(); ++i) {
    double p[3] = {targets_(i, 0), targets_(i, 1), targets_(i, 2)};
    widgets_[i]->rep->SetSphereRadius(0.018 * diag);
    widgets_[i]->rep->SetWorldPosition(p);
    widgets_[i]->widget->SetEnabled(shown_model_ && opens_.empty() && settings_.view == View::kMesh ? 1 : 0);
  }
}

void StudioWindow::push_undo() {
  undo_.push_back({sources_, targets_});
  redo_.clear();
}

void StudioWindow::send_handles() {
  try {
    session_->set_handles(sources_, targets_);
  } catch (const std::exception& e) {
    report_error("Handles", e.what());
  }
  sync_widgets();
  window_->Render();
}

bool StudioWindow::add_handle(const Vec3& source) {
  if (!edits_allowed()) return false;
  const std::string why = session_->check_source(source);
  if (!why.empty()) {
    status_->setText(QString::fromStdString("handle not added: " + why));
    return false;
  }
  // The target starts at the source's current image, so adding a handle does not move anything.
  Vec3 image = source;
  if (shown_ && shown_->coefficients.rows() > 0 && shown_->model) {
    const HarmonicBasis basis(shown_->model->cage);
    image = basis.map_jet(shown_->coefficients, source, 0).f;
  }
  push_undo();
  sources_.conservativeResize(sources_.rows() + 1, 3);
  targets_.conservativeResize(targets_.rows() + 1, 3);
  sources_.row(sources_.rows() - 1) = source.transpose();
  targets_.row(targets_.rows() - 1) = image.transpose();
  send_handles();
  return true;
}

bool StudioWindow::mesh_rest_point_at_display(int x, int y, Vec3& rest) {
  auto picker = vtkSmartPointer<vtkCellPicker>::New();
  const MatX3i& F = shown_->model->mesh.F;
  const MatX3d& V = shown_->model->mesh.V;
  // A point cloud's points are a few pixels wide: a wider tolerance (of the window's diagonal) reaches them.
  picker->SetTolerance(F.rows() == 0 ? 0.005 : 0.0005);
  picker->PickFromListOn();
  picker->AddPickList(scene_->mesh_actor());
  if (!picker->Pick(x, y, 0, renderer_) || picker->GetCellId() < 0) return false;
  const vtkIdType t = picker->GetCellId();
  if (F.rows() == 0) {  // a point cloud: cell t is point t
    if (t >= V.rows()) return false;
    rest = V.row(t).transpose();
    return true;
  }
  // The picked point pulled back to rest space: the same barycentric combination of the rest triangle's
  // corners (the shown mesh is the deformed one).
  if (t >= F.rows()) return false;
  const double* pc = picker->GetPCoords();
  const double w[3] = {1 - pc[0] - pc[1], pc[0], pc[1]};
  rest.setZero();
  for (int k = 0; k < 3; ++k) rest += w[k] * V.row(F(t, k)).transpose();
  return true;
}

bool StudioWindow::add_handle_at_display(int x, int y) {
  if (!shown_ || !shown_->model || settings_.view != View::kMesh) return false;
  Vec3 src;
  if (!mesh_rest_point_at_display(x, y, src)) return false;
  // Mesh surface points may sit on the cage; step slightly inside along the direction to the cage's center.
  const Model& m = *shown_->model;
  if (!session_->check_source(src).empty()) {
    const Vec3 c = 0.5 * (m.cage.bbox_min + m.cage.bbox_max);
    const double diag = (m.cage.bbox_max - m.cage.bbox_min).norm();
    src += 1e-3 * diag * (c - src).normalized();
  }
  return add_handle(src);
}

void StudioWindow::delete_handle(int i) {
  if (i < 0 || i >= num_handles() || !edits_allowed()) return;
  push_undo();
  auto drop = [i](MatX3d& M) {
    MatX3d R(M.rows() - 1, 3);
    for (Eigen::Index r = 0, k = 0; r < M.rows(); ++r)
      if (r != i) R.row(k++) = M.row(r);
    M = R;
  };
  drop(sources_);
  drop(targets_);
  send_handles();
}

void StudioWindow::move_target(int i, const Vec3& target) {
  if (i < 0 || i >= num_handles() || !edits_allowed()) return;
  push_undo();
  targets_.row(i) = target.transpose();
  try {
    session_->set_targets(targets_);
  } catch (const std::exception& e) {
    report_error("Handles", e.what());
  }
  sync_widgets();
}

void StudioWindow::undo() {
  if (undo_.empty() || !edits_allowed()) return;
  redo_.push_back({sources_, targets_});
  sources_ = undo_.back().sources;
  targets_ = undo_.back().targets;
  undo_.pop_back();
  send_handles();
}

void StudioWindow::redo() {
  if (redo_.empty() || !edits_allowed()) return;
  undo_.push_back({sources_, targets_});
  sources_ = redo_.back().sources;
  targets_ = redo_.back().targets;
  redo_.pop_back();
  send_handles();
}

bool StudioWindow::target_display_position(int i, double xy[2]) {
  if (i < 0 || i >= num_handles()) return false;
  renderer_->SetWorldPoint(targets_(i, 0), targets_(i, 1), targets_(i, 2), 1.0);
  renderer_->WorldToDisplay();
  const double* d = renderer_->GetDisplayPoint();
  xy[0] = d[0];
  xy[1] = d[1];
  return true;
}

bool StudioWindow::delete_handle_at_display(int x, int y) {
  int best = -1;
  double best_d = 12;  // pixels
  for (int i = 0; i < num_handles(); ++i) {
    double d[2];
    target_display_position(i, d);
    const double dist = std::hypot(d[0] - x, d[1] - y);
    if (dist < best_d) {
      best_d = dist;
      best = i;
    }
  }
  if (best < 0) return false;
  delete_handle(best);
  return true;
}

// ------------------------------------------------------------------------------------------- drag & drop

void StudioWindow::dragEnterEvent(QDragEnterEvent* e) {
  if (e->mimeData()->hasUrls()) e->acceptProposedAction();
}

void StudioWindow::dropEvent(QDropEvent* e) {
  const auto urls = e->mimeData()->urls();
  if (!urls.isEmpty()) open_path(urls.front().toLocalFile().toStdString());
}

void StudioWindow::closeEvent(QCloseEvent* e) {
  session_->stop();
  if (!view_only_) save_layout();
  e->accept();
}

}  // namespace lidef::studio
