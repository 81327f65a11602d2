#include "lidef/point_cloud_io.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"

namespace lidef {
namespace {

namespace fs = std::filesystem;

void reverse_bytes(unsigned char* b, std::size_t n) {
  for (std::size_t i = 0, j = n - 1; i < j; ++i, --j) {
    const unsigned char c = b[i];
    b[i] = b[j];
    b[j] = c;
  }
}

struct PlyType {
  int size = 0;  // bytes
  bool is_float = false, is_signed = false;
};

bool ply_type(const std::string& t, PlyType* out) {
  static const struct {
    const char* name;
    PlyType type;
  } kTypes[] = {{"char", {1, false, true}},    {"int8", {1, false, true}},    {"uchar", {1, false, false}},
                {"uint8", {1, false, false}},  {"short", {2, false, true}},   {"int16", {2, false, true}},
                {"ushort", {2, false, false}}, {"uint16", {2, false, false}}, {"int", {4, false, true}},
                {"int32", {4, false, true}},   {"uint", {4, false, false}},   {"uint32", {4, false, false}},
                {"float", {4, true, true}},    {"float32", {4, true, true}},  {"double", {8, true, true}},
                {"float64", {8, true, true}}};
  for (const auto& k : kTypes)
    if (t == k.name) {
      *out = k.type;
      return true;
    }
  return false;
}

struct PlyProp {
  std::string name;
  PlyType type;
  std::string type_name;
  bool is_list = false;
  PlyType count_type;
};

struct PlyElement {
  std::string name;
  long count = 0;
  std::vector<PlyProp> props;
};

struct Header {
  std::string format;
  std::vector<PlyElement> elements;
  std::vector<std::string> comments;
  std::size_t body = 0;  // byte offset of the body
};

Header parse_header(const std::string& path, const std::string& bytes) {
  Header h;
  std::size_t pos = 0;
  long line_no = 0;
  auto next_line = [&](std::string* line) {
    if (pos >= bytes.size()) return false;
    std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    *line = bytes.substr(pos, end - pos);
    if (!line->empty() && line->back() == '\r') line->pop_back();
    // A last line without '\n' ends at the file's end: the body offset must not pass it.
    pos = end < bytes.size() ? end + 1 : end;
    ++line_no;
    return true;
  };
  std::string line;
  if (!next_line(&line) || line != "ply")
    throw InputError(path, "not a PLY file (first line is not 'ply')", 1);
  bool ended = false;
  while (next_line(&line)) {
    std::istringstream ss(line);
    std::string key;
    ss >> key;
    if (key.empty()) continue;
    if (key == "end_header") {
      ended = true;
      break;
    }
    if (key == "comment" || key == "obj_info") {
      if (key == "comment") h.comments.push_back(line.size() > 8 ? line.substr(8) : "");
    } else if (key == "format") {
      std::string version;
      ss >> h.format >> version;
      if (h.format != "ascii" && h.format != "binary_little_endian" && h.format != "binary_big_endian")
        throw InputError(path, "unknown PLY format '" + h.format + "'", line_no);
    } else if (key == "element") {
      PlyElement e;
      ss >> e.name >> e.count;
      if (ss.fail() || e.count < 0) throw InputError(path, "malformed element line '" + line + "'", line_no);
      h.elements.push_back(e);
    } else if (key == "property") {
      if (h.elements.empty()) throw InputError(path, "property before any element", line_no);
      PlyProp p;
      std::string t;
      ss >> t;
      if (t == "list") {
        std::string ct, it;
        ss >> ct >> it >> p.name;
        p.is_list = true;
        if (!ply_type(ct, &p.count_type) || !ply_type(it, &p.type))
          throw InputError(path, "unknown PLY type in '" + line + "'", line_no);
        p.type_name = it;
      } else {
        ss >> p.name;
        if (!ply_type(t, &p.type)) throw InputError(path, "unknown PLY type '" + t + "'", line_no);
        p.type_name = t;
      }
      if (p.name.empty()) throw InputError(path, "property without a name", line_no);
      h.elements.back().props.push_back(p);
    } else {
      throw InputError(path, "unknown PLY header line '" + line + "'", line_no);
    }
  }
  if (!ended) throw InputError(path, "PLY header has no 'end_header'");
  if (h.format.empty()) throw InputError(path, "PLY header has no 'format' line");
  h.body = pos;
  return h;
}

// Reads the body value by value, ASCII or binary.
class BodyReader {
 public:
  BodyReader(const std::string& path, const std::string& bytes, const Header& h)
      : path_(path),
        bytes_(bytes),
        pos_(h.body),
        ascii_(h.format == "ascii"),
        swap_(h.format == "binary_big_endian") {
    if (ascii_) text_.str(bytes.substr(h.body));
  }

