// The studio's colour maps and colour ranges: perceptual maps (viridis for sequential quantities, Moreland's
// cool-warm for diverging ones) and the per-field range a view's colour bar spans: the data's full range
// (auto), a percentile clamp (one outlier no longer washes out the rest), or a manual min/max. No Qt here.
#pragma once
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <utility>
#include <vector>

class vtkLookupTable;
class vtkColorTransferFunction;

namespace lidef::studio {

// The scalar fields a view colours by (each has its own range settings).
// kDistortion: σ1/σ3 sampled (mesh vertices, slices); kDistortionBound: the certified upper bound of σ1/σ3
// per leaf.
enum class Field { kEiso, kDetJ, kSigma3, kL, kMargin, kDistortion, kDistortionBound };
constexpr int kNumFields = 7;
// "e_iso", "det_j", "sigma3", "lipschitz", "margin", "distortion", "distortion_upper"
const char* to_string(Field f);

struct ColorRange {
  enum class Mode { kAuto, kPercentile, kManual };
  Mode mode = Mode::kAuto;
  double percentile = 99;   // kPercentile: the range spans the [100 − p, p] percentiles of the shown values
  double min = 0, max = 1;  // kManual
};
const char* to_string(ColorRange::Mode m);  // "auto", "percentile", "manual"
nlohmann::json range_to_json(const ColorRange& r);
// Unknown keys are ignored, missing ones keep `r`'s values; bad values throw InputError(where, ...).
void range_from_json(const nlohmann::json& j, ColorRange& r, const std::string& where);

// The [lo, hi] that `r` asks for over the finite `values` (auto: their min and max; percentile: the
// (100 − p)-th and p-th percentiles, nearest rank; manual: r.min, r.max). {0, 0} when no value is finite and
// the mode is not manual. `values` is reordered.
std::pair<double, double> color_range(std::vector<double>& values, const ColorRange& r);

// Viridis (matplotlib's, sampled at 9 points and interpolated in RGB) at t in [0, 1].
void viridis(double t, double rgb[3]);
// Moreland's cool-warm diverging map at t in [0, 1] (blue, white-ish at 0.5, red).
void cool_warm(double t, double rgb[3]);
// A 256-entry table of the map on [lo, hi] (log10 scale when `log_scale`); NaN dark grey.
void viridis_lut(vtkLookupTable* lut, double lo, double hi, bool log_scale);
void cool_warm_lut(vtkLookupTable* lut, double lo, double hi, bool log_scale);

}  // namespace lidef::studio
