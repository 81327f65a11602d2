#include "explorer_panel.h"

#include <QVTKOpenGLNativeWidget.h>
#include <vtkActor.h>
#include <vtkBillboardTextActor3D.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkColorTransferFunction.h>
#include <vtkFloatArray.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkGlyph3DMapper.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkSphereSource.h>
#include <vtkTextProperty.h>
#include <vtkUnsignedCharArray.h>

#include <QApplication>
#include <QCheckBox>
#include <QFileDialog>
#include <QHBoxLayout>
#include <QLabel>
#include <QMessageBox>
#include <QPushButton>
#include <QSignalBlocker>
#include <QSlider>
#include <QSpinBox>
#include <QVBoxLayout>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <sstream>
#include <vector>

#include "lidef/errors.h"
#include "lidef/explorer/ball_fields.h"
#include "lidef/explorer/explorer_example.h"
#include "lidef/explorer/sigma_minima.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/number_format.h"
#include "lidef/signed_svd.h"
#include "studio_common.h"

namespace lidef::studio {

namespace {

template <class T>
using Ptr = vtkSmartPointer<T>;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kBoundarySubdivisions = 4;  // 2,562 points on the sphere, as `lidef explore search`
constexpr int kRangeGrid = 32;            // grid (per axis) that sets the colour range over the ball
constexpr int kMaxLabels = 5;             // labelled minima (the lowest)

// f(i) for i in [0, n) on all cores (the map's jacobian is thread-safe; the library evaluates it from OpenMP
// loops too).
template <class F>
void parallel_for(long n, const F& f) {
  const long threads = std::clamp<long>(std::thread::hardware_concurrency(), 1, 16);
  if (threads == 1 || n < 256) {
    for (long i = 0; i < n; ++i) f(i);
    return;
  }
  std::vector<std::thread> pool;
  for (long t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (long i = t; i < n; i += threads) f(i);
    });
  for (std::thread& th : pool) th.join();
}

std::string fmt_point(const Vec3& p) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(3);
  s << "(" << p.x() << ", " << p.y() << ", " << p.z() << ")";
  return s.str();
}

// What depends on the map only.
struct Analysis {
  std::vector<Sigma3Minimum> minima;  // sorted by σ3
  double boundary_min = kNaN;
  Vec3 boundary_where = Vec3::Zero();
  double lo = 0, hi = 0;  // σ3 over the ball: a grid, the minima and the boundary samples
  double seconds = 0;
};

Analysis analyse(const ExplorerExample& ex) {
  const auto t0 = Clock::now();
  Analysis a;
  a.minima = find_sigma3_minima(*ex.map, ex.ball);
  std::tie(a.boundary_min, a.boundary_where) =
      sampled_sphere_min_sigma3(*ex.map, ex.ball, kBoundarySubdivisions);
  const BallFieldGrid g = compute_ball_fields(*ex.map, ex.ball, kRangeGrid);
  a.lo = a.boundary_min;
  a.hi = a.boundary_min;
  for (float v : g.sigma3)
    if (std::isfinite(v)) {
      a.lo = std::min<double>(a.lo, v);
      a.hi = std::max<double>(a.hi, v);
    }
  for (const Sigma3Minimum& m : a.minima) {
    a.lo = std::min(a.lo, m.sigma3);
    a.hi = std::max(a.hi, m.sigma3);
  }
  a.seconds = seconds_since(t0);
  return a;
}

// σ3 on the disks where the planes x, y, z = c + t R meet the ball, on polar grids: point 0 is the disk's
// center, ring i (1 … rings) segment j is point 1 + (i − 1) segments + j; the outer ring lies on the sphere.
struct Slices {
  int rings = 0, segments = 0;
  std::array<std::vector<Vec3>, 3> points;
  std::array<std::vector<float>, 3> sigma3;
  double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
  double seconds = 0;
};