  double value(const PlyType& t, const std::string& what) {
    if (ascii_) {
      std::string tok;
      if (!(text_ >> tok)) throw InputError(path_, "file ends early: " + what + " is missing");
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0')
        throw InputError(path_, what + ": '" + tok + "' is not a number");
      return v;
    }
    if (pos_ + static_cast<std::size_t>(t.size) > bytes_.size())
      throw InputError(path_, "binary body is truncated: " + what + " is missing (file has " +
                                  std::to_string(bytes_.size()) + " bytes)");
    unsigned char b[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    const std::size_t n = std::min<std::size_t>(static_cast<std::size_t>(t.size), sizeof b);
    std::memcpy(b, bytes_.data() + pos_, n);
    pos_ += n;
    const bool host_little = [] {
      const std::uint16_t one = 1;
      unsigned char c;
      std::memcpy(&c, &one, 1);
      return c == 1;
    }();
    if (swap_ == host_little) reverse_bytes(b, n);
    if (t.is_float) {
      if (t.size == 4) {
        float f;
        std::memcpy(&f, b, 4);
        return f;
      }
      double d;
      std::memcpy(&d, b, 8);
      return d;
    }
    switch (t.size) {
      case 1:
        return t.is_signed ? static_cast<double>(static_cast<std::int8_t>(b[0])) : b[0];
      case 2: {
        std::uint16_t u;
        std::memcpy(&u, b, 2);
        return t.is_signed ? static_cast<double>(static_cast<std::int16_t>(u)) : u;
      }
      default: {
        std::uint32_t u;
        std::memcpy(&u, b, 4);
        return t.is_signed ? static_cast<double>(static_cast<std::int32_t>(u)) : u;
      }
    }
  }

 private:
  const std::string& path_;
  const std::string& bytes_;
  std::size_t pos_;
  bool ascii_, swap_;
  std::istringstream text_;
};

std::string read_bytes(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "file not found");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, expected a point cloud file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the file");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw InputError(path, "cannot read the file");
  return ss.str();
}

template <typename T>
void put(std::ostream& out, T v, bool big) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  const std::uint16_t one = 1;
  unsigned char c;
  std::memcpy(&c, &one, 1);
  if (big == (c == 1)) reverse_bytes(b, sizeof(T));
  out.write(reinterpret_cast<const char*>(b), sizeof(T));
}

void put_value(std::ostream& out, double v, const std::string& type_name, bool big) {
  PlyType t;
  ply_type(type_name, &t);
  if (t.is_float) {
    if (t.size == 4)
      put<float>(out, static_cast<float>(v), big);
    else
      put<double>(out, v, big);
    return;
  }
  const double r = std::nearbyint(v);
  switch (t.size) {
    case 1:
      t.is_signed ? put<std::int8_t>(out, static_cast<std::int8_t>(r), big)
                  : put<std::uint8_t>(out, static_cast<std::uint8_t>(r), big);
      break;
    case 2:
      t.is_signed ? put<std::int16_t>(out, static_cast<std::int16_t>(r), big)
                  : put<std::uint16_t>(out, static_cast<std::uint16_t>(r), big);
      break;
    default:
      t.is_signed ? put<std::int32_t>(out, static_cast<std::int32_t>(r), big)
                  : put<std::uint32_t>(out, static_cast<std::uint32_t>(r), big);
  }
}

std::string ascii_value(double v, const std::string& type_name) {
  PlyType t;
  ply_type(type_name, &t);
  if (!t.is_float) return std::to_string(static_cast<long long>(std::nearbyint(v)));
  if (t.size == 4) return format_double(static_cast<double>(static_cast<float>(v)));
  return format_double(v);
}

}  // namespace

int PlyCloud::column(const std::string& name) const {
  const auto it = std::find(names.begin(), names.end(), name);
  return it == names.end() ? -1 : static_cast<int>(it - names.begin());
}

MatX3d PlyCloud::columns3(const std::string& a, const std::string& b, const std::string& c) const {
  const int k[3] = {column(a), column(b), column(c)};
  MatX3d P(values.rows(), 3);
  for (int j = 0; j < 3; ++j) {
    if (k[j] < 0)
      throw InputError("", "point cloud has no property '" + std::string(j == 0 ? a : j == 1 ? b : c) + "'");
    P.col(j) = values.col(k[j]);
  }
  return P;
}

