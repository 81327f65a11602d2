#include "scene.h"

#include <vtkActor.h>
#include <vtkCellArray.h>
#include <vtkColorTransferFunction.h>
#include <vtkCubeSource.h>
#include <vtkDoubleArray.h>
#include <vtkFloatArray.h>
#include <vtkGlyph3DMapper.h>
#include <vtkImageData.h>
#include <vtkLookupTable.h>
#include <vtkPiecewiseFunction.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderWindow.h>
#include <vtkRenderer.h>
#include <vtkScalarBarActor.h>
#include <vtkScalarsToColors.h>
#include <vtkSmartVolumeMapper.h>
#include <vtkSphereSource.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkUnsignedCharArray.h>
#include <vtkVariant.h>
#include <vtkVolume.h>
#include <vtkVolumeProperty.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <utility>

#include "lidef/errors.h"
#include "lidef/internal/enum_names.h"
#include "lidef/number_format.h"
#include "studio_common.h"

namespace lidef {
template <>
struct EnumNames<studio::View> {
  static constexpr const char* names[] = {"mesh", "sigma3", "lipschitz", "octree"};
};
}  // namespace lidef

namespace lidef::studio {

const char* to_string(View v) {
  return enum_name(v);
}

View view_from_string(const std::string& name) {
  if (const auto v = enum_from_name<View>(name)) return *v;
  throw InputError("--view", "unknown view \"" + name + "\" (mesh, sigma3, lipschitz, octree)");
}

Field shown_field(const ViewSettings& s) {
  switch (s.view) {
    case View::kMesh:
      if (s.distortion) return Field::kDistortion;
      return s.mesh_volume_ratio ? Field::kDetJ : Field::kEiso;
    case View::kSigma3:
      return s.distortion ? Field::kDistortion : Field::kSigma3;
    case View::kLipschitz:
      if (s.distortion) return Field::kDistortionBound;
      return s.lipschitz_margin ? Field::kMargin : Field::kL;
    default:
      return Field::kSigma3;
  }
}

bool has_range(const ViewSettings& s) {
  return s.view != View::kOctree;
}

namespace {
nlohmann::json ranges_json(const ViewSettings& s) {
  nlohmann::json j = nlohmann::json::object();
  for (int k = 0; k < kNumFields; ++k) j[to_string(static_cast<Field>(k))] = range_to_json(s.range[k]);
  return j;
}
}  // namespace

nlohmann::json settings_to_json(const ViewSettings& s) {
  return {{"view", to_string(s.view)},
          {"mesh_volume_ratio", s.mesh_volume_ratio},
          {"rest_cage", s.rest_cage},
          {"deformed_cage", s.deformed_cage},
          {"mesh_edges", s.mesh_edges},
          {"point_colors", s.point_colors},
          {"global_injectivity", s.global_injectivity},
          {"distortion", s.distortion},
          {"sigma_deformed_space", s.sigma_deformed_space},
          {"slice", {s.slice[0], s.slice[1], s.slice[2]}},
          {"slice_pos", {s.slice_pos[0], s.slice_pos[1], s.slice_pos[2]}},
          {"sigma_volume", s.sigma_volume},
          {"sigma_whole_cage", s.sigma_whole_cage},
          {"field_resolution", s.field_resolution},
          {"lipschitz_margin", s.lipschitz_margin},
          {"only_refined_or_failed", s.only_refined_or_failed},
          {"octree_by_status", s.octree_by_status},
          {"clip", s.clip},
          {"min_depth", s.min_depth},
          {"ranges", ranges_json(s)}};
}

void settings_from_json(const nlohmann::json& j, ViewSettings& s, const std::string& where) {
  if (!j.is_object()) throw InputError(where, "studio view settings must be a JSON object");
  try {
    auto get = [&](const char* key, auto& v) {
      if (j.contains(key)) j.at(key).get_to(v);
    };
    if (j.contains("view")) s.view = view_from_string(j.at("view").get<std::string>());
    get("mesh_volume_ratio", s.mesh_volume_ratio);
    get("rest_cage", s.rest_cage);
    get("deformed_cage", s.deformed_cage);
    get("mesh_edges", s.mesh_edges);
    get("point_colors", s.point_colors);
    get("global_injectivity", s.global_injectivity);
    get("distortion", s.distortion);
    get("sigma_deformed_space", s.sigma_deformed_space);
    for (int a = 0; a < 3; ++a) {
      if (j.contains("slice")) s.slice[a] = j.at("slice").at(a).get<bool>();
      if (j.contains("slice_pos"))
        s.slice_pos[a] = std::clamp(j.at("slice_pos").at(a).get<double>(), 0.0, 1.0);
    }
    get("sigma_volume", s.sigma_volume);
    get("sigma_whole_cage", s.sigma_whole_cage);
    get("field_resolution", s.field_resolution);
    s.field_resolution = std::clamp(s.field_resolution, 8, 256);
    get("lipschitz_margin", s.lipschitz_margin);
    get("only_refined_or_failed", s.only_refined_or_failed);
    get("octree_by_status", s.octree_by_status);
    get("clip", s.clip);
    s.clip = std::clamp(s.clip, 0.0, 1.0);
    get("min_depth", s.min_depth);
    if (j.contains("ranges")) {
      const auto& r = j.at("ranges");
      if (!r.is_object()) throw InputError(where, "studio view settings: \"ranges\" must be an object");
      for (int k = 0; k < kNumFields; ++k) {
        const char* name = to_string(static_cast<Field>(k));
        if (r.contains(name)) range_from_json(r.at(name), s.range[k], where);
      }
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(where, std::string("studio view settings: ") + e.what());
  }
}

ExtrasRequest extras_for(const ViewSettings& s) {
  ExtrasRequest r;
  r.leaves = s.view == View::kLipschitz || s.view == View::kOctree;
  r.field = s.view == View::kSigma3;
  // The mesh view's distortion colours need σ1/σ3 per vertex; its caption names the certified bound, which
  // comes with the leaves.
  r.mesh_distortion = s.view == View::kMesh && s.distortion;
  r.leaves = r.leaves || r.mesh_distortion;
  r.field_resolution = s.field_resolution;
  r.global_injectivity = s.global_injectivity;
  return r;
}

std::vector<unsigned char> point_cloud_colors(const PlyCloud& cloud) {
  int c[3] = {cloud.column("f_dc_0"), cloud.column("f_dc_1"), cloud.column("f_dc_2")};
  const bool dc = c[0] >= 0 && c[1] >= 0 && c[2] >= 0;
  if (!dc) {
    c[0] = cloud.column("red"), c[1] = cloud.column("green"), c[2] = cloud.column("blue");
    if (c[0] < 0 || c[1] < 0 || c[2] < 0) return {};
  }
  bool bytes = !dc;
  for (int k = 0; k < 3 && bytes; ++k) {
    const std::string& t = cloud.types[static_cast<size_t>(c[k])];
    bytes = t != "float" && t != "double" && t != "float32" && t != "float64";
  }
  const double kC0 = 0.28209479177387814;  // Y_0^0 = 1 / (2 sqrt(pi))
  const Eigen::Index n = cloud.values.rows();
  std::vector<unsigned char> rgb(3 * static_cast<size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      const double v = cloud.values(i, c[k]);
      const double unit = dc ? 0.5 + kC0 * v : bytes ? v / 255.0 : v;
      rgb[3 * static_cast<size_t>(i) + k] = static_cast<unsigned char>(
          std::lround(255 * std::clamp(std::isfinite(unit) ? unit : 0.0, 0.0, 1.0)));
    }
  return rgb;
}

std::vector<int> faces_near(const MatX3i& F, const std::vector<int>& faces, int rings) {
  std::vector<std::vector<int>> vertex_faces(static_cast<size_t>(F.size() ? F.maxCoeff() + 1 : 0));
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) vertex_faces[static_cast<size_t>(F(f, k))].push_back(f);
  std::set<int> in;
  std::vector<int> front;
  for (int f : faces)
    if (f >= 0 && f < F.rows() && in.insert(f).second) front.push_back(f);
  for (int r = 0; r < rings && !front.empty(); ++r) {
    std::vector<int> next;
    for (int f : front)
      for (int k = 0; k < 3; ++k)
        for (int g : vertex_faces[static_cast<size_t>(F(f, k))])
          if (in.insert(g).second) next.push_back(g);
    front.swap(next);
  }
  return {in.begin(), in.end()};
}

namespace {

template <class T>
using Ptr = vtkSmartPointer<T>;

// One vertex cell per point (a point cloud: cell k is point k, so a picked cell names its point).
vtkSmartPointer<vtkPolyData> point_set(const MatX3d& V) {
  auto pts = vtkSmartPointer<vtkPoints>::New();
  pts->SetNumberOfPoints(V.rows());
  auto verts = vtkSmartPointer<vtkCellArray>::New();
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    pts->SetPoint(i, V(i, 0), V(i, 1), V(i, 2));
    const vtkIdType id = i;
    verts->InsertNextCell(1, &id);
  }
  auto pd = vtkSmartPointer<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetVerts(verts);
  return pd;
}

// Polygons on points, with optional point scalars.
Ptr<vtkPolyData> polydata(vtkPoints* pts, vtkCellArray* polys, vtkDataArray* scalars = nullptr) {
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetPolys(polys);
  if (scalars) pd->GetPointData()->SetScalars(scalars);
  return pd;
}

vtkSmartPointer<vtkPolyData> wireframe(const MatX3d& V, const MatX3i& F) {
  auto pts = Ptr<vtkPoints>::New();
  pts->SetNumberOfPoints(V.rows());
  for (Eigen::Index i = 0; i < V.rows(); ++i) pts->SetPoint(i, V(i, 0), V(i, 1), V(i, 2));
  auto cells = Ptr<vtkCellArray>::New();
  for (Eigen::Index t = 0; t < F.rows(); ++t) {
    const vtkIdType ids[3] = {F(t, 0), F(t, 1), F(t, 2)};
    cells->InsertNextCell(3, ids);
  }
  return polydata(pts, cells);
}

}  // namespace

