// The side-by-side picture of a `lidef compare` run (paper Fig. 3, Table 1; docs/compare.md): every method's
// deformed mesh in a row, coloured by E_iso − 6 on one shared scale, each labelled with its time and
// certificate. Reads only the files `lidef compare --out DIR` writes (table.csv, METHOD.vtp).
#pragma once
#include <string>
#include <vector>

class vtkRenderer;
class QVTKOpenGLNativeWidget;

namespace lidef::studio {

struct CompareEntry {
  std::string method, status, certified;  // certified: "1", "0" or "" (not applicable)
  double time_s = 0, time_ratio = 0, mean_e_iso = 0, max_handle_error = 0;
  std::string vtp;  // DIR/METHOD.vtp ("" when the method failed)
};

// Reads DIR/table.csv; throws InputError naming the file for a missing folder/file, a header without the
// needed columns, or a row with the wrong number of fields.
std::vector<CompareEntry> read_compare_dir(const std::string& dir);

// Fills `renderer` with the row of meshes (left to right in table order), their labels and one colour bar.
// Returns a caption ("N methods: ...").
// `aspect`: width / height of the view the row is fitted to.
std::string build_compare_scene(vtkRenderer* renderer, const std::vector<CompareEntry>& entries,
                                double aspect);

// A top-level window (titled with the folder, width x height) showing the comparison of DIR; throws
// InputError like read_compare_dir. `multisamples`: MSAA of its view.
QVTKOpenGLNativeWidget* open_compare_widget(const std::string& dir, int multisamples, std::string* caption,
                                            int width = 1400, int height = 600);

}  // namespace lidef::studio
