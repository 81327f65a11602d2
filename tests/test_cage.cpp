// Automatic cages (lidef_cage, docs/cages.md): read_any_mesh on every format and on bad inputs, make_cage on
// meshes with several components, holes, quads, extreme scales, determinism, `lidef cage`, and a mesh file
// used where a model folder is expected (`lidef deform`, resolve_model_path).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "lidef/cage/auto_cage.h"
#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "test_support.h"

namespace {

using namespace lidef;
using lidef::test::input_error_message;
using lidef::test::read_text;
using lidef::test::TempDir;
using lidef::test::write_text;
namespace fs = std::filesystem;

std::string quote(const std::string& s) {
  return "'" + s + "'";
}

int run_lidef(const std::string& args, std::string* output) {
  return lidef::test::run_command(quote(lidef::test::cli()) + " " + args, output);
}

// A polygon mesh as the tests write it: points and polygons (0-based) of any arity.
struct Poly {
  std::vector<Vec3> v;
  std::vector<std::vector<int>> f;
};

// Torus (major radius R, minor r) around the z axis at `center`, n x m quads, counter-clockwise seen from
// outside. `skip` quads (every skip-th, 0 = none) are left out, which opens holes.
Poly torus(const Vec3& center, double R, double r, int n, int m, int skip = 0) {
  Poly p;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      const double u = 2 * M_PI * i / n, w = 2 * M_PI * j / m;
      p.v.push_back(center + Vec3((R + r * std::cos(w)) * std::cos(u), (R + r * std::cos(w)) * std::sin(u),
                                  r * std::sin(w)));
    }
  int k = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j, ++k) {
      if (skip > 0 && k % skip == skip - 1) continue;
      const int a = i * m + j, b = ((i + 1) % n) * m + j, c = ((i + 1) % n) * m + (j + 1) % m,
                d = i * m + (j + 1) % m;
      p.f.push_back({a, b, c, d});
    }
  return p;
}

Poly merged(const Poly& a, const Poly& b) {
  Poly p = a;
  const int off = static_cast<int>(a.v.size());
  p.v.insert(p.v.end(), b.v.begin(), b.v.end());
  for (auto f : b.f) {
    for (int& x : f) x += off;
    p.f.push_back(f);
  }
  return p;
}

Poly scaled(Poly p, double s, const Vec3& shift = Vec3::Zero()) {
  for (Vec3& x : p.v) x = x * s + shift;
  return p;
}

std::string num(double x) {
  std::ostringstream s;
  s.precision(17);
  s << x;
  return s.str();
}

std::string obj_text(const Poly& p) {
  std::string s = "# test mesh\n";
  for (const Vec3& x : p.v) s += "v " + num(x.x()) + " " + num(x.y()) + " " + num(x.z()) + "\n";
  for (const auto& f : p.f) {
    s += "f";
    for (int i : f) s += " " + std::to_string(i + 1);
    s += "\n";
  }
  return s;
}

std::vector<std::array<int, 3>> fan(const Poly& p) {
  std::vector<std::array<int, 3>> t;
  for (const auto& f : p.f)
    for (size_t k = 1; k + 1 < f.size(); ++k) t.push_back({f[0], f[k], f[k + 1]});
  return t;
}

template <class T>
void put(std::string& s, T x) {
  char b[sizeof(T)];
  std::memcpy(b, &x, sizeof(T));
  s.append(b, sizeof(T));
}

// Binary little-endian PLY with float vertices and polygon faces (uchar count, int indices).
std::string ply_binary(const Poly& p) {
  std::string s = "ply\nformat binary_little_endian 1.0\ncomment lidef test\nelement vertex " +
                  std::to_string(p.v.size()) +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                  std::to_string(p.f.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const Vec3& x : p.v)
    for (int k = 0; k < 3; ++k) put(s, static_cast<float>(x[k]));
  for (const auto& f : p.f) {
    put(s, static_cast<unsigned char>(f.size()));
    for (int i : f) put(s, static_cast<std::int32_t>(i));
  }
  return s;
}