void style_scalar_bar(vtkScalarBarActor* bar, double height) {
  bar->SetMaximumWidthInPixels(90);
  bar->SetNumberOfLabels(5);
  bar->SetPosition(0.88, 0.1);
  bar->SetHeight(height);
  bar->SetWidth(0.1);
  bar->GetTitleTextProperty()->SetColor(0.1, 0.1, 0.1);
  bar->GetLabelTextProperty()->SetColor(0.1, 0.1, 0.1);
  bar->GetTitleTextProperty()->SetFontSize(14);
  bar->GetLabelTextProperty()->SetFontSize(12);
  bar->UnconstrainedFontSizeOn();
}

void heat_lut(vtkLookupTable* lut, double hi) {
  lut->SetNumberOfTableValues(256);
  lut->SetTableRange(0, std::max(hi, 1e-6));
  for (int i = 0; i < 256; ++i) {
    const double t = i / 255.0;
    lut->SetTableValue(i, 1.0 - 0.25 * t, 1.0 - 0.95 * t, 1.0 - 0.95 * t, 1.0);
  }
  lut->SetNanColor(0.2, 0.2, 0.2, 1.0);
  lut->SetUseAboveRangeColor(false);
}

void sigma3_colors(vtkColorTransferFunction* ctf, double lo, double hi) {
  ctf->RemoveAllPoints();
  hi = std::max(hi, lo + 1e-9);
  if (lo < 0) {
    ctf->AddRGBPoint(lo, 0.8, 0.0, 0.0);
    ctf->AddRGBPoint(0.0, 1.0, 0.5, 0.5);
    lo = 0;
  }
  for (int i = 0; i <= 8; ++i) {
    double c[3];
    viridis(i / 8.0, c);
    ctf->AddRGBPoint(lo + (hi - lo) * i / 8.0, c[0], c[1], c[2]);
  }
  ctf->ClampingOn();
}

struct Scene::Impl {
  vtkRenderer* ren;
  Ptr<vtkPolyData> mesh = Ptr<vtkPolyData>::New();
  Ptr<vtkActor> mesh_actor = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> mesh_mapper = Ptr<vtkPolyDataMapper>::New();
  Ptr<vtkLookupTable> mesh_lut = Ptr<vtkLookupTable>::New();
  Ptr<vtkActor> rest_cage = Ptr<vtkActor>::New(), def_cage = Ptr<vtkActor>::New();
  Ptr<vtkPolyData> rest_cage_pd, def_cage_pd;
  Ptr<vtkActor> images = Ptr<vtkActor>::New();  // handle images f(p): small black spheres
  Ptr<vtkGlyph3DMapper> images_mapper = Ptr<vtkGlyph3DMapper>::New();
  Ptr<vtkSphereSource> image_sphere = Ptr<vtkSphereSource>::New();
  Ptr<vtkActor> context_mesh = Ptr<vtkActor>::New();  // faint mesh in the σ3/leaf views
  Ptr<vtkPolyDataMapper> context_mapper = Ptr<vtkPolyDataMapper>::New();
  Ptr<vtkPolyData> rest_mesh;  // the model's mesh in rest space (context of the rest-space views)
  // σ3 view: the mesh surface where it crosses the slices (the certified domain's boundary, domain "mesh").
  Ptr<vtkActor> outline = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> outline_mapper = Ptr<vtkPolyDataMapper>::New();
  DomainKind domain = DomainKind::kMesh;
  // σ3 view.
  Ptr<vtkActor> slices = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> slices_mapper = Ptr<vtkPolyDataMapper>::New();
  Ptr<vtkColorTransferFunction> sigma_colors = Ptr<vtkColorTransferFunction>::New();
  Ptr<vtkVolume> volume = Ptr<vtkVolume>::New();
  Ptr<vtkSmartVolumeMapper> volume_mapper = Ptr<vtkSmartVolumeMapper>::New();
  Ptr<vtkImageData> volume_image;
  long volume_version = -2;
  // Leaves (Lipschitz and octree views).
  Ptr<vtkActor> leaves = Ptr<vtkActor>::New();
  Ptr<vtkGlyph3DMapper> leaves_mapper = Ptr<vtkGlyph3DMapper>::New();
  // Lipschitz view: outlines of the shown leaves that were refined (black) or failed (red).
  Ptr<vtkActor> marks = Ptr<vtkActor>::New();
  Ptr<vtkGlyph3DMapper> marks_mapper = Ptr<vtkGlyph3DMapper>::New();
  Ptr<vtkLookupTable> marks_lut = Ptr<vtkLookupTable>::New();
  Ptr<vtkLookupTable> leaves_lut = Ptr<vtkLookupTable>::New();
  Ptr<vtkScalarBarActor> bar = Ptr<vtkScalarBarActor>::New();
  Ptr<vtkTextActor> text = Ptr<vtkTextActor>::New();
  std::pair<double, double> range{0, 0};  // of the colour bar shown last
  bool bar_in_strip = false;              // the bar has its own renderer (a strip right of the model)
  long model_version = -1;
  std::string caption, model_name;
  // Handles not at their targets: red lines from the image to the target (mesh view).
  Ptr<vtkActor> misses = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> misses_mapper = Ptr<vtkPolyDataMapper>::New();
  double handle_tolerance = 1e-3;
  int unreached = 0;
  // The picked point.
  Ptr<vtkActor> picked = Ptr<vtkActor>::New();
  Ptr<vtkSphereSource> picked_sphere = Ptr<vtkSphereSource>::New();
  bool picked_valid = false;
  Vec3 picked_rest = Vec3::Zero(), picked_image = Vec3::Zero();
  void update_picked(const SessionFrame& f, const ViewSettings& s);
  // A point cloud (the model's mesh has no faces): drawn as points, with the file's colours when given.
  bool points = false;
  std::vector<unsigned char> point_rgb;
  bool point_rgb_shown = false;  // the last mesh view showed point_rgb instead of a field
  // Global injectivity: an overlap's neighbourhoods (red, on the deformed mesh) and a marker at its point.
  Ptr<vtkActor> overlap = Ptr<vtkActor>::New();
  Ptr<vtkPolyDataMapper> overlap_mapper = Ptr<vtkPolyDataMapper>::New();
  Ptr<vtkActor> overlap_marker = Ptr<vtkActor>::New();
  Ptr<vtkSphereSource> overlap_sphere = Ptr<vtkSphereSource>::New();
  std::vector<int> overlap_faces;               // drawn in the last shown frame
  std::vector<int> overlap_list;                // of overlap_key
  Ptr<vtkCellArray> overlap_cells;              // of overlap_key
  std::array<long, 3> overlap_key{-1, -1, -1};  // model version, face a, face b of overlap_faces
  bool marker_shown = false;
  Vec3 marker_at = Vec3::Zero();
  // The overlap is drawn in a layer over the model (same camera and viewport): the two parts of an overlap
  // meet where the shape passes through itself, often inside it or behind it.
  Ptr<vtkRenderer> overlay;
  void attach_overlay();
  void update_overlap(const SessionFrame& f, const ViewSettings& s);
  // What the leaf glyphs were last built from (show_leaves_view rebuilds them only when this changes).
  std::shared_ptr<const Certificate> glyph_leaves;
  std::string glyph_settings;
  const char* glyph_title = "";
  std::pair<double, double> glyph_range{0, 0};
  std::pair<long, long> glyph_counts{0, 0};  // leaves shown, failed
  bool glyph_marks = false;

