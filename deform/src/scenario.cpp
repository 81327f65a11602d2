#include "lidef/scenario.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <system_error>
#include <type_traits>
#include <variant>

#include "lidef/atomic_file.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"

namespace lidef {

namespace fs = std::filesystem;
using nlohmann::ordered_json;

namespace {

const char* const kTopKeys[] = {"name", "model", "description", "handles", "parameters", "studio"};
const char* const kHandleForm = "{\"source\": [x, y, z], \"target\": [x, y, z]}";

// Thrown from the parser callback; caught in parse_scenario_json only.
struct DuplicateKey {
  std::string key;
};

std::string read_whole_file(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "scenario file not found");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, not a scenario file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open scenario file");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw InputError(path, "cannot read scenario file");
  return ss.str();
}

long line_of_offset(const std::string& text, size_t offset) {
  offset = std::min(offset, text.size());
  return 1 + static_cast<long>(std::count(text.begin(), text.begin() + static_cast<long>(offset), '\n'));
}

// nlohmann's what() is "[json.exception.<kind>.<id>] <message>"; messages read better without the tag.
std::string untagged(const char* what) {
  std::string s = what;
  if (s.rfind("[json.exception.", 0) == 0) {
    const size_t end = s.find("] ");
    if (end != std::string::npos) s.erase(0, end + 2);
  }
  return s;
}

// Parses with the line of a syntax error and refuses duplicate keys: nlohmann keeps the last of them
// silently, so a scenario with "handles" twice would run with only one of the lists.
ordered_json parse_scenario_json(const std::string& path, const std::string& text) {
  std::vector<std::set<std::string>> keys;  // keys seen in each open object
  const ordered_json::parser_callback_t callback = [&keys](int, ordered_json::parse_event_t event,
                                                           ordered_json& parsed) {
    using E = ordered_json::parse_event_t;
    if (event == E::object_start) keys.emplace_back();
    if (event == E::object_end && !keys.empty()) keys.pop_back();
    if (event == E::key && !keys.empty() && !keys.back().insert(parsed.get<std::string>()).second)
      throw DuplicateKey{parsed.get<std::string>()};
    return true;
  };
  try {
    return ordered_json::parse(text, callback);
  } catch (const DuplicateKey& d) {
    throw InputError(path, "duplicate key \"" + d.key + "\" (each key may appear once in an object)");
  } catch (const ordered_json::parse_error& e) {
    // e.byte is the 1-based offset of the character where parsing failed.
    if (text.find_first_not_of(" \t\r\n") == std::string::npos)
      throw InputError(path, "the file is empty (expected a JSON object)");
    const size_t at = std::min(e.byte > 0 ? e.byte - 1 : 0, text.size());
    const long line = line_of_offset(text, at);
    const size_t newline = at == 0 ? std::string::npos : text.rfind('\n', at - 1);
    const size_t column = newline == std::string::npos ? at + 1 : at - newline;
    std::string detail = untagged(e.what());
    const size_t colon = detail.find(": ");  // drop nlohmann's own "parse error at line L, column C"
    if (detail.rfind("parse error", 0) == 0 && colon != std::string::npos) detail.erase(0, colon + 2);
    throw InputError(path,
                     "JSON syntax error at line " + std::to_string(line) + ", column " +
                         std::to_string(column) + " (byte " + std::to_string(e.byte) + "): " + detail,
                     line);
  } catch (const ordered_json::exception& e) {
    // E.g. out_of_range 406 "number overflow parsing '1e400'": locate the quoted token for the line.
    std::string detail = untagged(e.what());
    long line = 0;
    const size_t q1 = detail.find('\''), q2 = detail.rfind('\'');
    if (q1 != std::string::npos && q2 > q1 + 1) {
      const size_t pos = text.find(detail.substr(q1 + 1, q2 - q1 - 1));
      if (pos != std::string::npos) line = line_of_offset(text, pos);
    }
    throw InputError(path, "invalid JSON: " + detail, line);
  }
}

std::string json_type(const ordered_json& v) {
  if (v.is_array() || v.is_object()) return v.type_name();
  std::string text = v.dump();
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return v.is_string() ? "string " + text : text;
}

std::string optional_string(const ordered_json& root, const char* key, const std::string& path) {
  const auto it = root.find(key);
  if (it == root.end()) return "";
  if (!it->is_string())
    throw InputError(path, "\"" + std::string(key) + "\" must be a string, got " + json_type(*it));
  return it->get<std::string>();
}

// A point [x, y, z] of finite numbers; `what` names it in messages ("source", "path[2]").
Vec3 json_to_point(const ordered_json& v, const std::string& what, const std::string& where,
                   const std::string& path) {
  if (!v.is_array() || v.size() != 3)
    throw InputError(
        path, where + ": \"" + what + "\" must be an array of 3 numbers [x, y, z], got " + json_type(v));
  Vec3 p;
  for (int k = 0; k < 3; ++k) {
    const ordered_json& c = v[k];
    // null and strings such as "nan" are refused too: JSON has no NaN, so they are how one sneaks in.
    p(k) = c.is_number() ? c.get<double>() : std::nan("");
    if (!std::isfinite(p(k)))
      throw InputError(path, where + ": " + what + "[" + std::to_string(k) + "] (" + "xyz"[k] +
                                 ") is not a finite number (got " + json_type(c) + ")");
  }
  return p;
}

Vec3 handle_point(const ordered_json& h, const char* key, const std::string& where, const std::string& path) {
  const auto it = h.find(key);
  if (it == h.end())
    throw InputError(path, where + ": missing \"" + key + "\" (a handle is " + kHandleForm + ")");
  return json_to_point(*it, key, where, path);
}

// "path": waypoints visited in order before "target" (every handle the same number, or none has one);
// "group": the rigid part the handle belongs to (every handle, or none). docs/solver.md, "Continuation".
void read_handle_path_and_group(const ordered_json& h, Eigen::Index i, Eigen::Index n,
                                const std::string& where, const std::string& path, Scenario& s) {
  const auto wp = h.find("path");
  const size_t count = wp == h.end() ? 0 : (wp->is_array() ? wp->size() : 0);
  if (wp != h.end() && (!wp->is_array() || wp->empty()))
    throw InputError(
        path,
        where + ": \"path\" must be a non-empty array of waypoints [[x, y, z], ...], got " + json_type(*wp));
  if (i == 0) {
    s.waypoints.assign(count, MatX3d(n, 3));
  } else if (count != s.waypoints.size()) {
    throw InputError(path, where + ": \"path\" has " + std::to_string(count) +
                               " waypoints but handle 1 has " + std::to_string(s.waypoints.size()) +
                               " (every handle needs the same number; repeat a fixed handle's source)");
  }
  for (size_t k = 0; k < count; ++k)
    s.waypoints[k].row(i) =
        json_to_point((*wp)[k], "path[" + std::to_string(k) + "]", where, path).transpose();
  const auto g = h.find("group");
  if (i == 0 && g != h.end()) s.groups.assign(static_cast<size_t>(n), 0);
  if ((g != h.end()) != !s.groups.empty())
    throw InputError(path, where +
                               (g == h.end() ? ": has no \"group\" but handle 1 has one"
                                             : ": has a \"group\" but handle 1 has none") +
                               " (give every handle a group, or none)");
  if (g != h.end()) {
    if (!g->is_number_integer() || g->get<long>() < 0 || g->get<long>() > 1000000)
      throw InputError(path, where + ": \"group\" must be an integer in 0..1000000, got " + g->dump());
    s.groups[static_cast<size_t>(i)] = static_cast<int>(g->get<long>());
  }
}

// Candidate folders for `model`, in the order of scenario.h.
std::vector<fs::path> model_candidates(const std::string& scenario_path, const std::string& model,
                                       const std::string& models_dir) {
  std::vector<fs::path> c;
  if (!models_dir.empty()) c.push_back(fs::path(models_dir) / model);
  if (fs::path(model).is_absolute()) c.push_back(model);
  fs::path dir = fs::path(scenario_path).parent_path();
  if (dir.empty()) dir = ".";
  c.push_back(dir / model);
  c.push_back(dir / ".." / "models" / model);
  for (fs::path& p : c) p = p.lexically_normal();
  std::vector<fs::path> unique;
  for (const fs::path& p : c)
    if (std::find(unique.begin(), unique.end(), p) == unique.end()) unique.push_back(p);
  return unique;
}

// Shortest round-trip form, kept a JSON float for -0 (to_chars writes "-0", which JSON reads as integer 0).
std::string json_number(double x) {
  if (x == 0 && std::signbit(x)) return "-0.0";
  return format_double(x);
}

std::string json_string(const std::string& s, const std::string& path) {
  try {
    return nlohmann::json(s).dump();
  } catch (const nlohmann::json::exception& e) {  // invalid UTF-8
    throw InputError(path, "cannot write scenario: " + untagged(e.what()));
  }
}

std::string json_point(const MatX3d& M, Eigen::Index i) {
  return "[" + json_number(M(i, 0)) + ", " + json_number(M(i, 1)) + ", " + json_number(M(i, 2)) + "]";
}

}  // namespace

