// Point clouds, Gaussian splats, open and crossing meshes as inputs: PLY reading and writing, refused inputs,
// splat covariance and spherical-harmonic mapping, what the certified domain is for each, and the automatic
// cage of a point set.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <tuple>

#include "lidef/cage.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/coefficients.h"
#include "lidef/domain_sampling.h"
#include "lidef/gaussian_splats.h"
#include "lidef/green_coordinates.h"
#include "lidef/mesh_io.h"
#include "lidef/point_cloud_io.h"
#include "lidef/procedural_models.h"
#include "lidef/sampling.h"
#include "test_cli_outputs.h"
#include "test_support.h"

namespace lidef {
namespace {

using test::input_error_message;
using test::TempDir;
using test::write_text;

// n points on the sphere of radius r around c (seeded).
MatX3d sphere_points(int n, double r, const Vec3& c, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  MatX3d P(n, 3);
  for (int i = 0; i < n; ++i) {
    const Vec3 d = Vec3(g(rng), g(rng), g(rng)).normalized();
    P.row(i) = (c + r * d).transpose();
  }
  return P;
}

// A splat cloud of n splats on a sphere: random log scales and rotations, random colours, one extra property.
PlyCloud random_splats(int n, unsigned seed) {
  PlyCloud c;
  c.names = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
  for (int k = 0; k < 45; ++k) c.names.push_back("f_rest_" + std::to_string(k));
  for (const char* s : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    c.names.push_back(s);
  c.names.push_back("tag");
  c.types.assign(c.names.size(), "float");
  c.types.back() = "int";
  c.values.resize(n, static_cast<Eigen::Index>(c.names.size()));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < n; ++i)
    for (Eigen::Index k = 0; k < c.values.cols(); ++k)
      c.values(i, k) = static_cast<float>(u(rng));  // float-representable, so a write/read is exact
  c.set_columns3("x", "y", "z", sphere_points(n, 0.5, Vec3::Zero(), seed).cast<float>().cast<double>());
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k)
      c.values(i, c.column("scale_" + std::to_string(k))) = static_cast<float>(-4 + u(rng));
    c.values(i, c.column("tag")) = i;
  }
  return c;
}

std::string write_ply(const std::string& path, const PlyCloud& c) {
  std::ofstream out(path, std::ios::binary);
  write_ply_cloud(out, c);
  return path;
}

TEST(PointCloudPly, RoundTripsInEveryFormat) {
  TempDir dir;
  PlyCloud c = random_splats(50, 1);
  c.F.resize(2, 3);
  c.F << 0, 1, 2, 2, 3, 4;
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    c.format = format;
    const PlyCloud r = read_ply_cloud(write_ply((dir.path / (std::string(format) + ".ply")).string(), c));
    EXPECT_EQ(r.format, format);
    EXPECT_EQ(r.names, c.names);
    EXPECT_EQ(r.types, c.types);
    EXPECT_EQ(r.values, c.values) << format;
    EXPECT_EQ(r.F, c.F) << format;
  }
}

TEST(PointCloudPly, ReadsColoursAndOtherElements) {
  TempDir dir;
  const std::string path = (dir.path / "c.ply").string();
  write_text(
      path,
      "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\nproperty double x\nproperty double "
      "y\nproperty double z\nproperty uchar red\nelement edge 1\nproperty int vertex1\nproperty int "
      "vertex2\nend_header\n1 2 3 255\n4 5 6 0\n0 1\n");
  const PlyCloud c = read_ply_cloud(path);
  ASSERT_EQ(c.values.rows(), 2);
  EXPECT_EQ(c.points()(1, 2), 6);
  EXPECT_EQ(c.values(0, c.column("red")), 255);
  EXPECT_EQ(c.F.rows(), 0);
  EXPECT_EQ(read_point_cloud(path).rows(), 2);
}