  // Stages of Scene::show.
  void hide_all();
  void show_no_model(const SessionFrame& f);
  void adopt_model(const SessionFrame& f);
  void update_mesh(const SessionFrame& f, const ViewSettings& s);
  void update_handle_images(const SessionFrame& f, const ViewSettings& s);
  std::string show_mesh_view(const SessionFrame& f, const ViewSettings& s);
  std::string show_sigma3_view(const SessionFrame& f, const ViewSettings& s);
  void show_sigma3_volume(const SessionFrame& f, const ViewSettings& s, double lo, double hi);
  std::string show_leaves_view(const SessionFrame& f, const ViewSettings& s);
  const char* color_leaves(const Certificate& c, const ViewSettings& s, double lo, double hi);
  void show_bar(vtkScalarsToColors* colors, const char* title);
  void set_caption(const std::string& what, const SessionFrame& f, const ViewSettings& s);
  void set_caption_text(const std::string& c);  // wrapped to the view's width
};

Scene::Scene(vtkRenderer* renderer, vtkRenderer* bar_renderer) : impl_(std::make_unique<Impl>()) {
  Impl& I = *impl_;
  I.ren = renderer;
  I.mesh_mapper->SetInputData(I.mesh);
  I.mesh_mapper->SetLookupTable(I.mesh_lut);
  I.mesh_mapper->SetScalarModeToUsePointData();
  I.mesh_mapper->SetColorModeToMapScalars();
  I.mesh_actor->SetMapper(I.mesh_mapper);
  I.mesh_actor->GetProperty()->SetInterpolationToPhong();
  I.context_mapper->ScalarVisibilityOff();
  I.context_mesh->SetMapper(I.context_mapper);
  I.context_mesh->GetProperty()->SetColor(0.85, 0.85, 0.85);
  I.context_mesh->GetProperty()->SetOpacity(0.15);
  I.context_mesh->PickableOff();
  for (vtkActor* a : {I.rest_cage.Get(), I.def_cage.Get()}) {
    a->SetMapper(Ptr<vtkPolyDataMapper>::New());
    a->GetProperty()->SetRepresentationToWireframe();
    a->GetProperty()->LightingOff();
    a->PickableOff();
  }
  I.rest_cage->GetProperty()->SetColor(0.55, 0.55, 0.55);
  I.def_cage->GetProperty()->SetColor(0.1, 0.2, 0.6);
  I.image_sphere->SetThetaResolution(16);
  I.image_sphere->SetPhiResolution(12);
  I.images_mapper->SetSourceConnection(I.image_sphere->GetOutputPort());
  I.images_mapper->ScalingOff();
  I.images->SetMapper(I.images_mapper);
  I.images->GetProperty()->SetColor(0, 0, 0);
  I.images->PickableOff();
  I.slices_mapper->SetLookupTable(I.sigma_colors);
  I.slices_mapper->SetScalarModeToUsePointData();
  I.slices->SetMapper(I.slices_mapper);
  I.slices->PickableOff();
  I.slices->GetProperty()->SetAmbient(0.5);  // colours read true from any side
  I.slices->GetProperty()->SetDiffuse(0.5);
  I.volume->SetMapper(I.volume_mapper);
  I.volume->PickableOff();
  auto cube = Ptr<vtkCubeSource>::New();
  I.leaves_mapper->SetSourceConnection(cube->GetOutputPort());
  I.leaves_mapper->SetScaleArray("side");
  I.leaves_mapper->SetScaleModeToScaleByMagnitude();
  I.leaves_mapper->SetLookupTable(I.leaves_lut);
  I.leaves_mapper->SetScalarModeToUsePointFieldData();
  I.leaves->SetMapper(I.leaves_mapper);
  I.leaves->PickableOff();
  I.marks_mapper->SetSourceConnection(cube->GetOutputPort());
  I.marks_mapper->SetScaleArray("side");
  I.marks_mapper->SetScaleModeToScaleByMagnitude();
  I.marks_lut->SetNumberOfTableValues(2);
  I.marks_lut->SetTableRange(0, 1);
  I.marks_lut->SetTableValue(0, 0.05, 0.05, 0.05, 1);
  I.marks_lut->SetTableValue(1, 0.9, 0.0, 0.0, 1);
  I.marks_mapper->SetLookupTable(I.marks_lut);
  I.marks_mapper->SetScalarModeToUsePointFieldData();
  I.marks_mapper->SelectColorArray("failed");
  I.marks_mapper->SetScalarRange(0, 1);
  I.marks->SetMapper(I.marks_mapper);
  I.marks->GetProperty()->SetRepresentationToWireframe();
  I.marks->GetProperty()->LightingOff();
  I.marks->GetProperty()->SetLineWidth(1.5);
  I.outline->SetMapper(I.outline_mapper);
  I.outline->GetProperty()->SetColor(0.05, 0.05, 0.05);
  I.outline->GetProperty()->SetLineWidth(2);
  I.outline->GetProperty()->LightingOff();
  I.outline->PickableOff();
  I.marks->PickableOff();
  style_scalar_bar(I.bar, 0.8);
  I.bar_in_strip = bar_renderer != nullptr;
  if (bar_renderer) {  // the bar fills its own viewport
    I.bar->SetPosition(0.08, 0.1);
    I.bar->SetWidth(0.8);
    I.bar->SetMaximumWidthInPixels(110);
  }
  I.text->GetTextProperty()->SetColor(0.1, 0.1, 0.1);
  I.text->GetTextProperty()->SetFontSize(15);
  I.text->SetPosition(10, 10);
  I.text->GetPositionCoordinate()->SetCoordinateSystemToNormalizedViewport();
  // Anchored by its top edge just below the viewport's top: a caption of one or two lines stays whole
  // (anchored by its bottom at 0.94, the second line pushed the first out of the view).
  I.text->GetTextProperty()->SetVerticalJustificationToTop();
  I.text->SetPosition(0.01, 0.985);
  I.misses->SetMapper(I.misses_mapper);
  I.misses->GetProperty()->SetColor(0.85, 0.1, 0.1);
  I.misses->GetProperty()->SetLineWidth(3);
  I.misses->GetProperty()->LightingOff();
  I.misses->PickableOff();
  I.picked_sphere->SetThetaResolution(16);
  I.picked_sphere->SetPhiResolution(12);
  auto picked_mapper = Ptr<vtkPolyDataMapper>::New();
  picked_mapper->SetInputConnection(I.picked_sphere->GetOutputPort());
  I.picked->SetMapper(picked_mapper);
  I.picked->GetProperty()->SetColor(1.0, 0.55, 0.0);
  I.picked->PickableOff();
  I.mesh_actor->GetProperty()->SetEdgeColor(0.25, 0.25, 0.25);
  // An overlap: pure red without shading (no heat-map colour is), drawn over the coincident mesh faces.
  vtkMapper::SetResolveCoincidentTopologyToPolygonOffset();
  I.overlap_mapper->ScalarVisibilityOff();
  I.overlap_mapper->SetRelativeCoincidentTopologyPolygonOffsetParameters(-2, -4);
  I.overlap->SetMapper(I.overlap_mapper);
  I.overlap->GetProperty()->SetColor(1.0, 0.0, 0.0);
  I.overlap->GetProperty()->LightingOff();
  I.overlap->PickableOff();
  I.overlap_sphere->SetThetaResolution(20);
  I.overlap_sphere->SetPhiResolution(14);
  auto marker_mapper = Ptr<vtkPolyDataMapper>::New();
  marker_mapper->SetInputConnection(I.overlap_sphere->GetOutputPort());
  I.overlap_marker->SetMapper(marker_mapper);
  I.overlap_marker->GetProperty()->SetColor(1.0, 0.85, 0.0);
  I.overlap_marker->PickableOff();
  for (vtkProp* p : std::initializer_list<vtkProp*>{I.mesh_actor, I.context_mesh, I.rest_cage, I.def_cage,
                                                    I.images, I.slices, I.volume, I.leaves, I.marks,
                                                    I.outline, I.misses, I.picked, I.text}) {
    p->VisibilityOff();
    renderer->AddViewProp(p);
  }
  I.overlay = Ptr<vtkRenderer>::New();
  I.overlay->SetLayer(1);
  I.overlay->InteractiveOff();
  I.overlay->PreserveDepthBufferOff();
  for (vtkProp* p : std::initializer_list<vtkProp*>{I.overlap, I.overlap_marker}) {
    p->VisibilityOff();
    I.overlay->AddViewProp(p);
  }
  I.bar->VisibilityOff();
  (bar_renderer ? bar_renderer : renderer)->AddViewProp(I.bar);
  I.text->VisibilityOn();
}

