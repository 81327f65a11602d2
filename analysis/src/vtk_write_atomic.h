// Private to lidef_analysis (includes VTK): writes a configured VTK XML writer's output atomically.
#pragma once
#include <vtkXMLWriter.h>

#include <string>

namespace lidef::detail {

// Configures `writer` (zlib-compressed appended raw binary, 64-bit headers), writes `path`.tmp.<pid><ext> and
// renames it over `path`. VTK's error and warning messages (of the writer and its executive) are caught
// instead of printed; on failure the temporary is removed and InputError(path, <VTK's message, one line>) is
// thrown. A missing destination folder is reported as such.
void write_vtk_atomic(vtkXMLWriter* writer, const std::string& path, const char* ext);

}  // namespace lidef::detail
