#include "lidef/deform_params.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "lidef/errors.h"
#include "lidef/internal/enum_names.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"

namespace lidef {

namespace {

using nlohmann::json;

// Help lines are ASCII on purpose: CLI11 pads --help columns by bytes, so Greek letters would misalign them
// (docs/parameters.md carries the typeset version).
std::vector<ParamInfo> make_table() {
  using D = DeformParams;
  return {
      // --- Subspace and sampling
      {"reduced_dof", "sampling", &D::reduced_dof, 4, 100000,
       "s: reduced coefficients per coordinate (3s unknowns)"},
      {"samples", "sampling", &D::samples, 1, 5000000,
       "|I|: target number of voxels (the voxel side is searched to match)"},
      {"voxel_side", "sampling", &D::voxel_side, 0, 1e6,
       "voxel side; > 0 uses it instead of searching from 'samples' (0 = search)"},
      // Strictly above 1: at 1 a voxel may touch the cage, where the harmonic basis is singular.
      {"safety", "sampling", &D::safety, 1.0000001, 100, "voxel center to cage >= safety * voxel radius"},
      // Strictly positive: an empty Hessian subset leaves the Newton system without the distortion term.
      {"hessian_fraction", "sampling", &D::hessian_fraction, 1e-9, 1,
       "|H| / |I|: fraction of the voxels whose distortion Hessian is assembled"},
      {"domain", "sampling", &D::domain, 0, 0,
       "certified domain: \"mesh\" (the mesh and its solid, leaves refined toward the cage) or \"voxels\" "
       "(the paper's grid inside the cage)"},
      // --- Energy
      {"lambda_p2p", "energy", &D::lambda_p2p, 0, 1e12,
       "lambda1: weight of the handle (point-to-point) energy"},
      {"lambda_smooth", "energy", &D::lambda_smooth, 0, 1e12, "lambda2: weight of the smoothness energy"},
      // --- Projected Newton
      {"max_iterations", "newton", &D::max_iterations, 0, 100000, "Newton iterations at most"},
      {"step_tolerance", "newton", &D::step_tolerance, 0, 1,
       "converged when t*|delta| <= step_tolerance * max(1, |y|)"},
      {"energy_tolerance", "newton", &D::energy_tolerance, 0, 1,
       "... or when the relative energy decrease of a step is below this"},
      {"armijo", "newton", &D::armijo, 1e-12, 0.5, "sufficient-decrease constant c1 of the line search"},
      {"max_halvings", "newton", &D::max_halvings, 0, 200,
       "line-search halvings before giving up with \"no certified step\""},
      {"diagonal_shift", "newton", &D::diagonal_shift, 0, 1e6, "added to the reduced Hessian's diagonal"},
      {"drag_hessian_reuse", "newton", &D::drag_hessian_reuse, 0, 1000,
       "while handles are dragged (studio): Newton steps in a row that may reuse the previous step's Hessian "
       "factor (0 = never)"},
      {"newton_cg_steps", "newton", &D::newton_cg_steps, 0, 20,
       "conjugate-gradient iterates on the exact Hessian after the subset Hessian's solve (1 = scale the "
       "direction to the exact model's minimum; 0 = off)"},
      {"kept_factor_cg_steps", "newton", &D::kept_factor_cg_steps, 0, 1000,
       "a Newton system may be solved by at most this many CG steps on the subset Hessian, preconditioned by "
       "an earlier iteration's factor, before the Hessian is assembled and factored anew (0 = assemble every "
       "iteration)"},
      {"kept_factor_tolerance", "newton", &D::kept_factor_tolerance, 1e-12, 1,
       "relative residual of those CG steps, in the kept factor's norm, at which the system counts as "
       "solved"},
      {"hessian_precision", "newton", &D::hessian_precision, 0, 0,
       "products of the reduced Hessian: \"single\" (fast) or \"double\" (for backend parity checks)"},
      {"handle_tolerance", "newton", &D::handle_tolerance, 0, 1e6,
       "handle error reported as \"reached\", relative to the model size (half its cage's largest extent)"},
      {"continuation", "newton", &D::continuation, 0, 0,
       "large rotations of the handles (and stalled solves) go through rotation-aware intermediate targets"},
      // Above 0: a zero angle would ask for infinitely many stages.
      {"continuation_angle", "newton", &D::continuation_angle, 1, 180,
       "degrees: the largest rotation of a handle group per intermediate stage"},
      {"continuation_stage_iterations", "newton", &D::continuation_stage_iterations, 1, 1000,
       "Newton iterations at most per intermediate stage"},
      // --- Certificate
      {"max_depth", "certificate", &D::max_depth, 0, 20, "octree levels of the certificate"},
      {"bound", "certificate", &D::bound, 0, 0,
       "Lipschitz bound: \"first\" (17), \"third\" (21) order, or \"combined\" (per leaf the smaller of "
       "first order and the Taylor form with the Hessian's operator norm), or \"spectral\" "
       "(combined, and the Taylor polynomial's sigma3 bounded through the eigenvalues of J^T J); "
       "docs/certificate.md"},
      {"refinement", "certificate", &D::refinement, 0, 0,
       "how the certificate evaluates octree children: \"far-field\" (the faces near a child exactly, the "
       "others expanded around its parent with a bounded remainder; third-order bound only), \"batched\" "
       "(every face, 8 children per SIMD pass), \"per-edge\", \"per-face\"; docs/certificate.md"},
      {"max_refined", "certificate", &D::max_refined, 0, 1e9,
       "child voxels evaluated per certification of a result at most"},
      {"line_search_max_refined", "certificate", &D::line_search_max_refined, 0, 1e9,
       "the same budget for line-search trials (a trial needing more is rejected, the step halved)"},
      {"line_search_spectral_fallback", "certificate", &D::line_search_spectral_fallback, 0, 0,
       "line-search certificates (third-order bound, no distortion target): a base voxel the third-order "
       "bound leaves unproven takes the spectral bound where that proves it, before any refinement; the "
       "certificate written stays the third-order bound's (docs/certificate.md, Step 4f)"},
      {"bound_tolerance", "certificate", &D::bound_tolerance, 0, 0.99,
       "above 0: refine a certified map until its lower bound of sigma3 is within this fraction of the "
       "smallest sampled sigma3 (0.1 = 10%); never changes the verdict"},
      {"max_distortion", "certificate", &D::max_distortion, 0, 1e12,
       "above 0: a bound K on the distortion sigma1/sigma3: a map is certified only when every leaf's upper "
       "bound of sigma1/sigma3 is <= K (leaves above it are refined); the line search accepts only such maps "
       "(0 = off; docs/certificate.md, 'Bounded distortion')"},
      {"max_sigma1", "certificate", &D::max_sigma1, 0, 1e12,
       "above 0: a bound on the largest singular value sigma1 of J (the most any length is stretched), "
       "proven on every leaf like max_distortion; the line search accepts only such maps (0 = off)"},
      {"min_sigma3", "certificate", &D::min_sigma3, 0, 1,
       "above 0: a lower bound on the smallest singular value sigma3 of J (the most any length is "
       "compressed), proven on every leaf like max_distortion; the line search accepts only such maps "
       "(0 = off)"},
      {"injectivity", "certificate", &D::injectivity, 0, 0,
       "what the line search proves of an accepted map: \"local\" (the octree certificate) or \"global\" "
       "(also that the shape does not pass through itself: a step that would is shortened, the solve stops "
       "'blocked'; needs the mesh domain and a surface that does not intersect itself at rest; costs a "
       "check per accepted step; docs/solver.md)"},
      {"global_cache_mb", "certificate", &D::global_cache_mb, 0, 1e6,
       "memory (MB) the global injectivity check of the solve and of the studio keeps for what no map "
       "changes: the basis values and gradients at the mesh vertices, then the factor rows of the surface's "
       "balls, each kept while it fits, otherwise evaluated in every check (every verdict is proven either "
       "way; docs/parameters.md)"},
      // --- Dynamic weighting
      {"dynamic_weighting", "weighting", &D::dynamic_weighting, 0, 0,
       "adapt lambda1 and lambda2 during the solve (Sec. 7.3; kappa1, kappa2 below)"},
      {"e0", "weighting", &D::e0, 0, 1e6,
       "E_P2P threshold, relative to the squared cage bounding-box diagonal"},
      {"kappa1", "weighting", &D::kappa1, 1e-9, 1,
       "lambda1 <- kappa1 * lambda1 when E_P2P >= E0 and condition (36) fails"},
      {"kappa2", "weighting", &D::kappa2, 1, 1000, "lambda2 <- kappa2 * lambda2"},
      {"epsilon", "weighting", &D::epsilon, 0, 1e6,
       "margin of condition (36): min over leaves of sigma3 - r L >= epsilon"},
      {"max_smooth_factor", "weighting", &D::max_smooth_factor, 1, 1e12,
       "lambda2 stays <= this times its default"},
      {"min_p2p_factor", "weighting", &D::min_p2p_factor, 0, 1, "lambda1 stays >= this times its default"},
      {"direction_retries", "weighting", &D::direction_retries, 0, 100,
       "per iteration: recompute the direction with weaker handles when its full step fails the certificate"},
      {"max_weight_resets", "weighting", &D::max_weight_resets, 0, 100,
       "times that convergence with changed weights resets them and continues"},
      // --- Execution
      {"threads", "execution", &D::threads, 0, 1024, "OpenMP threads (0 = all cores)"},
      {"backend", "execution", &D::backend, 0, 0,
       "compute backend: \"cpu\", \"opencl\" or \"auto\" (OpenCL when a device with fp64 exists, else CPU)"},
      {"opencl_device", "execution", &D::opencl_device, 0, 0,
       "OpenCL device: a case-insensitive substring of \"<platform> <device>\" (\"\" = the first with fp64, "
       "GPUs "
       "first)"},
      {"opencl_gpu_layout", "execution", &D::opencl_gpu_layout, 0, 0,
       "a CPU OpenCL device (PoCL) takes the GPU code paths, to test them without a GPU"},
      {"trace_line_search", "execution", &D::trace_line_search, 0, 0,
       "print every line-search trial (step, energy, certificate and its stage times) to stderr"},
      // --- Test hooks: failure injection for the test suite (docs/parameters.md).
      {"test_interrupt_after", "testing", &D::test_interrupt_after, 0, 100000,
       "lidef deform raises SIGINT after this many iterations (0 = never)"},
      {"test_break_kernels", "testing", &D::test_break_kernels, 0, 0,
       "OpenCL: the kernels get a line that does not compile"},
      {"test_opencl_max_alloc", "testing", &D::test_opencl_max_alloc, 0, 1e18,
       "OpenCL: pretend the device allows buffers of at most this many bytes (0 = the device's limit)"},
  };
}

template <class T>
constexpr bool is_enum_param_v = std::is_enum_v<T>;
template <class T>
constexpr bool is_integer_v = std::is_same_v<T, int> || std::is_same_v<T, long>;

template <class T>
std::vector<std::string> enum_names() {
  return std::vector<std::string>(std::begin(EnumNames<T>::names), std::end(EnumNames<T>::names));
}

// Integers print as integers; a huge out-of-range value (no long long holds it) falls back to a double.
std::string number_text(double x, bool integral) {
  return integral && std::abs(x) < 1e18 ? std::to_string(static_cast<long long>(x)) : format_double(x);
}

std::string quoted(const std::string& s) {
  return "'" + s + "'";
}

// A short description of a JSON value for messages ("string \"abc\"", "null", "array").
std::string describe(const json& v) {
  if (v.is_array() || v.is_object()) return v.type_name();
  std::string text = v.dump();
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  if (v.is_string()) return "string " + text;
  return text;
}

// Optimal-string-alignment distance (Levenshtein plus adjacent transpositions, the commonest typo).
int edit_distance(const std::string& a, const std::string& b) {
  const size_t n = a.size(), m = b.size();
  std::vector<std::vector<int>> d(n + 1, std::vector<int>(m + 1));
  for (size_t i = 0; i <= n; ++i) d[i][0] = static_cast<int>(i);
  for (size_t j = 0; j <= m; ++j) d[0][j] = static_cast<int>(j);
  for (size_t i = 1; i <= n; ++i)
    for (size_t j = 1; j <= m; ++j) {
      const int cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[n][m];
}

// Lower case with '-' read as '_', so that "Lambda-P2P" (a CLI spelling) is suggested its JSON name.
std::string normalized(std::string s) {
  for (char& c : s) {
    if (c == '-') c = '_';
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return s;
}

std::string unknown_message(const std::string& name) {
  const std::string key = normalized(name);
  // At most 3 edits and at most half the name, so that a short unrelated word gets no far-fetched suggestion.
  const int limit = std::min(3, std::max(1, static_cast<int>(key.size()) / 2));
  std::vector<std::pair<int, const char*>> close;  // (distance, name), table order within a distance
  for (const ParamInfo& p : deform_param_table()) {
    const int d = edit_distance(key, p.name);
    if (d <= limit) close.emplace_back(d, p.name);
  }
  std::stable_sort(close.begin(), close.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::string msg = "unknown parameter " + quoted(name);
  if (!close.empty()) {
    msg += " (did you mean ";
    const size_t shown = std::min<size_t>(close.size(), 3);
    for (size_t i = 0; i < shown; ++i) {
      if (i > 0) msg += i + 1 == shown ? " or " : ", ";
      msg += quoted(close[i].second);
    }
    return msg + "?)";
  }
  msg += " (valid parameters:";
  for (const ParamInfo& p : deform_param_table()) msg += std::string(" ") + p.name;
  return msg + ")";
}

void check_range(const ParamInfo& p, double x, bool integral, const std::string& where) {
  if (!(x >= p.min && x <= p.max))
    throw InputError(where, "parameter " + quoted(p.name) + " = " + number_text(x, integral) +
                                " is out of range [" + number_text(p.min, integral) + ", " +
                                number_text(p.max, integral) + "]");
}

// The enum value named `s`; InputError listing the names otherwise.
template <class T>
T enum_from_name(const ParamInfo& p, const std::string& s, const std::string& where) {
  const std::vector<std::string> allowed = enum_names<T>();
  for (size_t i = 0; i < allowed.size(); ++i)
    if (allowed[i] == s) return static_cast<T>(i);
  std::string list;
  for (size_t i = 0; i < allowed.size(); ++i)
    list += (i == 0 ? "" : i + 1 == allowed.size() ? " or " : ", ") + ("\"" + allowed[i] + "\"");
  throw InputError(where, "parameter " + quoted(p.name) + " must be " + list + " (got \"" + s + "\")");
}

template <class T>
void assign(T& field, const ParamInfo& p, const json& v, const std::string& where) {
  const std::string what = "parameter " + quoted(p.name);
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) throw InputError(where, what + ": expected true or false, got " + describe(v));
    field = v.get<bool>();
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!v.is_string()) throw InputError(where, what + ": expected a string, got " + describe(v));
    field = v.get<std::string>();
  } else if constexpr (is_enum_param_v<T>) {
    if (!v.is_string()) throw InputError(where, what + ": expected a string, got " + describe(v));
    field = enum_from_name<T>(p, v.get<std::string>(), where);
  } else {
    constexpr bool integral = is_integer_v<T>;
    if (!v.is_number())
      throw InputError(
          where, what + ": expected " + (integral ? "an integer" : "a number") + ", got " + describe(v));
    const double x = v.get<double>();
    if (!std::isfinite(x)) throw InputError(where, what + " is not a finite number");
    if (integral && x != std::floor(x))
      throw InputError(where, what + ": expected an integer, got " + v.dump());
    check_range(p, x, integral, where);
    // In range, hence exactly representable in T (every range fits an int).
    field = static_cast<T>(x);
  }
}

// The value as JSON: enums by name, the others as themselves.
nlohmann::ordered_json param_value_json(const DeformParams& params, const ParamInfo& p) {
  return std::visit(
      [&](auto member) -> nlohmann::ordered_json {
        using T = std::decay_t<decltype(params.*member)>;
        if constexpr (is_enum_param_v<T>)
          return to_string(params.*member);
        else
          return params.*member;
      },
      p.member);
}

}  // namespace

const std::vector<ParamInfo>& deform_param_table() {
  static const std::vector<ParamInfo> table = make_table();
  return table;
}

const ParamInfo* find_param(const std::string& name) {
  for (const ParamInfo& p : deform_param_table())
    if (name == p.name) return &p;
  return nullptr;
}

std::vector<std::string> param_choices(const ParamInfo& p) {
  return std::visit(
      [](auto member) -> std::vector<std::string> {
        using T = std::decay_t<decltype(DeformParams{}.*member)>;
        if constexpr (is_enum_param_v<T>)
          return enum_names<T>();
        else
          return {};
      },
      p.member);
}

bool is_test_hook(const ParamInfo& p) {
  return std::string(p.group) == "testing";
}

const char* to_string(HessianPrecision p) {
  return enum_name(p);
}

const char* to_string(BackendKind b) {
  return enum_name(b);
}

const char* to_string(DomainKind d) {
  return enum_name(d);
}

const char* to_string(InjectivityMode m) {
  return enum_name(m);
}

std::string param_flag(const ParamInfo& p) {
  std::string flag = std::string("--") + p.name;
  std::replace(flag.begin(), flag.end(), '_', '-');
  return flag;
}

void set_param(DeformParams& params, const std::string& name, const nlohmann::json& value,
               const std::string& where) {
  const ParamInfo* p = find_param(name);
  if (!p) throw InputError(where, unknown_message(name));
  std::visit([&](auto member) { assign(params.*member, *p, value, where); }, p->member);
}

void set_param_from_text(DeformParams& params, const std::string& name, const std::string& text,
                         const std::string& where) {
  const ParamInfo* p = find_param(name);
  json v;
  if (p && !param_choices(*p).empty()) {
    v = text;
  } else if (p && std::holds_alternative<std::string DeformParams::*>(p->member)) {
    v = text;
  } else {
    try {
      v = json::parse(text);
    } catch (const json::exception&) {
      throw InputError(where, "'" + text + "' is not a number or true/false");
    }
  }
  set_param(params, name, v, where);
}

void apply_params(DeformParams& params, const nlohmann::json& object, const std::string& where) {
  if (!object.is_object())
    throw InputError(where,
                     "parameters must be a JSON object {\"name\": value, ...}, got " + describe(object));
  for (const auto& [name, value] : object.items()) set_param(params, name, value, where);
}

void validate_params(const DeformParams& params, const std::string& where) {
  // Each field on its own; no parameter constrains another so far (voxel_side > 0 simply wins over samples).
  for (const ParamInfo& p : deform_param_table()) {
    std::visit(
        [&](auto member) {
          using T = std::decay_t<decltype(params.*member)>;
          const T& v = params.*member;
          if constexpr (is_enum_param_v<T>) {
            // Only code can set an enum to a value without a name (a cast); JSON and text are checked by
            // name.
            const auto i = static_cast<size_t>(v);
            if (i >= enum_names<T>().size())
              throw InputError(
                  where, "parameter " + quoted(p.name) + " has no valid value (" + std::to_string(i) + ")");
          } else if constexpr (!std::is_same_v<T, bool> && !std::is_same_v<T, std::string>) {
            const double x = static_cast<double>(v);
            if (!std::isfinite(x))
              throw InputError(where, "parameter " + quoted(p.name) + " is not a finite number");
            check_range(p, x, is_integer_v<T>, where);
          }
        },
        p.member);
  }
  // σ1/σ3 ≥ 1 for every matrix: a target below 1 can never be proven.
  if (params.max_distortion > 0 && params.max_distortion < 1)
    throw InputError(where,
                     "parameter \"max_distortion\" must be 0 (off) or >= 1 (sigma1/sigma3 >= 1 "
                     "always), got " +
                         format_g(params.max_distortion));
  // The map a solve starts from (the identity) has σ1 = 1: a bound below 1 would refuse every map.
  if (params.max_sigma1 > 0 && params.max_sigma1 < 1)
    throw InputError(
        where, "parameter \"max_sigma1\" must be 0 (off) or >= 1 (the rest state has sigma1 = 1), got " +
                   format_g(params.max_sigma1));
}

nlohmann::ordered_json params_to_json(const DeformParams& params) {
  nlohmann::ordered_json j = nlohmann::ordered_json::object();
  for (const ParamInfo& p : deform_param_table()) j[p.name] = param_value_json(params, p);
  return j;
}

std::string param_value_string(const DeformParams& params, const ParamInfo& p) {
  return std::visit(
      [&](auto member) -> std::string {
        using T = std::decay_t<decltype(params.*member)>;
        const T& v = params.*member;
        if constexpr (std::is_same_v<T, std::string>)
          return v;
        else if constexpr (is_enum_param_v<T>)
          return to_string(v);
        else if constexpr (std::is_same_v<T, bool>)
          return v ? "true" : "false";
        else if constexpr (std::is_same_v<T, double>)
          return format_double(v);
        else
          return std::to_string(v);
      },
      p.member);
}

SamplingParams sampling_params_of(const DeformParams& params) {
  SamplingParams sp;
  sp.target_count = params.samples;
  sp.voxel_side = params.voxel_side;
  sp.safety = params.safety;
  sp.hessian_fraction = params.hessian_fraction;
  return sp;
}

CertifyParams certify_params_of(const DeformParams& params, bool stop_on_failure, bool keep_leaves) {
  CertifyParams cp;
  cp.bound = params.bound;
  cp.refinement = params.refinement;
  cp.max_depth = params.max_depth;
  cp.max_refined_voxels = params.max_refined;
  cp.stop_on_failure = stop_on_failure;
  cp.keep_leaves = keep_leaves;
  cp.bound_tolerance = params.bound_tolerance;
  cp.max_distortion = params.max_distortion;
  cp.max_sigma1 = params.max_sigma1;
  cp.min_sigma3 = params.min_sigma3;
  return cp;
}

bool changes_precomputation(const DeformParams& a, const DeformParams& b) {
  return a.reduced_dof != b.reduced_dof || a.samples != b.samples || a.voxel_side != b.voxel_side ||
         a.domain != b.domain || a.safety != b.safety || a.hessian_fraction != b.hessian_fraction ||
         a.threads != b.threads || a.backend != b.backend || a.opencl_device != b.opencl_device ||
         a.opencl_gpu_layout != b.opencl_gpu_layout || a.test_break_kernels != b.test_break_kernels ||
         a.test_opencl_max_alloc != b.test_opencl_max_alloc;
}

}  // namespace lidef