Scene::~Scene() = default;
vtkActor* Scene::mesh_actor() const {
  return impl_->mesh_actor;
}
vtkPolyData* Scene::mesh_data() const {
  return impl_->mesh;
}
std::string Scene::caption() const {
  return impl_->caption;
}
std::pair<double, double> Scene::shown_range() const {
  return impl_->range;
}
void Scene::set_certified_domain(DomainKind d) {
  impl_->domain = d;
}
void Scene::set_model_name(const std::string& name) {
  impl_->model_name = name;
}
void Scene::set_handle_tolerance(double fraction) {
  impl_->handle_tolerance = fraction;
}
int Scene::unreached_handles() const {
  return impl_->unreached;
}
void Scene::set_picked(bool valid, const Vec3& rest, const Vec3& image) {
  impl_->picked_valid = valid;
  impl_->picked_rest = rest;
  impl_->picked_image = image;
}
void Scene::set_point_colors(std::vector<unsigned char> rgb) {
  impl_->point_rgb = std::move(rgb);
}
const std::vector<int>& Scene::overlap_faces() const {
  return impl_->overlap_faces;
}
bool Scene::overlap_marker_shown() const {
  return impl_->marker_shown;
}
Vec3 Scene::overlap_marker_at() const {
  return impl_->marker_at;
}
vtkActor* Scene::leaves_actor() const {
  return impl_->leaves;
}
vtkActor* Scene::slices_actor() const {
  return impl_->slices;
}

namespace {

// Quads of one grid plane (axis a at index k) whose 4 corners are inside the cage, with σ3 at the points;
// `deformed` places the points at f(p).
// The σ3 view's quantity at grid point n: σ3, or σ1/σ3 (NaN where σ3 <= 0: no finite distortion there).
float grid_value(const FieldGrid& g, size_t n, bool distortion) {
  if (!distortion) return g.sigma3[n];
  return g.sigma3[n] > 0 ? g.sigma1[n] / g.sigma3[n] : std::numeric_limits<float>::quiet_NaN();
}

// The σ3 view's colours: viridis with low σ3 (near-degenerate) dark; red below 0. For σ1/σ3 reversed, so high
// distortion is dark.
void field_colors(vtkColorTransferFunction* ctf, double lo, double hi, bool distortion) {
  if (!distortion) return sigma3_colors(ctf, lo, hi);
  ctf->RemoveAllPoints();
  hi = std::max(hi, lo + 1e-9);
  for (int i = 0; i <= 8; ++i) {
    double c[3];
    viridis(1 - i / 8.0, c);
    ctf->AddRGBPoint(lo + (hi - lo) * i / 8.0, c[0], c[1], c[2]);
  }
  ctf->SetNanColor(0.8, 0.0, 0.0);  // σ3 <= 0
  ctf->ClampingOn();
}

Ptr<vtkPolyData> slice_polydata(const FieldGrid& g, const std::vector<float>* deformed, int a, int k,
                                bool whole_cage, bool distortion) {
  const int b = (a + 1) % 3, c = (a + 2) % 3;
  auto index = [&](int i, int j) {
    int ijk[3];
    ijk[a] = k;
    ijk[b] = i;
    ijk[c] = j;
    return static_cast<long>(ijk[0]) + g.dims[0] * (static_cast<long>(ijk[1]) + g.dims[1] * ijk[2]);
  };
  auto pts = Ptr<vtkPoints>::New();
  auto sig = Ptr<vtkFloatArray>::New();
  sig->SetName("sigma3");
  auto quads = Ptr<vtkCellArray>::New();
  std::vector<vtkIdType> id(static_cast<size_t>(g.dims[b]) * g.dims[c], -1);
  for (int i = 0; i < g.dims[b]; ++i)
    for (int j = 0; j < g.dims[c]; ++j) {
      const long n = index(i, j);
      if (!g.inside_cage[static_cast<size_t>(n)] || std::isnan(g.sigma3[static_cast<size_t>(n)])) continue;
      if (!whole_cage && !g.inside_sampled[static_cast<size_t>(n)]) continue;
      double p[3];
      if (deformed) {
        for (int d = 0; d < 3; ++d) p[d] = (*deformed)[3 * static_cast<size_t>(n) + d];
        if (std::isnan(p[0])) continue;
      } else {
        const long ix = n % g.dims[0], iy = (n / g.dims[0]) % g.dims[1],
                   iz = n / (static_cast<long>(g.dims[0]) * g.dims[1]);
        p[0] = g.origin.x() + g.spacing * ix;
        p[1] = g.origin.y() + g.spacing * iy;
        p[2] = g.origin.z() + g.spacing * iz;
      }
      id[static_cast<size_t>(i) * g.dims[c] + j] = pts->InsertNextPoint(p);
      sig->InsertNextValue(grid_value(g, static_cast<size_t>(n), distortion));
    }
  for (int i = 0; i + 1 < g.dims[b]; ++i)
    for (int j = 0; j + 1 < g.dims[c]; ++j) {
      const vtkIdType q[4] = {
          id[static_cast<size_t>(i) * g.dims[c] + j], id[static_cast<size_t>(i + 1) * g.dims[c] + j],
          id[static_cast<size_t>(i + 1) * g.dims[c] + j + 1], id[static_cast<size_t>(i) * g.dims[c] + j + 1]};
      if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[3] < 0) continue;
      quads->InsertNextCell(4, q);
    }
  return polydata(pts, quads, sig);
}

// Lowest and highest σ3 (or σ1/σ3) of the grid points a view shows (inside the cage, inside the voxels unless
// the whole cage is asked for); 0, 0 when there are none.
std::pair<double, double> field_range(const FieldGrid& g, const ViewSettings& s) {
  std::vector<double> v;
  for (size_t i = 0; i < g.sigma3.size(); ++i)
    if (g.inside_cage[i] && (s.sigma_whole_cage || g.inside_sampled[i]))
      v.push_back(grid_value(g, i, s.distortion));
  return color_range(v, s.range[static_cast<int>(shown_field(s))]);
}

// The chosen grid planes appended into one polydata with σ3 at the points.
Ptr<vtkPolyData> sigma3_slices(const SessionFrame& f, const ViewSettings& s) {
  const FieldGrid& g = *f.field;
  auto all_pts = Ptr<vtkPoints>::New();
  auto all_sig = Ptr<vtkFloatArray>::New();
  all_sig->SetName(s.distortion ? "sigma1/sigma3" : "sigma3");
  auto all_quads = Ptr<vtkCellArray>::New();
  for (int a = 0; a < 3; ++a) {
    if (!s.slice[a]) continue;
    const int k =
        std::clamp(static_cast<int>(std::lround(s.slice_pos[a] * (g.dims[a] - 1))), 0, g.dims[a] - 1);
    auto pd = slice_polydata(g, s.sigma_deformed_space ? f.field_deformed.get() : nullptr, a, k,
                             s.sigma_whole_cage, s.distortion);
    const vtkIdType off = all_pts->GetNumberOfPoints();
    for (vtkIdType i = 0; i < pd->GetNumberOfPoints(); ++i) {
      all_pts->InsertNextPoint(pd->GetPoint(i));
      all_sig->InsertNextValue(static_cast<vtkFloatArray*>(pd->GetPointData()->GetScalars())->GetValue(i));
    }
    vtkCellArray* q = pd->GetPolys();
    q->InitTraversal();
    vtkIdType n;
    const vtkIdType* ids;
    while (q->GetNextCell(n, ids)) {
      vtkIdType shifted[4];
      for (int e = 0; e < 4; ++e) shifted[e] = ids[e] + off;
      all_quads->InsertNextCell(4, shifted);
    }
  }
  return polydata(all_pts, all_quads, all_sig);
}

}  // namespace

bool leaf_shown(const CertLeaf& l, const Model& model, const ViewSettings& s) {
  const Vec3 ext = model.cage.bbox_max - model.cage.bbox_min;
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (ext(a) > ext(axis)) axis = a;
  const double cut = model.cage.bbox_min(axis) + s.clip * ext(axis);
  if (l.center(axis) > cut || l.depth < s.min_depth) return false;
  return !(s.view == View::kLipschitz && s.only_refined_or_failed && l.depth == 0 && l.certified);
}

