#include "lidef/analysis/explorer_export.h"

#include <vtkFloatArray.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkXMLImageDataWriter.h>

#include <algorithm>

#include "vtk_write_atomic.h"

namespace lidef {
using detail::make_array;

void write_ball_fields_vti(const std::string& path, const BallFieldGrid& g) {
  vtkNew<vtkImageData> image;
  image->SetDimensions(g.n, g.n, g.n);
  image->SetOrigin(g.origin.x(), g.origin.y(), g.origin.z());
  image->SetSpacing(g.spacing, g.spacing, g.spacing);
  vtkPointData* pd = image->GetPointData();
  pd->AddArray(make_array<vtkFloatArray>("sigma1", g.sigma1));
  pd->AddArray(make_array<vtkFloatArray>("sigma2", g.sigma2));
  pd->AddArray(make_array<vtkFloatArray>("sigma3", g.sigma3));
  pd->AddArray(make_array<vtkFloatArray>("detJ", g.det_j));
  pd->AddArray(make_array<vtkUnsignedCharArray>("inside_ball", g.inside));
  pd->SetActiveScalars("sigma3");
  vtkNew<vtkXMLImageDataWriter> writer;
  writer->SetInputData(image);
  detail::write_vtk_atomic(writer, path, ".vti");
}

}  // namespace lidef