Slices compute_slices(const ExplorerMap& map, const Ball& ball, double t, int resolution) {
  const auto t0 = Clock::now();
  Slices s;
  s.rings = std::max(2, resolution / 2);
  s.segments = std::max(16, 4 * static_cast<int>(std::ceil(M_PI * resolution / 4)));
  const double rho = ball.radius * std::sqrt(std::max(0.0, 1 - t * t));
  for (int a = 0; a < 3; ++a) {
    if (rho <= 1e-9 * ball.radius) continue;
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    Vec3 o = ball.center;
    o(a) += t * ball.radius;
    std::vector<Vec3>& P = s.points[a];
    P.push_back(o);
    for (int i = 1; i <= s.rings; ++i) {
      const double r = rho * i / s.rings;
      for (int j = 0; j < s.segments; ++j) {
        const double phi = 2 * M_PI * j / s.segments;
        Vec3 p = o;
        p(b) += r * std::cos(phi);
        p(c) += r * std::sin(phi);
        P.push_back(p);
      }
    }
    std::vector<float>& S = s.sigma3[a];
    S.assign(P.size(), 0.f);
    parallel_for(static_cast<long>(P.size()), [&](long i) {
      S[static_cast<size_t>(i)] = static_cast<float>(signed_singular_values(map.jacobian(P[i]))(2));
    });
    for (float v : S)
      if (std::isfinite(v)) {
        s.lo = std::min<double>(s.lo, v);
        s.hi = std::max<double>(s.hi, v);
      }
  }
  s.seconds = seconds_since(t0);
  return s;
}

Ptr<vtkPolyData> slices_polydata(const Slices& s) {
  auto pts = Ptr<vtkPoints>::New();
  auto sig = Ptr<vtkFloatArray>::New();
  sig->SetName("sigma3");
  auto polys = Ptr<vtkCellArray>::New();
  for (int a = 0; a < 3; ++a) {
    if (s.points[a].empty()) continue;
    const vtkIdType off = pts->GetNumberOfPoints();
    for (size_t i = 0; i < s.points[a].size(); ++i) {
      pts->InsertNextPoint(s.points[a][i].data());
      sig->InsertNextValue(s.sigma3[a][i]);
    }
    auto id = [&](int ring, int seg) -> vtkIdType {
      return ring == 0 ? off : off + 1 + static_cast<vtkIdType>(ring - 1) * s.segments + seg % s.segments;
    };
    for (int j = 0; j < s.segments; ++j) {
      const vtkIdType tri[3] = {id(0, 0), id(1, j), id(1, j + 1)};
      polys->InsertNextCell(3, tri);
    }
    for (int i = 1; i < s.rings; ++i)
      for (int j = 0; j < s.segments; ++j) {
        const vtkIdType q[4] = {id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)};
        polys->InsertNextCell(4, q);
      }
  }
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetPolys(polys);
  pd->GetPointData()->SetScalars(sig);
  return pd;
}

// The disks' boundary circles (their outer rings).
Ptr<vtkPolyData> outlines_polydata(const Slices& s) {
  auto pts = Ptr<vtkPoints>::New();
  auto lines = Ptr<vtkCellArray>::New();
  for (int a = 0; a < 3; ++a) {
    if (s.points[a].empty()) continue;
    std::vector<vtkIdType> ids;
    const size_t first = 1 + static_cast<size_t>(s.rings - 1) * s.segments;
    for (int j = 0; j < s.segments; ++j) ids.push_back(pts->InsertNextPoint(s.points[a][first + j].data()));
    ids.push_back(ids.front());
    lines->InsertNextCell(static_cast<vtkIdType>(ids.size()), ids.data());
  }
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetLines(lines);
  return pd;
}

