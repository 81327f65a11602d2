#include "lidef/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string_view>

#include "lidef/errors.h"
#include "lidef/number_format.h"

namespace lidef {
namespace {

namespace fs = std::filesystem;

// Whole file as text. Rejects missing, unreadable, empty and binary files with a message naming the file.
std::string read_text_file(const std::string& path, const char* what) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "file not found");
  if (fs::is_directory(path, ec))
    throw InputError(path, "is a directory, expected a " + std::string(what) + " file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  if (text.empty()) throw InputError(path, "file is empty");
  // Control characters other than whitespace never occur in a text mesh; reporting them up front gives a
  // clearer message than the first parse error they would cause.
  long line = 1;
  for (size_t i = 0; i < text.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') ++line;
    if ((c < 0x20 && c != '\n' && c != '\r' && c != '\t' && c != '\f' && c != '\v') || c == 0x7f) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "binary data (byte 0x%02x at offset %zu); expected a text %s file", c, i,
                    what);
      throw InputError(path, buf, line);
    }
  }
  return text;
}

// Splits text into lines (without '\n', '\r' or '#' comments) and each line into whitespace tokens.
class LineReader {
 public:
  explicit LineReader(const std::string& text) : text_(text) {}
  // Advances to the next line with at least one token. Returns false at the end of the text.
  bool next() {
    while (pos_ < text_.size()) {
      const size_t end = std::min(text_.find('\n', pos_), text_.size());
      std::string_view line(text_.data() + pos_, end - pos_);
      pos_ = end + 1;
      ++line_;
      const size_t hash = line.find('#');
      if (hash != std::string_view::npos) line = line.substr(0, hash);
      tokens_.clear();
      size_t i = 0;
      while (i < line.size()) {
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
        size_t j = i;
        while (j < line.size() && !std::isspace(static_cast<unsigned char>(line[j]))) ++j;
        if (j > i) tokens_.push_back(line.substr(i, j - i));
        i = j;
      }
      if (!tokens_.empty()) return true;
    }
    return false;
  }
  const std::vector<std::string_view>& tokens() const { return tokens_; }
  long line() const { return line_; }

 private:
  const std::string& text_;
  size_t pos_ = 0;
  long line_ = 0;
  std::vector<std::string_view> tokens_;
};

std::string quoted(std::string_view tok) {
  std::string s(tok.substr(0, 40));
  if (tok.size() > 40) s += "...";
  return "'" + s + "'";
}

// Parses a whole token as a double (locale-independent). NaN/Inf are accepted here and rejected by the
// caller with a message that says which coordinate.
double parse_double(std::string_view tok, const std::string& file, long line) {
  if (!tok.empty() && tok[0] == '+') tok.remove_prefix(1);
  double x = 0;
  const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), x);
  if (ec == std::errc::result_out_of_range)
    throw InputError(file, "number " + quoted(tok) + " is out of the range of a double", line);
  if (ec != std::errc() || ptr != tok.data() + tok.size() || tok.empty())
    throw InputError(file, quoted(tok) + " is not a number", line);
  return x;
}

long parse_int(std::string_view tok, const std::string& file, long line, const char* what) {
  if (!tok.empty() && tok[0] == '+') tok.remove_prefix(1);
  long x = 0;
  const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), x);
  if (ec == std::errc::result_out_of_range || (ec == std::errc() && (x > 2000000000L || x < -2000000000L)))
    throw InputError(file, std::string(what) + " " + quoted(tok) + " is out of range", line);
  if (ec != std::errc() || ptr != tok.data() + tok.size() || tok.empty())
    throw InputError(file, std::string(what) + " " + quoted(tok) + " is not an integer", line);
  return x;
}

void check_finite(const Vec3& p, long vertex1, const std::string& file, long line) {
  static const char* axis[] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k) {
    if (std::isnan(p[k]))
      throw InputError(file, "vertex " + std::to_string(vertex1) + ": " + axis[k] + " coordinate is NaN",
                       line);
    if (std::isinf(p[k]))
      throw InputError(file, "vertex " + std::to_string(vertex1) + ": " + axis[k] + " coordinate is infinite",
                       line);
  }
}

Vec3 parse_point(const std::vector<std::string_view>& tok, size_t first, long vertex1,
                 const std::string& file, long line) {
  if (tok.size() < first + 3)
    throw InputError(file,
                     "vertex " + std::to_string(vertex1) + " needs 3 coordinates, found " +
                         std::to_string(tok.size() - first),
                     line);
  Vec3 p;
  for (int k = 0; k < 3; ++k) p[k] = parse_double(tok[first + k], file, line);
  for (size_t k = first + 3; k < tok.size(); ++k)
    parse_double(tok[k], file, line);  // w or colors: must be numbers
  check_finite(p, vertex1, file, line);
  return p;
}