std::string ply_ascii(const Poly& p) {
  std::string s = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(p.v.size()) +
                  "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
                  std::to_string(p.f.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const Vec3& x : p.v) s += num(x.x()) + " " + num(x.y()) + " " + num(x.z()) + "\n";
  for (const auto& f : p.f) {
    s += std::to_string(f.size());
    for (int i : f) s += " " + std::to_string(i);
    s += "\n";
  }
  return s;
}

std::string stl_ascii(const Poly& p) {
  std::string s = "solid test\n";
  for (const auto& t : fan(p)) {
    s += "facet normal 0 0 0\nouter loop\n";
    for (int i : t) s += "vertex " + num(p.v[i].x()) + " " + num(p.v[i].y()) + " " + num(p.v[i].z()) + "\n";
    s += "endloop\nendfacet\n";
  }
  return s + "endsolid test\n";
}

// Binary OFF (Geomview): "OFF BINARY", three big-endian int32 counts, big-endian float32 coordinates, faces
// as int32 n, n indices, int32 colour count (0).
std::string off_binary(const Poly& p) {
  std::string out = "OFF BINARY\n";
  auto be32 = [&](std::uint32_t u) {
    for (int s = 24; s >= 0; s -= 8) out += static_cast<char>((u >> s) & 0xff);
  };
  be32(static_cast<std::uint32_t>(p.v.size()));
  be32(static_cast<std::uint32_t>(p.f.size()));
  be32(0);
  for (const Vec3& x : p.v)
    for (int a = 0; a < 3; ++a) {
      const float f = static_cast<float>(x(a));
      std::uint32_t u;
      std::memcpy(&u, &f, 4);
      be32(u);
    }
  for (const auto& f : p.f) {
    be32(4);
    for (int k = 0; k < 4; ++k) be32(static_cast<std::uint32_t>(f[k]));
    be32(0);
  }
  return out;
}

std::string stl_binary(const Poly& p) {
  std::string s(80, ' ');
  s.replace(0, 12, "binary stl  ");
  const auto tris = fan(p);
  put(s, static_cast<std::uint32_t>(tris.size()));
  for (const auto& t : tris) {
    for (int k = 0; k < 3; ++k) put(s, 0.0f);
    for (int i : t)
      for (int k = 0; k < 3; ++k) put(s, static_cast<float>(p.v[i][k]));
    put(s, static_cast<std::uint16_t>(0));
  }
  return s;
}

// Independent inside test: the winding number of every mesh vertex w.r.t. the cage, summed face by face with
// solid_angle_fraction, is 1.
void expect_winding_one(const TriMesh& cage, const TriMesh& mesh) {
  int bad = 0;
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    const Vec3 p = mesh.V.row(i);
    double w = 0;
    for (Eigen::Index f = 0; f < cage.F.rows(); ++f)
      w += solid_angle_fraction(cage.V.row(cage.F(f, 0)), cage.V.row(cage.F(f, 1)), cage.V.row(cage.F(f, 2)),
                                p);
    if (std::abs(w - 1) > 1e-6 && bad++ < 5) ADD_FAILURE() << "vertex " << i << ": winding number " << w;
  }
  EXPECT_EQ(bad, 0) << "mesh vertices with winding number != 1";
}

// Reads `path`, makes a cage, writes the model folder to `dir`, loads it back with load_model and checks the
// winding numbers. Returns the result.
CageResult cage_roundtrip(const std::string& path, const std::string& dir, const CageOptions& opt = {}) {
  MeshReadInfo info;
  const TriMesh mesh = read_any_mesh(path, &info);
  CageResult r = make_cage(mesh, opt);
  fs::create_directories(dir);
  write_cage_model(r, path, info, opt, [&](const std::string& name) { return dir + "/" + name; });
  const Model m = load_model(dir);  // throws InputError when the folder is not usable
  EXPECT_TRUE(m.report.self_intersections.empty());
  EXPECT_EQ(m.report.mesh_vertices_outside, 0);
  EXPECT_GT(m.report.min_distance, 0);
  EXPECT_EQ(m.mesh.V, mesh.V) << "mesh.obj must hold the input's vertices unchanged";
  EXPECT_LE(r.cage.F.rows(), 4000);
  // The clearance: every cage face proven clear, so every mesh vertex is at least that far from the cage.
  EXPECT_EQ(r.report.attempts.back().faces_within_clearance, 0);
  EXPECT_GE(m.report.min_distance, r.report.attempts.back().clearance);
  expect_winding_one(read_mesh(dir + "/cage.obj"), mesh);
  return r;
}

