// Mesh reading/writing, model validation, self-intersections, procedural models and `lidef check`.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/procedural_models.h"
#include "lidef/self_intersections.h"
#include "test_support.h"

namespace {

using namespace lidef;
using lidef::test::TempDir;

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The cube [-1,1]^3 as a cage: 8 vertices, 12 outward (counter-clockwise) triangles, 1-based.
const char* kCubeVertices =
    "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n";
const std::vector<std::array<int, 3>> kCubeFaces = {{1, 3, 2}, {1, 4, 3}, {5, 6, 7}, {5, 7, 8},
                                                    {1, 2, 6}, {1, 6, 5}, {4, 8, 7}, {4, 7, 3},
                                                    {1, 5, 8}, {1, 8, 4}, {2, 3, 7}, {2, 7, 6}};

std::string faces_text(const std::vector<std::array<int, 3>>& faces) {
  std::string s;
  for (const auto& f : faces)
    s += "f " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + "\n";
  return s;
}
std::string cube_cage(std::vector<std::array<int, 3>> faces = kCubeFaces,
                      const std::string& extra_vertices = "") {
  return std::string("# cube cage\n") + kCubeVertices + extra_vertices + faces_text(faces);
}
std::vector<std::array<int, 3>> reversed(std::vector<std::array<int, 3>> faces, int only = -1) {
  for (int i = 0; i < static_cast<int>(faces.size()); ++i)
    if (only < 0 || i == only) std::swap(faces[i][1], faces[i][2]);
  return faces;
}
// A small tetrahedron well inside the cube; `first` replaces its first vertex line.
std::string tet_mesh(const std::string& first = "v 0 0 0") {
  return first + "\nv 0.5 0 0\nv 0 0.5 0\nv 0 0 0.5\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
}

// The cube with a T-junction on edge 1-2 sealed by a zero-area sliver: closed, consistently oriented,
// but face 13 = (1, 2, 9) has collinear corners.
std::string sliver_cage() {
  auto f = kCubeFaces;
  f[4] = {1, 9, 6};
  f.push_back({9, 2, 6});
  f.push_back({1, 2, 9});
  return cube_cage(f, "v 0 -1 -1\n");
}

// ---------------------------------------------------------------------------------------------------------
// Malformed models: each must be rejected with an error naming the file and containing the given text.
struct BadModel {
  std::string name;
  const char* cage;  // nullptr: no cage file
  const char* mesh;  // nullptr: no mesh file
  std::string expect;
  std::string file;  // file name the error must mention
  std::string cage_name = "cage.obj";
};

std::vector<BadModel> bad_models() {
  static const std::string cube = cube_cage(), tet = tet_mesh();
  static const std::string open = cube_cage({kCubeFaces.begin(), kCubeFaces.end() - 1});
  static const std::string flipped = cube_cage(reversed(kCubeFaces, 4));
  static const std::string inverted = cube_cage(reversed(kCubeFaces));
  static const std::string fin = [] {
    auto f = kCubeFaces;
    f.push_back({1, 2, 9});
    return cube_cage(f, "v 0 -3 -3\n");
  }();
  static const std::string duplicate = [] {
    auto f = kCubeFaces;
    f.push_back(f[0]);
    return cube_cage(f);
  }();
  static const std::string sliver = sliver_cage();
  static const std::string nan_cage =
      std::string(kCubeVertices).replace(0, 10, "v nan -1 -1") + faces_text(kCubeFaces);
  static const std::string inf_cage =
      std::string(kCubeVertices).replace(0, 10, "v -1 -inf -1") + faces_text(kCubeFaces);
  static const std::string range = cube_cage() + "f 1 2 9\n";
  static const std::string zero = cube_cage() + "f 0 1 2\n";
  static const std::string bad_number = std::string("v 0 1.2.3 0\n") + kCubeVertices + faces_text(kCubeFaces);
  static const std::string two = cube_cage() + "f 1 2\n";
  static const std::string quad = cube_cage() + "f 1 2 3 4\n";
  static const std::string unknown = cube_cage() + "hello world\n";
  static const std::string no_faces = kCubeVertices;
  static const std::string before_first = "v 0 0 0\nf -1 -2 -3\n";
  static const std::string binary = std::string(
                                        "\x7f"
                                        "ELF\x02\x01\x01\0\0\0\0\0",
                                        12) +
                                    "garbage";
  static const std::string outside = tet_mesh("v 2 0 0");
  static const std::string on_cage = tet_mesh("v 1 0.2 0.3");
  static const std::string mesh_nan = tet_mesh("v 0 NaN 0");
  static const std::string off_short = "OFF\n8 12 0\n-1 -1 -1\n1 -1 -1\n";
  static const std::string off_header = "PLY\n8 12 0\n";
  // Found by fuzzing (fuzz/regressions/mesh_off/): the reader reserved the header's counts, so this 27-byte
  // file asked for ~100 GB and failed with std::bad_alloc instead of an InputError.
  static const std::string off_huge = "OFF\n2000000000 2000000000\n";
  return {
      {"empty_cage", "", tet.c_str(), "file is empty", "cage.obj"},
      {"missing_cage", nullptr, tet.c_str(), "no cage.obj or cage.off", ""},
      {"binary_garbage", binary.c_str(), tet.c_str(), "binary data", "cage.obj"},
      {"open_cage", open.c_str(), tet.c_str(), "the cage is not closed", "cage.obj"},
      {"flipped_face", flipped.c_str(), tet.c_str(), "face 5: flipped", "cage.obj"},
      {"inverted_cage", inverted.c_str(), tet.c_str(), "the cage is inverted", "cage.obj"},
      {"nonmanifold_edge", fin.c_str(), tet.c_str(), "edge 1-2: is shared by 3 faces", "cage.obj"},
      {"nan_coordinate", nan_cage.c_str(), tet.c_str(), "vertex 1: x coordinate is NaN", "cage.obj"},
      {"inf_coordinate", inf_cage.c_str(), tet.c_str(), "vertex 1: y coordinate is infinite", "cage.obj"},
      {"index_out_of_range", range.c_str(), tet.c_str(), "face 13: vertex index 9 is out of range",
       "cage.obj:22"},
      {"zero_index", zero.c_str(), tet.c_str(), "face 13: vertex index 0 is invalid", "cage.obj:22"},
      {"degenerate_face", sliver.c_str(), tet.c_str(), "face 14: degenerate face", "cage.obj"},
      {"duplicate_face", duplicate.c_str(), tet.c_str(), "face 13: duplicate of face 1", "cage.obj"},
      {"mesh_vertex_outside", cube.c_str(), outside.c_str(), "vertex 1: is outside the cage", "mesh.obj:1"},
      {"mesh_vertex_on_cage", cube.c_str(), on_cage.c_str(), "vertex 1: lies on the cage", "mesh.obj:1"},
      {"mesh_nan", cube.c_str(), mesh_nan.c_str(), "y coordinate is NaN", "mesh.obj:1"},
      {"malformed_number", bad_number.c_str(), tet.c_str(), "'1.2.3' is not a number", "cage.obj:1"},
      {"face_with_2_indices", two.c_str(), tet.c_str(), "face 13 has 2 vertices", "cage.obj"},
      {"quad_face", quad.c_str(), tet.c_str(), "only triangles are supported", "cage.obj"},
      {"unknown_statement", unknown.c_str(), tet.c_str(), "unknown OBJ statement 'hello'", "cage.obj"},
      {"no_faces", no_faces.c_str(), tet.c_str(), "no faces", "cage.obj"},
      {"relative_index_before_first", before_first.c_str(), tet.c_str(), "points before the first vertex",
       "cage.obj"},
      {"missing_mesh", cube.c_str(), nullptr, "no mesh.obj or mesh.off", ""},
      {"off_truncated", off_short.c_str(), tet.c_str(), "file ends after 2 of 8 vertices", "cage.off",
       "cage.off"},
      {"off_bad_header", off_header.c_str(), tet.c_str(), "missing OFF header", "cage.off", "cage.off"},
      {"off_huge_counts", off_huge.c_str(), tet.c_str(), "file ends after 0 of 2000000000 vertices",
       "cage.off", "cage.off"},
  };
}

void PrintTo(const BadModel& b, std::ostream* os) {
  *os << b.name;
}

class ModelCheckMalformed : public ::testing::TestWithParam<BadModel> {};

TEST_P(ModelCheckMalformed, IsRejectedWithAMessageNamingFileAndElement) {
  const BadModel& c = GetParam();
  TempDir dir;
  if (c.cage) write_text(dir / c.cage_name, c.cage);
  if (c.mesh) write_text(dir / "mesh.obj", c.mesh);
  const ValidationReport r = check_model_dir(dir.str());
  ASSERT_FALSE(r.usable()) << c.name;
  bool found = false;
  std::string all;
  for (const Issue& e : r.errors) {
    all += e.str() + "\n";
    if (e.str().find(c.expect) != std::string::npos && e.str().find(c.file) != std::string::npos)
      found = true;
  }
  EXPECT_TRUE(found) << "expected an error containing '" << c.expect << "' naming '" << c.file << "', got:\n"
                     << all;
  try {
    load_model(dir.str());
    ADD_FAILURE() << "load_model accepted " << c.name;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(c.expect), std::string::npos) << e.what();
    EXPECT_EQ(e.file(), dir.str());
  }
}