TEST(PointCloudPly, BadInputsAreRefusedNamingTheFile) {
  TempDir dir;
  auto msg = [&](const std::string& name, const std::string& text) {
    const std::string path = (dir.path / name).string();
    write_text(path, text);
    return input_error_message([&] { read_gaussian_splats(path); });
  };
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n";
  EXPECT_NE(msg("empty.ply",
                "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                "property float z\nend_header\n")
                .find("empty.ply: empty point cloud"),
            std::string::npos);
  EXPECT_NE(msg("nan.ply", head + "property float z\nproperty float scale_0\nend_header\n0 nan 0 1\n")
                .find("nan.ply: vertex 1: coordinate is NaN"),
            std::string::npos);
  EXPECT_NE(msg("noscale.ply", head + "property float z\nend_header\n0 0 0\n")
                .find("noscale.ply: splat PLY without scales"),
            std::string::npos);
  EXPECT_NE(msg("noz.ply", head + "end_header\n0 0\n").find("no property 'z'"), std::string::npos);
  EXPECT_NE(msg("short.ply", head + "property float z\nend_header\n0 0\n").find("file ends early"),
            std::string::npos);
  // The header's last line at the very end of the file, without '\n': no body at all, in both formats.
  EXPECT_NE(msg("nobody.ply", head + "property float z\nend_header").find("nobody.ply: file ends early"),
            std::string::npos);
  const std::string bin =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nend_header";
  EXPECT_NE(msg("nobody_bin.ply", bin).find("nobody_bin.ply: binary body is truncated"), std::string::npos);
  // A binary body cut short.
  PlyCloud c = random_splats(10, 2);
  std::ostringstream full;
  write_ply_cloud(full, c);
  const std::string cut = full.str().substr(0, full.str().size() - 7);
  EXPECT_NE(msg("cut.ply", cut).find("cut.ply: binary body is truncated"), std::string::npos);
  EXPECT_NE(msg("notply.ply", "hello\n").find("not a PLY file"), std::string::npos);
}

TEST(PointCloudPly, XyzAndObjPointSets) {
  TempDir dir;
  const std::string xyz = (dir.path / "p.xyz").string(), obj = (dir.path / "p.obj").string();
  write_text(xyz, "0 0 0\n1 2 3\n");
  write_text(obj, "v 0 0 0\nv 1 2 3\nv 4 5 6\n");
  EXPECT_EQ(read_point_cloud(xyz).rows(), 2);
  const MatX3d P = read_point_cloud(obj);
  ASSERT_EQ(P.rows(), 3);
  EXPECT_EQ(P(2, 1), 5);
  EXPECT_EQ(read_mesh_or_points(obj).F.rows(), 0);
  // The automatic cage's reader takes all three as point clouds (CGAL's OBJ reader would fail on `v` lines
  // only).
  for (const std::string& path : {xyz, obj}) {
    const TriMesh m = read_any_mesh(path);
    EXPECT_EQ(m.F.rows(), 0) << path;
    EXPECT_EQ(m.V.rows(), path == obj ? 3 : 2) << path;
  }
  // read_mesh still wants faces.
  EXPECT_NE(input_error_message([&] { read_mesh(obj); }).find("no faces"), std::string::npos);
}

// XYZ files with a normal per point: read with their normals, written back exactly; a file that mixes 3 and 6
// columns is refused naming the line.
TEST(PointCloudPly, XyzWithNormals) {
  TempDir dir;
  const std::string path = (dir.path / "n.xyz").string();
  write_text(path, "# x y z nx ny nz\n0 0 0 0 0 1\n1 2 3 0.6 0.8 0\n");
  MatX3d N;
  const MatX3d P = read_points_xyz(path, &N);
  ASSERT_EQ(P.rows(), 2);
  ASSERT_EQ(N.rows(), 2);
  EXPECT_EQ(P.row(1), Eigen::RowVector3d(1, 2, 3));
  EXPECT_EQ(N.row(1), Eigen::RowVector3d(0.6, 0.8, 0));
  EXPECT_EQ(read_point_cloud(path).rows(), 2);
  std::ostringstream written;
  write_points_xyz(written, P * (1.0 / 3), N);
  write_text(path, written.str());
  MatX3d N2;
  EXPECT_EQ(read_points_xyz(path, &N2), P * (1.0 / 3));  // shortest round-trip digits: exact
  EXPECT_EQ(N2, N);
  MatX3d none;
  write_text(path, "0 0 0\n1 1 1\n");
  read_points_xyz(path, &none);
  EXPECT_EQ(none.rows(), 0);
  write_text(path, "0 0 0 0 0 1\n1 1 1\n");
  const std::string msg = input_error_message([&] { read_points_xyz(path); });
  EXPECT_NE(msg.find("n.xyz:2: point 2: expected 6 numbers"), std::string::npos) << msg;
}

// A PLY mesh with a vertex that no face uses: the model drops it (the cage maker keeps the mesh's used
// vertices), yet deformed.ply holds every input vertex in input order, the unused one evaluated by the map
// and counted in summary.json as not in the model.
TEST(PointCloudPly, DeformedPlyKeepsUnusedVertices) {
  TempDir dir;
  const Model ball = make_ball();
  PlyCloud mesh;
  mesh.format = "ascii";
  mesh.names = {"x", "y", "z"};
  mesh.types = {"double", "double", "double"};
  const Eigen::Index n = ball.mesh.V.rows();
  mesh.values.resize(n + 1, 3);
  mesh.values.topRows(n) = ball.mesh.V;
  mesh.values.row(n) << 0.1, 0.2, 0.3;  // inside the ball, used by no face
  mesh.F = ball.mesh.F;
  const std::string ply = write_ply((dir.path / "ball.ply").string(), mesh);
  const std::string scenario = (dir.path / "pull.json").string(), out = (dir.path / "out").string();
  write_text(scenario, "{\"name\": \"pull\", \"model\": \"" + ply +
                           "\", \"handles\": [{\"source\": [-1, 0, 0], \"target\": [-1, 0, 0]}, "
                           "{\"source\": [1, 0, 0], \"target\": [1.05, 0, 0]}]}");
  std::string log;
  ASSERT_LE(test::run_lidef_cli("deform " + scenario + " --out " + out + " --cache-dir " +
                                    (dir.path / "cache").string() +
                                    " --samples 2000 --reduced-dof 30 --max-iterations 2 --quiet",
                                &log),
            1)
      << log;
  const PlyCloud d = read_ply_cloud(out + "/deformed.ply");
  ASSERT_EQ(d.values.rows(), n + 1);
  EXPECT_EQ(d.F, mesh.F);
  const std::string summary = test::read_text(out + "/summary.json");
  EXPECT_NE(summary.find("\"points_not_in_model\": 1"), std::string::npos) << summary;
  // The unused vertex is f at it: the map of the written coefficients evaluated there.
  const TriMesh cage = read_mesh(out + "/cage.obj");
  const Cage cg(cage);
  const MatX3d y = read_coefficients(out + "/coefficients.txt", cg);
  const MatX3d want = HarmonicBasis(cg).map_values(y, mesh.values.bottomRows(1));
  EXPECT_LT((d.points().bottomRows(1) - want).norm(), 1e-12);
  // The used vertices are deformed.obj's, in input order.
  const TriMesh obj = read_mesh(out + "/deformed.obj");
  ASSERT_EQ(obj.V.rows(), n);
  EXPECT_EQ(d.points().topRows(n), obj.V);
}

TEST(GaussianSplats, ScaleRotationRoundTrip) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int t = 0; t < 100; ++t) {
    const Vec3 s(-3 + u(rng), -3 + u(rng), -3 + u(rng));
    const Eigen::Vector4d q(u(rng), u(rng), u(rng), u(rng));
    const Mat3 S = splat_covariance(s, q);
    Vec3 s2;
    Eigen::Vector4d q2;
    splat_scale_rotation(S, &s2, &q2);
    EXPECT_NEAR(q2.norm(), 1.0, 1e-12);
    EXPECT_GE(q2(0), 0.0);
    EXPECT_LE(s2(0), s2(1));
    EXPECT_LE(s2(1), s2(2));
    EXPECT_LT((splat_covariance(s2, q2) - S).norm(), 1e-12 * S.norm());
  }
}

