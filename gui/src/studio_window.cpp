#include "studio_window.h"

#include <QVTKOpenGLNativeWidget.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCellPicker.h>
#include <vtkCommand.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkHandleWidget.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkObjectFactory.h>
#include <vtkPNGWriter.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkSphereHandleRepresentation.h>
#include <vtkWindowToImageFilter.h>

#include <QAction>
#include <QApplication>
#include <QButtonGroup>
#include <QCheckBox>
#include <QCloseEvent>
#include <QDockWidget>
#include <QDragEnterEvent>
#include <QDropEvent>
#include <QFileDialog>
#include <QFileInfo>
#include <QFormLayout>
#include <QGroupBox>
#include <QLabel>
#include <QMenuBar>
#include <QMessageBox>
#include <QMimeData>
#include <QProgressBar>
#include <QProgressDialog>
#include <QPushButton>
#include <QRadioButton>
#include <QSlider>
#include <QSpinBox>
#include <QStatusBar>
#include <QTimer>
#include <QToolBar>
#include <QVBoxLayout>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "compare_view.h"
#include "explorer_panel.h"
#include "lidef/atomic_file.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "lidef/opencl_backend.h"
#include "lidef/subspace.h"
#include "params_panel.h"
#include "plots_panel.h"
#include "studio_common.h"