INSTANTIATE_TEST_SUITE_P(ModelCheck, ModelCheckMalformed, ::testing::ValuesIn(bad_models()),
                         [](const ::testing::TestParamInfo<BadModel>& info) { return info.param.name; });

// ---------------------------------------------------------------------------------------------------------
TEST(ModelCheck, CubeCageIsValidWithExactSummary) {
  TempDir dir;
  write_text(dir / "cage.obj", cube_cage());
  write_text(dir / "mesh.obj", tet_mesh());
  const ValidationReport r = check_model_dir(dir.str());
  EXPECT_TRUE(r.usable());
  EXPECT_TRUE(r.warnings.empty());
  EXPECT_EQ(r.cage_vertices, 8);
  EXPECT_EQ(r.cage_faces, 12);
  EXPECT_EQ(r.cage_edges, 18);
  EXPECT_EQ(r.cage_components, 1);
  EXPECT_EQ(r.euler_characteristic, 2);
  EXPECT_EQ(r.genus, 0);
  EXPECT_DOUBLE_EQ(r.cage_volume, 8.0);
  EXPECT_EQ(r.mesh_vertices, 4);
  EXPECT_TRUE(r.inside_checked);
  EXPECT_DOUBLE_EQ(r.min_distance, 0.5);  // (0.5,0,0) is 0.5 from the face x = 1
  EXPECT_EQ(r.min_distance_vertex, 1);
  EXPECT_EQ(r.cage_bbox_min, Vec3(-1, -1, -1));
  EXPECT_EQ(r.mesh_bbox_max, Vec3(0.5, 0.5, 0.5));
  const Model m = load_model(dir.str());
  EXPECT_EQ(m.cage.num_faces(), 12);
  EXPECT_EQ(m.mesh.V.rows(), 4);
}