class Cage : public ::testing::Test {
 protected:
  void SetUp() override { std::srand(static_cast<unsigned>(::getpid()) * 2654435761u); }
  TempDir tmp;
};

// libcgal-demo's data.tar.gz (Debian), the source of real meshes; "" when the package is not installed.
std::string cgal_data_archive() {
  for (const char* p : {"/usr/share/doc/libcgal-dev/data.tar.gz", "/usr/share/doc/libcgal-demo/data.tar.gz"})
    if (fs::is_regular_file(p)) return p;
  return "";
}

// Extracts data/meshes/NAME from the archive into `dir`; returns its path ("" on failure).
std::string extract_cgal_mesh(const std::string& name, const std::string& dir) {
  const std::string archive = cgal_data_archive();
  if (archive.empty()) return "";
  std::string out;
  if (lidef::test::run_command("tar xzf " + quote(archive) + " -C " + quote(dir) + " data/meshes/" + name,
                               &out) != 0)
    return "";
  return dir + "/data/meshes/" + name;
}

#define LIDEF_REQUIRE_CGAL_DATA()                                                                     \
  do {                                                                                                \
    if (cgal_data_archive().empty())                                                                  \
      GTEST_SKIP()                                                                                    \
          << "libcgal-demo is not installed (apt-get install libcgal-demo; scripts/install-deps.sh)"; \
  } while (0)

// ---------------------------------------------------------------------------------------------------------
TEST_F(Cage, ReadsEveryFormatToTheSameTriangles) {
  const Poly p = torus(Vec3(0.1, -0.2, 0.3), 1.0, 0.375, 12, 8);  // values exact in float
  write_text(tmp / "t.obj", obj_text(p));
  write_text(tmp / "t.OFF", "OFF\n" + std::to_string(p.v.size()) + " " + std::to_string(p.f.size()) + " 0\n");
  {
    std::string off = read_text(tmp / "t.OFF");
    for (const Vec3& x : p.v) off += num(x.x()) + " " + num(x.y()) + " " + num(x.z()) + "\n";
    for (const auto& f : p.f)
      off += "4 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + " " +
             std::to_string(f[3]) + "\n";
    write_text(tmp / "t.OFF", off);
  }
  write_text(tmp / "t.ply", ply_ascii(p));
  write_text(tmp / "tb.ply", ply_binary(p));
  std::string crlf;  // the ASCII PLY with Windows line ends
  for (const char c : ply_ascii(p)) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  write_text(tmp / "tcrlf.ply", crlf);
  write_text(tmp / "t.stl", stl_ascii(p));
  write_text(tmp / "tb.stl", stl_binary(p));
  // Binary OFF is refused (CGAL 5.5 dropped 2 of a tetrahedron's 4 faces of a file written per the format).
  write_text(tmp / "tb.off", off_binary(p));
  EXPECT_NE(input_error_message([&] { read_any_mesh(tmp / "tb.off"); }).find("binary OFF"),
            std::string::npos);
  MeshReadInfo info;
  const TriMesh obj = read_any_mesh(tmp / "t.obj", &info);
  EXPECT_EQ(info.format, "obj");
  EXPECT_EQ(obj.V.rows(), 96);
  EXPECT_EQ(obj.F.rows(), 192);
  EXPECT_EQ(info.fan_triangles, 96);
  EXPECT_EQ(obj.F.row(0), Eigen::RowVector3i(0, 8, 9));
  EXPECT_EQ(obj.F.row(1), Eigen::RowVector3i(0, 9, 1));
  for (const char* name : {"t.OFF", "t.ply", "tb.ply", "tcrlf.ply"}) {
    const TriMesh m = read_any_mesh(tmp / name);
    EXPECT_EQ(m.F, obj.F) << name;
    EXPECT_LT((m.V - obj.V).cwiseAbs().maxCoeff(), 1e-6) << name;  // tb.ply holds floats
  }
  for (const char* name : {"t.stl", "tb.stl"}) {  // STL repeats points per triangle; CGAL merges equal ones
    const TriMesh m = read_any_mesh(tmp / name, &info);
    EXPECT_EQ(info.format, "stl");
    EXPECT_EQ(m.F.rows(), 192) << name;
    EXPECT_EQ(m.V.rows(), 96) << name;
  }
}

