#include "plots_panel.h"

#include <QFontMetrics>
#include <QPaintEvent>
#include <QPainter>
#include <QPainterPath>
#include <QString>
#include <algorithm>
#include <cmath>
#include <limits>

namespace lidef::studio {

namespace {

const QColor kEnergyColor(31, 119, 180);  // blue
const QColor kBoundColor(230, 110, 0);    // orange
const QColor kSampledColor(148, 103, 189);  // purple
const QColor kLColor(31, 119, 180);
const QColor kQuotientColor(44, 160, 44);   // green
const QColor kViolationColor(214, 39, 40);  // red
const QColor kGridColor(225, 225, 225);
const QColor kFrameColor(110, 110, 110);
const QColor kTextColor(0, 0, 0);
constexpr double kMarker = 3.0;  // marker radius, px

// One axis. lo/hi are in axis units: log10 of the value for a log axis.
struct Scale {
  double lo = 0, hi = 1;
  bool log = false;
  std::vector<double> ticks;  // axis units

  bool usable(double v) const { return std::isfinite(v) && (!log || v > 0); }
  double unit(double v) const { return ((log ? std::log10(v) : v) - lo) / (hi - lo); }
  QString label(double t) const {
    if (!log) return QString::number(t, 'g', 4);
    const int k = static_cast<int>(std::lround(t));
    return k >= -3 && k <= 4 ? QString::number(std::pow(10.0, k), 'g', 6) : QString("1e%1").arg(k);
  }
};

// 1, 2 or 5 times a power of ten, giving about `target` intervals over `span`.
double nice_step(double span, int target) {
  const double raw = span / target;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / mag;
  return (f <= 1 ? 1 : f <= 2 ? 2 : f <= 5 ? 5 : 10) * mag;
}

// Linear axis over [mn, mx] widened to whole steps. min_step: 1 for integer axes (iterations, ranks).
Scale linear_scale(double mn, double mx, int target, double min_step = 0) {
  if (!(mx > mn)) {
    const double pad = mn == 0 ? 1 : std::abs(mn) * 0.1;
    mn -= pad;
    mx += pad;
  }
  const double step = std::max(nice_step(mx - mn, target), min_step);
  Scale s;
  s.lo = std::floor(mn / step) * step;
  s.hi = std::ceil(mx / step) * step;
  const int n = static_cast<int>(std::lround((s.hi - s.lo) / step));
  for (int i = 0; i <= n; ++i) {
    const double t = s.lo + i * step;
    s.ticks.push_back(std::abs(t) < step * 1e-9 ? 0.0 : t);  // no "-1.2e-17" label for zero
  }
  return s;
}

// Log axis over [mn, mx] (both > 0) widened to whole decades; at most ~6 labelled decades.
Scale log_scale(double mn, double mx) {
  Scale s;
  s.log = true;
  s.lo = std::floor(std::log10(mn));
  s.hi = std::ceil(std::log10(mx));
  if (s.hi <= s.lo) s.hi = s.lo + 1;
  const int step = std::max(1, static_cast<int>(std::ceil((s.hi - s.lo) / 6)));
  s.hi = s.lo + std::ceil((s.hi - s.lo) / step) * step;
  for (double t = s.lo; t <= s.hi + 0.5; t += step) s.ticks.push_back(t);
  return s;
}

struct LegendEntry {
  enum Kind { kLineCircle, kLineSquare, kHollowCircle, kLine, kDot } kind;
  QColor color;
  QString text;
};

void draw_marker(QPainter& p, QPointF c, const QColor& color, bool square, bool filled) {
  p.setPen(QPen(color, 1.3));
  p.setBrush(filled ? QBrush(color) : QBrush(Qt::white));
  if (square)
    p.drawRect(QRectF(c.x() - kMarker, c.y() - kMarker, 2 * kMarker, 2 * kMarker));
  else
    p.drawEllipse(c, kMarker, kMarker);
}

// Lays the entries out left to right below `top`, wrapping at area's width; returns the height used.
int draw_legend(QPainter& p, const QRect& area, int top, const std::vector<LegendEntry>& entries) {
  const QFontMetrics fm(p.font());
  const int sample_w = 22, gap = 12, row_h = fm.height() + 2;
  int x = area.left() + 6, y = top;
  for (const LegendEntry& e : entries) {
    const int w = sample_w + 4 + fm.horizontalAdvance(e.text);
    if (x + w > area.right() - 4 && x > area.left() + 6) {
      x = area.left() + 6;
      y += row_h;
    }
    const QPointF mid(x + sample_w / 2.0, y + row_h / 2.0);
    if (e.kind == LegendEntry::kLineCircle || e.kind == LegendEntry::kLineSquare ||
        e.kind == LegendEntry::kLine) {
      p.setPen(QPen(e.color, 1.5));
      p.drawLine(QPointF(x, mid.y()), QPointF(x + sample_w, mid.y()));
    }
    if (e.kind == LegendEntry::kLineCircle || e.kind == LegendEntry::kLineSquare)
      draw_marker(p, mid, e.color, e.kind == LegendEntry::kLineSquare, true);
    if (e.kind == LegendEntry::kHollowCircle) draw_marker(p, mid, e.color, false, false);
    if (e.kind == LegendEntry::kDot) {
      p.setPen(Qt::NoPen);
      p.setBrush(e.color);
      p.drawEllipse(mid, 2.0, 2.0);
    }
    p.setPen(kTextColor);
    p.drawText(QRect(x + sample_w + 4, y, w, row_h), Qt::AlignLeft | Qt::AlignVCenter, e.text);
    x += w + gap;
  }
  return y + row_h - top;
}

int max_label_width(const QFontMetrics& fm, const Scale* s) {
  int w = 0;
  if (s)
    for (double t : s->ticks) w = std::max(w, fm.horizontalAdvance(s->label(t)));
  return w;
}

// Keeps every k-th tick so that neighbours are at least `min_px` apart on an axis `length_px` long (a small
// panel would otherwise print overlapping labels).
Scale thinned(const Scale& s, double length_px, double min_px) {
  Scale t = s;
  if (s.ticks.size() < 3) return t;
  const double spacing = length_px / (s.ticks.size() - 1);
  const size_t k = spacing >= min_px ? 1 : static_cast<size_t>(std::ceil(min_px / std::max(spacing, 1e-9)));
  t.ticks.clear();
  for (size_t i = 0; i < s.ticks.size(); i += k) t.ticks.push_back(s.ticks[i]);
  return t;
}

// The frame, grid, ticks and tick labels of one plot. left/right may be null (no such axis).
void draw_axes(QPainter& p, const QRectF& plot, const Scale& x_in, const Scale* left_in,
               const QColor& left_color, const Scale* right_in, const QColor& right_color,
               const QString& x_title) {
  const QFontMetrics fm(p.font());
  const int th = fm.height();
  const Scale x = thinned(x_in, plot.width(), max_label_width(fm, &x_in) + 12);
  const Scale left_thin = left_in ? thinned(*left_in, plot.height(), 1.3 * th) : Scale{};
  const Scale right_thin = right_in ? thinned(*right_in, plot.height(), 1.3 * th) : Scale{};
  const Scale* left = left_in ? &left_thin : nullptr;
  const Scale* right = right_in ? &right_thin : nullptr;
  p.setBrush(Qt::NoBrush);
  // Grid along the main (left, else right) axis and x.
  p.setPen(QPen(kGridColor, 1));
  if (const Scale* g = left ? left : right)
    for (double t : g->ticks) {
      const double y = plot.bottom() - (t - g->lo) / (g->hi - g->lo) * plot.height();
      p.drawLine(QPointF(plot.left(), y), QPointF(plot.right(), y));
    }
  for (double t : x.ticks) {
    const double px = plot.left() + (t - x.lo) / (x.hi - x.lo) * plot.width();
    p.drawLine(QPointF(px, plot.top()), QPointF(px, plot.bottom()));
  }
  p.setPen(QPen(kFrameColor, 1));
  p.drawRect(plot);
  // x ticks and labels.
  for (double t : x.ticks) {
    const double px = plot.left() + (t - x.lo) / (x.hi - x.lo) * plot.width();
    p.setPen(QPen(kFrameColor, 1));
    p.drawLine(QPointF(px, plot.bottom()), QPointF(px, plot.bottom() + 4));
    p.setPen(kTextColor);
    p.drawText(QRectF(px - 40, plot.bottom() + 5, 80, th), Qt::AlignHCenter | Qt::AlignTop, x.label(t));
  }
  p.drawText(QRectF(plot.left(), plot.bottom() + 5 + th, plot.width(), th), Qt::AlignHCenter | Qt::AlignTop,
             x_title);
  // y ticks and labels, coloured like their series so that the two y axes cannot be confused.
  auto y_axis = [&](const Scale& s, const QColor& color, bool on_left) {
    for (double t : s.ticks) {
      const double y = plot.bottom() - (t - s.lo) / (s.hi - s.lo) * plot.height();
      p.setPen(QPen(kFrameColor, 1));
      const double edge = on_left ? plot.left() : plot.right();
      p.drawLine(QPointF(edge, y), QPointF(edge + (on_left ? -4 : 4), y));
      p.setPen(color);
      const QRectF box =
          on_left ? QRectF(edge - 205, y - th / 2.0, 200, th) : QRectF(edge + 5, y - th / 2.0, 200, th);
      p.drawText(box, (on_left ? Qt::AlignRight : Qt::AlignLeft) | Qt::AlignVCenter, s.label(t));
    }
  };
  if (left) y_axis(*left, left_color, true);
  if (right) y_axis(*right, right_color, false);
}

// The plot rectangle inside `area` below `top`, leaving room for the tick labels and the x title.
QRectF plot_rect(const QFontMetrics& fm, const QRect& area, int top, const Scale* left, const Scale* right) {
  const double l = area.left() + std::max(max_label_width(fm, left) + 10, 14);
  const double r = area.right() - std::max(right ? max_label_width(fm, right) + 10 : 0, 14);
  const double b = area.bottom() - 2 * fm.height() - 8;
  return QRectF(QPointF(l, top + 4), QPointF(r, std::max<double>(b, top + 24)));
}

void draw_message(QPainter& p, const QRect& area, const QString& title, const QString& message) {
  const QFontMetrics fm(p.font());
  p.setPen(kTextColor);
  p.drawText(area.adjusted(6, 4, -6, 0), Qt::AlignHCenter | Qt::AlignTop, title);
  p.setPen(QColor(130, 130, 130));
  p.drawText(area.adjusted(0, fm.height(), 0, 0), Qt::AlignCenter, message);
}

QPointF map(const QRectF& plot, const Scale& x, const Scale& y, double xv, double yv) {
  return {plot.left() + x.unit(xv) * plot.width(), plot.bottom() - y.unit(yv) * plot.height()};
}

}  // namespace

PlotsPanel::PlotsPanel(QWidget* parent) : QWidget(parent) {
  setMinimumSize(320, 360);
  setAttribute(Qt::WA_OpaquePaintEvent);  // paintEvent fills everything
}

void PlotsPanel::set_history(const std::vector<IterationRecord>& history) {
  iterations_.clear();
  iterations_.reserve(history.size());
  for (const IterationRecord& r : history)
    iterations_.push_back(
        {r.iteration, r.terms.total, r.min_lower_bound, r.min_sigma3, r.refined, r.accepted});
  update();
}

void PlotsPanel::set_bound_tolerance(double t) {
  bound_tolerance_ = t;
  update();
}

void PlotsPanel::set_model_name(const QString& name) {
  model_name_ = name;
  update();
}

QString PlotsPanel::history_title() const {
  const QString who = model_name_.isEmpty() ? QString() : model_name_ + ": ";
  if (iterations_.empty()) return who + "Solver history";
  const IterationPoint& last = iterations_.back();
  const QString tol = bound_tolerance_ > 0
                          ? QString::fromUtf8("within %1% of sampled").arg(100 * bound_tolerance_, 0, 'g', 3)
                          : QString::fromUtf8("only proven > 0: set bound_tolerance");
  return who + QString::fromUtf8("%1 iterations; last: σ3 ≥ %2 certified (%3), sampled min %4, %5 refined")
                   .arg(iterations_.size())
                   .arg(last.lower_bound, 0, 'g', 4)
                   .arg(tol)
                   .arg(last.sampled, 0, 'g', 4)
                   .arg(last.refined);
}

void PlotsPanel::set_verification(const VerificationResult& v) {
  leaves_.clear();
  leaves_.reserve(v.voxels.size());
  for (const VoxelVerification& x : v.voxels) leaves_.push_back({x.L, x.max_quotient, x.violations > 0});
  // NaN L last, so that the sort is a strict weak ordering.
  std::stable_sort(leaves_.begin(), leaves_.end(), [](const LeafPoint& a, const LeafPoint& b) {
    if (std::isnan(a.L) || std::isnan(b.L)) return !std::isnan(a.L) && std::isnan(b.L);
    return a.L < b.L;
  });
  violations_ = v.violations;
  has_verification_ = true;
  update();
}

void PlotsPanel::clear_verification() {
  leaves_.clear();
  violations_ = 0;
  has_verification_ = false;
  update();
}

void PlotsPanel::paintEvent(QPaintEvent*) {
  QPainter p(this);
  // A white page whatever the style: the plot colours are chosen for it.
  p.fillRect(rect(), Qt::white);
  const int split = height() / 2;
  paint_history(p, QRect(0, 0, width(), split));
  paint_verification(p, QRect(0, split, width(), height() - split));
}

void PlotsPanel::paint_history(QPainter& p, const QRect& area) const {
  const QString title = history_title();
  if (iterations_.empty()) return draw_message(p, area, "Solver history", "no data yet");

  double e_min = std::numeric_limits<double>::infinity(), e_max = -e_min, b_min = e_min, b_max = -e_min;
  double x_min = e_min, x_max = -e_min;
  for (const IterationPoint& it : iterations_) {
    x_min = std::min<double>(x_min, it.iteration);
    x_max = std::max<double>(x_max, it.iteration);
    if (std::isfinite(it.energy) && it.energy > 0) {
      e_min = std::min(e_min, it.energy);
      e_max = std::max(e_max, it.energy);
    }
    for (double v : {it.lower_bound, it.sampled})
      if (std::isfinite(v)) {
        b_min = std::min(b_min, v);
        b_max = std::max(b_max, v);
      }
  }
  const bool have_energy = e_min <= e_max, have_bound = b_min <= b_max;
  if (!have_energy && !have_bound) return draw_message(p, area, title, "no finite values");

  const Scale x = linear_scale(x_min, x_max, 6, 1);
  const Scale energy = have_energy ? log_scale(e_min, e_max) : Scale{};
  const Scale bound = have_bound ? linear_scale(b_min, b_max, 4) : Scale{};
  const Scale* left = have_energy ? &energy : nullptr;
  const Scale* right = have_bound ? &bound : nullptr;

  const QFontMetrics fm(p.font());
  p.setPen(kTextColor);
  const QRect title_box = area.adjusted(6, 4, -6, 0);
  const QRect title_used =
      fm.boundingRect(title_box, Qt::AlignHCenter | Qt::AlignTop | Qt::TextWordWrap, title);
  p.drawText(title_box, Qt::AlignHCenter | Qt::AlignTop | Qt::TextWordWrap, title);
  std::vector<LegendEntry> legend;
  if (have_energy) legend.push_back({LegendEntry::kLineCircle, kEnergyColor, "E (left, log)"});
  if (have_bound) {
    legend.push_back(
        {LegendEntry::kLineSquare, kBoundColor, QString::fromUtf8("certified lower bound of σ3 (right)")});
    legend.push_back({LegendEntry::kLineCircle, kSampledColor, QString::fromUtf8("smallest sampled σ3")});
  }
  if (std::any_of(iterations_.begin(), iterations_.end(),
                  [](const IterationPoint& it) { return !it.accepted; }))
    legend.push_back({LegendEntry::kHollowCircle, kFrameColor, "not accepted"});
  const int legend_top = area.top() + 4 + title_used.height();
  const int legend_h = draw_legend(p, area, legend_top, legend);
  const QRectF plot = plot_rect(fm, area, legend_top + legend_h, left, right);
  draw_axes(p, plot, x, left, kEnergyColor, right, kBoundColor, "iteration");

  p.setRenderHint(QPainter::Antialiasing, true);
  if (have_bound && bound.lo < 0 && bound.hi > 0) {  // σ3 − r L > 0 is what certifies
    p.setPen(QPen(kBoundColor, 1, Qt::DashLine));
    const double y = map(plot, x, bound, x.lo, 0).y();
    p.drawLine(QPointF(plot.left(), y), QPointF(plot.right(), y));
  }
  // One series: a polyline broken at unusable values, then the markers on top.
  auto series = [&](const Scale& y, double IterationPoint::*field, const QColor& color, bool square) {
    QPainterPath path;
    bool pen_down = false;
    for (const IterationPoint& it : iterations_) {
      const double v = it.*field;
      if (!y.usable(v)) {
        pen_down = false;
        continue;
      }
      const QPointF c = map(plot, x, y, it.iteration, v);
      if (pen_down)
        path.lineTo(c);
      else
        path.moveTo(c);
      pen_down = true;
    }
    p.setPen(QPen(color, 1.5));
    p.setBrush(Qt::NoBrush);
    p.drawPath(path);
    for (const IterationPoint& it : iterations_)
      if (y.usable(it.*field))
        draw_marker(p, map(plot, x, y, it.iteration, it.*field), color, square, it.accepted);
  };
  if (have_bound) series(bound, &IterationPoint::sampled, kSampledColor, false);
  if (have_bound) series(bound, &IterationPoint::lower_bound, kBoundColor, true);
  if (have_energy) series(energy, &IterationPoint::energy, kEnergyColor, false);
  p.setRenderHint(QPainter::Antialiasing, false);
}

void PlotsPanel::paint_verification(QPainter& p, const QRect& area) const {
  if (!has_verification_) return draw_message(p, area, "Certificate vs. ground truth", "no data yet");
  const long n = static_cast<long>(leaves_.size());
  if (n == 0) return draw_message(p, area, "Certificate vs. ground truth: 0 leaves", "no leaves");

  double y_min = std::numeric_limits<double>::infinity(), y_max = -y_min;
  for (const LeafPoint& l : leaves_)
    for (double v : {l.L, l.quotient})
      if (std::isfinite(v) && v > 0) {
        y_min = std::min(y_min, v);
        y_max = std::max(y_max, v);
      }

  // Title in two runs so that the violation count alone can turn red.
  const QFontMetrics fm(p.font());
  const QString who = model_name_.isEmpty() ? QString() : model_name_ + ": ";
  QString head = who + QString("Certificate vs. ground truth: %1 leaves, ").arg(n);
  const QString tail = QString("%1 violation%2").arg(violations_).arg(violations_ == 1 ? "" : "s");
  if (fm.horizontalAdvance(head + tail) > area.width() - 12)
    head = who + QString("Certificate: %1 leaves, ").arg(n);
  const int title_w = fm.horizontalAdvance(head) + fm.horizontalAdvance(tail);
  const int title_x = area.left() + std::max(6, (area.width() - title_w) / 2);
  const QRect title_box(title_x, area.top() + 4, area.width(), fm.height());
  p.setPen(kTextColor);
  p.drawText(title_box, Qt::AlignLeft | Qt::AlignTop, head);
  QFont bold = p.font();
  bold.setBold(violations_ != 0);
  p.save();
  p.setFont(bold);
  p.setPen(violations_ == 0 ? kTextColor : kViolationColor);
  p.drawText(title_box.adjusted(fm.horizontalAdvance(head), 0, 0, 0), Qt::AlignLeft | Qt::AlignTop, tail);
  p.restore();
  if (!(y_min <= y_max))
    return draw_message(p, area.adjusted(0, fm.height(), 0, 0), "", "no positive values");

  const Scale x = linear_scale(0, static_cast<double>(n - 1), 5, 1);
  const Scale y = log_scale(y_min, y_max);
  std::vector<LegendEntry> legend = {
      {LegendEntry::kLine, kLColor, "certificate L"},
      {LegendEntry::kDot, kQuotientColor, QString::fromUtf8("sampled |Δσ3|/|p−c|")}};
  if (std::any_of(leaves_.begin(), leaves_.end(), [](const LeafPoint& l) { return l.violated; }))
    legend.push_back({LegendEntry::kDot, kViolationColor, "violating leaf"});
  const int legend_top = area.top() + 4 + fm.height();
  const int legend_h = draw_legend(p, area, legend_top, legend);
  const QRectF plot = plot_rect(fm, area, legend_top + legend_h, &y, nullptr);
  draw_axes(p, plot, x, &y, kTextColor, nullptr, kTextColor, "leaves, sorted by L");

  // Up to ~1e5 leaves: plot each occupied pixel once, so a paint costs O(leaves) cheap tests, not O(leaves)
  // QPainter calls.
  const int w = static_cast<int>(plot.width()) + 2, h = static_cast<int>(plot.height()) + 2;
  std::vector<char> seen(static_cast<size_t>(w) * h, 0);
  QVector<QPointF> dots, red_dots;
  QPolygonF line;
  int last_column = -1;
  for (long i = 0; i < n; ++i) {
    const LeafPoint& l = leaves_[i];
    if (y.usable(l.L)) {
      const QPointF c = map(plot, x, y, static_cast<double>(i), l.L);
      // L is sorted, so one vertex per pixel column (the last) draws the same curve.
      const int column = static_cast<int>(c.x());
      if (column == last_column && !line.isEmpty())
        line.back() = c;
      else
        line.push_back(c);
      last_column = column;
    }
    if (y.usable(l.quotient)) {
      const QPointF c = map(plot, x, y, static_cast<double>(i), l.quotient);
      if (l.violated) {
        red_dots.push_back(c);
        continue;
      }
      const int px = std::clamp(static_cast<int>(c.x() - plot.left()), 0, w - 1);
      const int py = std::clamp(static_cast<int>(c.y() - plot.top()), 0, h - 1);
      char& s = seen[static_cast<size_t>(py) * w + px];
      if (!s) dots.push_back(c);
      s = 1;
    }
  }
  p.setPen(QPen(kQuotientColor, 2));
  p.drawPoints(dots.data(), dots.size());
  p.setRenderHint(QPainter::Antialiasing, true);
  p.setPen(QPen(kLColor, 1.5));
  p.drawPolyline(line);
  p.setPen(Qt::NoPen);
  p.setBrush(kViolationColor);
  for (const QPointF& c : red_dots) p.drawEllipse(c, 2.5, 2.5);
  p.setRenderHint(QPainter::Antialiasing, false);
}

}  // namespace lidef::studio