TEST(ModelCheck, OffCageIsAccepted) {
  TempDir dir;
  std::string off = "OFF 8 12 0\n# corners\n";
  std::istringstream vs(kCubeVertices);
  for (std::string line; std::getline(vs, line);) off += line.substr(2) + "\n";
  for (const auto& f : kCubeFaces)
    off += "3 " + std::to_string(f[0] - 1) + " " + std::to_string(f[1] - 1) + " " + std::to_string(f[2] - 1) +
           " 255 0 0\n";
  write_text(dir / "cage.off", off);
  write_text(dir / "mesh.obj", tet_mesh());
  const ValidationReport r = check_model_dir(dir.str());
  EXPECT_TRUE(r.usable());
  EXPECT_EQ(r.cage_faces, 12);
  EXPECT_DOUBLE_EQ(r.cage_volume, 8.0);
}

TEST(ModelCheck, WarningsKeepTheModelUsable) {
  // Two disjoint cubes (2 components) and an unused vertex; the mesh is inside the first cube.
  std::string cage = std::string(kCubeVertices);
  std::istringstream vs(kCubeVertices);
  for (std::string line; std::getline(vs, line);) {
    std::istringstream ls(line.substr(2));
    double x, y, z;
    ls >> x >> y >> z;
    cage += "v " + std::to_string(x + 5) + " " + std::to_string(y) + " " + std::to_string(z) + "\n";
  }
  cage += "v 9 9 9\n";
  auto faces = kCubeFaces;
  for (const auto& f : kCubeFaces) faces.push_back({f[0] + 8, f[1] + 8, f[2] + 8});
  cage += faces_text(faces);
  TempDir dir;
  write_text(dir / "cage.obj", cage);
  write_text(dir / "mesh.obj", tet_mesh() + "v 0 0 0\nf 1 2 5\n");  // a degenerate mesh face
  const ValidationReport r = check_model_dir(dir.str());
  EXPECT_TRUE(r.usable());
  EXPECT_EQ(r.cage_components, 2);
  EXPECT_EQ(r.genus, 0);
  std::string all;
  for (const Issue& w : r.warnings) all += w.str() + "\n";
  EXPECT_NE(all.find("2 connected components"), std::string::npos) << all;
  EXPECT_NE(all.find("vertex 17: not used by any face"), std::string::npos) << all;
  EXPECT_NE(all.find("mesh.obj:10: face 5: degenerate face"), std::string::npos) << all;
  EXPECT_NO_THROW(load_model(dir.str()));
}

TEST(ModelCheck, MissingOrNonDirectoryFolderIsAnError) {
  TempDir dir;
  ValidationReport r = check_model_dir(dir / "nope");
  ASSERT_EQ(r.errors.size(), 1u);
  EXPECT_NE(r.errors[0].str().find("model folder not found"), std::string::npos);
  write_text(dir / "file", "x");
  r = check_model_dir(dir / "file");
  ASSERT_EQ(r.errors.size(), 1u);
  EXPECT_NE(r.errors[0].str().find("is not a folder"), std::string::npos);
}

TEST(ModelCheck, ManyBadElementsAreListedThenCounted) {
  // 20 mesh vertices outside: one error with the count and the first few 1-based indices.
  std::string mesh;
  for (int i = 0; i < 20; ++i) mesh += "v " + std::to_string(3 + i) + " 0 0\n";
  mesh += "f 1 2 3\n";
  TempDir dir;
  write_text(dir / "cage.obj", cube_cage());
  write_text(dir / "mesh.obj", mesh);
  const ValidationReport r = check_model_dir(dir.str());
  ASSERT_EQ(r.errors.size(), 1u);
  EXPECT_EQ(r.mesh_vertices_outside, 20);
  EXPECT_NE(r.errors[0].str().find("20 of 20 mesh vertices are outside (first: 1, 2, 3, 4, 5, ...)"),
            std::string::npos)
      << r.errors[0].str();
}