TEST_F(Cage, BadInputsNameTheFile) {
  struct Bad {
    std::string name, bytes, expect;
  };
  std::string garbage;
  for (int i = 0; i < 4000; ++i) garbage += static_cast<char>((i * 7919 + 13) % 256);
  const std::vector<Bad> bad = {
      {"empty.obj", "", "file is empty"},
      {"empty.stl", "", "file is empty"},
      {"garbage.ply", garbage, "not printable"},  // refused at its first header line
      {"garbage.off", garbage, "binary data"},    // lidef's own OFF parser (auto_cage.cpp)
      {"garbage.stl", garbage, "cannot read"},
      {"garbage.obj", garbage, ""},  // CGAL's OBJ reader skips unknown lines; any error naming the file
      {"nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n", ""},
      {"nan.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 nan 0\n3 0 1 2\n", ""},
      {"flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\nf 1 1 2\n", "degenerate"},
      {"points.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no faces"},
      {"mesh.vtk", "0 0 0\n", "unsupported mesh format"},
      // Point clouds are read, but not an empty one or one with a NaN.
      {"empty.ply",
       "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
       "end_header\n",
       "empty point cloud"},
      {"nan.xyz", "0 0 0\n1 nan 0\n", "NaN"},
      // CGAL's binary OFF header multiplied a negative count (UB; fuzz/regressions/cgal_off/): refused first.
      {"negative.off", std::string("OFF BINARY\n\xff\xff\xff\xfe\0\0\0\1\0\0\0\0", 23), "not supported"},
      // A NUL in a PLY header line made CGAL read a face list of ~10^9 entries (out of memory; CI's libFuzzer
      // run, fuzz/regressions/cgal_ply/oom_list_count_garbled_header.ply): the header is refused.
      {"nul.ply", std::string("ply\nformat ascii 1.0\nelement vert\0ex 3\nend_header\n", 50),
       "not printable"},
      // A list count larger than the rest of the file (CGAL resizes to it before reading).
      {"list.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_index\nend_header\n0 0 0\n1 0 0\n0 1 0\n200 0 1 2\n",
       "a list of 200 items"},
      // No end_header: CGAL read the elements from a failed stream into an uninitialized list count (out of
      // memory under CI's libFuzzer run, fuzz/regressions/cgal_ply/oom_no_end_header.ply).
      {"noend.ply", "ply\nformat ascii 1.0\nelement v 2\nproperty list uint double y\n0 1\n3 0 1 2\n",
       "no 'end_header'"},
      // A body that ends where a list count belongs (ASCII and binary): CGAL's count would be uninitialized.
      {"short.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_index\nend_header\n0 0 0\n1 0 0\n0 1 0\n",
       "the file ends inside this entry"},
      {"shortb.ply",
       std::string(
           "ply\nformat binary_little_endian 1.0\nelement face 2\nproperty list int int vertex_index\n"
           "end_header\n\1\0\0\0\0\0\0\0\0\0",
           107),
       "entry 2 of 2: the file ends inside this entry"},
      // A negative count in a signed binary count type (CGAL casts it to size_t) and a value out of its
      // type's range in ASCII (CGAL would read a different count than the file says).
      {"negb.ply",
       std::string(
           "ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list char int vertex_index\n"
           "end_header\n\xff\0\0\0\0",
           103),
       "a negative list count (-1)"},
      {"range.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_index\nend_header\n0 0 0\n1 0 0\n0 1 0\n300 0 1 2\n",
       "'300' is not an integer in the range"},
      {"token.ply",
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uchar int vertex_index\nend_header\n0 0 0\n1 0 0\n0 1.5x 0\n3 0 1 2\n",
       "'1.5x' is not a number"},
  };
  for (const Bad& b : bad) {
    write_text(tmp / b.name, b.bytes);
    const std::string msg = input_error_message([&] { read_any_mesh(tmp / b.name); });
    EXPECT_NE(msg.find(tmp / b.name), std::string::npos) << b.name << ": " << msg;
    EXPECT_NE(msg.find(b.expect), std::string::npos) << b.name << ": " << msg;
  }
  EXPECT_NE(input_error_message([&] { read_any_mesh(tmp / "missing.obj"); }).find("file not found"),
            std::string::npos);
  // A binary PLY with a NaN coordinate (text formats fail in the reader already).
  Poly p = torus(Vec3::Zero(), 1, 0.3, 6, 4);
  p.v[5].y() = std::numeric_limits<double>::quiet_NaN();
  write_text(tmp / "nan.ply", ply_binary(p));
  const std::string msg = input_error_message([&] { read_any_mesh(tmp / "nan.ply"); });
  EXPECT_NE(msg.find("vertex 6: coordinate is NaN or infinite"), std::string::npos) << msg;
}