std::string arity_message(size_t n, long face1) {
  const std::string f = "face " + std::to_string(face1) + " has " + std::to_string(n) + " vertices";
  return n < 3 ? f + " (a face needs 3)" : f + "; only triangles are supported (triangulate the mesh first)";
}

TriMesh to_mesh(const std::vector<Vec3>& V, const std::vector<Eigen::Vector3i>& F, const std::string& path) {
  TriMesh m;
  m.source = path;
  m.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  m.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) m.V.row(i) = V[i].transpose();
  for (size_t i = 0; i < F.size(); ++i) m.F.row(i) = F[i].transpose();
  return m;
}

TriMesh read_obj(const std::string& path, MeshLines* lines, bool allow_points) {
  const std::string text = read_text_file(path, ".obj");
  LineReader rd(text);
  std::vector<Vec3> V;
  std::vector<Eigen::Vector3i> F;
  MeshLines ml;
  bool any = false;
  while (rd.next()) {
    any = true;
    const auto& tok = rd.tokens();
    const std::string_view key = tok[0];
    if (key == "v") {
      V.push_back(parse_point(tok, 1, static_cast<long>(V.size()) + 1, path, rd.line()));
      ml.vertex.push_back(rd.line());
    } else if (key == "f") {
      const long face1 = static_cast<long>(F.size()) + 1;
      if (tok.size() != 4) throw InputError(path, arity_message(tok.size() - 1, face1), rd.line());
      Eigen::Vector3i f;
      for (int k = 0; k < 3; ++k) {
        const std::string_view corner = tok[k + 1];
        const std::string_view idx = corner.substr(0, corner.find('/'));
        const long i = parse_int(idx, path, rd.line(), "vertex index");
        if (i == 0)
          throw InputError(
              path, "face " + std::to_string(face1) + ": vertex index 0 is invalid (OBJ indices start at 1)",
              rd.line());
        if (i < 0 && -i > static_cast<long>(V.size()))
          throw InputError(path,
                           "face " + std::to_string(face1) + ": relative vertex index " + std::to_string(i) +
                               " points before the first vertex (" + std::to_string(V.size()) +
                               " vertices defined so far)",
                           rd.line());
        // Positive indices may refer to vertices defined later in the file; their range is checked at the
        // end.
        f[k] = static_cast<int>(i < 0 ? static_cast<long>(V.size()) + i : i - 1);
      }
      F.push_back(f);
      ml.face.push_back(rd.line());
    } else if (key == "vt" || key == "vn" || key == "vp" || key == "g" || key == "o" || key == "s" ||
               key == "l" || key == "p" || key == "usemtl" || key == "mtllib") {
      continue;
    } else {
      throw InputError(path,
                       "unknown OBJ statement " + quoted(key) +
                           " (expected v, f or one that is ignored: "
                           "vt vn vp g o s l p usemtl mtllib)",
                       rd.line());
    }
  }
  if (!any) throw InputError(path, "file is empty (only blank lines or comments)");
  if (V.empty()) throw InputError(path, "no vertices ('v' lines)");
  if (F.empty() && !allow_points) throw InputError(path, "no faces ('f' lines)");
  for (size_t t = 0; t < F.size(); ++t)
    for (int k = 0; k < 3; ++k)
      if (F[t][k] >= static_cast<int>(V.size()))
        throw InputError(path,
                         "face " + std::to_string(t + 1) + ": vertex index " + std::to_string(F[t][k] + 1) +
                             " is out of range (file has " + std::to_string(V.size()) + " vertices)",
                         ml.face[t]);
  if (lines) *lines = std::move(ml);
  return to_mesh(V, F, path);
}

bool is_off_header(std::string_view tok) {
  // [ST][C][N]OFF; the 4OFF / nOFF variants are for other dimensions and are rejected.
  if (tok.size() < 3 || tok.substr(tok.size() - 3) != "OFF") return false;
  tok.remove_suffix(3);
  if (tok.substr(0, 2) == "ST") tok.remove_prefix(2);
  if (!tok.empty() && tok[0] == 'C') tok.remove_prefix(1);
  if (!tok.empty() && tok[0] == 'N') tok.remove_prefix(1);
  return tok.empty();
}

