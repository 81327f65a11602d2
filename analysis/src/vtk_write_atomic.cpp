// See vtk_write_atomic.h.
#include "vtk_write_atomic.h"

#include <vtkCommand.h>
#include <vtkExecutive.h>
#include <vtkNew.h>

#include <algorithm>
#include <filesystem>

#include "lidef/atomic_file.h"
#include "lidef/errors.h"

namespace lidef::detail {
namespace {

namespace fs = std::filesystem;

// Collects VTK's error messages instead of letting it print them, so that a failure becomes one InputError.
class VtkErrorCatcher : public vtkCommand {
 public:
  static VtkErrorCatcher* New() { return new VtkErrorCatcher; }
  void Execute(vtkObject*, unsigned long, void* data) override {
    if (data && message.empty()) message = static_cast<const char*>(data);
  }
  std::string message;
};

// Writes `tmp` with the configured writer; InputError(path, VTK's message) on failure.
void write_vtk_file(vtkXMLWriter* writer, const std::string& path, const std::string& tmp) {
  vtkNew<VtkErrorCatcher> errors;
  writer->AddObserver(vtkCommand::ErrorEvent, errors);
  writer->AddObserver(vtkCommand::WarningEvent, errors);
  // A failed write is also reported by the pipeline's executive; without an observer VTK prints it to stderr.
  writer->GetExecutive()->AddObserver(vtkCommand::ErrorEvent, errors);
  writer->SetFileName(tmp.c_str());
  writer->SetDataModeToAppended();
  writer->EncodeAppendedDataOff();
  writer->SetCompressorTypeToZLib();
  writer->SetHeaderTypeToUInt64();
  const int ok = writer->Write();
  if (ok != 1 || writer->GetErrorCode() != 0) {
    // VTK's message is "ERROR: In <source>, line N\n<Class> (0x...): <text>"; keep <text>, on one line.
    std::string why = errors->message;
    if (why.rfind("ERROR: In ", 0) == 0 && why.find('\n') != std::string::npos)
      why.erase(0, why.find('\n') + 1);
    if (const size_t obj = why.find("): "); obj != std::string::npos) why.erase(0, obj + 3);
    while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
    std::replace(why.begin(), why.end(), '\n', ' ');
    throw InputError(path, "cannot write VTK file" + (why.empty() ? std::string() : ": " + why));
  }
}

}  // namespace

void write_vtk_atomic(vtkXMLWriter* writer, const std::string& path, const char* ext) {
  // The commonest failure, said plainly (VTK would only report that it cannot open the temporary).
  const fs::path folder = fs::path(path).parent_path();
  std::error_code ec;
  if (!folder.empty() && !fs::is_directory(folder, ec))
    throw InputError(path, "cannot write: folder " + folder.string() + " does not exist");
  write_file_atomic_via_path(path, ext, [&](const std::string& tmp) { write_vtk_file(writer, path, tmp); });
}

}  // namespace lidef::detail