namespace {

// The leaves a Lipschitz/octree view shows, as glyph points (cubes of side `side` coloured by `value`), and
// the outlines of the refined or failed ones (Lipschitz view).
struct LeafGlyphs {
  Ptr<vtkPoints> pts = Ptr<vtkPoints>::New();
  Ptr<vtkDoubleArray> side = Ptr<vtkDoubleArray>::New();
  Ptr<vtkDoubleArray> value = Ptr<vtkDoubleArray>::New();
  Ptr<vtkPoints> mark_pts = Ptr<vtkPoints>::New();
  Ptr<vtkDoubleArray> mark_side = Ptr<vtkDoubleArray>::New();
  Ptr<vtkDoubleArray> mark_failed = Ptr<vtkDoubleArray>::New();
  long shown = 0, failed = 0;
  std::vector<double> finite;  // the finite values shown (colour range)
};

// Leaves in front of the clip plane across the longest axis of the cage's box (so the inside shows).
LeafGlyphs leaf_glyphs(const Certificate& c, const Model& model, const ViewSettings& s) {
  const bool lip = s.view == View::kLipschitz;
  LeafGlyphs L;
  L.side->SetName("side");
  L.value->SetName("value");
  L.mark_side->SetName("side");
  L.mark_failed->SetName("failed");
  for (const CertLeaf& l : c.leaves) {
    if (!l.certified) ++L.failed;
    if (!leaf_shown(l, model, s)) continue;
    double x;
    // A bound of +inf (L, σ1/σ3) is drawn above the range; a margin of -inf below it.
    const bool upper = lip && (s.distortion || !s.lipschitz_margin);
    if (lip && s.distortion)
      x = l.distortion_upper;
    else if (lip)
      x = s.lipschitz_margin ? l.margin : l.L;
    else
      x = s.octree_by_status ? (l.certified ? 1 : 0) : l.depth;
    if (!std::isfinite(x)) x = upper ? 1e300 : -1e300;
    L.pts->InsertNextPoint(l.center.x(), l.center.y(), l.center.z());
    L.side->InsertNextValue(l.side * kLeafDrawnSide);  // a small gap shows the cells
    if (lip && (l.depth > 0 || !l.certified)) {
      L.mark_pts->InsertNextPoint(l.center.x(), l.center.y(), l.center.z());
      L.mark_side->InsertNextValue(l.side);
      L.mark_failed->InsertNextValue(l.certified ? 0 : 1);
    }
    L.value->InsertNextValue(x);
    if (std::abs(x) < 1e299) L.finite.push_back(x);
    ++L.shown;
  }
  return L;
}

}  // namespace

namespace {
struct LeafCounts {
  long shown, failed;
};
// The settings the leaf glyphs depend on (view, leaf filters, colouring and its range).
std::string glyph_key(const ViewSettings& s) {
  return nlohmann::json{
      {"view", to_string(s.view)},    {"margin", s.lipschitz_margin},
      {"distortion", s.distortion},   {"refined", s.only_refined_or_failed},
      {"status", s.octree_by_status}, {"clip", s.clip},
      {"min_depth", s.min_depth},     {"range", range_to_json(s.range[static_cast<int>(shown_field(s))])}}
      .dump();
}
}  // namespace

void Scene::Impl::hide_all() {
  for (vtkProp* p :
       std::initializer_list<vtkProp*>{mesh_actor, context_mesh, rest_cage, def_cage, images, slices, volume,
                                       leaves, marks, outline, misses, picked, overlap, overlap_marker, bar})
    p->VisibilityOff();
  overlap_faces.clear();
  marker_shown = false;
  unreached = 0;
  bar->SetNumberOfLabels(5);
  range = {0, 0};
}

void Scene::Impl::show_no_model(const SessionFrame& f) {
  set_caption_text(f.status.empty() ? "no model: File > Open (a model folder or a scenario)" : f.status);
}

// Polydata that change with the model only (mesh and cage connectivity, rest-space cage and mesh).
void Scene::Impl::adopt_model(const SessionFrame& f) {
  if (model_version == f.model_version) return;
  const Model& model = *f.model;
  model_version = f.model_version;
  points = model.mesh.F.rows() == 0;
  auto pd = points ? point_set(f.mesh_V) : wireframe(f.mesh_V, model.mesh.F);
  mesh->SetPoints(pd->GetPoints());
  mesh->SetPolys(points ? Ptr<vtkCellArray>::New().Get() : pd->GetPolys());
  mesh->SetVerts(points ? pd->GetVerts() : Ptr<vtkCellArray>::New().Get());
  // Points as small shaded spheres: a few pixels each, smaller for dense clouds.
  vtkProperty* mp = mesh_actor->GetProperty();
  mp->SetRenderPointsAsSpheres(points);
  mp->SetPointSize(f.mesh_V.rows() > 20000 ? 3 : f.mesh_V.rows() > 5000 ? 5 : 7);
  context_mesh->GetProperty()->SetRenderPointsAsSpheres(points);
  context_mesh->GetProperty()->SetPointSize(3);
  rest_cage_pd = wireframe(model.cage.V, model.cage.F);
  rest_mesh = points ? point_set(model.mesh.V) : wireframe(model.mesh.V, model.mesh.F);
  def_cage_pd = wireframe(f.cage_V, model.cage.F);
  static_cast<vtkPolyDataMapper*>(rest_cage->GetMapper())->SetInputData(rest_cage_pd);
  static_cast<vtkPolyDataMapper*>(def_cage->GetMapper())->SetInputData(def_cage_pd);
  volume_version = -2;
  glyph_leaves.reset();
}

// Deformed mesh geometry and its field (always: the handles are picked on it), and the deformed cage.
void Scene::Impl::update_mesh(const SessionFrame& f, const ViewSettings& s) {
  vtkPoints* pts = mesh->GetPoints();
  for (Eigen::Index i = 0; i < f.mesh_V.rows(); ++i)
    pts->SetPoint(i, f.mesh_V(i, 0), f.mesh_V(i, 1), f.mesh_V(i, 2));
  pts->Modified();
  auto arr = Ptr<vtkDoubleArray>::New();
  const Field fld = shown_field(s);
  // Frames built before the view asked for σ1/σ3 lack it: their vertices show NaN until the next frame.
  const VecXd nan = VecXd::Constant(f.mesh_V.rows(), std::numeric_limits<double>::quiet_NaN());
  const VecXd& v = fld == Field::kDistortion
                       ? (f.mesh_distortion.size() == f.mesh_V.rows() ? f.mesh_distortion : nan)
                   : fld == Field::kDetJ ? f.mesh_det
                                         : f.mesh_e_iso;
  arr->SetName(fld == Field::kDistortion ? "sigma1/sigma3"
               : fld == Field::kDetJ     ? "volume ratio (det J)"
                                         : "E_iso - 6");
  arr->SetNumberOfValues(v.size());
  for (Eigen::Index i = 0; i < v.size(); ++i) arr->SetValue(i, v(i));
  point_rgb_shown = points && s.point_colors && s.view == View::kMesh &&
                    point_rgb.size() == 3 * static_cast<size_t>(f.mesh_V.rows());
  if (point_rgb_shown) {
    auto rgb = Ptr<vtkUnsignedCharArray>::New();
    rgb->SetName("colour of the file");
    rgb->SetNumberOfComponents(3);
    rgb->SetNumberOfTuples(f.mesh_V.rows());
    std::copy(point_rgb.begin(), point_rgb.end(), rgb->GetPointer(0));
    mesh->GetPointData()->SetScalars(rgb);
    mesh_mapper->SetColorModeToDirectScalars();
  } else {
    mesh->GetPointData()->SetScalars(arr);
    mesh_mapper->SetColorModeToMapScalars();
  }
  mesh->Modified();
  vtkPoints* cp = def_cage_pd->GetPoints();
  for (Eigen::Index i = 0; i < f.cage_V.rows(); ++i)
    cp->SetPoint(i, f.cage_V(i, 0), f.cage_V(i, 1), f.cage_V(i, 2));
  cp->Modified();
  def_cage_pd->Modified();
}