Scenario read_scenario(const std::string& path, const std::string& models_dir) {
  const std::string text = read_whole_file(path);
  const ordered_json root = parse_scenario_json(path, text);
  if (!root.is_object()) throw InputError(path, "the scenario must be a JSON object, got " + json_type(root));
  for (const auto& [key, value] : root.items()) {
    (void)value;
    if (std::find(std::begin(kTopKeys), std::end(kTopKeys), key) == std::end(kTopKeys))
      throw InputError(path, "unknown key \"" + key +
                                 "\" (allowed: name, model, description, handles, parameters, studio)");
  }

  Scenario s;
  s.path = path;
  s.name = optional_string(root, "name", path);
  if (s.name.empty()) s.name = fs::path(path).stem().string();
  s.description = optional_string(root, "description", path);

  const auto model = root.find("model");
  if (model == root.end()) throw InputError(path, "missing \"model\" (the name or path of the model folder)");
  if (!model->is_string()) throw InputError(path, "\"model\" must be a string, got " + json_type(*model));
  s.model = model->get<std::string>();
  if (s.model.empty()) throw InputError(path, "\"model\" is empty");
  const std::vector<fs::path> tried = model_candidates(path, s.model, models_dir);
  for (const fs::path& p : tried) {
    std::error_code ec;
    // A mesh file stands for the model folder lidef_cage makes from it (resolve_model_path, docs/cages.md).
    const std::string ext = lowercase_extension(p.string());
    const bool mesh_file = fs::is_regular_file(p, ec) && (ext == ".obj" || ext == ".off" || ext == ".ply" ||
                                                          ext == ".stl" || ext == ".xyz");
    if (fs::is_directory(p, ec) || mesh_file) {
      s.model_dir = p.string();
      break;
    }
  }
  if (s.model_dir.empty()) {
    std::string list;
    for (const fs::path& p : tried) list += (list.empty() ? "" : ", ") + p.string();
    throw InputError(path, "model folder \"" + s.model + "\" not found (tried " + list + ")");
  }

  const auto handles = root.find("handles");
  if (handles == root.end())
    throw InputError(path, "missing \"handles\": a scenario needs at least one handle");
  if (!handles->is_array())
    throw InputError(
        path, "\"handles\" must be an array of " + std::string(kHandleForm) + ", got " + json_type(*handles));
  if (handles->empty()) throw InputError(path, "no handles: a scenario needs at least one handle");
  const Eigen::Index n = static_cast<Eigen::Index>(handles->size());
  s.sources.resize(n, 3);
  s.targets.resize(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    const ordered_json& h = (*handles)[static_cast<size_t>(i)];
    // Handles are numbered from 1 in messages, like faces and vertices elsewhere in lidef.
    const std::string where = "handle " + std::to_string(i + 1) + " of " + std::to_string(n);
    if (!h.is_object())
      throw InputError(path, where + " must be an object " + kHandleForm + ", got " + json_type(h));
    for (const auto& [key, value] : h.items()) {
      (void)value;
      if (key != "source" && key != "target" && key != "path" && key != "group")
        throw InputError(path,
                         where + ": unknown key \"" + key + "\" (allowed: source, target, path, group)");
    }
    s.sources.row(i) = handle_point(h, "source", where, path).transpose();
    s.targets.row(i) = handle_point(h, "target", where, path).transpose();
    read_handle_path_and_group(h, i, n, where, path, s);
  }

  const auto params = root.find("parameters");
  if (params != root.end()) {
    if (!params->is_object())
      throw InputError(
          path, "\"parameters\" must be a JSON object {\"name\": value, ...}, got " + json_type(*params));
    // set_param key by key rather than apply_params: apply_params takes a nlohmann::json, whose keys are
    // sorted, and params_given must keep the file's order.
    for (const auto& [key, value] : params->items()) {
      set_param(s.params, key, nlohmann::json(value), path);
      s.params_given.push_back(key);
    }
  }
  validate_params(s.params, path);
  const auto studio = root.find("studio");
  if (studio != root.end()) {
    if (!studio->is_object())
      throw InputError(
          path, "\"studio\" must be a JSON object (the studio's view settings), got " + json_type(*studio));
    s.studio = studio->dump();
  }
  return s;
}

