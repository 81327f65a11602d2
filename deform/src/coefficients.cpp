#include "lidef/coefficients.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"

namespace lidef {

MatX3d read_coefficients(const std::string& path, const Cage& cage) {
  if (path == "identity") return cage.identity_coefficients();
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot open coefficient file");
  std::vector<Vec3> rows;
  std::string line;
  long ln = 0;
  while (std::getline(in, line)) {
    ++ln;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r,") == std::string::npos) continue;
    for (char& c : line)
      if (c == ',') c = ' ';
    std::istringstream ss(line);
    Vec3 v;
    std::string extra;
    for (int k = 0; k < 3; ++k) {
      std::string tok;
      if (!(ss >> tok)) throw InputError(path, "expected 3 numbers per row", ln);
      char* end = nullptr;
      v(k) = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0') throw InputError(path, "'" + tok + "' is not a number", ln);
      if (!std::isfinite(v(k))) throw InputError(path, "non-finite coefficient '" + tok + "'", ln);
    }
    if (ss >> extra) throw InputError(path, "more than 3 numbers in a row", ln);
    rows.push_back(v);
  }
  if (static_cast<int>(rows.size()) != cage.num_coeffs())
    throw InputError(path, "has " + std::to_string(rows.size()) +
                               " rows, expected #V+#F = " + std::to_string(cage.num_vertices()) + "+" +
                               std::to_string(cage.num_faces()) + " = " + std::to_string(cage.num_coeffs()) +
                               " (vertex rows first, then face rows)");
  MatX3d y(rows.size(), 3);
  for (size_t i = 0; i < rows.size(); ++i) y.row(i) = rows[i];
  return y;
}

void write_coefficients(std::ostream& out, const MatX3d& y) {
  for (Eigen::Index i = 0; i < y.rows(); ++i)
    out << format_double(y(i, 0)) << ' ' << format_double(y(i, 1)) << ' ' << format_double(y(i, 2)) << '\n';
}

}  // namespace lidef