// Handle images f(p): small black spheres, shown in the mesh view.
void Scene::Impl::update_handle_images(const SessionFrame& f, const ViewSettings& s) {
  const Model& model = *f.model;
  const double diag = (model.cage.bbox_max - model.cage.bbox_min).norm();
  auto pts = Ptr<vtkPoints>::New();
  for (Eigen::Index i = 0; i < f.images.rows(); ++i)
    pts->InsertNextPoint(f.images(i, 0), f.images(i, 1), f.images(i, 2));
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  images_mapper->SetInputData(pd);
  image_sphere->SetRadius(0.008 * diag);
  images->SetVisibility(s.view == View::kMesh && f.images.rows() > 0);
  // Unreached handles, as the solver measures "reached" (handle_tolerance of Frame::scale), once the solver
  // rests: while it iterates the images trail the targets anyway.
  const double scale = 0.5 * (model.cage.bbox_max - model.cage.bbox_min).maxCoeff();
  auto lpts = Ptr<vtkPoints>::New();
  auto lines = Ptr<vtkCellArray>::New();
  unreached = 0;
  if (f.images.rows() == f.targets.rows() && f.state == SessionState::kResting)
    for (Eigen::Index i = 0; i < f.images.rows(); ++i) {
      if ((f.images.row(i) - f.targets.row(i)).norm() <= handle_tolerance * scale) continue;
      ++unreached;
      const vtkIdType a = lpts->InsertNextPoint(f.images(i, 0), f.images(i, 1), f.images(i, 2));
      const vtkIdType b = lpts->InsertNextPoint(f.targets(i, 0), f.targets(i, 1), f.targets(i, 2));
      const vtkIdType ids[2] = {a, b};
      lines->InsertNextCell(2, ids);
    }
  auto lpd = Ptr<vtkPolyData>::New();
  lpd->SetPoints(lpts);
  lpd->SetLines(lines);
  misses_mapper->SetInputData(lpd);
  misses->SetVisibility(s.view == View::kMesh && unreached > 0);
}

void Scene::Impl::update_picked(const SessionFrame& f, const ViewSettings& s) {
  if (!picked_valid) return;
  const bool deformed = s.view == View::kMesh || (s.view == View::kSigma3 && s.sigma_deformed_space);
  const Vec3 p = deformed ? picked_image : picked_rest;
  const Model& model = *f.model;
  picked_sphere->SetCenter(p.x(), p.y(), p.z());
  picked_sphere->SetRadius(0.012 * (model.cage.bbox_max - model.cage.bbox_min).norm());
  picked->VisibilityOn();
}

void Scene::Impl::show_bar(vtkScalarsToColors* colors, const char* title) {
  bar->SetLookupTable(colors);
  // Annotations (indexed tables: depth, status) are drawn left of the bar, tick labels right of it; both
  // must stay inside the bar's strip, whose left edge touches the model's viewport.
  if (bar_in_strip) {
    const bool indexed = colors->GetIndexedLookup() != 0;  // annotations left of the bar: room for them
    bar->SetPosition(indexed ? 0.5 : 0.08, 0.1);
    bar->SetWidth(indexed ? 0.45 : 0.8);
  }
  bar->SetTitle(title);
  bar->VisibilityOn();
}

namespace {
// The certificate's bound on σ1/σ3 over the certified domain (the largest per-leaf bound), for captions.
std::string distortion_bound_text(const SessionFrame& f) {
  if (!f.leaves) return "; certified bound: computing...";
  const Certificate& c = *f.leaves;
  if (!c.certified) return "; no certified bound (the map is not certified)";
  std::string t =
      "; certified on the domain: sigma1/sigma3 <= " + format_bound(c.max_distortion_upper_bound, true, 4);
  // With the isometric targets on, the two bounds they constrain too.
  if (c.max_sigma1 > 0 || c.min_sigma3 > 0)
    t += ", sigma1 <= " + format_bound(c.max_sigma1_upper_bound, true, 4) +
         ", sigma3 >= " + format_bound(c.min_lower_bound, false, 4);
  if (f.leaves_version != f.map_version) t += " (of an earlier iterate)";
  return t;
}
}  // namespace

// Mesh view: the deformed mesh coloured by σ1/σ3, det J (log scale, symmetric around 1) or E_iso − 6.
std::string Scene::Impl::show_mesh_view(const SessionFrame& f, const ViewSettings& s) {
  mesh_actor->VisibilityOn();
  mesh_actor->GetProperty()->SetEdgeVisibility(s.mesh_edges ? 1 : 0);
  rest_cage->SetVisibility(s.rest_cage);
  def_cage->SetVisibility(s.deformed_cage);
  const Field fld = shown_field(s);
  const ColorRange& cr = s.range[static_cast<int>(fld)];
  if (fld == Field::kDistortion) {
    // 1 = conformal: the heat map starts there.
    std::vector<double> v(f.mesh_distortion.data(), f.mesh_distortion.data() + f.mesh_distortion.size());
    auto [lo, hi] = color_range(v, cr);
    if (cr.mode != ColorRange::Mode::kManual) {
      lo = 1;
      hi = std::max(hi, 1.05);
    }
    mesh_lut->SetScaleToLinear();
    heat_lut(mesh_lut, hi);
    mesh_lut->SetTableRange(lo, std::max(hi, lo + 1e-9));
  } else if (fld == Field::kDetJ) {
    // Symmetric around 1 on a log scale (a volume halved and doubled get opposite colours): the range is
    // taken on log det J.
    std::vector<double> v;
    v.reserve(static_cast<size_t>(f.mesh_det.size()));
    for (Eigen::Index i = 0; i < f.mesh_det.size(); ++i)
      if (f.mesh_det(i) > 0) v.push_back(f.mesh_det(i));
    auto [lo, hi] = color_range(v, cr);
    if (cr.mode != ColorRange::Mode::kManual) {
      const double m = std::max({hi, 1 / std::max(lo, 1e-300), 1.05});
      lo = 1 / m;
      hi = m;
    }
    lo = std::max(lo, 1e-6);
    cool_warm_lut(mesh_lut, lo, std::max(hi, lo * 1.001), true);
  } else {
    std::vector<double> v(f.mesh_e_iso.data(), f.mesh_e_iso.data() + f.mesh_e_iso.size());
    auto [lo, hi] = color_range(v, cr);
    if (cr.mode != ColorRange::Mode::kManual) {  // 0 = isometry: the heat map starts there
      lo = 0;
      hi = std::max(hi, 0.05);
    }
    mesh_lut->SetScaleToLinear();
    heat_lut(mesh_lut, hi);
    mesh_lut->SetTableRange(lo, std::max(hi, lo + 1e-9));
  }
  mesh_lut->Build();
  mesh_mapper->SetScalarRange(mesh_lut->GetTableRange());
  range = {mesh_lut->GetTableRange()[0], mesh_lut->GetTableRange()[1]};
  update_overlap(f, s);
  if (point_rgb_shown) {
    range = {0, 0};
    return "deformed points, colours of the file";
  }
  const std::string things = points ? "deformed points, " : "deformed mesh, ";
  if (fld == Field::kDistortion) {
    show_bar(mesh_lut, "sigma1/sigma3");
    return things + "distortion sigma1/sigma3 at the vertices" + distortion_bound_text(f);
  }
  show_bar(mesh_lut, fld == Field::kDetJ ? "det J" : "E_iso - 6");
  return things + (fld == Field::kDetJ ? "local volume ratio det J" : "E_iso - 6");
}

void Scene::Impl::attach_overlay() {
  vtkRenderWindow* w = ren->GetRenderWindow();
  if (!w) return;
  if (!w->HasRenderer(overlay)) {
    w->SetNumberOfLayers(std::max(2, w->GetNumberOfLayers()));
    w->AddRenderer(overlay);
  }
  overlay->SetViewport(ren->GetViewport());
  overlay->SetActiveCamera(ren->GetActiveCamera());
}

// A proven overlap of the map on screen (its verdict, not an earlier map's): the neighbourhoods of its two
// rest-mesh triangles red on the deformed mesh, and a marker at the point where the surface meets itself.
void Scene::Impl::update_overlap(const SessionFrame& f, const ViewSettings& s) {
  const bool shown = s.global_injectivity && f.global && f.global_version == f.map_version &&
                     f.global->verdict == GlobalInjectivity::Verdict::kOverlap && !points;
  if (!shown) return;
  const GlobalInjectivity& g = *f.global;
  const MatX3i& F = f.model->mesh.F;
  const std::array<long, 3> key{f.model_version, g.overlap_face_a, g.overlap_face_b};
  if (key != overlap_key) {
    overlap_key = key;
    overlap_cells = Ptr<vtkCellArray>::New();
    for (int t : faces_near(F, {g.overlap_face_a, g.overlap_face_b}, kOverlapRings)) {
      const vtkIdType ids[3] = {F(t, 0), F(t, 1), F(t, 2)};
      overlap_cells->InsertNextCell(3, ids);
    }
    overlap_list = faces_near(F, {g.overlap_face_a, g.overlap_face_b}, kOverlapRings);
  }
  attach_overlay();
  overlap_faces = overlap_list;
  overlap_mapper->SetInputData(polydata(mesh->GetPoints(), overlap_cells));
  overlap->VisibilityOn();
  const Model& model = *f.model;
  overlap_sphere->SetCenter(g.overlap_point.x(), g.overlap_point.y(), g.overlap_point.z());
  overlap_sphere->SetRadius(0.015 * (model.cage.bbox_max - model.cage.bbox_min).norm());
  overlap_marker->VisibilityOn();
  marker_shown = true;
  marker_at = g.overlap_point;
}