// A marker: a sphere glyph at each point (colours from the point data, or the actor's colour) and a halo
// around it, the back faces of a larger sphere, which shows as a ring of `halo` colour in any light.
struct Marker {
  Ptr<vtkActor> body = Ptr<vtkActor>::New(), halo = Ptr<vtkActor>::New();
  Ptr<vtkGlyph3DMapper> body_mapper = Ptr<vtkGlyph3DMapper>::New(),
                        halo_mapper = Ptr<vtkGlyph3DMapper>::New();
  Ptr<vtkSphereSource> body_sphere = Ptr<vtkSphereSource>::New(), halo_sphere = Ptr<vtkSphereSource>::New();
  void init(vtkRenderer* ren, double r, double g, double b) {
    for (vtkSphereSource* s : {body_sphere.Get(), halo_sphere.Get()}) {
      s->SetThetaResolution(24);
      s->SetPhiResolution(16);
    }
    body_mapper->SetSourceConnection(body_sphere->GetOutputPort());
    halo_mapper->SetSourceConnection(halo_sphere->GetOutputPort());
    for (vtkGlyph3DMapper* m : {body_mapper.Get(), halo_mapper.Get()}) m->ScalingOff();
    body_mapper->SetScalarModeToUsePointData();
    body_mapper->SetColorModeToDirectScalars();
    halo_mapper->ScalarVisibilityOff();
    body->SetMapper(body_mapper);
    body->GetProperty()->SetSpecular(0.4);
    body->GetProperty()->SetSpecularPower(30);
    body->GetProperty()->SetAmbient(0.35);
    body->GetProperty()->SetDiffuse(0.65);
    halo->SetMapper(halo_mapper);
    halo->GetProperty()->SetColor(r, g, b);
    halo->GetProperty()->LightingOff();
    halo->GetProperty()->FrontfaceCullingOn();
    for (vtkActor* a : {body.Get(), halo.Get()}) {
      a->VisibilityOff();
      a->PickableOff();
      ren->AddViewProp(a);
    }
  }
  void set(vtkPolyData* points, double radius, bool visible) {
    body_mapper->SetInputData(points);
    halo_mapper->SetInputData(points);
    body_sphere->SetRadius(radius);
    halo_sphere->SetRadius(1.5 * radius);
    body->SetVisibility(visible);
    halo->SetVisibility(visible);
  }
};