TEST(GaussianSplats, ShRotationIsARepresentation) {
  std::mt19937 rng(4);
  std::normal_distribution<double> g;
  for (int t = 0; t < 10; ++t) {
    const Mat3 R = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
    const auto M = sh_rotation(R), Mt = sh_rotation(R.transpose());
    // Rotating by R then by Rᵀ gives the coefficients back.
    EXPECT_LT((Mt * M - Eigen::Matrix<double, 15, 15>::Identity()).norm(), 1e-10);
    // Y(Rᵀd) = M Y(d) at directions that were not fitted.
    for (int k = 0; k < 5; ++k) {
      const Vec3 d = Vec3(g(rng), g(rng), g(rng)).normalized();
      EXPECT_LT((sh_basis_degree1to3(R.transpose() * d) - M * sh_basis_degree1to3(d)).norm(), 1e-10);
    }
    // Band 1 is the direct rotation: Y1(d) = C1 (−y, z, −x) = C1 P d with P a signed permutation.
    Mat3 P;
    P << 0, -1, 0, 0, 0, 1, -1, 0, 0;
    const Mat3 direct = P * R.transpose() * P.transpose();
    EXPECT_LT((M.block<3, 3>(0, 0) - direct).norm(), 1e-10);
  }
}

TEST(GaussianSplats, PolarRotation) {
  Mat3 J;
  J << 1.2, 0.3, -0.1, 0.2, 0.9, 0.4, -0.3, 0.1, 1.5;
  const Mat3 Q = polar_rotation(J);
  EXPECT_LT((Q.transpose() * Q - Mat3::Identity()).norm(), 1e-12);
  EXPECT_NEAR(Q.determinant(), 1.0, 1e-12);
  const Mat3 P = Q.transpose() * J;
  EXPECT_LT((P - P.transpose()).norm(), 1e-12);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Mat3>(0.5 * (P + P.transpose())).eigenvalues().minCoeff(), 0);
}