TEST_F(Cage, QuadTorusGetsAValidCage) {
  write_text(tmp / "torus.obj", obj_text(torus(Vec3::Zero(), 1, 0.35, 32, 16)));
  const CageResult r = cage_roundtrip(tmp / "torus.obj", tmp / "model");
  EXPECT_EQ(r.report.validation.genus, 1);
  EXPECT_LE(r.cage.F.rows(), 800);
  EXPECT_GE(r.report.validation.min_distance, 0.01 * r.report.diagonal * 0.999);
}

TEST_F(Cage, SeveralComponentsAndHoles) {
  // Two tori far apart (two cage components) and one with every 5th quad missing (an open surface).
  const Poly a = torus(Vec3::Zero(), 1, 0.35, 24, 12);
  const Poly b = torus(Vec3(4, 0.5, 0), 1, 0.35, 24, 12, 5);
  write_text(tmp / "two.obj", obj_text(merged(a, b)));
  const CageResult r = cage_roundtrip(tmp / "two.obj", tmp / "two");
  EXPECT_EQ(r.report.validation.cage_components, 2);
  write_text(tmp / "holes.ply", ply_binary(torus(Vec3::Zero(), 1, 0.35, 24, 12, 3)));
  cage_roundtrip(tmp / "holes.ply", tmp / "holes");
  write_text(tmp / "holes.stl", stl_binary(torus(Vec3::Zero(), 1, 0.35, 24, 12, 4)));
  cage_roundtrip(tmp / "holes.stl", tmp / "holes_stl");
}

// A large alpha makes the wrap's faces chord in closer than the clearance: the attempt is recorded as failed
// and retried with a larger offset; the returned cage still passes every check.
TEST_F(Cage, RetriesAreRecorded) {
  write_text(tmp / "t.obj", obj_text(torus(Vec3::Zero(), 1, 0.35, 24, 12)));
  CageOptions opt;
  opt.alpha = 0.15;
  const CageResult r = cage_roundtrip(tmp / "t.obj", tmp / "model", opt);
  ASSERT_GE(r.report.attempts.size(), 2u);
  EXPECT_NE(r.report.attempts[0].failure.find("closer than the clearance"), std::string::npos)
      << r.report.attempts[0].failure;
  EXPECT_GT(r.report.attempts[1].offset, r.report.attempts[0].offset);
  EXPECT_TRUE(r.report.attempts.back().failure.empty());
  const auto j = nlohmann::json::parse(read_text(tmp / "model/model.json"));
  EXPECT_EQ(j["retries"], r.report.retries());
  EXPECT_EQ(j["attempts"].size(), r.report.attempts.size());
}

