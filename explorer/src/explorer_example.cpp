#include "lidef/explorer/explorer_example.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/procedural_models.h"

namespace lidef {

const HarmonicPolynomialMap* ExplorerExample::polynomial() const {
  const auto* p = dynamic_cast<const PolynomialExplorerMap*>(map.get());
  return p ? &p->map() : nullptr;
}

ExplorerExample read_explorer_example(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the map file");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(path, std::string("malformed JSON: ") + e.what());
  }
  auto number = [&](const nlohmann::json& v, const std::string& what) {
    if (!v.is_number()) throw InputError(path, what + " must be a number");
    const double x = v.get<double>();
    if (!std::isfinite(x)) throw InputError(path, what + " is not finite");
    return x;
  };
  auto vec3 = [&](const nlohmann::json& v, const std::string& what) {
    if (!v.is_array() || v.size() != 3) throw InputError(path, what + " must be an array of 3 numbers");
    return Vec3(number(v[0], what), number(v[1], what), number(v[2], what));
  };
  if (!j.is_object()) throw InputError(path, "the map file must hold a JSON object");
  // An optional string member ("" when absent); a member of another type is an input error, not
  // nlohmann's type_error (which json::value() throws).
  auto text = [&](const char* key) -> std::string {
    if (!j.contains(key)) return "";
    if (!j[key].is_string()) throw InputError(path, std::string("\"") + key + "\" must be a string");
    return j[key].get<std::string>();
  };
  if (text("format") != "lidef-explorer-map")
    throw InputError(path, "not a lidef explorer map (\"format\": \"lidef-explorer-map\" missing)");
  ExplorerExample ex;
  ex.kind = text("type");
  if (j.contains("note")) {
    if (!j["note"].is_string()) throw InputError(path, "\"note\" must be a string");
    ex.note = j["note"].get<std::string>();
  }
  if (j.contains("domain")) {
    const nlohmann::json& d = j["domain"];
    if (!d.is_object()) throw InputError(path, "\"domain\" must be an object {center, radius}");
    if (d.contains("center")) ex.ball.center = vec3(d["center"], "domain.center");
    if (d.contains("radius")) ex.ball.radius = number(d["radius"], "domain.radius");
    if (!(ex.ball.radius > 0)) throw InputError(path, "domain.radius must be positive");
  }
  if (ex.kind == "harmonic_polynomial") {
    if (!j.contains("degree") || !j["degree"].is_number_integer())
      throw InputError(path, "\"degree\" (an integer) is missing");
    const long deg = j["degree"].get<long>();
    if (deg < 1 || deg > kMaxHarmonicDegree)
      throw InputError(path, "degree must be in 1.." + std::to_string(kMaxHarmonicDegree) + " (got " +
                                 std::to_string(deg) + ")");
    const int n = harmonic_basis_size(static_cast<int>(deg));
    const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(static_cast<int>(deg));
    if (!j.contains("coefficients") || !j["coefficients"].is_array())
      throw InputError(path, "\"coefficients\" (an array of [x, y, z] rows) is missing");
    const nlohmann::json& c = j["coefficients"];
    if (static_cast<int>(c.size()) != n)
      throw InputError(path, "a degree-" + std::to_string(deg) + " map needs " + std::to_string(n) +
                                 " coefficient rows (got " + std::to_string(c.size()) + ")");
    if (j.contains("basis")) {
      const nlohmann::json& b = j["basis"];
      if (!b.is_array() || static_cast<int>(b.size()) != n)
        throw InputError(path, "\"basis\" must list the " + std::to_string(n) + " basis names");
      for (int i = 0; i < n; ++i)
        if (!b[i].is_string() || b[i].get<std::string>() != B.names[i])
          throw InputError(path,
                           "basis entry " + std::to_string(i + 1) + " should be \"" + B.names[i] + "\"");
    }
    Eigen::Matrix<double, 3, Eigen::Dynamic> C(3, n);
    for (int i = 0; i < n; ++i)
      C.col(i) = vec3(c[i], "coefficient row " + std::to_string(i + 1) + " (" + B.names[i] + ")");
    ex.map = std::make_shared<PolynomialExplorerMap>(HarmonicPolynomialMap(static_cast<int>(deg), C));
  } else if (ex.kind == "cage") {
    if (!j.contains("model") || !j["model"].is_string())
      throw InputError(path, "\"model\" (a folder) is missing");
    if (!j.contains("coefficients") || !j["coefficients"].is_string())
      throw InputError(path, "\"coefficients\" (a coefficient file or \"identity\") is missing");
    const std::filesystem::path base = std::filesystem::path(path).parent_path();
    auto resolve = [&](const std::string& p) {
      if (p == "identity" || std::filesystem::path(p).is_absolute()) return p;
      return (base / p).string();
    };
    const Model model = load_model(resolve(j["model"].get<std::string>()));
    const MatX3d y = read_coefficients(resolve(j["coefficients"].get<std::string>()), model.cage);
    // The ball must stay inside the cage, away from it (the basis is singular on the cage).
    const double clearance = ex.ball.radius * 1e-3;
    const TriMesh s = icosphere(ex.ball.radius, 3);
    for (int i = 0; i < s.V.rows(); ++i) {
      const Vec3 p = ex.ball.center + s.V.row(i).transpose();
      if (std::abs(model.cage.winding_number(p) - 1) > 1e-6 || model.cage.distance(p) < clearance)
        throw InputError(path, "the domain ball is not inside the cage of " + j["model"].get<std::string>());
    }
    ex.map = std::make_shared<CageExplorerMap>(model.cage, y, path);
    ex.cage_model = resolve(j["model"].get<std::string>());
    ex.cage_coefficients = resolve(j["coefficients"].get<std::string>());
  } else {
    throw InputError(path, "\"type\" must be \"harmonic_polynomial\" or \"cage\"");
  }
  return ex;
}

std::string explorer_example_json(const HarmonicPolynomialMap& map, const Ball& ball,
                                  const std::string& note) {
  const HarmonicPolynomialBasis& B = harmonic_polynomial_basis(map.degree());
  std::ostringstream s;
  s << "{\n  \"format\": \"lidef-explorer-map\",\n  \"type\": \"harmonic_polynomial\",\n";
  s << "  \"note\": " << nlohmann::json(note).dump() << ",\n";
  s << "  \"degree\": " << map.degree() << ",\n";
  s << "  \"domain\": {\"center\": [" << format_double(ball.center.x()) << ", "
    << format_double(ball.center.y()) << ", " << format_double(ball.center.z())
    << "], \"radius\": " << format_double(ball.radius) << "},\n";
  s << "  \"basis\": [";
  for (int i = 0; i < B.size(); ++i) s << (i ? ", " : "") << '"' << B.names[i] << '"';
  s << "],\n  \"coefficients\": [\n";
  for (int i = 0; i < B.size(); ++i) {
    const auto& c = map.coefficients().col(i);
    s << "    [" << format_double(c(0)) << ", " << format_double(c(1)) << ", " << format_double(c(2)) << "]"
      << (i + 1 < B.size() ? "," : "") << "\n";
  }
  s << "  ]\n}\n";
  return s.str();
}

}  // namespace lidef