void write_scenario(const std::string& path, const Scenario& s) {
  // Refuse what read_scenario would refuse: a file that cannot be read back is worse than no file.
  if (s.sources.rows() == 0) throw InputError(path, "no handles: a scenario needs at least one handle");
  if (s.targets.rows() != s.sources.rows())
    throw InputError(path, "scenario has " + std::to_string(s.sources.rows()) + " sources but " +
                               std::to_string(s.targets.rows()) + " targets");
  if (!s.sources.allFinite() || !s.targets.allFinite())
    throw InputError(path, "handle coordinates must be finite numbers");
  for (const MatX3d& w : s.waypoints)
    if (w.rows() != s.sources.rows() || !w.allFinite())
      throw InputError(path, "every waypoint needs one finite point per handle");
  if (!s.groups.empty() && static_cast<Eigen::Index>(s.groups.size()) != s.sources.rows())
    throw InputError(path, "one group per handle is needed");
  validate_params(s.params, path);
  // `model` as given keeps the file portable; a scenario built in memory with only the folder gets its path.
  const std::string model = !s.model.empty() ? s.model : s.model_dir;
  if (model.empty()) throw InputError(path, "scenario has no model");

  // Hand-formatted rather than dump(2): one line per handle keeps long handle lists readable.
  std::string out = "{\n";
  if (!s.name.empty()) out += "  \"name\": " + json_string(s.name, path) + ",\n";
  out += "  \"model\": " + json_string(model, path) + ",\n";
  if (!s.description.empty()) out += "  \"description\": " + json_string(s.description, path) + ",\n";
  out += "  \"handles\": [\n";
  for (Eigen::Index i = 0; i < s.sources.rows(); ++i) {
    out += "    {\"source\": " + json_point(s.sources, i);
    if (!s.waypoints.empty()) {
      out += ", \"path\": [";
      for (size_t k = 0; k < s.waypoints.size(); ++k) out += (k ? ", " : "") + json_point(s.waypoints[k], i);
      out += "]";
    }
    out += ", \"target\": " + json_point(s.targets, i);
    if (!s.groups.empty()) out += ", \"group\": " + std::to_string(s.groups[static_cast<size_t>(i)]);
    out += std::string("}") + (i + 1 < s.sources.rows() ? ",\n" : "\n");
  }
  out += "  ]";
  const DeformParams defaults;
  std::vector<std::string> changed;
  for (const ParamInfo& p : deform_param_table()) {
    std::visit(
        [&](auto member) {
          const auto& v = s.params.*member;
          if (v == defaults.*member) return;
          using T = std::decay_t<decltype(v)>;
          std::string text;
          if constexpr (std::is_same_v<T, std::string>)
            text = json_string(v, path);
          else if constexpr (std::is_enum_v<T>)
            text = json_string(to_string(v), path);
          else if constexpr (std::is_same_v<T, bool>)
            text = v ? "true" : "false";
          else if constexpr (std::is_same_v<T, double>)
            text = json_number(v);
          else
            text = std::to_string(v);
          changed.push_back("    \"" + std::string(p.name) + "\": " + text);
        },
        p.member);
  }
  if (!changed.empty()) {
    out += ",\n  \"parameters\": {\n";
    for (size_t i = 0; i < changed.size(); ++i) out += changed[i] + (i + 1 < changed.size() ? ",\n" : "\n");
    out += "  }";
  }
  if (!s.studio.empty()) {
    // Validated and re-indented: a saved session must read back.
    ordered_json st;
    try {
      st = ordered_json::parse(s.studio);
    } catch (const std::exception& e) {
      throw InputError(path, std::string("studio settings are not valid JSON: ") + e.what());
    }
    if (!st.is_object()) throw InputError(path, "studio settings must be a JSON object");
    std::string body = st.dump(2);
    std::string indented;
    for (char c : body) indented += c == '\n' ? std::string("\n  ") : std::string(1, c);
    out += ",\n  \"studio\": " + indented;
  }
  out += "\n}\n";

  // Readers never see a half-written scenario.
  write_file_atomic(path, [&](std::ostream& f) { f << out; });
}

}  // namespace lidef