namespace lidef::studio {

// The camera style with the studio's clicks: a left click (press and release within 3 pixels) adds a handle,
// a right press on a target deletes it instead of zooming. It lives in the style because the style grabs the
// interactor's focus on a press, so observers of the interactor never see the matching release.
class StudioStyle : public vtkInteractorStyleTrackballCamera {
 public:
  static StudioStyle* New();
  vtkTypeMacro(StudioStyle, vtkInteractorStyleTrackballCamera) std::function<void(int, int)> on_click;
  std::function<bool(int, int)> on_right_press;  // true = consumed
  void OnLeftButtonDown() override {
    this->Interactor->GetEventPosition(press_);
    vtkInteractorStyleTrackballCamera::OnLeftButtonDown();
  }
  void OnLeftButtonUp() override {
    vtkInteractorStyleTrackballCamera::OnLeftButtonUp();
    int xy[2];
    this->Interactor->GetEventPosition(xy);
    if (std::abs(xy[0] - press_[0]) <= 3 && std::abs(xy[1] - press_[1]) <= 3 && on_click)
      on_click(xy[0], xy[1]);
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

StudioWindow::StudioWindow(QWidget* parent) : QMainWindow(parent) {
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
  // render time and the renderer shares the cores with the solver (docs/benchmarks.md, "Studio").
  window_->SetMultiSamples(0);
  auto ren = vtkSmartPointer<vtkRenderer>::New();
  ren->SetBackground(1, 1, 1);
  ren->SetBackground2(0.86, 0.89, 0.94);
  ren->GradientBackgroundOn();
  window_->AddRenderer(ren);
  renderer_ = ren;
  scene_ = std::make_unique<Scene>(renderer_);
  setCentralWidget(view_);

  // Click on the mesh adds a handle; right-click on a target deletes it. The handle widgets (observer
  // priority 0.5) see a press before the style and keep it when they grab a sphere.
  auto style = vtkSmartPointer<StudioStyle>::New();
  style->on_click = [this](int x, int y) {
    if (dragging_ < 0) add_handle_at_display(x, y);
  };
  style->on_right_press = [this](int x, int y) { return delete_handle_at_display(x, y); };
  window_->GetInteractor()->SetInteractorStyle(style);

  // Menus and tool bar.
  QMenu* file = menuBar()->addMenu("&File");
  QAction* open_model = file->addAction("Open &model folder...", this, [this] {
    const QString d = QFileDialog::getExistingDirectory(this, "Open model folder (cage.obj, mesh.obj)");
    if (!d.isEmpty()) open_path(d.toStdString());
  });
  file->addAction("Open m&esh (automatic cage)...", this, [this] {
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
  file->addSeparator();
  file->addAction("&Quit", this, [this] { close(); })->setShortcut(QKeySequence::Quit);
  QMenu* edit = menuBar()->addMenu("&Edit");
  QAction* undo_a = edit->addAction("&Undo handle edit", this, [this] { undo(); });
  undo_a->setShortcut(QKeySequence::Undo);
  QAction* redo_a = edit->addAction("&Redo handle edit", this, [this] { redo(); });
  redo_a->setShortcut(QKeySequence::Redo);
  edit->addAction("Delete all handles", this, [this] {
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
  QToolBar* tb = addToolBar("Main");
  tb->addAction(open_model);
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

  // Panels.
  auto dock = [&](const char* title, QWidget* w, Qt::DockWidgetArea area) {
    auto* d = new QDockWidget(title, this);
    d->setObjectName(title);
    d->setWidget(w);
    addDockWidget(area, d);
    chrome_.push_back(d);
    return d;
  };
  view_panel_ = build_view_panel();
  dock("View", view_panel_, Qt::LeftDockWidgetArea);
  params_ = new ParamsPanel(this);
  auto* pd = dock("Parameters", params_, Qt::LeftDockWidgetArea);
  tabifyDockWidget(findChild<QDockWidget*>("View"), pd);
  findChild<QDockWidget*>("View")->raise();
  connect(params_, &ParamsPanel::params_applied, this, [this](const DeformParams& p, bool) {
    try {
      session_->set_params(p);
    } catch (const std::exception& e) {
      report_error("Parameters", e.what());
    }
  });
  plots_ = new PlotsPanel(this);
  auto* plots_dock = dock("Plots", plots_, Qt::RightDockWidgetArea);
  // The σ3 counterexample explorer (docs/explorer.md): its own map and view, beside the plots.
  const char* data_env = std::getenv("LIDEF_DATA");
  auto* explorer = new ExplorerPanel(data_env ? data_env : LIDEF_STUDIO_DATA_DIR, this);
  explorer->set_error_sink([this](const std::string& e) { report_error("Explorer", e); });
  tabifyDockWidget(plots_dock, dock("sigma3 explorer", explorer, Qt::RightDockWidgetArea));
  plots_dock->raise();

  badge_ = new QLabel(" no map ");
  status_ = new QLabel("File > Open a model folder or a scenario; click on the mesh to add a handle");
  statusBar()->addWidget(status_, 1);
  prepare_bar_ = new QProgressBar;
  prepare_bar_->setRange(0, 1000);
  prepare_bar_->setMinimumWidth(320);
  prepare_bar_->setVisible(false);
  prepare_cancel_ = new QPushButton("Cancel");
  prepare_cancel_->setToolTip("Stop preprocessing this model (the model before stays open)");
  prepare_cancel_->setVisible(false);
  connect(prepare_cancel_, &QPushButton::clicked, this, [this] { session_->cancel_preparation(); });
  statusBar()->addPermanentWidget(prepare_bar_);
  statusBar()->addPermanentWidget(prepare_cancel_);
  statusBar()->addPermanentWidget(badge_);
  chrome_.push_back(statusBar());
  resize(1280, 800);
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
  });
  lay->addWidget(views);
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
  return w;
}

void StudioWindow::set_multisamples(int n) {
  window_->SetMultiSamples(n);
}

void StudioWindow::set_view_only(bool on) {
  for (QWidget* c : chrome_) c->setVisible(!on);
}

void StudioWindow::set_settings(const ViewSettings& s) {
  settings_ = s;
  refresh_view_panel();
  settings_changed();
}

void StudioWindow::refresh_view_panel() {
  // The panel's widgets are bound to settings_ fields; rebuilding it is the simplest way to show new values.
  auto* d = findChild<QDockWidget*>("View");
  if (!d) return;
  QWidget* old = d->widget();
  view_panel_ = build_view_panel();
  d->setWidget(view_panel_);
  if (old) old->deleteLater();
}

void StudioWindow::set_params(const DeformParams& p) {
  params_->set_params(p);
  try {
    session_->set_params(p);
  } catch (const std::exception& e) {
    report_error("Parameters", e.what());
  }
}

void StudioWindow::settings_changed() {
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
  // Making a cage takes seconds: a worker thread makes it while this (UI) thread shows its stages.
  QProgressDialog progress(QString::fromStdString("Making a cage for " + path), QString(), 0, 0, this);
  progress.setWindowTitle("Automatic cage");
  progress.setWindowModality(Qt::WindowModal);
  progress.setMinimumDuration(300);
  std::mutex m;
  std::string last_line, folder;
  std::exception_ptr failure;
  std::atomic<bool> done{false};
  std::thread worker([&] {
    try {
      folder = resolve_model_path(path, [&](const std::string& line) {
        std::lock_guard<std::mutex> lk(m);
        last_line = line;
      });
    } catch (...) {
      failure = std::current_exception();
    }
    done.store(true);
  });
  while (!done.load()) {
    {
      std::lock_guard<std::mutex> lk(m);
      if (!last_line.empty()) progress.setLabelText(QString::fromStdString(last_line));
      model_note_ = last_line;
    }
    QApplication::processEvents(QEventLoop::AllEvents, 30);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  worker.join();
  if (failure) std::rethrow_exception(failure);
  model_note_ = last_line;
  return folder;
}

bool StudioWindow::open_path(const std::string& path) {
  model_note_.clear();
  try {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec) || is_mesh_file(path)) {
      session_->open_model(resolve_model(path), params_->params());
      scenario_name_ = std::filesystem::path(path).filename().string();
      pending_camera_.clear();
    } else {
      session_->open_scenario(path);
      const Scenario sc = session_->scenario();
      scenario_name_ = sc.name;
      pending_camera_ = sc.studio;
      if (!sc.studio.empty()) {
        const auto j = nlohmann::json::parse(sc.studio);
        if (j.contains("views")) {
          settings_from_json(j.at("views"), settings_, path);
          refresh_view_panel();
        }
      }
      params_->set_params(sc.params);
    }
  } catch (const std::exception& e) {
    report_error("Cannot open " + path, e.what());
    return false;
  }
  const Scenario sc = session_->scenario();
  sources_ = sc.sources;
  targets_ = sc.targets;
  undo_.clear();
  redo_.clear();
  sync_widgets();
  session_->set_extras(extras_for(settings_));
  setWindowTitle(QString::fromStdString("lidef-studio — " + scenario_name_));
  status_->setText(
      QString::fromStdString("opened " + path + (model_note_.empty() ? "" : " (" + model_note_ + ")")));
  return true;
}

std::string StudioWindow::studio_json() const {
  vtkCamera* cam = renderer_->GetActiveCamera();
  const double* p = cam->GetPosition();
  const double* fp = cam->GetFocalPoint();
  const double* up = cam->GetViewUp();
  nlohmann::json j;
  j["camera"] = {{"position", {p[0], p[1], p[2]}},
                 {"focal_point", {fp[0], fp[1], fp[2]}},
                 {"view_up", {up[0], up[1], up[2]}},
                 {"view_angle", cam->GetViewAngle()}};
  j["views"] = settings_to_json(settings_);
  return j.dump();
}

void StudioWindow::apply_camera_json(const std::string& text) {
  if (text.empty()) return;
  try {
    const auto j = nlohmann::json::parse(text);
    if (!j.contains("camera")) return;
    const auto& c = j.at("camera");
    vtkCamera* cam = renderer_->GetActiveCamera();
    auto v = [&](const char* k) { return c.at(k).get<std::vector<double>>(); };
    const auto p = v("position"), fp = v("focal_point"), up = v("view_up");
    cam->SetPosition(p.at(0), p.at(1), p.at(2));
    cam->SetFocalPoint(fp.at(0), fp.at(1), fp.at(2));
    cam->SetViewUp(up.at(0), up.at(1), up.at(2));
    cam->SetViewAngle(c.at("view_angle").get<double>());
    renderer_->ResetCameraClippingRange();
  } catch (const std::exception& e) {
    report_error("Session camera", e.what());
  }
}

bool StudioWindow::save_session(const std::string& path) {
  try {
    Scenario sc = session_->scenario();
    if (sc.model_dir.empty()) throw InputError(path, "nothing to save: no model is loaded");
    if (sc.sources.rows() == 0) throw InputError(path, "nothing to save: add at least one handle first");
    sc.sources = sources_;
    sc.targets = targets_;
    sc.studio = studio_json();
    // A model given as a relative name only resolves next to the original scenario: store the folder.
    sc.model = std::filesystem::absolute(sc.model_dir).lexically_normal().string();
    if (sc.name.empty()) sc.name = scenario_name_;
    write_scenario(path, sc);
  } catch (const std::exception& e) {
    report_error("Cannot save", e.what());
    return false;
  }
  status_->setText(QString::fromStdString("saved " + path));
  return true;
}

std::string write_window_png(vtkRenderWindow* window, const std::string& path) {
  window->Render();
  auto grab = vtkSmartPointer<vtkWindowToImageFilter>::New();
  grab->SetInput(window);
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

bool StudioWindow::save_screenshot(const std::string& path) {
  const std::string why = write_window_png(window_, path);
  if (!why.empty()) report_error("Cannot save screenshot", why);
  return why.empty();
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
  const auto t0 = std::chrono::steady_clock::now();
  scene_->show(*f, settings_);
  if (f->model && f->mesh_V.rows() > 0 && f->model_version != shown_model_version_) {
    shown_model_version_ = f->model_version;
    renderer_->ResetCamera();
    renderer_->GetActiveCamera()->Azimuth(25);  // a three-quarter view shows depth
    renderer_->GetActiveCamera()->Elevation(20);
    renderer_->ResetCamera();
    apply_camera_json(pending_camera_);
    pending_camera_.clear();
    sync_widgets();
  }
  window_->Render();
  last_render_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  shown_ = f;
  ++rendered_;
  update_status(*f);
  plots_->set_history(f->history);
  if (f->verification && f->verification_version != shown_verification_version_) {
    shown_verification_version_ = f->verification_version;
    plots_->set_verification(*f->verification);
  }
  emit frame_shown();
}

void StudioWindow::update_status(const SessionFrame& f) {
  const bool preparing = f.state == SessionState::kPreparing;
  prepare_bar_->setVisible(preparing);
  prepare_cancel_->setVisible(preparing);
  if (preparing) {
    prepare_bar_->setValue(static_cast<int>(1000 * std::max(0.0, f.progress)));
    prepare_bar_->setFormat(QString::fromStdString(f.stage) + " %p%");
    badge_->setText(" preprocessing ");
    badge_->setStyleSheet("");
    status_->setText(QString::fromStdString(f.status));
    return;
  }
  if (f.mesh_V.rows() == 0) {
    badge_->setText(" no map ");
    badge_->setStyleSheet("");
    status_->setText(QString::fromStdString(f.status));
    return;
  }
  badge_->setText(f.certified ? " CERTIFIED locally injective " : " NOT certified ");
  badge_->setStyleSheet(f.certified ? "background:#2e7d32; color:white; font-weight:bold"
                                    : "background:#c62828; color:white; font-weight:bold");
  std::ostringstream s;
  s << to_string(f.state) << " | iteration " << f.history.size() << " | energy "
    << format_g(f.energy.total, 4) << " | min sigma3 LB " << format_g(f.min_lower_bound, 4)
    << " | handle error " << format_g(f.max_handle_error, 3) << " | " << f.status;
  status_->setText(QString::fromStdString(s.str()));
}

// ------------------------------------------------------------------------------------------------ handles

void StudioWindow::sync_widgets() {
  vtkRenderWindowInteractor* iren = window_->GetInteractor();
  const auto m = session_->model();
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
    widgets_[i]->widget->SetEnabled(shown_model_version_ >= 0 && settings_.view == View::kMesh ? 1 : 0);
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

bool StudioWindow::add_handle_at_display(int x, int y) {
  if (!shown_ || !shown_->model || settings_.view != View::kMesh) return false;
  auto picker = vtkSmartPointer<vtkCellPicker>::New();
  picker->SetTolerance(0.0005);
  picker->PickFromListOn();
  picker->AddPickList(scene_->mesh_actor());
  if (!picker->Pick(x, y, 0, renderer_) || picker->GetCellId() < 0) return false;
  // The source is the picked point pulled back to rest space: the same barycentric combination of the rest
  // triangle's corners (the shown mesh is the deformed one).
  const vtkIdType t = picker->GetCellId();
  const MatX3i& F = shown_->model->mesh.F;
  const MatX3d& V = shown_->model->mesh.V;
  if (t >= F.rows()) return false;
  const double* pc = picker->GetPCoords();
  const double w[3] = {1 - pc[0] - pc[1], pc[0], pc[1]};
  Vec3 src = Vec3::Zero();
  for (int k = 0; k < 3; ++k) src += w[k] * V.row(F(t, k)).transpose();
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
  if (i < 0 || i >= num_handles()) return;
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
  if (i < 0 || i >= num_handles()) return;
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
  if (undo_.empty()) return;
  redo_.push_back({sources_, targets_});
  sources_ = undo_.back().sources;
  targets_ = undo_.back().targets;
  undo_.pop_back();
  send_handles();
}

void StudioWindow::redo() {
  if (redo_.empty()) return;
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
  e->accept();
}

}  // namespace lidef::studio