TEST_F(Cage, ExtremeScales) {
  const Poly p = torus(Vec3(0.2, 0.1, 0), 1, 0.35, 24, 12);
  write_text(tmp / "big.obj", obj_text(scaled(p, 1e8, Vec3(3e8, -1e8, 2e8))));
  write_text(tmp / "micro.obj", obj_text(scaled(p, 1e-6, Vec3(1e-6, 0, 0))));
  const CageResult big = cage_roundtrip(tmp / "big.obj", tmp / "big");
  const CageResult micro = cage_roundtrip(tmp / "micro.obj", tmp / "micro");
  EXPECT_NEAR(big.report.validation.min_distance / big.report.diagonal,
              micro.report.validation.min_distance / micro.report.diagonal, 0.005);
}

TEST_F(Cage, Deterministic) {
  write_text(tmp / "t.obj", obj_text(torus(Vec3::Zero(), 1, 0.35, 24, 12, 7)));
  std::string out;
  ASSERT_EQ(run_lidef("cage " + quote(tmp / "t.obj") + " --out " + quote(tmp / "a") + " --quiet", &out), 0)
      << out;
  ASSERT_EQ(run_lidef("cage " + quote(tmp / "t.obj") + " --out " + quote(tmp / "b") + " --quiet", &out), 0)
      << out;
  for (const char* f : {"cage.obj", "mesh.obj"}) {
    EXPECT_FALSE(read_text(tmp / (std::string("a/") + f)).empty());
    EXPECT_EQ(read_text(tmp / (std::string("a/") + f)), read_text(tmp / (std::string("b/") + f))) << f;
  }
  auto ja = nlohmann::json::parse(read_text(tmp / "a/model.json"));
  auto jb = nlohmann::json::parse(read_text(tmp / "b/model.json"));
  ja.erase("seconds");
  jb.erase("seconds");
  ja["input"].erase("file");
  jb["input"].erase("file");
  EXPECT_EQ(ja, jb);
}