// The winding number is propagated along mesh edges instead of being summed at every vertex; it must agree
// with the brute-force sum on a mesh that crosses the cage many times.
TEST(ModelCheck, InsideTestAgreesWithBruteForceWindingNumber) {
  TriMesh cage = icosphere(1.0, 1);
  TriMesh mesh = box_surface(Vec3(-1.2, -0.3, -0.3), Vec3(1.2, 0.3, 0.3), {30, 7, 7});
  const ValidationReport r = validate_model(cage, mesh);
  const Cage c(cage);
  int outside = 0;
  for (int v = 0; v < mesh.V.rows(); ++v) outside += c.winding_number(mesh.V.row(v).transpose()) < 0.5;
  ASSERT_GT(outside, 0);
  ASSERT_LT(outside, mesh.V.rows());
  EXPECT_EQ(r.mesh_vertices_outside + r.mesh_vertices_on_cage, outside);
  EXPECT_FALSE(r.usable());
}

TEST(ModelCheck, ReportJsonIsComplete) {
  TempDir dir;
  write_text(dir / "cage.obj", cube_cage());
  write_text(dir / "mesh.obj", tet_mesh("v 2 0 0"));
  const auto j = nlohmann::json::parse(report_to_json(check_model_dir(dir.str())));
  EXPECT_FALSE(j["usable"].get<bool>());
  ASSERT_EQ(j["errors"].size(), 1u);
  EXPECT_EQ(j["errors"][0]["element"], "vertex 1");
  EXPECT_EQ(j["errors"][0]["line"], 1);
  EXPECT_EQ(j["cage"]["faces"], 12);
  EXPECT_EQ(j["mesh"]["vertices_outside"], 1);
}

// ---------------------------------------------------------------------------------------------------------
// Published models (../shared/data).
TEST(ModelCheck, SharedModelsWithoutWarnings) {
  LIDEF_REQUIRE_SHARED();
  for (const std::string name : {"bar", "horse", "spot"}) {
    const ValidationReport r = check_model_dir(test::shared_model(name));
    EXPECT_TRUE(r.usable()) << name;
    EXPECT_TRUE(r.warnings.empty()) << name << ": " << (r.warnings.empty() ? "" : r.warnings[0].str());
    EXPECT_TRUE(r.self_intersections.empty()) << name;
    EXPECT_EQ(r.genus, 0) << name;
    EXPECT_GT(r.min_distance, 0.02) << name;
  }
}

TEST(ModelCheck, SharedAnimalLoadsWithSelfIntersectionWarning) {
  LIDEF_REQUIRE_SHARED();
  const Model m = load_model(test::shared_model("animal"));
  const ValidationReport& r = m.report;
  EXPECT_EQ(r.cage_faces, 1526);
  EXPECT_EQ(r.mesh_vertices, 19522);
  ASSERT_EQ(r.warnings.size(), 1u);
  const std::string w = r.warnings[0].str();
  EXPECT_NE(w.find("cage.obj"), std::string::npos) << w;
  EXPECT_NE(w.find("intersects itself"), std::string::npos) << w;
  EXPECT_TRUE(w.find("128 & 914") != std::string::npos || w.find("128 & 915") != std::string::npos) << w;
  const auto& si = r.self_intersections;
  EXPECT_TRUE(std::count(si.begin(), si.end(), std::make_pair(127, 913)) +
                  std::count(si.begin(), si.end(), std::make_pair(127, 914)) >=
              1);
  // The crossing is local: every reported pair involves faces 128, 914, 915 or 917 (917 shares the edge of
  // 128 that pierces 914/915).
  for (const auto& [a, b] : si)
    for (int f : {a + 1, b + 1}) EXPECT_TRUE(f == 128 || f == 914 || f == 915 || f == 917) << f;
  EXPECT_EQ(r.mesh_vertices_outside, 0);
  EXPECT_LT(r.seconds, 5.0);
}

// ---------------------------------------------------------------------------------------------------------
// Self-intersections on hand-made configurations (0-based faces).
MatX3d points(std::initializer_list<Vec3> pts) {
  MatX3d V(static_cast<Eigen::Index>(pts.size()), 3);
  int i = 0;
  for (const Vec3& p : pts) V.row(i++) = p.transpose();
  return V;
}
MatX3i tris(std::initializer_list<Eigen::Vector3i> f) {
  MatX3i F(static_cast<Eigen::Index>(f.size()), 3);
  int i = 0;
  for (const auto& t : f) F.row(i++) = t.transpose();
  return F;
}
using Pairs = std::vector<std::pair<int, int>>;