// An ASCII OFF file, faces of any size (`arity` 0) or only triangles (`arity` 3: a face of another size is an
// error naming it). Vertex lines: 3 coordinates, then optional numbers (normals, colours, texture) that are
// checked and ignored; face lines: n, n vertex indices, then optional colour numbers, likewise.
struct OffData {
  std::vector<Vec3> V;
  std::vector<std::vector<std::size_t>> faces;
  MeshLines lines;
};
OffData parse_off(const std::string& path, int arity) {
  const std::string text = read_text_file(path, ".off");
  LineReader rd(text);
  if (!rd.next()) throw InputError(path, "file is empty (only blank lines or comments)");
  if (!is_off_header(rd.tokens()[0]))
    throw InputError(path, "missing OFF header (first line must be 'OFF'), found " + quoted(rd.tokens()[0]),
                     rd.line());
  std::vector<std::string_view> counts(rd.tokens().begin() + 1, rd.tokens().end());
  long counts_line = rd.line();
  if (counts.empty()) {
    if (!rd.next()) throw InputError(path, "file ends before the vertex/face counts", rd.line());
    counts = rd.tokens();
    counts_line = rd.line();
  }
  if (counts.size() < 2 || counts.size() > 3)
    throw InputError(path, "expected counts 'nv nf [ne]'", counts_line);
  const long nv = parse_int(counts[0], path, counts_line, "vertex count");
  const long nf = parse_int(counts[1], path, counts_line, "face count");
  if (counts.size() == 3) parse_int(counts[2], path, counts_line, "edge count");
  if (nv <= 0)
    throw InputError(path, "no vertices (vertex count is " + std::to_string(nv) + ")", counts_line);
  if (nf <= 0) throw InputError(path, "no faces (face count is " + std::to_string(nf) + ")", counts_line);
  OffData d;
  // The counts come from the file: reserve no more than its text can hold (a vertex line has at least 6
  // characters "0 0 0\n", a face line 8). Reserving the counts themselves let a 20-byte file
  // ("OFF\n99999999 99999\n") allocate gigabytes, or fail with std::bad_alloc (found by fuzzing,
  // fuzz/regressions/mesh_off/); an over-large count is then reported as the file ending early.
  d.V.reserve(static_cast<size_t>(std::min<long>(nv, static_cast<long>(text.size() / 6))));
  d.faces.reserve(static_cast<size_t>(std::min<long>(nf, static_cast<long>(text.size() / 8))));
  for (long i = 0; i < nv; ++i) {
    if (!rd.next())
      throw InputError(path,
                       "file ends after " + std::to_string(i) + " of " + std::to_string(nv) + " vertices",
                       rd.line());
    d.V.push_back(parse_point(rd.tokens(), 0, i + 1, path, rd.line()));
    d.lines.vertex.push_back(rd.line());
  }
  for (long t = 0; t < nf; ++t) {
    if (!rd.next())
      throw InputError(path, "file ends after " + std::to_string(t) + " of " + std::to_string(nf) + " faces",
                       rd.line());
    const auto& tok = rd.tokens();
    const long n = parse_int(tok[0], path, rd.line(), "face size");
    if (arity > 0 && n != arity) throw InputError(path, arity_message(n < 0 ? 0 : n, t + 1), rd.line());
    if (n < 0) throw InputError(path, "face " + std::to_string(t + 1) + ": negative size", rd.line());
    if (static_cast<long>(tok.size()) - 1 < n)
      throw InputError(path,
                       "face " + std::to_string(t + 1) + " lists " + std::to_string(tok.size() - 1) +
                           " of its " + std::to_string(n) + " vertex indices",
                       rd.line());
    std::vector<std::size_t> f(static_cast<size_t>(n));
    for (long k = 0; k < n; ++k) {
      const long i = parse_int(tok[static_cast<size_t>(k) + 1], path, rd.line(), "vertex index");
      if (i < 0 || i >= nv)
        throw InputError(path,
                         "face " + std::to_string(t + 1) + ": vertex index " + std::to_string(i) +
                             " is out of range (OFF indices are 0-based; file has " + std::to_string(nv) +
                             " vertices)",
                         rd.line());
      f[static_cast<size_t>(k)] = static_cast<std::size_t>(i);
    }
    for (size_t k = static_cast<size_t>(n) + 1; k < tok.size(); ++k)
      parse_double(tok[k], path, rd.line());  // optional color
    d.faces.push_back(std::move(f));
    d.lines.face.push_back(rd.line());
  }
  if (rd.next()) throw InputError(path, "unexpected data after the last face", rd.line());
  return d;
}

