// write_mesh_vtp (mesh_export.h): a small mesh with point arrays, read back with VTK's own reader; refusals
// leave no file behind.
#include <gtest/gtest.h>
#include <vtkCellArray.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkXMLPolyDataReader.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "lidef/analysis/mesh_export.h"
#include "lidef/errors.h"
#include "test_support.h"

namespace {

using namespace lidef;
using lidef::test::TempDir;
namespace fs = std::filesystem;

// A tetrahedron's surface: 4 vertices, 4 triangles.
void tetrahedron(MatX3d& V, MatX3i& F) {
  V.resize(4, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1.5;
  F.resize(4, 3);
  F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

int entries(const fs::path& dir) {
  int n = 0;
  for (auto it = fs::directory_iterator(dir); it != fs::directory_iterator(); ++it) ++n;
  return n;
}

TEST(MeshVtp, WritesPointsTrianglesAndArrays) {
  TempDir t;
  MatX3d V;
  MatX3i F;
  tetrahedron(V, F);
  VecXd sigma3(4), disp(4);
  sigma3 << 1, 0.5, -0.25, 2;
  disp << 0, 0.1, 0.2, 0.3;
  const std::string path = t / "deformed.vtp";
  write_mesh_vtp(path, V, F, {{"sigma3", sigma3}, {"displacement", disp}});

  ASSERT_TRUE(fs::is_regular_file(path));
  EXPECT_EQ(entries(t.path), 1);  // no temporary left
  const std::string text = read_text(path);
  EXPECT_TRUE(text.rfind("<?xml", 0) == 0 || text.rfind("<VTKFile", 0) == 0) << text.substr(0, 80);
  EXPECT_NE(text.find("type=\"PolyData\""), std::string::npos);
  EXPECT_NE(text.find("NumberOfPoints=\"4\""), std::string::npos);
  EXPECT_NE(text.find("NumberOfPolys=\"4\""), std::string::npos);
  EXPECT_NE(text.find("Name=\"sigma3\""), std::string::npos);
  EXPECT_NE(text.find("Name=\"displacement\""), std::string::npos);
  EXPECT_NE(text.find("Float64"), std::string::npos);
  EXPECT_NE(text.find("vtkZLibDataCompressor"), std::string::npos);

  // VTK's reader gets the same geometry and values back.
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(path.c_str());
  reader->Update();
  vtkPolyData* mesh = reader->GetOutput();
  ASSERT_EQ(mesh->GetNumberOfPoints(), 4);
  ASSERT_EQ(mesh->GetNumberOfPolys(), 4);
  double p[3];
  mesh->GetPoint(3, p);
  EXPECT_EQ(p[2], 1.5);
  vtkDataArray* a = mesh->GetPointData()->GetArray("sigma3");
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->GetDataType(), VTK_DOUBLE);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(a->GetTuple1(i), sigma3(i));
  ASSERT_NE(mesh->GetPointData()->GetArray("displacement"), nullptr);
  EXPECT_EQ(mesh->GetPointData()->GetArray("displacement")->GetTuple1(3), 0.3);
  vtkNew<vtkIdList> ids;
  mesh->GetPolys()->GetCellAtId(1, ids);
  ASSERT_EQ(ids->GetNumberOfIds(), 3);
  EXPECT_EQ(ids->GetId(0), 0);
  EXPECT_EQ(ids->GetId(1), 1);
  EXPECT_EQ(ids->GetId(2), 3);
}

TEST(MeshVtp, OverwritesAnExistingFile) {
  TempDir t;
  MatX3d V;
  MatX3i F;
  tetrahedron(V, F);
  const std::string path = t / "m.vtp";
  write_mesh_vtp(path, V, F, {});
  write_mesh_vtp(path, V, F, {{"x", V.col(0)}});
  EXPECT_NE(read_text(path).find("Name=\"x\""), std::string::npos);
  EXPECT_EQ(entries(t.path), 1);
}

TEST(MeshVtp, WrongArraySizeThrowsAndWritesNothing) {
  TempDir t;
  MatX3d V;
  MatX3i F;
  tetrahedron(V, F);
  const std::string path = t / "bad.vtp";
  try {
    write_mesh_vtp(path, V, F, {{"ok", VecXd::Zero(4)}, {"short", VecXd::Zero(3)}});
    FAIL() << "no exception";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);
    EXPECT_NE(std::string(e.what()).find("'short' has 3 values"), std::string::npos) << e.what();
  }
  EXPECT_EQ(entries(t.path), 0);
  EXPECT_THROW(write_mesh_vtp(path, V, F, {{"a", VecXd::Zero(4)}, {"a", VecXd::Zero(4)}}), InputError);
  EXPECT_THROW(write_mesh_vtp(path, V, F, {{"", VecXd::Zero(4)}}), InputError);
  F(2, 1) = 4;  // index past the last vertex
  EXPECT_THROW(write_mesh_vtp(path, V, F, {}), InputError);
  EXPECT_EQ(entries(t.path), 0);
}

TEST(MeshVtp, MissingFolderThrowsAndLeavesNothing) {
  TempDir t;
  MatX3d V;
  MatX3i F;
  tetrahedron(V, F);
  const std::string path = t / "no_such_dir/m.vtp";
  try {
    write_mesh_vtp(path, V, F, {{"x", V.col(0)}});
    FAIL() << "no exception";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(t.path / "no_such_dir"));
  EXPECT_EQ(entries(t.path), 0);
}

TEST(MeshVtp, UnrenamableTargetThrowsAndLeavesNoTemporary) {
  TempDir t;
  MatX3d V;
  MatX3i F;
  tetrahedron(V, F);
  const std::string path = t / "taken.vtp";
  fs::create_directories(fs::path(path) / "inside");  // a non-empty folder where the file should go
  try {
    write_mesh_vtp(path, V, F, {});
    FAIL() << "no exception";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);
  }
  EXPECT_EQ(entries(t.path), 1);  // only the folder
  EXPECT_TRUE(fs::is_directory(fs::path(path) / "inside"));
}

}  // namespace