TEST(GaussianSplats, MappedCovarianceIsJSigmaJt) {
  PlyCloud c = random_splats(200, 5);
  const PlyCloud before = c;
  const int n = static_cast<int>(c.values.rows());
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  MatXd JT(3 * n, 3);
  std::vector<Mat3> J(n);
  for (int i = 0; i < n; ++i) {
    J[i] = Mat3::Identity();
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) J[i](a, b) += u(rng);
    if (J[i].determinant() < 0) J[i].col(0) *= -1;
    JT.block<3, 3>(3 * i, 0) = J[i].transpose();
  }
  const MatX3d mapped = c.points() * 2.0;
  map_gaussian_splats(c, mapped, JT);
  EXPECT_EQ(c.points(), mapped);
  auto cov = [](const PlyCloud& p, int i) {
    Vec3 s;
    Eigen::Vector4d q;
    for (int k = 0; k < 3; ++k) s(k) = p.values(i, p.column("scale_" + std::to_string(k)));
    for (int k = 0; k < 4; ++k) q(k) = p.values(i, p.column("rot_" + std::to_string(k)));
    return splat_covariance(s, q);
  };
  for (int i = 0; i < n; ++i) {
    const Mat3 want = J[i] * cov(before, i) * J[i].transpose();
    EXPECT_LT((cov(c, i) - want).norm(), 1e-10 * want.norm()) << "splat " << i;
    // Kept: opacity, f_dc, the extra property.
    for (const char* k : {"opacity", "f_dc_0", "f_dc_2", "tag"})
      EXPECT_EQ(c.values(i, c.column(k)), before.values(i, before.column(k)));
    // The view-dependent colour follows the polar rotation: colour along Q d after = colour along d before.
    const Mat3 Q = polar_rotation(J[i]);
    const Vec3 d = Vec3(0.3, -0.5, 0.8).normalized();
    for (int ch = 0; ch < 3; ++ch) {
      Eigen::Matrix<double, 15, 1> c0, c1;
      for (int k = 0; k < 15; ++k) {
        c0(k) = before.values(i, before.column("f_rest_" + std::to_string(ch * 15 + k)));
        c1(k) = c.values(i, c.column("f_rest_" + std::to_string(ch * 15 + k)));
      }
      EXPECT_NEAR(c1.dot(sh_basis_degree1to3(Q * d)), c0.dot(sh_basis_degree1to3(d)), 1e-10);
    }
  }
}