TEST_F(Cage, CommandWritesAModelFolderOrNothing) {
  write_text(tmp / "t.ply", ply_ascii(torus(Vec3::Zero(), 1, 0.35, 24, 12)));
  std::string out;
  const std::string model = tmp / "model";
  ASSERT_EQ(run_lidef("cage " + quote(tmp / "t.ply") + " --out " + quote(model) + " --faces 300", &out), 0)
      << out;
  EXPECT_NE(out.find("alpha wrap"), std::string::npos) << out;  // progress on stderr
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(model)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"cage.obj", "mesh.obj", "model.json"}));
  const auto j = nlohmann::json::parse(read_text(model + "/model.json"));
  EXPECT_EQ(j["input"]["format"], "ply");
  EXPECT_EQ(j["input"]["fnv1a64"].get<std::string>().size(), 16u);
  EXPECT_EQ(j["options"]["faces"], 300);
  for (const char* key : {"alpha", "offset", "clearance", "retries", "seconds", "attempts"})
    EXPECT_TRUE(j.contains(key)) << key;
  std::string check;
  EXPECT_EQ(run_lidef("check " + quote(model), &check), 0) << check;

  // An existing non-empty folder is refused without --force.
  const std::string before = read_text(model + "/cage.obj");
  EXPECT_EQ(run_lidef("cage " + quote(tmp / "t.ply") + " --out " + quote(model), &out), 2) << out;
  EXPECT_NE(out.find("--force"), std::string::npos) << out;
  EXPECT_EQ(
      run_lidef("cage " + quote(tmp / "t.ply") + " --out " + quote(model) + " --faces 200 --force --quiet",
                &out),
      0)
      << out;
  EXPECT_NE(read_text(model + "/cage.obj"), before);

  // Bad input, bad option: exit 2, nothing written.
  write_text(tmp / "bad.stl", "");
  EXPECT_EQ(run_lidef("cage " + quote(tmp / "bad.stl") + " --out " + quote(tmp / "nothing"), &out), 2) << out;
  EXPECT_NE(out.find("bad.stl: file is empty"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(tmp / "nothing"));
  write_text(tmp / "nan.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 nan 0\n3 0 1 2\n");
  write_text(tmp / "flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
  write_text(tmp / "garbage.ply", std::string("ply\n\x01\x02\xff garbage", 16));
  for (const char* bad : {"nan.off", "flat.obj", "garbage.ply"}) {
    EXPECT_EQ(run_lidef("cage " + quote(tmp / bad) + " --out " + quote(tmp / "nothing"), &out), 2)
        << bad << out;
    EXPECT_NE(out.find(tmp / bad), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(tmp / "nothing")) << bad;
  }
  EXPECT_EQ(
      run_lidef("cage " + quote(tmp / "t.ply") + " --out " + quote(tmp / "nothing") + " --faces 3", &out), 2);
  EXPECT_NE(out.find("--faces"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(tmp / "nothing"));
  EXPECT_EQ(run_lidef("cage --help", &out), 0);
  EXPECT_NE(out.find("--clearance"), std::string::npos) << out;
}

// Ctrl-C while the cage is being made leaves nothing (the folder is only created when the cage is done, and
// the writing itself runs with SIGINT blocked).
TEST_F(Cage, InterruptLeavesNothing) {
  write_text(tmp / "t.obj", obj_text(torus(Vec3::Zero(), 1, 0.35, 128, 64)));
  std::string out;
  const int rc = lidef::test::run_command("timeout -s INT 0.3 " + quote(lidef::test::cli()) + " cage " +
                                              quote(tmp / "t.obj") + " --out " + quote(tmp / "model"),
                                          &out);
  if (rc == 0) GTEST_SKIP() << "lidef cage finished before the signal; nothing to test";
  EXPECT_EQ(rc, 124) << out;  // timeout's code: the command was interrupted
  EXPECT_FALSE(fs::exists(tmp / "model")) << out;
}

TEST_F(Cage, MeshFileResolvesToACachedModel) {
  write_text(tmp / "t.obj", obj_text(torus(Vec3::Zero(), 1, 0.35, 24, 12)));
  std::vector<std::string> lines;
  auto log = [&](const std::string& s) { lines.push_back(s); };
  const std::string dir = resolve_model_path(tmp / "t.obj", log, tmp / "cache");
  EXPECT_EQ(fs::path(dir).parent_path(), fs::path(tmp / "cache") / "cages");
  load_model(dir);
  lines.clear();
  EXPECT_EQ(resolve_model_path(tmp / "t.obj", log, tmp / "cache"), dir);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_NE(lines[0].find("reused cached cage"), std::string::npos) << lines[0];
  // A folder is returned unchanged; a changed file gets a new entry.
  EXPECT_EQ(resolve_model_path(dir, log, tmp / "cache"), dir);
  write_text(tmp / "t.obj", obj_text(torus(Vec3::Zero(), 1, 0.3, 24, 12)));
  EXPECT_NE(resolve_model_path(tmp / "t.obj", log, tmp / "cache"), dir);
}

// A made model deforms certified: a pull on the torus (a handle on the outer equator moves outwards by 20 %
// of the major radius; the opposite side is fixed), through `lidef deform` with the mesh file as the model.
TEST_F(Cage, PullScenarioOnAMeshFileDeformsCertified) {
  write_text(tmp / "torus.ply", ply_ascii(torus(Vec3::Zero(), 1, 0.35, 32, 16)));
  nlohmann::ordered_json s;
  s["name"] = "torus_pull";
  s["model"] = "torus.ply";
  s["handles"] = {{{"source", {1.35, 0, 0}}, {"target", {1.55, 0, 0}}},
                  {{"source", {-1.35, 0, 0}}, {"target", {-1.35, 0, 0}}}};
  write_text(tmp / "pull.json", s.dump(2));
  std::string out;
  const std::string args = "deform " + quote(tmp / "pull.json") + " --out " + quote(tmp / "out") +
                           " --quiet --cache-dir " + quote(tmp / "cache") +
                           " --samples 4000 --reduced-dof 60";
  ASSERT_EQ(run_lidef(args, &out), 0) << out;
  EXPECT_NE(out.find("making a cage"), std::string::npos) << out;
  const auto summary = nlohmann::json::parse(read_text(tmp / "out/summary.json"));
  EXPECT_EQ(summary["certified"], true) << summary.dump(2);
  EXPECT_EQ(summary["handles_reached"], true) << summary.dump(2);
  EXPECT_GT(summary["min_sigma3_lower_bound"].get<double>(), 0);
  std::cerr << "torus pull: " << summary.dump() << "\n";
  ASSERT_EQ(run_lidef(args + " --max-iterations 1", &out), 1) << out;  // 1: stopped at the iteration limit
  EXPECT_NE(out.find("reused cached cage"), std::string::npos) << out;
}

// `lidef certify MESH`: the mesh file's cached cage (LIDEF_CACHE_DIR) with the identity map is certified.
TEST_F(Cage, CertifyAcceptsAMeshFile) {
  write_text(tmp / "t.stl", stl_ascii(torus(Vec3::Zero(), 1, 0.35, 24, 12)));
  std::string out;
  const std::string cmd = "LIDEF_CACHE_DIR=" + quote(tmp / "cache") + " " + quote(lidef::test::cli()) +
                          " certify " + quote(tmp / "t.stl") +
                          " --coeffs identity --samples 2000 --grid 0 --out " + quote(tmp / "cert");
  ASSERT_EQ(lidef::test::run_command(cmd, &out), 0) << out;
  EXPECT_NE(out.find("making a cage"), std::string::npos) << out;
  EXPECT_NE(out.find("CERTIFIED"), std::string::npos) << out;
  ASSERT_EQ(lidef::test::run_command(cmd, &out), 0) << out;
  EXPECT_NE(out.find("reused cached cage"), std::string::npos) << out;
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp / "cache/cages"), fs::directory_iterator()), 1);
}