void PlyCloud::set_columns3(const std::string& a, const std::string& b, const std::string& c,
                            const MatX3d& P) {
  const int k[3] = {column(a), column(b), column(c)};
  for (int j = 0; j < 3; ++j) {
    if (k[j] < 0)
      throw InputError("", "point cloud has no property '" + std::string(j == 0 ? a : j == 1 ? b : c) + "'");
    values.col(k[j]) = P.col(j);
  }
}

PlyCloud read_ply_cloud(const std::string& path) {
  const std::string bytes = read_bytes(path);
  if (bytes.empty()) throw InputError(path, "file is empty");
  const Header h = parse_header(path, bytes);
  PlyCloud cloud;
  cloud.format = h.format;
  cloud.comments = h.comments;
  const PlyElement* vertex = nullptr;
  for (const PlyElement& e : h.elements)
    if (e.name == "vertex") vertex = &e;
  if (!vertex) throw InputError(path, "PLY file has no vertex element");
  for (const PlyProp& p : vertex->props) {
    if (p.is_list) throw InputError(path, "vertex property '" + p.name + "' is a list (not supported)");
    cloud.names.push_back(p.name);
    cloud.types.push_back(p.type_name);
  }
  for (const char* axis : {"x", "y", "z"})
    if (cloud.column(axis) < 0)
      throw InputError(path, std::string("vertex element has no property '") + axis + "'");
  if (vertex->count == 0) throw InputError(path, "empty point cloud (0 vertices)");
  // A count far beyond the bytes present is refused before anything is allocated for it.
  if (h.format != "ascii") {
    std::size_t row = 0;
    for (const PlyProp& p : vertex->props) row += static_cast<std::size_t>(p.type.size);
    if (static_cast<double>(vertex->count) * static_cast<double>(row) >
        static_cast<double>(bytes.size() - h.body))
      throw InputError(path, "binary body is truncated: " + std::to_string(vertex->count) + " vertices of " +
                                 std::to_string(row) + " bytes need more than the file's " +
                                 std::to_string(bytes.size() - h.body) + " bytes after the header");
  } else if (static_cast<double>(vertex->count) * static_cast<double>(vertex->props.size()) >
             static_cast<double>(bytes.size() - h.body)) {
    // Each ASCII value takes at least one byte.
    throw InputError(path, "file ends early: " + std::to_string(vertex->count) + " vertices of " +
                               std::to_string(vertex->props.size()) + " values declared, " +
                               std::to_string(bytes.size() - h.body) + " bytes after the header");
  }
  BodyReader rd(path, bytes, h);
  std::vector<std::array<int, 3>> tris;
  for (const PlyElement& e : h.elements) {
    // Entries without properties hold no bytes: nothing to read, however many are declared.
    if (e.props.empty()) continue;
    const bool is_vertex = &e == vertex, is_face = e.name == "face";
    if (is_vertex) cloud.values.resize(e.count, static_cast<Eigen::Index>(e.props.size()));
    for (long i = 0; i < e.count; ++i)
      for (std::size_t k = 0; k < e.props.size(); ++k) {
        const PlyProp& p = e.props[k];
        const std::string what = e.name + " " + std::to_string(i + 1) + " '" + p.name + "'";
        if (!p.is_list) {
          const double v = rd.value(p.type, what);
          if (is_vertex) cloud.values(i, static_cast<Eigen::Index>(k)) = v;
          continue;
        }
        const double n = rd.value(p.count_type, what + " count");
        if (!(n >= 0 && n <= 1e6))
          throw InputError(path, what + ": list length " + format_g(n) + " is invalid");
        // Kept as read: a list of another element may hold anything (floats, a uint beyond int's range).
        std::vector<double> items(static_cast<std::size_t>(n));
        for (double& v : items) v = rd.value(p.type, what);
        if (!is_face || (p.name != "vertex_indices" && p.name != "vertex_index")) continue;
        std::vector<int> idx;
        for (const double v : items) {
          if (!(v >= 0 && v < static_cast<double>(vertex->count)))  // also before the conversion to int
            throw InputError(path, "face " + std::to_string(i + 1) + ": vertex index " + format_g(v) +
                                       " is out of range (" + std::to_string(vertex->count) + " vertices)");
          idx.push_back(static_cast<int>(v));
        }
        for (std::size_t c = 1; c + 1 < idx.size(); ++c) tris.push_back({idx[0], idx[c], idx[c + 1]});
      }
  }
  cloud.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (std::size_t t = 0; t < tris.size(); ++t)
    cloud.F.row(static_cast<Eigen::Index>(t)) = Eigen::RowVector3i(tris[t][0], tris[t][1], tris[t][2]);
  const int cx = cloud.column("x"), cy = cloud.column("y"), cz = cloud.column("z");
  for (Eigen::Index i = 0; i < cloud.values.rows(); ++i)
    if (!std::isfinite(cloud.values(i, cx)) || !std::isfinite(cloud.values(i, cy)) ||
        !std::isfinite(cloud.values(i, cz)))
      throw InputError(path, "vertex " + std::to_string(i + 1) + ": coordinate is NaN or infinite");
  return cloud;
}