TEST(MeshDomainKinds, PointsOpenClosedAndMixed) {
  // A closed tetrahedron, an open triangle, an isolated point.
  MatX3d V(8, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 5, 0, 0, 6, 0, 0, 5, 1, 0, 9, 9, 9;
  MatX3i tet(4, 3);
  tet << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  MatX3i F(5, 3);
  F << tet, Eigen::RowVector3i(4, 5, 6);
  const MeshDomain closed = mesh_domain_of(V.topRows(4), tet);
  EXPECT_EQ(closed.description(), "mesh and its solid");
  EXPECT_EQ(closed.solid.rows(), 4);
  const MeshDomain points = mesh_domain_of(V, MatX3i(0, 3));
  EXPECT_EQ(points.description(), "points and surface, no solid");
  EXPECT_EQ(points.elements.rows(), 8);
  EXPECT_EQ(points.solid.rows(), 0);
  const MeshDomain mixed = mesh_domain_of(V, F);
  EXPECT_EQ(mixed.closed_components, 1);
  EXPECT_EQ(mixed.open_components, 1);
  EXPECT_EQ(mixed.isolated_points, 1);
  EXPECT_EQ(mixed.solid.rows(), 4);
  EXPECT_EQ(mixed.elements.rows(), 6);
  // The exact cube test: the isolated point, the open triangle and the tetrahedron's inside meet D; empty
  // space next to the triangle (no solid there) and far from everything does not.
  MatX3d C(5, 3);
  C << 9.05, 9.05, 9.05,  // holds the point (9, 9, 9)
      5.2, 0.2, 0.0,      // on the open triangle
      0.1, 0.1, 0.1,      // inside the tetrahedron, no face crossing a tiny cube
      5.2, 0.2, 0.5,      // above the open triangle
      3, 3, 3;
  VecXd S(5);
  S << 0.2, 0.1, 0.01, 0.1, 0.1;
  const std::vector<char> meets = cubes_meeting_mesh_domain(V, F, C, S);
  EXPECT_EQ(meets, (std::vector<char>{1, 1, 1, 0, 0}));
}

// A cage for a point cloud, sampled: every point lies in a leaf (point-in-box), and the statement says there
// is no solid.
TEST(PointCloudCage, WrapsPointsAndTheDomainHoldsThem) {
  TempDir dir;
  const MatX3d P = sphere_points(2000, 1.0, Vec3(3, -2, 7), 7);
  const std::string path = (dir.path / "sphere.xyz").string();
  {
    std::ofstream out(path);
    out.precision(17);
    for (Eigen::Index i = 0; i < P.rows(); ++i) out << P(i, 0) << " " << P(i, 1) << " " << P(i, 2) << "\n";
  }
  MeshReadInfo info;
  const TriMesh cloud = read_any_mesh(path, &info);
  EXPECT_EQ(cloud.F.rows(), 0);
  EXPECT_EQ(cloud.V.rows(), 2000);
  EXPECT_EQ(info.format, "xyz");
  const CageResult made = make_cage(cloud);
  EXPECT_TRUE(made.report.validation.usable());
  EXPECT_GT(made.report.validation.min_distance, 0);
  const Cage cage(made.cage);
  SamplingParams sp;
  sp.target_count = 3000;
  const VoxelSampling s = sample_domain(cage, cloud.V, cloud.F, sp);
  ASSERT_GT(s.size(), 0);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    bool inside = false;
    for (int l = 0; l < s.size() && !inside; ++l) {
      const double h = 0.5 * s.side_of(l);
      inside = ((P.row(i) - s.centers.row(l)).cwiseAbs().array() <= h * (1 + 1e-12)).all();
    }
    EXPECT_TRUE(inside) << "point " << i;
  }
  // No solid: the sphere's center is not in D.
  bool center_kept = false;
  for (int l = 0; l < s.size(); ++l)
    center_kept |=
        ((Vec3(3, -2, 7).transpose() - s.centers.row(l)).cwiseAbs().array() <= 0.5 * s.side_of(l)).all();
  EXPECT_FALSE(center_kept);
}

}  // namespace
}  // namespace lidef

