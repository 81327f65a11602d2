// The .vtp writer of mesh_export.h. Includes VTK; keep VTK out of the public headers.
#include "lidef/analysis/mesh_export.h"

#include <unistd.h>
#include <vtkCellArray.h>
#include <vtkCommand.h>
#include <vtkDoubleArray.h>
#include <vtkExecutive.h>
#include <vtkIdTypeArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkXMLPolyDataWriter.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <set>

#include "lidef/errors.h"
#include "vtk_write_atomic.h"

namespace lidef {
namespace {

namespace fs = std::filesystem;

}  // namespace

void write_mesh_vtp(const std::string& path, const MatX3d& V, const MatX3i& F,
                    const std::vector<PointArray>& point_data) {
  const vtkIdType nv = V.rows(), nf = F.rows();
  // Check everything before VTK sees it: VTK writes short arrays and stray indices without complaint.
  std::set<std::string> names;
  for (const PointArray& a : point_data) {
    if (a.name.empty()) throw InputError(path, "point array without a name");
    if (!names.insert(a.name).second) throw InputError(path, "point array '" + a.name + "' given twice");
    if (a.values.size() != nv)
      throw InputError(path, "point array '" + a.name + "' has " + std::to_string(a.values.size()) +
                                 " values, expected one per vertex (#V = " + std::to_string(nv) + ")");
  }
  if (nf > 0 && (F.minCoeff() < 0 || F.maxCoeff() >= nv)) {
    for (vtkIdType t = 0; t < nf; ++t)
      for (int k = 0; k < 3; ++k)
        if (F(t, k) < 0 || F(t, k) >= nv)
          throw InputError(path, "triangle " + std::to_string(t + 1) + " has vertex index " +
                                     std::to_string(F(t, k)) + " outside [0, " + std::to_string(nv) + ")");
  }

  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  points->SetNumberOfPoints(nv);
  for (vtkIdType i = 0; i < nv; ++i) points->SetPoint(i, V(i, 0), V(i, 1), V(i, 2));
  vtkNew<vtkIdTypeArray> offsets, connectivity;
  offsets->SetNumberOfTuples(nf + 1);
  connectivity->SetNumberOfTuples(3 * nf);
  for (vtkIdType t = 0; t < nf; ++t) {
    offsets->SetValue(t, 3 * t);
    for (int k = 0; k < 3; ++k) connectivity->SetValue(3 * t + k, F(t, k));
  }
  offsets->SetValue(nf, 3 * nf);
  vtkNew<vtkCellArray> polys;
  polys->SetData(offsets, connectivity);
  vtkNew<vtkPolyData> mesh;
  mesh->SetPoints(points);
  mesh->SetPolys(polys);
  vtkPointData* pd = mesh->GetPointData();
  for (const PointArray& a : point_data) {
    auto arr = vtkSmartPointer<vtkDoubleArray>::New();
    arr->SetName(a.name.c_str());
    arr->SetNumberOfComponents(1);
    arr->SetNumberOfTuples(nv);
    std::copy(a.values.data(), a.values.data() + nv, arr->GetPointer(0));
    pd->AddArray(arr);
  }
  if (!point_data.empty()) pd->SetActiveScalars(point_data.front().name.c_str());
  vtkNew<vtkXMLPolyDataWriter> writer;
  writer->SetInputData(mesh);
  detail::write_vtk_atomic(writer, path, ".vtp");
}

}  // namespace lidef