TEST(ModelSelfIntersections, CrossingTrianglesAreFound) {
  const MatX3d V = points({{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0.5, 0.5, -1}, {0.5, 0.5, 1}, {3, 3, 0}});
  EXPECT_EQ(find_self_intersections(V, tris({{0, 1, 2}, {3, 4, 5}})), Pairs({{0, 1}}));
  const MatX3d far = points({{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {5.5, 0.5, -1}, {5.5, 0.5, 1}, {8, 3, 0}});
  EXPECT_TRUE(find_self_intersections(far, tris({{0, 1, 2}, {3, 4, 5}})).empty());
}

TEST(ModelSelfIntersections, TouchingWithoutSharedIndexCounts) {
  // The apex of the second triangle lies inside the first; no vertex index is shared.
  const MatX3d V = points({{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0.5, 0.5, 0}, {0.5, 0.5, 1}, {1, 0.5, 1}});
  EXPECT_EQ(find_self_intersections(V, tris({{0, 1, 2}, {3, 4, 5}})), Pairs({{0, 1}}));
}

TEST(ModelSelfIntersections, EdgeNeighboursAreNotReported) {
  // A bent pair (dihedral angle) and a flat pair sharing edge 0-1.
  const MatX3d V = points({{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -1, 0.3}, {0.5, -1, 0}});
  EXPECT_TRUE(find_self_intersections(V, tris({{0, 1, 2}, {1, 0, 3}})).empty());
  EXPECT_TRUE(find_self_intersections(V, tris({{0, 1, 2}, {1, 0, 4}})).empty());
}

TEST(ModelSelfIntersections, FoldedEdgeNeighboursOverlapCoplanarly) {
  // Both apexes on the same side of the shared edge, in the same plane: the triangles overlap.
  const MatX3d V = points({{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.3, 0.5, 0}});
  EXPECT_EQ(find_self_intersections(V, tris({{0, 1, 2}, {1, 0, 3}})), Pairs({{0, 1}}));
  // Same side but out of plane: they only share the edge.
  const MatX3d W = points({{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.3, 0.5, 0.01}});
  EXPECT_TRUE(find_self_intersections(W, tris({{0, 1, 2}, {1, 0, 3}})).empty());
}

TEST(ModelSelfIntersections, VertexNeighbours) {
  // Sharing vertex 0 only: a fan around it is fine.
  const MatX3d V = points({{0, 0, 0},
                           {1, 0, 0},
                           {0, 1, 0},
                           {-1, 0, 0.2},
                           {0, -1, 0.2},
                           {0.5, 0.2, -1},
                           {0.2, 0.5, 1},
                           {0.3, 0.3, 0},
                           {0.6, 0.1, 0},
                           {-1, 0, 0},
                           {0, -1, 0}});
  EXPECT_TRUE(find_self_intersections(V, tris({{0, 1, 2}, {0, 3, 4}})).empty());
  // Coplanar, corners at vertex 0 only touching: fine.
  EXPECT_TRUE(find_self_intersections(V, tris({{0, 1, 2}, {0, 9, 10}})).empty());
  // Sharing vertex 0, the second triangle's opposite edge 5-6 pierces the first: reported.
  EXPECT_EQ(find_self_intersections(V, tris({{0, 1, 2}, {0, 5, 6}})), Pairs({{0, 1}}));
  // Sharing vertex 0, coplanar, the second inside the first: reported.
  EXPECT_EQ(find_self_intersections(V, tris({{0, 1, 2}, {0, 8, 7}})), Pairs({{0, 1}}));
}

TEST(ModelSelfIntersections, DuplicatesAndDegenerateFaces) {
  const MatX3d V = points({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {2, 0, 0}});
  EXPECT_EQ(find_self_intersections(V, tris({{0, 1, 2}, {2, 1, 0}})), Pairs({{0, 1}}));
  // A collinear face (0,1,3) is skipped, not passed to the predicates.
  EXPECT_TRUE(find_self_intersections(V, tris({{0, 1, 2}, {0, 1, 3}, {0, 0, 2}})).empty());
}

TEST(ModelSelfIntersections, ClosedSurfacesHaveNone) {
  const TriMesh s = icosphere(1.0, 3);
  EXPECT_TRUE(find_self_intersections(s.V, s.F).empty());
  const TriMesh b = box_surface(Vec3(-1, -2, -3), Vec3(1, 2, 3), {5, 6, 7});
  EXPECT_TRUE(find_self_intersections(b.V, b.F).empty());
  // Pushing one box vertex through the opposite side makes the surface cross itself.
  TriMesh bad = box_surface(Vec3(-1, -1, -1), Vec3(1, 1, 1), {2, 2, 2});
  int v = 0;
  for (int i = 0; i < bad.V.rows(); ++i)
    if (bad.V.row(i) == Eigen::RowVector3d(1, 0, 0)) v = i;
  bad.V(v, 0) = -1.5;
  EXPECT_FALSE(find_self_intersections(bad.V, bad.F).empty());
}

// ---------------------------------------------------------------------------------------------------------
// Mesh I/O.
TEST(MeshIo, ObjRoundTripIsExact) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  MatX3d V(50, 3);
  for (int i = 0; i < V.rows(); ++i)
    for (int k = 0; k < 3; ++k) V(i, k) = u(rng) * std::pow(10.0, static_cast<int>(u(rng) * 30));
  V(0, 0) = 0.1;
  V(0, 1) = -0.0;
  V(0, 2) = std::numeric_limits<double>::denorm_min();
  MatX3i F(2, 3);
  F << 0, 1, 2, 49, 3, 0;
  TempDir dir;
  std::ostringstream ss;
  write_obj(ss, V, F, "round trip\nsecond line");
  write_text(dir / "m.obj", ss.str());
  const TriMesh m = read_mesh(dir / "m.obj");
  EXPECT_TRUE((m.V.array() == V.array()).all());
  EXPECT_EQ(m.F, F);
  EXPECT_EQ(m.source, dir / "m.obj");
  EXPECT_EQ(ss.str().rfind("# round trip\n# second line\nv 0.1 -0 ", 0), 0u) << ss.str().substr(0, 60);
  EXPECT_NE(ss.str().find("\nf 50 4 1\n"), std::string::npos);
}