namespace lidef {
namespace {

// Rows of a CSV file with a header line, as numbers.
std::vector<std::vector<double>> read_csv_numbers(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::vector<double> r;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) r.push_back(std::strtod(cell.c_str(), nullptr));
    rows.push_back(r);
  }
  return rows;
}

// A point cloud (binary big-endian PLY with normals and colours) and a splat PLY on a sphere, each made into
// a model by `lidef deform` (automatic cage), pulled and certified: every input point lies in a certified
// leaf, deformed.ply's points are `lidef eval`'s f, splat covariances are J Σ Jᵀ with eval's J, normals
// cof(J) n.
TEST(DeformSlow, PointCloudAndSplatsPulledAndCertified) {
  TempDir dir;
  const int n = 1500;
  PlyCloud points;
  points.format = "binary_big_endian";
  points.names = {"x", "y", "z", "nx", "ny", "nz", "red"};
  points.types = {"double", "double", "double", "float", "float", "float", "uchar"};
  points.values.resize(n, 7);
  const MatX3d P = sphere_points(n, 0.5, Vec3(1, 2, 3), 11);
  for (int i = 0; i < n; ++i) {
    points.values.row(i).head(3) = P.row(i);
    points.values.row(i).segment(3, 3) =
        ((P.row(i) - Eigen::RowVector3d(1, 2, 3)) / 0.5).cast<float>().cast<double>();
    points.values(i, 6) = i % 256;
  }
  PlyCloud splats = random_splats(n, 12);
  splats.set_columns3("x", "y", "z",
                      (splats.points().rowwise() + Eigen::RowVector3d(1, 2, 3)).cast<float>().cast<double>());
  struct Case {
    std::string name;
    PlyCloud cloud;
    bool xyz = false;  // written as x y z nx ny nz lines (the cloud's first six columns)
  };
  for (const Case& c : {Case{"points", points}, Case{"splats", splats}, Case{"xyz", points, true}}) {
    SCOPED_TRACE(c.name);
    std::string ply;
    if (c.xyz) {
      ply = (dir.path / "points.xyz").string();
      std::ostringstream text;
      write_points_xyz(text, c.cloud.points(), c.cloud.columns3("nx", "ny", "nz"));
      write_text(ply, text.str());
    } else {
      ply = write_ply((dir.path / (c.name + ".ply")).string(), c.cloud);
    }
    const MatX3d X = c.cloud.points();
    Eigen::Index lo = 0, hi = 0;
    X.col(0).minCoeff(&lo);
    X.col(0).maxCoeff(&hi);
    std::ostringstream sc;
    sc.precision(17);
    sc << "{\"name\": \"pull_" << c.name << "\", \"model\": \"" << ply << "\", \"handles\": [{\"source\": ["
       << X(lo, 0) << ", " << X(lo, 1) << ", " << X(lo, 2) << "], \"target\": [" << X(lo, 0) << ", "
       << X(lo, 1) << ", " << X(lo, 2) << "]}, {\"source\": [" << X(hi, 0) << ", " << X(hi, 1) << ", "
       << X(hi, 2) << "], \"target\": [" << X(hi, 0) + 0.05 << ", " << X(hi, 1) << ", " << X(hi, 2) << "]}]}";
    const std::string scenario = (dir.path / (c.name + ".json")).string(),
                      out = (dir.path / ("out_" + c.name)).string();
    write_text(scenario, sc.str());
    std::string log;
    // Exit 1: stopped at the iteration limit with the handles reached; certified or not is checked below.
    ASSERT_LE(
        test::run_lidef_cli("deform " + scenario + " --out " + out + " --cache-dir " +
                                (dir.path / "cache").string() + " --samples 3000 --reduced-dof 60 --quiet",
                            &log),
        1)
        << log;
    const std::string summary = test::read_text(out + "/summary.json");
    EXPECT_NE(summary.find("\"certified\": true"), std::string::npos);
    EXPECT_NE(summary.find("\"points_not_in_model\": 0"), std::string::npos);
    EXPECT_NE(summary.find("\"domain_statement\": \"points and surface, no solid\""), std::string::npos);
    EXPECT_NE(
        test::read_text(out + "/certificate.json").find("\"statement\": \"points and surface, no solid\""),
        std::string::npos);
    ASSERT_TRUE(std::filesystem::exists(out + "/cage.obj"));
    // Every input point in a certified leaf (voxels.csv: cx, cy, cz, side, ..., certified in column 9).
    const auto leaves = read_csv_numbers(out + "/voxels.csv");
    long outside = 0;
    for (Eigen::Index i = 0; i < X.rows(); ++i) {
      bool in = false;
      for (const auto& l : leaves)
        in = in || (l[8] == 1 && std::abs(X(i, 0) - l[0]) <= 0.5 * l[3] * (1 + 1e-9) &&
                    std::abs(X(i, 1) - l[1]) <= 0.5 * l[3] * (1 + 1e-9) &&
                    std::abs(X(i, 2) - l[2]) <= 0.5 * l[3] * (1 + 1e-9));
      outside += !in;
    }
    EXPECT_EQ(outside, 0);
    // deformed.ply against `lidef eval` on a model folder made of the result's cage.obj and the input points:
    // the result folder is usable on its own.
    const std::string model = (dir.path / ("model_" + c.name)).string();
    std::filesystem::create_directories(model);
    std::filesystem::copy_file(out + "/cage.obj", model + "/cage.obj");
    {
      std::ofstream m(model + "/mesh.obj");
      write_obj(m, X, MatX3i(0, 3));
      std::ofstream xyz(model + "/points.xyz");
      xyz.precision(17);
      for (Eigen::Index i = 0; i < X.rows(); ++i) xyz << X(i, 0) << " " << X(i, 1) << " " << X(i, 2) << "\n";
    }
    ASSERT_EQ(test::run_lidef_cli("eval " + model + " --coeffs " + out + "/coefficients.txt --points " +
                                      model + "/points.xyz --out " + model + "/eval.csv",
                                  &log),
              0)
        << log;
    const auto ev = read_csv_numbers(model + "/eval.csv");  // x,y,z,fx,fy,fz,J00..J22,...
    ASSERT_EQ(static_cast<Eigen::Index>(ev.size()), X.rows());
    PlyCloud d;
    if (c.xyz) {
      MatX3d N;
      const MatX3d Yx = read_points_xyz(out + "/deformed.xyz", &N);
      d = c.cloud;  // the same columns; only x y z and the normals are in the file
      d.set_columns3("x", "y", "z", Yx);
      d.set_columns3("nx", "ny", "nz", N);
      EXPECT_FALSE(std::filesystem::exists(out + "/deformed.ply"));
    } else {
      d = read_ply_cloud(out + "/deformed.ply");
    }
    ASSERT_EQ(d.names, c.cloud.names);
    const MatX3d Y = d.points();
    double worst_f = 0, worst_cov = 0, worst_n = 0;
    for (Eigen::Index i = 0; i < X.rows(); ++i) {
      Mat3 J;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) J(a, b) = ev[i][6 + 3 * a + b];
      worst_f = std::max(worst_f, (Y.row(i) - Eigen::RowVector3d(ev[i][3], ev[i][4], ev[i][5])).norm());
      if (c.name == "splats") {
        auto cov = [](const PlyCloud& p, Eigen::Index k) {
          return splat_covariance(
              Vec3(p.values(k, p.column("scale_0")), p.values(k, p.column("scale_1")),
                   p.values(k, p.column("scale_2"))),
              Eigen::Vector4d(p.values(k, p.column("rot_0")), p.values(k, p.column("rot_1")),
                              p.values(k, p.column("rot_2")), p.values(k, p.column("rot_3"))));
        };
        const Mat3 want = J * cov(c.cloud, i) * J.transpose();
        worst_cov = std::max(worst_cov, (cov(d, i) - want).norm() / want.norm());
        EXPECT_EQ(d.values(i, d.column("tag")), c.cloud.values(i, c.cloud.column("tag")));
        EXPECT_EQ(d.values(i, d.column("opacity")), c.cloud.values(i, c.cloud.column("opacity")));
      } else {
        const Vec3 n0 = c.cloud.columns3("nx", "ny", "nz").row(i).transpose();
        const Vec3 want = (J.inverse().transpose() * n0).normalized();  // cof J ∝ J⁻ᵀ for det J > 0
        worst_n = std::max(worst_n, (d.columns3("nx", "ny", "nz").row(i).transpose() - want).norm());
        EXPECT_EQ(d.values(i, 6), c.cloud.values(i, 6));
      }
    }
    // Points are doubles (eval prints 17 digits); splat positions and all splat fields are float32 in the
    // file.
    EXPECT_LT(worst_f, c.name == "splats" ? 1e-6 : 1e-12);
    EXPECT_LT(worst_cov, 1e-5);
    EXPECT_LT(worst_n, 1e-6);
  }
}