// Real meshes from Debian's libcgal-demo.
TEST_F(Cage, ElephantFromCgalData) {
  LIDEF_REQUIRE_CGAL_DATA();
  const std::string path = extract_cgal_mesh("elephant.off", tmp.str());
  ASSERT_FALSE(path.empty());
  const CageResult r = cage_roundtrip(path, tmp / "elephant");
  EXPECT_LE(r.cage.F.rows(), 1000);
}

// The largest meshes of docs/cages.md (26,002 and 44,460 vertices): the target is <= 30 s for 50k
// vertices on 2 threads.
TEST(CageSlow, LargeMeshesFromCgalData) {
  LIDEF_REQUIRE_CGAL_DATA();
  TempDir tmp;
  for (const char* name : {"armadillo.off", "refined_elephant.off"}) {
    const std::string path = extract_cgal_mesh(name, tmp.str());
    ASSERT_FALSE(path.empty()) << name;
    const CageResult r = cage_roundtrip(path, tmp / (std::string(name) + ".model"));
    std::cerr << name << ": " << r.mesh.V.rows() << " vertices, " << r.cage.F.rows()
              << " cage faces, min distance / diagonal "
              << r.report.validation.min_distance / r.report.diagonal << ", " << r.report.seconds << " s\n";
    EXPECT_LT(r.report.seconds, 30) << name;
  }
}

// README's and docs/cages.md's "the elephant in two commands": the project's scenario on the extracted demo
// mesh deforms certified to its handles (its cage made on first use, in a private cache).
TEST(CageSlow, ElephantPullScenarioFromTheReadme) {
  LIDEF_REQUIRE_CGAL_DATA();
  TempDir tmp;
  ASSERT_FALSE(extract_cgal_mesh("elephant.off", tmp.str()).empty());
  const std::string cmd = "LIDEF_CACHE_DIR=" + quote(tmp / "cache") + " " + lidef::test::cli() + " deform " +
                          quote(lidef::test::project_data() + "/scenarios/elephant_pull.json") +
                          " --models " + quote(tmp / "data/meshes") + " --quiet --out " + quote(tmp / "out");
  std::string out;
  ASSERT_EQ(lidef::test::run_command(cmd, &out), 0) << out;
  const auto s = nlohmann::json::parse(lidef::test::read_text(tmp / "out/summary.json"));
  EXPECT_TRUE(s.at("certified").get<bool>()) << out;
  EXPECT_LT(s.at("max_handle_error").get<double>(), 1e-3) << out;
}

}  // namespace
