#include "lidef/distortion_targets.h"

#include <algorithm>
#include <limits>

#include "lidef/number_format.h"

namespace lidef {

DistortionTarget DistortionTargets::unproven(double sigma1_upper, double sigma3_lower,
                                             double distortion_upper) const {
  // Written as "not (bound within target)" so that a NaN bound never proves a target.
  if (max_distortion > 0 && !(distortion_upper <= max_distortion)) return DistortionTarget::kDistortion;
  if (max_sigma1 > 0 && !(sigma1_upper <= max_sigma1)) return DistortionTarget::kSigma1;
  if (min_sigma3 > 0 && !(sigma3_lower >= min_sigma3)) return DistortionTarget::kSigma3;
  return DistortionTarget::kNone;
}

DistortionTarget DistortionTargets::violated(double sigma1_lower, double sigma3_upper, double slack) const {
  if (max_distortion > 0 && sigma3_upper > 0 && sigma1_lower > max_distortion * sigma3_upper * (1 + slack))
    return DistortionTarget::kDistortion;
  if (max_sigma1 > 0 && sigma1_lower > max_sigma1 * (1 + slack)) return DistortionTarget::kSigma1;
  if (min_sigma3 > 0 && sigma3_upper < min_sigma3 * (1 - slack)) return DistortionTarget::kSigma3;
  return DistortionTarget::kNone;
}

double DistortionTargets::excess(double sigma1_upper, double sigma3_lower, double distortion_upper) const {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double e = 0;
  if (max_distortion > 0) e = std::max(e, distortion_upper >= 0 ? distortion_upper / max_distortion : kInf);
  if (max_sigma1 > 0) e = std::max(e, sigma1_upper >= 0 ? sigma1_upper / max_sigma1 : kInf);
  if (min_sigma3 > 0) e = std::max(e, sigma3_lower > 0 ? min_sigma3 / sigma3_lower : kInf);
  return e;
}

std::string DistortionTargets::reason(DistortionTarget which, const Vec3& where) const {
  std::string what;
  switch (which) {
    case DistortionTarget::kSigma1:
      what = "sigma1 <= " + format_g(max_sigma1);
      break;
    case DistortionTarget::kSigma3:
      what = "sigma3 >= " + format_g(min_sigma3);
      break;
    default:
      what = format_g(max_distortion);
      break;
  }
  return "distortion bound " + what + " not proven at (" + format_g(where.x()) + ", " + format_g(where.y()) +
         ", " + format_g(where.z()) + ")";
}

std::string DistortionTargets::describe() const {
  std::string s;
  const auto add = [&s](const char* name, double v) {
    if (v > 0) s += (s.empty() ? "" : ", ") + std::string(name) + " " + format_g(v);
  };
  add("max_distortion", max_distortion);
  add("max_sigma1", max_sigma1);
  add("min_sigma3", min_sigma3);
  return s;
}

}  // namespace lidef
