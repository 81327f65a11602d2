// VTK writers for ParaView (VTK 9.1): the certification octree (.vtu) and map fields (.vti).
#include "lidef/analysis/vtk_export.h"

#include <unistd.h>
#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkCommand.h>
#include <vtkDoubleArray.h>
#include <vtkFloatArray.h>
#include <vtkIdTypeArray.h>
#include <vtkImageData.h>
#include <vtkIntArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLImageDataWriter.h>
#include <vtkXMLUnstructuredGridWriter.h>
#include <vtkXMLWriter.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "lidef/errors.h"
#include "lidef/signed_svd.h"
#include "vtk_write_atomic.h"

namespace lidef {
namespace {

vtkSmartPointer<vtkDoubleArray> double_array(const char* name, vtkIdType n) {
  auto a = vtkSmartPointer<vtkDoubleArray>::New();
  a->SetName(name);
  a->SetNumberOfComponents(1);
  a->SetNumberOfTuples(n);
  return a;
}

}  // namespace

void write_leaves_vtu(const std::string& path, const std::vector<CertLeaf>& leaves) {
  const vtkIdType n = static_cast<vtkIdType>(leaves.size());
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  points->SetNumberOfPoints(8 * n);
  vtkNew<vtkIdTypeArray> offsets, connectivity;
  offsets->SetNumberOfTuples(n + 1);
  connectivity->SetNumberOfTuples(8 * n);
  auto depth = vtkSmartPointer<vtkIntArray>::New();
  depth->SetName("depth");
  depth->SetNumberOfTuples(n);
  auto side = double_array("side", n), sigma3 = double_array("sigma3", n), L = double_array("L", n),
       margin = double_array("margin", n);
  auto sigma1_upper = double_array("sigma1_upper", n), distortion_upper = double_array("distortion_upper", n);
  auto status = vtkSmartPointer<vtkUnsignedCharArray>::New();
  status->SetName("status");
  status->SetNumberOfTuples(n);
  // VTK_HEXAHEDRON order: the bottom face counter-clockwise seen from +z, then the top face above it.
  static const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                   {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  for (vtkIdType i = 0; i < n; ++i) {
    const CertLeaf& l = leaves[i];
    for (int k = 0; k < 8; ++k) {
      const Vec3 p =
          l.center + l.side * (Vec3(corner[k][0], corner[k][1], corner[k][2]) - Vec3::Constant(0.5));
      points->SetPoint(8 * i + k, p.x(), p.y(), p.z());
      connectivity->SetValue(8 * i + k, 8 * i + k);
    }
    offsets->SetValue(i, 8 * i);
    depth->SetValue(i, l.depth);
    side->SetValue(i, l.side);
    sigma3->SetValue(i, l.sigma3);
    L->SetValue(i, l.L);
    margin->SetValue(i, l.margin);
    sigma1_upper->SetValue(i, l.sigma1_upper);
    distortion_upper->SetValue(i, l.distortion_upper);
    status->SetValue(i, l.certified ? 1 : 0);
  }
  offsets->SetValue(n, 8 * n);
  vtkNew<vtkCellArray> cells;
  cells->SetData(offsets, connectivity);
  vtkNew<vtkUnstructuredGrid> grid;
  grid->SetPoints(points);
  grid->SetCells(VTK_HEXAHEDRON, cells);
  vtkCellData* cd = grid->GetCellData();
  cd->AddArray(depth);
  cd->AddArray(side);
  cd->AddArray(sigma3);
  cd->AddArray(L);
  cd->AddArray(margin);
  cd->AddArray(sigma1_upper);
  cd->AddArray(distortion_upper);
  cd->AddArray(status);
  cd->SetActiveScalars("margin");
  vtkNew<vtkXMLUnstructuredGridWriter> writer;
  writer->SetInputData(grid);
  detail::write_vtk_atomic(writer, path, ".vtu");
}

void write_field_vti(const std::string& path, const FieldGrid& g) {
  vtkNew<vtkImageData> image;
  image->SetDimensions(g.dims[0], g.dims[1], g.dims[2]);
  image->SetOrigin(g.origin.x(), g.origin.y(), g.origin.z());
  image->SetSpacing(g.spacing, g.spacing, g.spacing);
  vtkPointData* pd = image->GetPointData();
  pd->AddArray(detail::make_array<vtkFloatArray>("sigma1", g.sigma1));
  pd->AddArray(detail::make_array<vtkFloatArray>("sigma3", g.sigma3));
  pd->AddArray(detail::make_array<vtkFloatArray>("detJ", g.det_j));
  pd->AddArray(detail::make_array<vtkFloatArray>("E_iso", g.e_iso));
  pd->AddArray(detail::make_array<vtkUnsignedCharArray>("inside_cage", g.inside_cage));
  pd->AddArray(detail::make_array<vtkUnsignedCharArray>("inside_sampled", g.inside_sampled));
  pd->SetActiveScalars("sigma3");
  vtkNew<vtkXMLImageDataWriter> writer;
  writer->SetInputData(image);
  detail::write_vtk_atomic(writer, path, ".vti");
}

FieldGrid write_field_vti(const std::string& path, const Cage& cage, const HarmonicBasis& basis,
                          const MatX3d& y, const VoxelSampling& sampling, int resolution) {
  FieldGrid g = compute_field_grid(cage, basis, y, sampling, resolution);
  write_field_vti(path, g);
  return g;
}

}  // namespace lidef