// Two closed boxes through each other and a box with a hole, sampled: every point of the triangles and of the
// closed solids is in a leaf; the statement names what is in D.
TEST(MeshDomainKinds, CrossingComponentsKeepTheirSolids) {
  auto box = [](const Vec3& lo, const Vec3& hi, int offset) {
    MatX3d V(8, 3);
    for (int k = 0; k < 8; ++k)
      V.row(k) = Eigen::RowVector3d(k & 1 ? hi(0) : lo(0), k & 2 ? hi(1) : lo(1), k & 4 ? hi(2) : lo(2));
    MatX3i F(12, 3);
    F << 0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3,
        7, 5;
    F.array() += offset;
    return std::make_pair(V, F);
  };
  const auto a = box(Vec3(-0.5, -0.3, -0.3), Vec3(0.2, 0.3, 0.3), 0),
             b = box(Vec3(-0.2, -0.2, -0.5), Vec3(0.5, 0.2, 0.1), 8);
  MatX3d V(16, 3);
  V << a.first, b.first;
  MatX3i F(24, 3);
  F << a.second, b.second;
  const MeshDomain dom = mesh_domain_of(V, F);
  EXPECT_EQ(dom.description(), "mesh and its solid");
  EXPECT_EQ(dom.closed_components, 2);
  TriMesh cage_mesh;
  std::tie(cage_mesh.V, cage_mesh.F) = box(Vec3(-1, -1, -1), Vec3(1, 1, 1), 0);
  const Cage cage(cage_mesh);
  SamplingParams sp;
  sp.target_count = 2000;
  const VoxelSampling s = sample_domain(cage, V, F, sp);
  // Points of both solids, including the part where they overlap, and on every face.
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  MatX3d Q(2000, 3);
  for (int i = 0; i < 1000; ++i) {
    const auto& bx = i % 2 ? a : b;
    const Vec3 lo = bx.first.colwise().minCoeff(), hi = bx.first.colwise().maxCoeff();
    Q.row(i) = (lo + (hi - lo).cwiseProduct(Vec3(u(rng), u(rng), u(rng)))).transpose();
    const int t = static_cast<int>(u(rng) * 24) % 24;
    const double r = u(rng), q = u(rng) * (1 - r);
    Q.row(1000 + i) = (1 - r - q) * V.row(F(t, 0)) + r * V.row(F(t, 1)) + q * V.row(F(t, 2));
  }
  const VecXi where = containing_voxel(s, Q);
  EXPECT_EQ((where.array() < 0).count(), 0);
  // With one face of the second box removed it is open: its solid leaves D, its triangles stay.
  const MeshDomain open = mesh_domain_of(V, F.topRows(23));
  EXPECT_EQ(open.description(), "points, surface and the solid of 1 closed components");
  EXPECT_EQ(open.solid.rows(), 12);
}

}  // namespace
}  // namespace lidef