// σ3 view: slices (and in rest space optionally a volume rendering) of the field grid, over a faint mesh.
namespace {
// Where the mesh surface crosses the shown σ3 slices (planes x_a = const of the field grid), as line
// segments: the boundary of the certified domain D (the mesh and its solid) on each slice. Each triangle
// crossing a plane gives one segment between its two edge crossings (a vertex on the plane counts as above
// it, so every crossing is found once); in deformed space the same crossings are mapped by the same edge
// interpolation of the deformed vertices, i.e. the image of the rest-space curve under the piecewise-linear
// deformed mesh.
Ptr<vtkPolyData> domain_outline_on_slices(const SessionFrame& f, const ViewSettings& s) {
  const FieldGrid& g = *f.field;
  const MatX3d& V = f.model->mesh.V;
  const MatX3i& F = f.model->mesh.F;
  const bool def = s.sigma_deformed_space && f.mesh_V.rows() == V.rows();
  const MatX3d& W = def ? f.mesh_V : V;
  auto pts = Ptr<vtkPoints>::New();
  auto lines = Ptr<vtkCellArray>::New();
  for (int a = 0; a < 3; ++a) {
    if (!s.slice[a]) continue;
    const int k =
        std::clamp(static_cast<int>(std::lround(s.slice_pos[a] * (g.dims[a] - 1))), 0, g.dims[a] - 1);
    const double c = g.origin(a) + g.spacing * k;
    for (Eigen::Index t = 0; t < F.rows(); ++t) {
      vtkIdType ids[2];
      int n = 0;
      for (int e = 0; e < 3 && n < 2; ++e) {
        const int i = F(t, e), j = F(t, (e + 1) % 3);
        const double di = V(i, a) - c, dj = V(j, a) - c;
        if ((di >= 0) == (dj >= 0)) continue;
        const double u = di / (di - dj);
        const Vec3 p = (1 - u) * W.row(i).transpose() + u * W.row(j).transpose();
        ids[n++] = pts->InsertNextPoint(p.x(), p.y(), p.z());
      }
      if (n == 2) lines->InsertNextCell(2, ids);
    }
  }
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetLines(lines);
  return pd;
}
}  // namespace

std::string Scene::Impl::show_sigma3_view(const SessionFrame& f, const ViewSettings& s) {
  context_mapper->SetInputData(s.sigma_deformed_space ? mesh.Get() : rest_mesh.Get());
  context_mesh->VisibilityOn();
  rest_cage->SetVisibility(!s.sigma_deformed_space && s.rest_cage);
  def_cage->SetVisibility(s.sigma_deformed_space && s.deformed_cage);
  std::string what = std::string(s.distortion ? "distortion sigma1/sigma3, " : "sigma3 field, ") +
                     (s.sigma_deformed_space ? "deformed space" : "rest space");
  if (!f.field) return what + " (computing...)";
  const auto [lo, hi] = field_range(*f.field, s);
  field_colors(sigma_colors, lo, hi, s.distortion);
  range = {lo, hi};
  slices_mapper->SetInputData(sigma3_slices(f, s));
  slices_mapper->SetScalarRange(lo, hi);
  slices->VisibilityOn();
  if (domain == DomainKind::kMesh) {
    outline_mapper->SetInputData(domain_outline_on_slices(f, s));
    outline->VisibilityOn();
  }
  if (s.sigma_volume && !s.sigma_deformed_space) show_sigma3_volume(f, s, lo, hi);
  show_bar(sigma_colors, s.distortion ? "sigma1/sigma3" : "sigma3");
  what += std::string(s.sigma_whole_cage ? " (whole cage interior; certified only inside the voxels)"
                                         : " (inside the voxels)") +
          ", colours " + format_g(lo, 3) + " to " + format_g(hi, 3);
  if (domain == DomainKind::kMesh)
    what += "\nblack lines: the mesh surface, boundary of the certified domain";
  if (f.field_version != f.map_version) what += " (of an earlier iterate; updates when the solver rests)";
  return what;
}

// Volume rendering of σ3 in rest space; rebuilt when the field or the whole-cage choice changes.
void Scene::Impl::show_sigma3_volume(const SessionFrame& f, const ViewSettings& s, double lo, double hi) {
  const FieldGrid& g = *f.field;
  const long volume_key = 4 * f.field_version + (s.sigma_whole_cage ? 1 : 0) + (s.distortion ? 2 : 0);
  if (volume_version != volume_key) {
    volume_version = volume_key;
    volume_image = Ptr<vtkImageData>::New();
    volume_image->SetDimensions(g.dims);
    volume_image->SetOrigin(g.origin.x(), g.origin.y(), g.origin.z());
    volume_image->SetSpacing(g.spacing, g.spacing, g.spacing);
    auto v = Ptr<vtkFloatArray>::New();
    v->SetName(s.distortion ? "sigma1/sigma3" : "sigma3");
    v->SetNumberOfValues(g.points());
    // Outside the cage: beyond the range's transparent end. The interesting end is opaque: low σ3
    // (near-degenerate), high σ1/σ3 (most distorted).
    const double span = hi - lo + 1e-9;
    const float outside = static_cast<float>(s.distortion ? hi + 0.01 * span : lo - 0.01 * span);
    for (long i = 0; i < g.points(); ++i) {
      const size_t n = static_cast<size_t>(i);
      const float x = grid_value(g, n, s.distortion);
      v->SetValue(i, g.inside_cage[n] && (s.sigma_whole_cage || g.inside_sampled[n]) && std::isfinite(x)
                         ? x
                         : outside);
    }
    volume_image->GetPointData()->SetScalars(v);
    volume_mapper->SetInputData(volume_image);
    auto opacity = Ptr<vtkPiecewiseFunction>::New();
    const double bad = s.distortion ? hi : lo, good = s.distortion ? lo : hi;
    opacity->AddPoint(outside, 0.0);
    opacity->AddPoint(bad, 0.5);
    opacity->AddPoint(0.5 * (lo + hi), 0.08);
    opacity->AddPoint(good, 0.02);
    auto prop = Ptr<vtkVolumeProperty>::New();
    prop->SetColor(sigma_colors);
    prop->SetScalarOpacity(opacity);
    prop->SetScalarOpacityUnitDistance(2 * g.spacing);
    prop->SetInterpolationTypeToLinear();
    volume->SetProperty(prop);
  }
  volume->VisibilityOn();
}