long ply_face_count(const std::string& path) {
  // The header only: read up to its end (headers are short; a body may be large).
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the file");
  std::string head, line;
  while (std::getline(in, line) && head.size() < (1u << 20)) {
    head += line + "\n";
    if (line.rfind("end_header", 0) == 0) break;
  }
  const Header h = parse_header(path, head);
  for (const PlyElement& e : h.elements)
    if (e.name == "face") return e.count;
  return 0;
}

void write_ply_cloud(std::ostream& out, const PlyCloud& cloud) {
  out << "ply\nformat " << cloud.format << " 1.0\n";
  for (const std::string& c : cloud.comments) out << "comment " << c << "\n";
  out << "element vertex " << cloud.values.rows() << "\n";
  for (std::size_t k = 0; k < cloud.names.size(); ++k)
    out << "property " << cloud.types[k] << " " << cloud.names[k] << "\n";
  if (cloud.F.rows() > 0)
    out << "element face " << cloud.F.rows() << "\nproperty list uchar int vertex_indices\n";
  out << "end_header\n";
  if (cloud.format == "ascii") {
    for (Eigen::Index i = 0; i < cloud.values.rows(); ++i) {
      for (std::size_t k = 0; k < cloud.names.size(); ++k)
        out << (k ? " " : "") << ascii_value(cloud.values(i, static_cast<Eigen::Index>(k)), cloud.types[k]);
      out << "\n";
    }
    for (Eigen::Index t = 0; t < cloud.F.rows(); ++t)
      out << "3 " << cloud.F(t, 0) << " " << cloud.F(t, 1) << " " << cloud.F(t, 2) << "\n";
    return;
  }
  const bool big = cloud.format == "binary_big_endian";
  for (Eigen::Index i = 0; i < cloud.values.rows(); ++i)
    for (std::size_t k = 0; k < cloud.names.size(); ++k)
      put_value(out, cloud.values(i, static_cast<Eigen::Index>(k)), cloud.types[k], big);
  for (Eigen::Index t = 0; t < cloud.F.rows(); ++t) {
    put<std::uint8_t>(out, 3, big);
    for (int k = 0; k < 3; ++k) put<std::int32_t>(out, cloud.F(t, k), big);
  }
}

void map_point_cloud(PlyCloud& cloud, const MatX3d& mapped, const MatXd& JT) {
  cloud.set_columns3("x", "y", "z", mapped);
  if (!cloud.has_normals()) return;
  MatX3d N = cloud.columns3("nx", "ny", "nz");
  for (Eigen::Index i = 0; i < N.rows(); ++i) {
    const Mat3 J = JT.block<3, 3>(3 * i, 0).transpose();
    // cof J = det J · J⁻ᵀ, written out so that it exists for singular J too.
    Mat3 cof;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        cof(r, c) = J((r + 1) % 3, (c + 1) % 3) * J((r + 2) % 3, (c + 2) % 3) -
                    J((r + 1) % 3, (c + 2) % 3) * J((r + 2) % 3, (c + 1) % 3);
    const Vec3 n = cof * N.row(i).transpose();
    const double len = n.norm();
    N.row(i) = (len > 0 ? Vec3(n / len) : n).transpose();
  }
  cloud.set_columns3("nx", "ny", "nz", N);
}

MatX3d read_point_cloud(const std::string& path) {
  const std::string ext = lowercase_extension(path);
  if (ext == ".ply") return read_ply_cloud(path).points();
  if (ext == ".xyz") return read_points_xyz(path);
  if (ext == ".obj") return read_mesh_or_points(path).V;
  throw InputError(path, "unsupported point cloud format '" + ext + "' (expected .ply, .xyz or .obj)");
}

}  // namespace lidef