TEST(MeshIo, ObjFaceCornerFormsAndNegativeIndices) {
  TempDir dir;
  write_text(
      dir / "a.obj",
      "# header\r\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0 1\nvt 0 0\nvn 0 0 1\nv 0 1 0 0.5 0.5 0.5\n"
      "s off\nusemtl red\nf 1/1/1 2//1 3/1\nf -3 -2/1 -1//1\nv +1e0 1 .5\nf 4 2 3\nf 2 3 5\nv 2 2 2\n");
  MeshLines lines;
  const TriMesh m = read_mesh(dir / "a.obj", &lines);
  ASSERT_EQ(m.V.rows(), 5);
  ASSERT_EQ(m.F.rows(), 4);
  EXPECT_EQ(m.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(m.F.row(2), Eigen::RowVector3i(3, 1, 2));
  EXPECT_EQ(m.F.row(3), Eigen::RowVector3i(1, 2, 4));  // a positive index may refer to a later vertex
  EXPECT_EQ(m.V.row(3), Eigen::RowVector3d(1, 1, 0.5));
  EXPECT_EQ(lines.vertex, (std::vector<long>{4, 5, 8, 13, 16}));
  EXPECT_EQ(lines.face, (std::vector<long>{11, 12, 14, 15}));
}

TEST(MeshIo, OffVariants) {
  TempDir dir;
  write_text(dir / "a.off",
             "COFF\n# comment\n4 2 0\n0 0 0 1 0 0 1\n1 0 0 1 0 0 1\n0 1 0 1 0 0 1\n0 0 1 1 0 0 1\n"
             "3 0 1 2\n3 0 2 3 0.5 0.5 0.5\n");
  const TriMesh m = read_mesh(dir / "a.off");
  EXPECT_EQ(m.V.rows(), 4);
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 2, 3));
  write_text(dir / "b.OFF", "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  try {
    read_mesh(dir / "b.OFF");
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 5);
    EXPECT_NE(e.message().find("face 1: vertex index 3 is out of range (OFF indices are 0-based"),
              std::string::npos)
        << e.what();
  }
  write_text(dir / "c.off", "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 0\n");
  EXPECT_THROW(read_mesh(dir / "c.off"), InputError);
  write_text(dir / "d.off", "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n");
  EXPECT_THROW(read_mesh(dir / "d.off"), InputError);  // data after the last face
}

TEST(MeshIo, ErrorsNameFileAndLine) {
  TempDir dir;
  auto message = [&](const std::string& name, const std::string& text) {
    write_text(dir / name, text);
    try {
      read_mesh(dir / name);
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), dir / name);
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("a.obj", "v 0 0 0\nv 1 0\n").find("a.obj:2: vertex 2 needs 3 coordinates, found 2"),
            std::string::npos);
  EXPECT_NE(message("b.obj", "v 0 0 1e999\n").find("b.obj:1: number '1e999' is out of the range"),
            std::string::npos);
  EXPECT_NE(message("c.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n")
                .find("c.obj:4: vertex index 'x' is not an integer"),
            std::string::npos);
  EXPECT_NE(message("d.obj", "# only a comment\n\n").find("file is empty"), std::string::npos);
  EXPECT_NE(message("e.ply", "ply\n").find("unsupported mesh format '.ply'"), std::string::npos);
  EXPECT_NE(message("f.obj", "v 0 0 0\n").find("no faces"), std::string::npos);
  EXPECT_NE(message("g.obj", "f 1 2 3\n").find("no vertices"), std::string::npos);
  EXPECT_NE(message("h.obj", "v 0 0 0\nv\t1 0 0\x01\n").find("h.obj:2: binary data (byte 0x01"),
            std::string::npos);
  try {
    read_mesh(dir / "missing.obj");
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.obj: file not found"), std::string::npos) << e.what();
  }
}