// Lipschitz / octree views: the certificate's leaves in rest space.
std::string Scene::Impl::show_leaves_view(const SessionFrame& f, const ViewSettings& s) {
  context_mapper->SetInputData(rest_mesh);
  context_mesh->VisibilityOn();
  rest_cage->SetVisibility(s.rest_cage);
  const bool lip = s.view == View::kLipschitz;
  std::string what = lip ? (s.distortion         ? "leaf voxels, certified upper bound of sigma1/sigma3"
                            : s.lipschitz_margin ? "leaf voxels, margin sigma3 - rL"
                                                 : "leaf voxels, Lipschitz bound L")
                         : (s.octree_by_status ? "octree leaves by status" : "octree leaves by depth");
  if (!f.leaves) return what + " (computing...)";
  const Certificate& c = *f.leaves;
  // The glyph inputs are rebuilt only when the leaves or what the view draws of them changed: a new input
  // makes the glyph mapper rebuild its per-instance buffers, and the leaves arrive far less often (once the
  // solver rests, or every second while dragging) than the frames of the mesh and handles.
  const std::string key = glyph_key(s);
  if (f.leaves != glyph_leaves || key != glyph_settings) {
    glyph_leaves = f.leaves;
    glyph_settings = key;
    LeafGlyphs L = leaf_glyphs(c, *f.model, s);
    auto pd = Ptr<vtkPolyData>::New();
    pd->SetPoints(L.pts);
    pd->GetPointData()->AddArray(L.side);
    pd->GetPointData()->AddArray(L.value);
    leaves_mapper->SetInputData(pd);
    leaves_mapper->SelectColorArray("value");
    const auto [lo, hi] = color_range(L.finite, s.range[static_cast<int>(shown_field(s))]);
    glyph_title = color_leaves(c, s, lo, hi);
    leaves_mapper->SetScalarRange(leaves_lut->GetTableRange());
    glyph_range =
        lip ? std::pair<double, double>{leaves_lut->GetTableRange()[0], leaves_lut->GetTableRange()[1]}
            : std::pair<double, double>{0, 0};
    glyph_marks = lip && L.mark_pts->GetNumberOfPoints() > 0;
    if (glyph_marks) {
      auto mpd = Ptr<vtkPolyData>::New();
      mpd->SetPoints(L.mark_pts);
      mpd->GetPointData()->AddArray(L.mark_side);
      mpd->GetPointData()->AddArray(L.mark_failed);
      marks_mapper->SetInputData(mpd);
    }
    glyph_counts = {L.shown, L.failed};
  }
  range = glyph_range;
  leaves->GetProperty()->SetEdgeVisibility(!lip);
  leaves->GetProperty()->SetEdgeColor(0.15, 0.15, 0.15);
  leaves->VisibilityOn();
  marks->SetVisibility(glyph_marks);
  const char* title = glyph_title;
  const LeafCounts L{glyph_counts.first, glyph_counts.second};
  show_bar(leaves_lut, title);
  what += ": " + std::to_string(L.shown) + " of " + std::to_string(c.leaves.size()) + " leaves shown, " +
          std::to_string(c.refined) + " voxels refined, " + std::to_string(L.failed) + " failed";
  if (s.clip < 1) what += ", clipped";
  if (lip && s.distortion) what += distortion_bound_text(f);
  if (f.leaves_version != f.map_version) what += " (of an earlier iterate; updates when the solver rests)";
  return what;
}

// The leaves' colour table for the view: L (log scale), margin (diverging), status or depth (indexed).
// Returns the colour bar's title.
const char* Scene::Impl::color_leaves(const Certificate& c, const ViewSettings& s, double lo, double hi) {
  const bool lip = s.view == View::kLipschitz;
  leaves_lut->SetScaleToLinear();
  leaves_lut->IndexedLookupOff();
  leaves_lut->ResetAnnotations();
  leaves_lut->SetAboveRangeColor(0.2, 0.2, 0.2, 1);
  if (lip && (s.distortion || !s.lipschitz_margin)) {
    // L and the σ1/σ3 bound span decades: log scale, viridis (a rainbow would invent boundaries that are
    // not in the data).
    lo = std::max(lo, 1e-12);
    viridis_lut(leaves_lut, lo, std::max(hi, lo * 10), true);
    leaves_lut->SetAboveRangeColor(0.2, 0.2, 0.2, 1);  // an infinite bound: dark grey
    leaves_lut->SetUseAboveRangeColor(s.range[static_cast<int>(shown_field(s))].mode ==
                                      ColorRange::Mode::kAuto);
    return s.distortion ? "K bound" : "L";
  }
  if (lip) {
    // Diverging around 0 (certified above, red at and below 0), symmetric unless set by hand.
    if (s.range[static_cast<int>(Field::kMargin)].mode != ColorRange::Mode::kManual) {
      const double m = std::max({std::abs(lo), std::abs(hi), 1e-12});
      lo = -m;
      hi = m;
    }
    cool_warm_lut(leaves_lut, lo, hi, false);
    // Reversed: a positive margin (certified) blue, a failing one red.
    for (int i = 0; i < 128; ++i) {
      double a[4], b[4];
      leaves_lut->GetTableValue(i, a);
      leaves_lut->GetTableValue(255 - i, b);
      leaves_lut->SetTableValue(i, b);
      leaves_lut->SetTableValue(255 - i, a);
    }
    return "sigma3 - rL";
  }
  if (s.octree_by_status) {
    leaves_lut->SetNumberOfTableValues(2);
    leaves_lut->SetTableRange(0, 1);
    leaves_lut->SetTableValue(0, 0.85, 0.1, 0.1, 1);
    leaves_lut->SetTableValue(1, 0.3, 0.75, 0.35, 1);
    leaves_lut->ResetAnnotations();
    leaves_lut->SetAnnotation(vtkVariant(0.0), "failed");
    leaves_lut->SetAnnotation(vtkVariant(1.0), "ok");
    leaves_lut->IndexedLookupOn();
    return "status";
  }
  const int dmax = std::max(1, c.max_depth_used);
  leaves_lut->SetNumberOfTableValues(dmax + 1);
  leaves_lut->SetTableRange(0, dmax);
  leaves_lut->ResetAnnotations();
  for (int d = 0; d <= dmax; ++d) {
    double c[3];
    viridis(1 - static_cast<double>(d) / dmax, c);  // deep leaves dark
    leaves_lut->SetTableValue(d, c[0], c[1], c[2], 1);
    leaves_lut->SetAnnotation(vtkVariant(static_cast<double>(d)), std::to_string(d));  // title: depth
  }
  leaves_lut->IndexedLookupOn();
  return "depth";
}

// Breaks each line of `text` after ", " where it would pass `max_chars` characters (a part longer than that
// stays whole).
static std::string wrap_caption(const std::string& text, size_t max_chars) {
  std::string out, line;
  auto flush = [&] {
    out += (out.empty() ? "" : "\n") + line;
    line.clear();
  };
  size_t start = 0;
  while (start <= text.size()) {
    const size_t nl = text.find('\n', start);
    const std::string src = text.substr(start, nl == std::string::npos ? std::string::npos : nl - start);
    size_t p = 0;
    while (p < src.size()) {
      const size_t comma = src.find(", ", p);
      const std::string part = src.substr(p, comma == std::string::npos ? std::string::npos : comma + 2 - p);
      if (!line.empty() && line.size() + part.size() > max_chars) {
        while (!line.empty() && line.back() == ' ') line.pop_back();
        flush();
      }
      line += part;
      p = comma == std::string::npos ? src.size() : comma + 2;
    }
    flush();
    if (nl == std::string::npos) break;
    start = nl + 1;
  }
  return out;
}

// The caption is drawn at 15 px (about 8 px per character) from the left edge; without its own strip the
// colour bar takes the right ~12% of the view.
void Scene::Impl::set_caption_text(const std::string& c) {
  const int* size = ren ? ren->GetSize() : nullptr;
  const double width = size && size[0] > 0 ? size[0] : 640;
  const double usable = width * (bar_in_strip ? 0.97 : 0.86);
  caption = wrap_caption(c, static_cast<size_t>(std::max(30.0, usable / 8.0)));
  text->SetInput(caption.c_str());
}

namespace {
// The global verdict of the map on screen, for the caption ("" when not asked for or not certified).
std::string global_text(const SessionFrame& f, const ViewSettings& s) {
  if (!s.global_injectivity || !f.certified) return "";
  if (!f.global || f.global_version != f.map_version) return "; global injectivity: checking...";
  const GlobalInjectivity& g = *f.global;
  if (g.verdict == GlobalInjectivity::Verdict::kInjective) return "; globally injective";
  if (g.verdict == GlobalInjectivity::Verdict::kOverlap)
    return "; overlaps itself at (" + format_g(g.overlap_point.x(), 3) + ", " +
           format_g(g.overlap_point.y(), 3) + ", " + format_g(g.overlap_point.z(), 3) +
           ") (red, yellow marker)";
  return "; global injectivity not decided";
}
}  // namespace

void Scene::Impl::set_caption(const std::string& what, const SessionFrame& f, const ViewSettings& s) {
  const std::string cert = (f.certified ? "certified" : "NOT certified") + global_text(f, s);
  set_caption_text((model_name.empty() ? "" : model_name + ": ") + what + "\n" + cert +
                   ", min sigma3 lower bound " + format_bound(f.min_lower_bound, false, 4) + ", iteration " +
                   std::to_string(f.history.size()));
}

void Scene::show(const SessionFrame& f, const ViewSettings& s) {
  Impl& I = *impl_;
  I.hide_all();
  if (!f.model || f.mesh_V.rows() == 0) {
    I.show_no_model(f);
    return;
  }
  I.adopt_model(f);
  I.update_mesh(f, s);
  I.update_handle_images(f, s);
  I.update_picked(f, s);
  std::string what;
  if (s.view == View::kMesh)
    what = I.show_mesh_view(f, s);
  else if (s.view == View::kSigma3)
    what = I.show_sigma3_view(f, s);
  else
    what = I.show_leaves_view(f, s);
  I.set_caption(what, f, s);
}

}  // namespace lidef::studio