TriMesh read_off(const std::string& path, MeshLines* lines) {
  OffData d = parse_off(path, 3);
  std::vector<Eigen::Vector3i> F;
  F.reserve(d.faces.size());
  for (const auto& f : d.faces)
    F.emplace_back(static_cast<int>(f[0]), static_cast<int>(f[1]), static_cast<int>(f[2]));
  if (lines) *lines = std::move(d.lines);
  return to_mesh(d.V, F, path);
}

}  // namespace

PolygonSoupMesh read_off_polygons(const std::string& path) {
  OffData d = parse_off(path, 0);
  PolygonSoupMesh out;
  out.V.resize(static_cast<Eigen::Index>(d.V.size()), 3);
  for (size_t i = 0; i < d.V.size(); ++i) out.V.row(static_cast<Eigen::Index>(i)) = d.V[i].transpose();
  out.polygons = std::move(d.faces);
  return out;
}

TriMesh read_mesh(const std::string& path, MeshLines* lines) {
  const std::string ext = lowercase_extension(path);
  if (ext == ".obj") return read_obj(path, lines, false);
  if (ext == ".off") return read_off(path, lines);
  throw InputError(path, "unsupported mesh format '" + ext + "' (expected .obj or .off)");
}

TriMesh read_mesh_or_points(const std::string& path, MeshLines* lines) {
  const std::string ext = lowercase_extension(path);
  if (ext == ".obj") return read_obj(path, lines, true);
  return read_mesh(path, lines);
}

void write_obj(std::ostream& out, const MatX3d& V, const MatX3i& F, const std::string& comment) {
  if (!comment.empty()) {
    std::istringstream ss(comment);
    for (std::string line; std::getline(ss, line);) out << "# " << line << "\n";
  }
  std::string buf;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    buf = "v " + format_double(V(i, 0)) + " " + format_double(V(i, 1)) + " " + format_double(V(i, 2)) + "\n";
    out << buf;
  }
  for (Eigen::Index t = 0; t < F.rows(); ++t)
    out << "f " << F(t, 0) + 1 << " " << F(t, 1) + 1 << " " << F(t, 2) + 1 << "\n";
}

std::string lowercase_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

void write_points_xyz(std::ostream& out, const MatX3d& P, const MatX3d& normals) {
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    out << format_double(P(i, 0)) << ' ' << format_double(P(i, 1)) << ' ' << format_double(P(i, 2));
    if (normals.rows() == P.rows())
      out << ' ' << format_double(normals(i, 0)) << ' ' << format_double(normals(i, 1)) << ' '
          << format_double(normals(i, 2));
    out << '\n';
  }
}

MatX3d read_points_xyz(const std::string& path, MatX3d* normals) {
  const std::string text = read_text_file(path, ".xyz");
  LineReader rd(text);
  std::vector<Vec3> P, N;
  size_t columns = 0;  // 3 or 6, set by the first point
  while (rd.next()) {
    const auto& tok = rd.tokens();
    const long point1 = static_cast<long>(P.size()) + 1;
    if (columns == 0 && (tok.size() == 3 || tok.size() == 6)) columns = tok.size();
    if (tok.size() != columns)
      throw InputError(path,
                       "point " + std::to_string(point1) + ": expected " +
                           (columns == 6 ? std::string("6 numbers 'x y z nx ny nz' like the first point")
                                         : std::string("3 numbers 'x y z' (or 6 with a normal)")) +
                           ", found " + std::to_string(tok.size()),
                       rd.line());
    Vec3 p, n = Vec3::Zero();
    for (int k = 0; k < 3; ++k) p[k] = parse_double(tok[k], path, rd.line());
    if (columns == 6)
      for (int k = 0; k < 3; ++k) n[k] = parse_double(tok[3 + k], path, rd.line());
    if (!p.allFinite() || !n.allFinite())
      throw InputError(path, "point " + std::to_string(point1) + " has a NaN or infinite coordinate",
                       rd.line());
    P.push_back(p);
    N.push_back(n);
  }
  if (P.empty()) throw InputError(path, "no points (file has only blank lines or comments)");
  MatX3d out(static_cast<Eigen::Index>(P.size()), 3);
  for (size_t i = 0; i < P.size(); ++i) out.row(i) = P[i].transpose();
  if (normals) {
    normals->resize(columns == 6 ? out.rows() : 0, 3);
    if (columns == 6)
      for (size_t i = 0; i < N.size(); ++i) normals->row(i) = N[i].transpose();
  }
  return out;
}

}  // namespace lidef