TEST(MeshIo, PointsXyz) {
  TempDir dir;
  write_text(dir / "p.xyz", "# points\n0 0 0\n\n1 2 3.5\n-1e-3 4 5\n");
  const MatX3d P = read_points_xyz(dir / "p.xyz");
  ASSERT_EQ(P.rows(), 3);
  EXPECT_EQ(P.row(1), Eigen::RowVector3d(1, 2, 3.5));
  write_text(dir / "q.xyz", "0 0 0\n1 2\n");
  try {
    read_points_xyz(dir / "q.xyz");
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("q.xyz:2: point 2: expected 3 numbers"), std::string::npos)
        << e.what();
  }
  write_text(dir / "r.xyz", "0 0 0\n1 nan 0\n");
  EXPECT_THROW(read_points_xyz(dir / "r.xyz"), InputError);
  write_text(dir / "s.xyz", "");
  EXPECT_THROW(read_points_xyz(dir / "s.xyz"), InputError);
}

TEST(MeshIo, ReadsSharedSamples) {
  LIDEF_REQUIRE_SHARED();
  const MatX3d P = read_points_xyz(test::shared_model("bar") + "/samples.xyz");
  EXPECT_EQ(P.rows(), 28857);
}

// ---------------------------------------------------------------------------------------------------------
// Procedural models and the project's data.
TEST(ModelProcedural, BeamAndBallAreValidWithExpectedSizes) {
  const Model beam = make_beam();
  EXPECT_TRUE(beam.report.warnings.empty());
  EXPECT_EQ(beam.cage.num_vertices(), 106);
  EXPECT_EQ(beam.cage.num_faces(), 208);
  EXPECT_EQ(beam.mesh.V.rows(), 3170);
  EXPECT_NEAR(beam.report.min_distance, 0.1 * 0.4, 1e-12);
  EXPECT_NEAR(beam.cage.volume, 2.08 * 0.48 * 0.48, 1e-12);
  const Model ball = make_ball();
  EXPECT_TRUE(ball.report.warnings.empty());
  EXPECT_EQ(ball.cage.num_vertices(), 162);
  EXPECT_EQ(ball.mesh.V.rows(), 2562);
  EXPECT_GE(ball.report.min_distance, 0.1 - 1e-12);
  EXPECT_LT(ball.report.min_distance, 0.11);
  for (int v = 0; v < ball.mesh.V.rows(); ++v) ASSERT_NEAR(ball.mesh.V.row(v).norm(), 1.0, 1e-14);
  EXPECT_THROW(make_beam(BeamParams{1, 0, 0.1}), Error);
  EXPECT_THROW(make_ball(BallParams{1, 0.1, 9, 2}), Error);
}

TEST(ModelProcedural, ProjectModelsPassCheckWithoutWarnings) {
  for (const std::string name : {"beam", "ball"}) {
    const ValidationReport r = check_model_dir(test::project_data() + "/models/" + name);
    EXPECT_TRUE(r.usable()) << name << ": " << (r.errors.empty() ? "" : r.errors[0].str());
    EXPECT_TRUE(r.warnings.empty()) << name << ": " << (r.warnings.empty() ? "" : r.warnings[0].str());
    const auto j = nlohmann::json::parse(read_text(test::project_data() + "/models/" + name + "/model.json"));
    EXPECT_EQ(j["name"], name);
    EXPECT_EQ(j["cage"]["vertices"], r.cage_vertices);
    EXPECT_EQ(j["mesh"]["vertices"], r.mesh_vertices);
  }
}

// The committed data/models must be what the generator makes today (numerically: the last bit of a
// coordinate may depend on the compiler's use of FMA), and the generator must be deterministic (bytes).
TEST(ModelProcedural, CommittedModelsMatchTheGeneratorAndGenerationIsDeterministic) {
  TempDir a, b;
  for (const std::string name : {"beam", "ball"}) {
    ASSERT_EQ(test::run_command(test::cli() + " make-model " + name + " --out " + (a / name)), 0);
    ASSERT_EQ(test::run_command(test::cli() + " make-model " + name + " --out " + (b / name)), 0);
    for (const std::string f : {"cage.obj", "mesh.obj", "model.json"})
      EXPECT_EQ(read_text(a / (name + "/" + f)), read_text(b / (name + "/" + f))) << name << "/" << f;
    for (const std::string f : {"cage", "mesh"}) {
      const TriMesh fresh = read_mesh(a / (name + "/" + f + ".obj"));
      const TriMesh committed = read_mesh(test::project_data() + "/models/" + name + "/" + f + ".obj");
      ASSERT_EQ(fresh.V.rows(), committed.V.rows()) << name << "/" << f;
      EXPECT_EQ(fresh.F, committed.F) << name << "/" << f;
      EXPECT_LT((fresh.V - committed.V).cwiseAbs().maxCoeff(), 1e-14) << name << "/" << f;
    }
  }
}

