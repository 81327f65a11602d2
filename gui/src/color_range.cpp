#include "color_range.h"

#include <vtkLookupTable.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "lidef/errors.h"
#include "lidef/internal/enum_names.h"

namespace lidef {
template <>
struct EnumNames<studio::Field> {
  static constexpr const char* names[] = {"e_iso",  "det_j",      "sigma3",          "lipschitz",
                                          "margin", "distortion", "distortion_upper"};
};
template <>
struct EnumNames<studio::ColorRange::Mode> {
  static constexpr const char* names[] = {"auto", "percentile", "manual"};
};
}  // namespace lidef

namespace lidef::studio {

const char* to_string(Field f) {
  return enum_name(f);
}

const char* to_string(ColorRange::Mode m) {
  return enum_name(m);
}

nlohmann::json range_to_json(const ColorRange& r) {
  return {{"mode", to_string(r.mode)}, {"percentile", r.percentile}, {"min", r.min}, {"max", r.max}};
}

void range_from_json(const nlohmann::json& j, ColorRange& r, const std::string& where) {
  if (!j.is_object()) throw InputError(where, "a colour range must be a JSON object");
  try {
    if (j.contains("mode")) {
      const std::string m = j.at("mode").get<std::string>();
      const auto mode = enum_from_name<ColorRange::Mode>(m);
      if (!mode) throw InputError(where, "colour range mode \"" + m + "\" (auto, percentile, manual)");
      r.mode = *mode;
    }
    if (j.contains("percentile")) r.percentile = std::clamp(j.at("percentile").get<double>(), 50.0, 100.0);
    if (j.contains("min")) r.min = j.at("min").get<double>();
    if (j.contains("max")) r.max = j.at("max").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw InputError(where, std::string("colour range: ") + e.what());
  }
  if (!(r.min < r.max)) throw InputError(where, "colour range: min must be below max");
}

std::pair<double, double> color_range(std::vector<double>& values, const ColorRange& r) {
  if (r.mode == ColorRange::Mode::kManual) return {r.min, r.max};
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }),
               values.end());
  if (values.empty()) return {0, 0};
  if (r.mode == ColorRange::Mode::kAuto) {
    const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
    return {*lo, *hi};
  }
  // Nearest rank: the smallest value with at least p% of the values at or below it.
  const double p = std::clamp(r.percentile, 50.0, 100.0) / 100.0;
  const size_t n = values.size();
  auto rank = [&](double q) {
    const double k = std::ceil(q * static_cast<double>(n)) - 1;
    return static_cast<size_t>(std::clamp(k, 0.0, static_cast<double>(n - 1)));
  };
  const size_t ih = rank(p), il = rank(1 - p);
  std::nth_element(values.begin(), values.begin() + static_cast<long>(ih), values.end());
  const double hi = values[ih];
  std::nth_element(values.begin(), values.begin() + static_cast<long>(il), values.end());
  return {values[il], hi};
}

namespace {

void interpolate(const double (*pts)[3], int n, double t, double rgb[3]) {
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * (n - 1);
  const int i = std::min(static_cast<int>(t), n - 2);
  const double u = t - i;
  for (int k = 0; k < 3; ++k) rgb[k] = (1 - u) * pts[i][k] + u * pts[i + 1][k];
}

void fill(vtkLookupTable* lut, double lo, double hi, bool log_scale, void (*map)(double, double[3])) {
  lut->SetNumberOfTableValues(256);
  lut->SetScale(log_scale ? VTK_SCALE_LOG10 : VTK_SCALE_LINEAR);
  lut->IndexedLookupOff();
  lut->SetTableRange(lo, std::max(hi, lo * (log_scale ? 1.001 : 1) + 1e-12));
  for (int i = 0; i < 256; ++i) {
    double c[3];
    map(i / 255.0, c);
    lut->SetTableValue(i, c[0], c[1], c[2], 1.0);
  }
  lut->SetNanColor(0.2, 0.2, 0.2, 1.0);
  lut->SetUseAboveRangeColor(false);
  lut->SetUseBelowRangeColor(false);
}

}  // namespace

void viridis(double t, double rgb[3]) {
  static const double pts[9][3] = {{0.267, 0.005, 0.329}, {0.283, 0.141, 0.458}, {0.254, 0.265, 0.530},
                                   {0.207, 0.372, 0.553}, {0.164, 0.471, 0.558}, {0.128, 0.567, 0.551},
                                   {0.135, 0.659, 0.518}, {0.478, 0.821, 0.318}, {0.993, 0.906, 0.144}};
  interpolate(pts, 9, t, rgb);
}

void cool_warm(double t, double rgb[3]) {
  static const double pts[9][3] = {{0.230, 0.299, 0.754}, {0.384, 0.510, 0.918}, {0.553, 0.690, 0.996},
                                   {0.722, 0.816, 0.976}, {0.865, 0.865, 0.865}, {0.958, 0.769, 0.678},
                                   {0.958, 0.604, 0.482}, {0.871, 0.376, 0.302}, {0.706, 0.016, 0.150}};
  interpolate(pts, 9, t, rgb);
}

void viridis_lut(vtkLookupTable* lut, double lo, double hi, bool log_scale) {
  fill(lut, lo, hi, log_scale, &viridis);
}

void cool_warm_lut(vtkLookupTable* lut, double lo, double hi, bool log_scale) {
  fill(lut, lo, hi, log_scale, &cool_warm);
}

}  // namespace lidef::studio
