#include "compare_view.h"

#include <QVTKOpenGLNativeWidget.h>
#include <vtkActor.h>
#include <vtkBillboardTextActor3D.h>
#include <vtkCamera.h>
#include <vtkDataArray.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkLookupTable.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkSmartPointer.h>
#include <vtkTextProperty.h>
#include <vtkXMLPolyDataReader.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "lidef/csv.h"
#include "lidef/errors.h"
#include "lidef/number_format.h"
#include "studio_common.h"

namespace lidef::studio {

namespace {

double number(const std::string& s) {
  if (s.empty()) return std::nan("");
  try {
    return std::stod(s);
  } catch (...) {
    return std::nan("");
  }
}

}  // namespace

std::vector<CompareEntry> read_compare_dir(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw InputError(dir, "not a folder (expected the --out folder of lidef compare)");
  const std::string path = (fs::path(dir) / "table.csv").string();
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot read (is this the --out folder of lidef compare?)");
  std::string line;
  if (!std::getline(in, line)) throw InputError(path, "empty file");
  const auto header = split_csv_line(line);
  auto col = [&](const char* name) {
    const auto it = std::find(header.begin(), header.end(), name);
    if (it == header.end()) throw InputError(path, std::string("no column \"") + name + "\"", 1);
    return static_cast<size_t>(it - header.begin());
  };
  const size_t c_method = col("method"), c_status = col("status"), c_time = col("time_s"),
               c_cert = col("certified"), c_ratio = col("time_ratio_to_lidef"),
               c_eiso = col("mean_e_iso_minus_6"), c_err = col("max_handle_error");
  std::vector<CompareEntry> rows;
  long n = 1;
  while (std::getline(in, line)) {
    ++n;
    if (line.empty()) continue;
    const auto f = split_csv_line(line);
    if (f.size() != header.size())
      throw InputError(
          path, std::to_string(f.size()) + " fields, the header has " + std::to_string(header.size()), n);
    CompareEntry e;
    e.method = f[c_method];
    e.status = f[c_status];
    e.certified = f[c_cert];
    e.time_s = number(f[c_time]);
    e.time_ratio = number(f[c_ratio]);
    e.mean_e_iso = number(f[c_eiso]);
    e.max_handle_error = number(f[c_err]);
    const fs::path vtp = fs::path(dir) / (e.method + ".vtp");
    if (e.status != "failed" && fs::exists(vtp, ec)) e.vtp = vtp.string();
    rows.push_back(e);
  }
  if (rows.empty()) throw InputError(path, "no methods in the table");
  return rows;
}

std::string build_compare_scene(vtkRenderer* ren, const std::vector<CompareEntry>& entries, double aspect) {
  std::vector<vtkSmartPointer<vtkPolyData>> meshes;
  double hi = 0;
  for (const CompareEntry& e : entries) {
    vtkSmartPointer<vtkPolyData> pd;
    if (!e.vtp.empty()) {
      auto r = vtkSmartPointer<vtkXMLPolyDataReader>::New();
      r->SetFileName(e.vtp.c_str());
      r->Update();
      if (r->GetOutput() && r->GetOutput()->GetNumberOfPoints() > 0) {
        pd = r->GetOutput();
        if (vtkDataArray* a = pd->GetPointData()->GetArray("E_iso_minus_6")) {
          // Shared scale up to the 98th percentile: one folded vertex must not wash out every other mesh.
          std::vector<double> v;
          for (vtkIdType i = 0; i < a->GetNumberOfTuples(); ++i)
            if (std::isfinite(a->GetTuple1(i))) v.push_back(a->GetTuple1(i));
          if (!v.empty()) {
            std::nth_element(v.begin(), v.begin() + static_cast<long>(0.98 * (v.size() - 1)), v.end());
            hi = std::max(hi, v[static_cast<size_t>(0.98 * (v.size() - 1))]);
          }
        }
      }
    }
    meshes.push_back(pd);
  }
  auto lut = vtkSmartPointer<vtkLookupTable>::New();
  heat_lut(lut, std::max(hi, 1e-3));
  lut->SetAboveRangeColor(0.45, 0.0, 0.0, 1);
  lut->UseAboveRangeColorOn();
  lut->Build();
  // Spacing from the widest mesh.
  double width = 0, ymax = -1e300;
  for (const auto& pd : meshes)
    if (pd) {
      const double* b = pd->GetBounds();
      width = std::max(width, b[1] - b[0]);
      ymax = std::max(ymax, b[3]);
    }
  const double step = 1.6 * std::max(width, 1e-6);
  double box[6] = {1e300, -1e300, 1e300, -1e300, 1e300, -1e300};  // of the meshes alone (not the labels)
  std::string caption = std::to_string(entries.size()) + " methods, E_iso - 6 on one scale (top 2% darkest):";
  for (size_t k = 0; k < entries.size(); ++k) {
    const CompareEntry& e = entries[k];
    std::string label = e.method + "\n";
    if (!meshes[k]) {
      label += e.status == "failed" ? "failed" : "no mesh";
    } else {
      label += format_g(e.time_s, 3) + " s";
      if (std::isfinite(e.time_ratio) && e.method != "lidef")
        label += " (" + format_g(e.time_ratio, 3) + "x lidef)";
      label += e.certified == "1"   ? "\ncertified"
               : e.certified == "0" ? "\nNOT certified"
                                    : "\nno certificate";
    }
    caption += " " + e.method;
    const double x = k * step;
    if (meshes[k]) {
      const double* b = meshes[k]->GetBounds();
      auto m = vtkSmartPointer<vtkPolyDataMapper>::New();
      m->SetInputData(meshes[k]);
      if (meshes[k]->GetPointData()->GetArray("E_iso_minus_6")) {
        m->SetScalarModeToUsePointFieldData();
        m->SelectColorArray("E_iso_minus_6");
        m->SetLookupTable(lut);
        m->UseLookupTableScalarRangeOn();
        m->ScalarVisibilityOn();
      } else {
        m->ScalarVisibilityOff();  // PWL(Tri): a surface map has no volumetric distortion
      }
      auto a = vtkSmartPointer<vtkActor>::New();
      a->SetMapper(m);
      a->GetProperty()->SetColor(0.75, 0.78, 0.85);
      a->SetPosition(x - 0.5 * (b[0] + b[1]), 0, 0);
      ren->AddActor(a);
      const double* ab = a->GetBounds();
      for (int i = 0; i < 3; ++i) {
        box[2 * i] = std::min(box[2 * i], ab[2 * i]);
        box[2 * i + 1] = std::max(box[2 * i + 1], ab[2 * i + 1]);
      }
    }
    auto t = vtkSmartPointer<vtkBillboardTextActor3D>::New();
    t->SetInput(label.c_str());
    t->SetPosition(x, ymax + 0.12 * step, 0);
    t->GetTextProperty()->SetFontSize(13);
    t->GetTextProperty()->SetJustificationToCentered();
    t->GetTextProperty()->SetColor(e.certified == "0" ? 0.8 : 0.1, 0.1, 0.1);
    ren->AddViewProp(t);
  }
  auto bar = vtkSmartPointer<vtkScalarBarActor>::New();
  bar->SetLookupTable(lut);
  bar->SetTitle("E_iso - 6");
  style_scalar_bar(bar, 0.8);
  ren->AddViewProp(bar);
  if (box[0] <= box[1]) {
    box[3] += 0.35 * step;  // room for the labels above the meshes
    // Parallel projection fitted to the row: ResetCamera fits a sphere, which leaves a wide row tiny.
    vtkCamera* cam = ren->GetActiveCamera();
    cam->ParallelProjectionOn();
    ren->ResetCamera(box);
    const double half_w = 0.5 * (box[1] - box[0]), half_h = 0.5 * (box[3] - box[2]);
    const double scale = 1.08 * std::max(half_h, half_w / (0.85 * std::max(aspect, 0.1)));
    cam->SetParallelScale(scale);
    // Keep the right 15% of the view for the colour bar.
    const double d = 0.075 * 2 * scale * aspect;
    double fp[3], pos[3];
    cam->GetFocalPoint(fp);
    cam->GetPosition(pos);
    cam->SetFocalPoint(fp[0] + d, fp[1], fp[2]);
    cam->SetPosition(pos[0] + d, pos[1], pos[2]);
  }
  return caption;
}

QVTKOpenGLNativeWidget* open_compare_widget(const std::string& dir, int multisamples, std::string* caption,
                                            int width, int height) {
  const std::vector<CompareEntry> entries = read_compare_dir(dir);
  auto* w = new QVTKOpenGLNativeWidget;
  w->setAttribute(Qt::WA_DeleteOnClose);
  w->setWindowTitle(QString::fromStdString("lidef-studio — comparison " + dir));
  auto win = vtkSmartPointer<vtkGenericOpenGLRenderWindow>::New();
  w->setRenderWindow(win);
  win->SetMultiSamples(multisamples);
  auto ren = vtkSmartPointer<vtkRenderer>::New();
  ren->SetBackground(1, 1, 1);
  ren->SetBackground2(0.86, 0.89, 0.94);
  ren->GradientBackgroundOn();
  win->AddRenderer(ren);
  const std::string c = build_compare_scene(ren, entries, static_cast<double>(width) / height);
  if (caption) *caption = c;
  w->resize(width, height);
  return w;
}

}  // namespace lidef::studio