TEST(ModelProcedural, BeamBendScenarioHandlesAreMeshVertices) {
  const auto s = nlohmann::json::parse(read_text(test::project_data() + "/scenarios/beam_bend.json"));
  EXPECT_EQ(s["model"], "beam");
  const TriMesh mesh =
      read_mesh(test::project_data() + "/models/" + s["model"].get<std::string>() + "/mesh.obj");
  int fixed = 0, moved = 0;
  for (const auto& h : s["handles"]) {
    const Vec3 src(h["source"][0].get<double>(), h["source"][1].get<double>(), h["source"][2].get<double>());
    const Vec3 dst(h["target"][0].get<double>(), h["target"][1].get<double>(), h["target"][2].get<double>());
    bool is_vertex = false;
    for (int v = 0; v < mesh.V.rows() && !is_vertex; ++v) is_vertex = mesh.V.row(v) == src.transpose();
    EXPECT_TRUE(is_vertex) << src.transpose();
    if (src == dst) {
      ++fixed;
      EXPECT_EQ(src.x(), -1.0);
    } else {
      ++moved;
      EXPECT_EQ(src.x(), 1.0);
      EXPECT_NEAR(dst.y() - src.y(), 0.3 * 2.0, 1e-12);  // sideways by 30% of the length
    }
  }
  EXPECT_GE(fixed, 3);
  EXPECT_GE(moved, 3);
}

// ---------------------------------------------------------------------------------------------------------
// The CLI.
TEST(CheckCli, BrokenModelExits2AndNamesTheFile) {
  TempDir dir;
  write_text(dir / "cage.obj", cube_cage({kCubeFaces.begin(), kCubeFaces.end() - 1}));
  write_text(dir / "mesh.obj", tet_mesh());
  std::string out;
  EXPECT_EQ(test::run_command(test::cli() + " check " + dir.str(), &out), 2);
  EXPECT_NE(out.find(dir / "cage.obj"), std::string::npos) << out;
  EXPECT_NE(out.find("not closed"), std::string::npos) << out;
  EXPECT_NE(out.find("result: NOT usable"), std::string::npos) << out;
}

TEST(CheckCli, GoodModelExits0AndWritesJson) {
  TempDir dir;
  std::string out;
  const std::string model = test::project_data() + "/models/beam";
  EXPECT_EQ(test::run_command(test::cli() + " check " + model + " --json " + (dir / "r.json"), &out), 0)
      << out;
  EXPECT_NE(out.find("106 vertices, 208 faces, 312 edges"), std::string::npos) << out;
  EXPECT_NE(out.find("min distance mesh -> cage 0.04"), std::string::npos) << out;
  const auto j = nlohmann::json::parse(read_text(dir / "r.json"));
  EXPECT_TRUE(j["usable"].get<bool>());
  EXPECT_EQ(j["mesh"]["vertices"], 3170);
}

TEST(CheckCli, HelpAndBadArguments) {
  std::string out;
  EXPECT_EQ(test::run_command(test::cli() + " check --help", &out), 0);
  EXPECT_NE(out.find("MODEL_DIR"), std::string::npos) << out;
  EXPECT_NE(out.find("Exit status"), std::string::npos) << out;
  EXPECT_EQ(test::run_command(test::cli() + " check", &out), 2);
  EXPECT_EQ(test::run_command(test::cli() + " make-model cube --out /tmp/x", &out), 2);
  EXPECT_EQ(test::run_command(test::cli() + " check /nonexistent/model", &out), 2);
  EXPECT_NE(out.find("/nonexistent/model: model folder not found"), std::string::npos) << out;
}

}  // namespace

// Moving a model far from the origin changes none of the checks (the signed volume was summed in
// absolute coordinates and the beam moved by 1e6 came out "inverted").
TEST(ModelCheck, FarFromTheOriginTheCheckAndVolumeAreUnchanged) {
  const std::string src = test::project_data() + "/models/beam";
  const ValidationReport original = check_model_dir(src);
  ASSERT_TRUE(original.usable());
  for (const double shift : {1e3, 1e6, 1e8}) {
    SCOPED_TRACE(shift);
    TempDir dir;
    for (const char* f : {"cage", "mesh"}) {
      TriMesh m = read_mesh(src + "/" + f + ".obj");
      m.V.rowwise() += Eigen::RowVector3d(shift, shift, shift);
      std::ofstream out(dir / (std::string(f) + ".obj"));
      write_obj(out, m.V, m.F);
    }
    const ValidationReport r = check_model_dir(dir.str());
    EXPECT_TRUE(r.usable()) << (r.errors.empty() ? "" : r.errors.front().str());
    // Coordinates near 1e8 hold ~1e-8 absolute rounding; relative to the beam's size (~2) that is 1e-8.
    EXPECT_NEAR(r.cage_volume, original.cage_volume, 1e-6 * original.cage_volume);
    EXPECT_EQ(r.cage_faces, original.cage_faces);
  }
}
