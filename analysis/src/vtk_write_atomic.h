// Private to lidef_analysis (includes VTK): writes a configured VTK XML writer's output atomically, and
// builds the one-component point-data arrays the writers share.
#pragma once
#include <vtkSmartPointer.h>
#include <vtkXMLWriter.h>

#include <algorithm>
#include <string>
#include <vector>

namespace lidef::detail {

// Configures `writer` (zlib-compressed appended raw binary, 64-bit headers), writes `path`.tmp.<pid><ext> and
// renames it over `path`. VTK's error and warning messages (of the writer and its executive) are caught
// instead of printed; on failure the temporary is removed and InputError(path, <VTK's message, one line>) is
// thrown. A missing destination folder is reported as such.
void write_vtk_atomic(vtkXMLWriter* writer, const std::string& path, const char* ext);

// A one-component VTK array (vtkFloatArray, vtkUnsignedCharArray, ...) named `name` holding a copy of `v`.
template <class Array, class T>
vtkSmartPointer<Array> make_array(const char* name, const std::vector<T>& v) {
  auto a = vtkSmartPointer<Array>::New();
  a->SetName(name);
  a->SetNumberOfComponents(1);
  a->SetNumberOfTuples(static_cast<vtkIdType>(v.size()));
  std::copy(v.begin(), v.end(), a->GetPointer(0));
  return a;
}

}  // namespace lidef::detail