// The boundary sphere as meridians and parallels.
Ptr<vtkPolyData> sphere_wireframe(const Ball& ball) {
  constexpr int kMeridians = 12, kParallels = 5, kSteps = 96;
  auto pts = Ptr<vtkPoints>::New();
  auto lines = Ptr<vtkCellArray>::New();
  auto add = [&](const std::function<Vec3(double)>& curve, int steps, bool closed) {
    std::vector<vtkIdType> ids;
    for (int k = 0; k <= steps; ++k) {
      if (closed && k == steps) {
        ids.push_back(ids.front());
        break;
      }
      const Vec3 p = ball.center + ball.radius * curve(static_cast<double>(k) / steps);
      ids.push_back(pts->InsertNextPoint(p.data()));
    }
    lines->InsertNextCell(static_cast<vtkIdType>(ids.size()), ids.data());
  };
  for (int m = 0; m < kMeridians; ++m) {
    const double lon = 2 * M_PI * m / kMeridians;
    add(
        [&](double u) {
          const double lat = M_PI * (u - 0.5);
          return Vec3(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
        },
        kSteps / 2, false);
  }
  for (int p = 1; p <= kParallels; ++p) {
    const double lat = M_PI * (static_cast<double>(p) / (kParallels + 1) - 0.5);
    add(
        [&](double u) {
          const double lon = 2 * M_PI * u;
          return Vec3(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
        },
        kSteps, true);
  }
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetLines(lines);
  return pd;
}

}  // namespace

struct ExplorerPanel::Request {
  std::shared_ptr<const ExplorerExample> example;
  std::string path;
  long example_id = 0;  // 0: none
  double offset = 0;
  int resolution = 48;
  std::shared_ptr<const Analysis> analysis;  // reused when already computed for this example
};

struct ExplorerPanel::Result {
  Request request;
  std::shared_ptr<const Analysis> analysis;
  std::shared_ptr<const Slices> slices;
  std::string error;
};

struct ExplorerPanel::Impl {
  vtkGenericOpenGLRenderWindow* window = nullptr;
  Ptr<vtkRenderer> ren = Ptr<vtkRenderer>::New();
  Ptr<vtkRenderer> overlay = Ptr<vtkRenderer>::New();  // minima and their labels, never hidden by the slices
  Ptr<vtkColorTransferFunction> ctf = Ptr<vtkColorTransferFunction>::New();
  Ptr<vtkActor> slices = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> slices_mapper = Ptr<vtkPolyDataMapper>::New();
  Ptr<vtkActor> sphere = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> sphere_mapper = Ptr<vtkPolyDataMapper>::New();
  Ptr<vtkActor> outlines = Ptr<vtkActor>::New();  // the disks' boundary circles
  Ptr<vtkPolyDataMapper> outlines_mapper = Ptr<vtkPolyDataMapper>::New();
  Marker minima;                                     // interior minima: white halo
  Marker boundary;                                   // the sampled boundary minimum: black halo
  std::vector<Ptr<vtkBillboardTextActor3D>> labels;  // kMaxLabels minima + the boundary minimum
  Ptr<vtkScalarBarActor> bar = Ptr<vtkScalarBarActor>::New();
  Request want;                   // what should be shown
  std::shared_ptr<Result> shown;  // what is shown
  long next_id = 0;
  bool show_minima = true;
  std::string caption;

  bool shows_wanted() const {
    if (!want.example) return true;
    return shown && shown->request.example_id == want.example_id && shown->request.offset == want.offset &&
           shown->request.resolution == want.resolution;
  }
};

ExplorerPanel::ExplorerPanel(std::string data_dir, QWidget* parent)
    : QWidget(parent), data_dir_(std::move(data_dir)), impl_(std::make_unique<Impl>()) {
  Impl& I = *impl_;
  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(4, 4, 4, 4);
  auto* row1 = new QHBoxLayout;
  auto* open = new QPushButton("Open example...", this);
  open->setToolTip("An explorer map JSON (docs/explorer.md, \"Map files\")");
  auto* shipped = new QPushButton("Shipped counterexample", this);
  shipped->setToolTip(QString::fromStdString(shipped_example_path()));
  minima_box_ = new QCheckBox("Minima", this);
  minima_box_->setChecked(true);
  minima_box_->setToolTip("Markers and labels of the located interior minima of σ3");
  row1->addWidget(open);
  row1->addWidget(shipped);
  row1->addWidget(minima_box_);
  row1->addStretch(1);
  auto* row2 = new QHBoxLayout;
  offset_slider_ = new QSlider(Qt::Horizontal, this);
  offset_slider_->setRange(-100, 100);
  offset_slider_->setValue(0);
  offset_slider_->setToolTip("Moves the x, y and z slice planes to center + t R along their axis");
  offset_label_ = new QLabel("t = 0.00", this);
  offset_label_->setMinimumWidth(offset_label_->fontMetrics().horizontalAdvance("t = -0.00") + 4);
  resolution_box_ = new QSpinBox(this);
  resolution_box_->setRange(8, 256);
  resolution_box_->setValue(48);
  resolution_box_->setToolTip("Samples of σ3 across the ball's diameter on each slice");
  row2->addWidget(new QLabel("Slice offset", this));
  row2->addWidget(offset_slider_, 1);
  row2->addWidget(offset_label_);
  row2->addWidget(new QLabel("Resolution", this));
  row2->addWidget(resolution_box_);
  layout->addLayout(row1);
  layout->addLayout(row2);
  caption_label_ = new QLabel(this);
  caption_label_->setWordWrap(true);
  caption_label_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  caption_label_->setMinimumHeight(3 * caption_label_->fontMetrics().lineSpacing());  // less jumping
  layout->addWidget(caption_label_);

  view_ = new QVTKOpenGLNativeWidget(this);
  auto win = vtkSmartPointer<vtkGenericOpenGLRenderWindow>::New();
  view_->setRenderWindow(win);
  I.window = win;
  I.ren->SetBackground(1, 1, 1);
  I.ren->SetBackground2(0.86, 0.89, 0.94);
  I.ren->GradientBackgroundOn();
  I.window->SetNumberOfLayers(2);
  I.window->AddRenderer(I.ren);
  I.overlay->SetLayer(1);
  I.overlay->InteractiveOff();
  I.overlay->SetActiveCamera(I.ren->GetActiveCamera());
  I.window->AddRenderer(I.overlay);
  layout->addWidget(view_, 1);
  status_ = new QLabel(this);
  status_->setWordWrap(true);
  status_->setStyleSheet("color: #555");
  layout->addWidget(status_);

  I.slices_mapper->SetLookupTable(I.ctf);
  I.slices_mapper->SetScalarModeToUsePointData();
  I.slices_mapper->UseLookupTableScalarRangeOn();
  I.slices->SetMapper(I.slices_mapper);
  I.slices->GetProperty()->SetAmbient(0.5);  // colours read true from any side
  I.slices->GetProperty()->SetDiffuse(0.5);
  I.sphere_mapper->ScalarVisibilityOff();
  I.sphere->SetMapper(I.sphere_mapper);
  I.sphere->GetProperty()->SetColor(0.35, 0.38, 0.45);
  I.sphere->GetProperty()->SetOpacity(0.35);
  I.sphere->GetProperty()->LightingOff();
  I.outlines_mapper->ScalarVisibilityOff();
  I.outlines->SetMapper(I.outlines_mapper);
  I.outlines->GetProperty()->SetColor(0.25, 0.25, 0.3);
  I.outlines->GetProperty()->LightingOff();
  I.minima.init(I.overlay, 1, 1, 1);
  I.boundary.init(I.overlay, 0.05, 0.05, 0.05);
  for (int i = 0; i <= kMaxLabels; ++i) {
    auto l = Ptr<vtkBillboardTextActor3D>::New();
    l->GetTextProperty()->SetFontSize(13);
    l->GetTextProperty()->SetColor(0.05, 0.05, 0.05);
    l->GetTextProperty()->SetBackgroundColor(1, 1, 1);
    l->GetTextProperty()->SetBackgroundOpacity(0.75);
    l->SetDisplayOffset(8, 6);
    l->VisibilityOff();
    I.overlay->AddViewProp(l);
    I.labels.push_back(l);
  }
  I.bar->SetLookupTable(I.ctf);
  I.bar->SetTitle("sigma3");
  style_scalar_bar(I.bar, 0.7);
  for (vtkProp* p : std::initializer_list<vtkProp*>{I.slices, I.outlines, I.sphere, I.bar}) {
    p->VisibilityOff();
    p->PickableOff();
    I.ren->AddViewProp(p);
  }
  I.caption = "no map: Open example... or Shipped counterexample";
  caption_label_->setText(QString::fromStdString(I.caption));

  connect(open, &QPushButton::clicked, this, [this] {
    const QString f = QFileDialog::getOpenFileName(this, "Open explorer map",
                                                   QString::fromStdString(data_dir_ + "/explorer"),
                                                   "Explorer map JSON (*.json)");
    if (!f.isEmpty()) open_example(f.toStdString());
  });
  connect(shipped, &QPushButton::clicked, this, [this] { open_shipped_example(); });
  connect(minima_box_, &QCheckBox::toggled, this, [this](bool on) { set_show_minima(on); });
  connect(offset_slider_, &QSlider::valueChanged, this, [this](int v) { set_slice_offset(v / 100.0); });
  connect(resolution_box_, qOverload<int>(&QSpinBox::valueChanged), this,
          [this](int n) { set_resolution(n); });
}

ExplorerPanel::~ExplorerPanel() {
  // The worker's last act is to post its result to this object; the post is dropped with the object.
  if (worker_.joinable()) worker_.join();
}

std::string ExplorerPanel::shipped_example_path() const {
  return data_dir_ + "/explorer/sigma3_interior_min.json";
}

bool ExplorerPanel::open_shipped_example() {
  return open_example(shipped_example_path());
}

void ExplorerPanel::report_error(const std::string& title, const std::string& message) {
  report_to_user(this, status_, error_sink_, title, message);
}

bool ExplorerPanel::open_example(const std::string& path) {
  std::shared_ptr<const ExplorerExample> ex;
  try {
    ex = std::make_shared<const ExplorerExample>(read_explorer_example(path));
  } catch (const std::exception& e) {
    std::string msg = e.what();
    if (msg.find(path) == std::string::npos) msg = path + ": " + msg;
    report_error("Cannot open explorer map", msg);
    return false;
  }
  Impl& I = *impl_;
  I.want.example = std::move(ex);
  I.want.path = path;
  I.want.example_id = ++I.next_id;
  kick();
  return true;
}

void ExplorerPanel::kick() {
  Impl& I = *impl_;
  if (running_ || I.shows_wanted()) return;
  Request r = I.want;
  if (I.shown && I.shown->request.example_id == r.example_id) r.analysis = I.shown->analysis;
  running_ = true;
  status_->setText(
      QString::fromStdString(std::string(r.analysis ? "computing the slices"
                                                    : "locating the minima of σ3 and the boundary minimum") +
                             " of " + std::filesystem::path(r.path).filename().string() + "..."));
  worker_ = std::thread([this, r] {
    auto res = std::make_shared<Result>();
    res->request = r;
    try {
      res->analysis = r.analysis ? r.analysis : std::make_shared<const Analysis>(analyse(*r.example));
      res->slices = std::make_shared<const Slices>(
          compute_slices(*r.example->map, r.example->ball, r.offset, r.resolution));
    } catch (const std::exception& e) {
      res->error = e.what();
    }
    QMetaObject::invokeMethod(
        this, [this, res] { finished(res); }, Qt::QueuedConnection);
  });
}

void ExplorerPanel::finished(std::shared_ptr<Result> r) {
  Impl& I = *impl_;
  if (worker_.joinable()) worker_.join();
  running_ = false;
  if (!r->error.empty()) {
    if (r->request.example_id == I.want.example_id) {  // back to the shown map
      const Request keep = I.want;
      I.want = I.shown ? I.shown->request : Request{};
      I.want.offset = keep.offset;
      I.want.resolution = keep.resolution;
      I.want.analysis.reset();
    }
    std::string msg = r->error;
    if (msg.find(r->request.path) == std::string::npos) msg = r->request.path + ": " + msg;
    report_error("Cannot analyse explorer map", msg);
  } else if (r->request.example_id == I.want.example_id) {  // results of an older map are dropped
    const bool new_map = !I.shown || I.shown->request.example_id != r->request.example_id;
    I.shown = r;
    draw(*r, new_map);
    status_->setText(QString::fromStdString(std::filesystem::path(r->request.path).filename().string() +
                                            ": minima, boundary and colour range " +
                                            format_g(1000 * r->analysis->seconds, 3) + " ms, slices " +
                                            format_g(1000 * r->slices->seconds, 3) + " ms"));
    emit example_shown();
  }
  kick();
}

bool ExplorerPanel::busy() const {
  return running_ || !impl_->shows_wanted();
}

bool ExplorerPanel::wait_until_idle(double seconds) {
  const auto t0 = Clock::now();
  while (busy()) {
    if (seconds_since(t0) > seconds) return false;
    QApplication::processEvents(QEventLoop::AllEvents, 20);
    if (busy()) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

void ExplorerPanel::set_slice_offset(double t) {
  t = std::clamp(std::isfinite(t) ? t : 0.0, -1.0, 1.0);
  {
    const QSignalBlocker block(offset_slider_);
    offset_slider_->setValue(static_cast<int>(std::lround(100 * t)));
  }
  offset_label_->setText(QString::fromStdString("t = " + format_g(t, 2)));
  impl_->want.offset = t;
  kick();
}

double ExplorerPanel::slice_offset() const {
  return impl_->want.offset;
}

void ExplorerPanel::set_resolution(int n) {
  n = std::clamp(n, 8, 256);
  {
    const QSignalBlocker block(resolution_box_);
    resolution_box_->setValue(n);
  }
  impl_->want.resolution = n;
  kick();
}

int ExplorerPanel::resolution() const {
  return impl_->want.resolution;
}

void ExplorerPanel::set_show_minima(bool on) {
  {
    const QSignalBlocker block(minima_box_);
    minima_box_->setChecked(on);
  }
  impl_->show_minima = on;
  if (impl_->shown) draw(*impl_->shown, false);
}

std::string ExplorerPanel::path() const {
  return impl_->shown ? impl_->shown->request.path : std::string();
}
int ExplorerPanel::num_minima() const {
  return impl_->shown ? static_cast<int>(impl_->shown->analysis->minima.size()) : 0;
}
int ExplorerPanel::num_strict_minima() const {
  if (!impl_->shown) return 0;
  const auto& m = impl_->shown->analysis->minima;
  return static_cast<int>(std::count_if(m.begin(), m.end(), [](const Sigma3Minimum& x) { return x.strict; }));
}
double ExplorerPanel::interior_min() const {
  return impl_->shown && !impl_->shown->analysis->minima.empty() ? impl_->shown->analysis->minima[0].sigma3
                                                                 : kNaN;
}
Vec3 ExplorerPanel::interior_min_position() const {
  return impl_->shown && !impl_->shown->analysis->minima.empty() ? impl_->shown->analysis->minima[0].position
                                                                 : Vec3::Constant(kNaN);
}
double ExplorerPanel::boundary_min() const {
  return impl_->shown ? impl_->shown->analysis->boundary_min : kNaN;
}
Vec3 ExplorerPanel::boundary_min_position() const {
  return impl_->shown ? impl_->shown->analysis->boundary_where : Vec3::Constant(kNaN);
}
double ExplorerPanel::analysis_ms() const {
  return impl_->shown ? 1000 * impl_->shown->analysis->seconds : 0;
}
double ExplorerPanel::slices_ms() const {
  return impl_->shown ? 1000 * impl_->shown->slices->seconds : 0;
}
std::string ExplorerPanel::caption() const {
  return impl_->caption;
}
vtkRenderWindow* ExplorerPanel::render_window() const {
  return impl_->window;
}

void ExplorerPanel::draw(const Result& r, bool reset_camera) {
  Impl& I = *impl_;
  const ExplorerExample& ex = *r.request.example;
  const Analysis& a = *r.analysis;
  const Slices& s = *r.slices;
  const Ball& ball = ex.ball;
  const double lo = std::min(a.lo, s.lo), hi = std::max(a.hi, s.hi);
  sigma3_colors(I.ctf, lo, hi);

  I.slices_mapper->SetInputData(slices_polydata(s));
  I.outlines_mapper->SetInputData(outlines_polydata(s));
  I.slices->VisibilityOn();
  I.outlines->VisibilityOn();
  I.bar->VisibilityOn();
  if (reset_camera) {
    I.sphere_mapper->SetInputData(sphere_wireframe(ball));
    I.sphere->VisibilityOn();
    vtkCamera* cam = I.ren->GetActiveCamera();
    const Vec3 dir = Vec3(1.0, 0.78, 0.62).normalized();
    const Vec3 eye = ball.center + 4.6 * ball.radius * dir;
    cam->SetFocalPoint(ball.center.x(), ball.center.y(), ball.center.z());
    cam->SetPosition(eye.x(), eye.y(), eye.z());
    cam->SetViewUp(0, 0, 1);
    cam->SetViewAngle(30);
  }

  // Markers coloured by σ3 like the slices, red when σ3 ≤ 0.
  auto markers = [&](const std::vector<std::pair<Vec3, double>>& at) {
    auto pts = Ptr<vtkPoints>::New();
    auto col = Ptr<vtkUnsignedCharArray>::New();
    col->SetName("colour");
    col->SetNumberOfComponents(3);
    for (const auto& [p, sigma] : at) {
      pts->InsertNextPoint(p.x(), p.y(), p.z());
      double rgb[3] = {0.85, 0.0, 0.0};
      if (sigma > 0) I.ctf->GetColor(sigma, rgb);
      const unsigned char c[3] = {static_cast<unsigned char>(std::lround(255 * rgb[0])),
                                  static_cast<unsigned char>(std::lround(255 * rgb[1])),
                                  static_cast<unsigned char>(std::lround(255 * rgb[2]))};
      col->InsertNextTypedTuple(c);
    }
    auto pd = Ptr<vtkPolyData>::New();
    pd->SetPoints(pts);
    pd->GetPointData()->SetScalars(col);
    return pd;
  };
  std::vector<std::pair<Vec3, double>> minima;
  for (const Sigma3Minimum& m : a.minima) minima.emplace_back(m.position, m.sigma3);
  I.minima.set(markers(minima), 0.035 * ball.radius, I.show_minima && !minima.empty());
  const bool boundary = std::isfinite(a.boundary_min);
  I.boundary.set(markers({{a.boundary_where, a.boundary_min}}), 0.025 * ball.radius,
                 I.show_minima && boundary);
  for (int i = 0; i < kMaxLabels; ++i) {
    vtkBillboardTextActor3D* l = I.labels[static_cast<size_t>(i)];
    const bool on = I.show_minima && i < static_cast<int>(a.minima.size());
    l->SetVisibility(on);
    if (!on) continue;
    const Sigma3Minimum& m = a.minima[static_cast<size_t>(i)];
    l->SetPosition(m.position.x(), m.position.y(), m.position.z());
    l->SetInput(("min " + format_fixed(m.sigma3, 3) + (m.strict ? "" : " (not strict)")).c_str());
  }
  vtkBillboardTextActor3D* bl = I.labels.back();
  bl->SetVisibility(I.show_minima && boundary);
  bl->SetPosition(a.boundary_where.x(), a.boundary_where.y(), a.boundary_where.z());
  bl->SetInput(("boundary min " + format_fixed(a.boundary_min, 3)).c_str());

  // Caption (the file's note, often long, is the label's tooltip).
  std::string c = std::filesystem::path(r.request.path).filename().string() + ": " + ex.map->description() +
                  " on the ball of center " + fmt_point(ball.center) + " and radius " +
                  format_g(ball.radius, 4) + "\n";
  const long strict =
      std::count_if(a.minima.begin(), a.minima.end(), [](const Sigma3Minimum& m) { return m.strict; });
  const std::string bmin = format_fixed(a.boundary_min, 3);
  const std::string boundary_text = "min σ3 on the boundary sphere " + bmin + " (2,562 samples)";
  if (a.minima.empty()) {
    c += "no interior local minimum of σ3 located (24 descents); " + boundary_text;
  } else {
    const Sigma3Minimum& m = a.minima[0];
    const std::string imin = format_fixed(m.sigma3, 3);
    c += std::to_string(a.minima.size()) + " interior minim" + (a.minima.size() == 1 ? "um" : "a") +
         " of σ3 (" + std::to_string(strict) + " strict), lowest " + imin + " at " + fmt_point(m.position) +
         "; " + boundary_text + "\n";
    if (m.sigma3 <= 0)
      c += "interior minimum " + imin + " ≤ 0: the map folds there (not a counterexample)";
    else if (m.sigma3 < a.boundary_min)
      c += "interior minimum " + imin + " < boundary minimum " + bmin + ": no minimum principle";
    else
      c += "interior minimum " + imin + " ≥ boundary minimum " + bmin +
           ": no violation of a minimum principle";
  }
  caption_label_->setToolTip(QString::fromStdString(ex.note));
  I.caption = c;
  caption_label_->setText(QString::fromStdString(I.caption));
  I.ren->ResetCameraClippingRange();
  I.window->Render();
}

}  // namespace lidef::studio
