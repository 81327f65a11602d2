// The studio's VTK scene: turns a SessionFrame (interactive_session.h) into actors for one of the four views.
// No Qt here; the window owns the render window and the handle widgets, the scene everything else.
#pragma once
#include <vtkSmartPointer.h>

#include <string>
#include <vector>

#include "color_range.h"
#include "lidef/analysis/interactive_session.h"
#include "lidef/point_cloud_io.h"

class vtkActor;
class vtkRenderer;
class vtkPolyData;
class vtkScalarBarActor;
class vtkTextActor;
class vtkVolume;

namespace lidef::studio {

enum class View { kMesh, kSigma3, kLipschitz, kOctree };
const char* to_string(View v);                   // "mesh", "sigma3", "lipschitz", "octree"
View view_from_string(const std::string& name);  // throws InputError

// What each view shows; saved with the session (studio JSON) and set from the view panel.
struct ViewSettings {
  View view = View::kMesh;
  // Mesh view.
  bool mesh_volume_ratio = false;  // colour by det J instead of E_iso − 6
  bool rest_cage = false, deformed_cage = true;
  bool mesh_edges = false;  // the mesh's triangle edges over its colours
  // Point clouds and Gaussian splats: their own colours (a splat's f_dc, a PLY's red green blue) instead of
  // the field, where the file has them (Scene::set_point_colors).
  bool point_colors = true;
  // Global injectivity of the map on screen (global_injectivity.h): checked when the engine rests; an
  // overlap is drawn on the mesh (red triangles, a yellow marker).
  bool global_injectivity = true;
  // Distortion σ1/σ3 instead of each view's own quantity: per vertex (mesh view), on the slices (σ3 view),
  // the certified upper bound per leaf (Lipschitz view). The octree view is unchanged.
  bool distortion = false;
  // σ3 view.
  bool sigma_deformed_space = false;      // slices drawn at the deformed grid positions
  bool slice[3] = {true, true, false};    // x, y, z slice planes
  double slice_pos[3] = {0.5, 0.5, 0.5};  // fraction of the bounding box along each axis
  bool sigma_volume = false;              // volume rendering (rest space)
  bool sigma_whole_cage = false;  // also outside the voxels (near the cage, where nothing is certified)
  int field_resolution = 48;
  // Lipschitz and octree views: leaves in rest space.
  bool lipschitz_margin = false;        // colour by σ3 − rL instead of L
  bool only_refined_or_failed = false;  // Lipschitz: show only leaves that were refined or failed
  bool octree_by_status = false;        // colour by certified/failed instead of depth
  double clip = 0.5;  // keep leaves whose center is below this fraction of the longest axis (1 = all)
  int min_depth = 0;  // keep leaves at least this deep
  // Colour-bar range of each field (color_range.h). E_iso − 6 clamps at its 99th percentile by default: one
  // outlier at a pulled corner would otherwise wash out the rest of the mesh.
  // σ1/σ3 per vertex likewise: it peaks at the same corners.
  ColorRange range[kNumFields] = {{ColorRange::Mode::kPercentile, 99, 0, 1}, {}, {}, {}, {},
                                  {ColorRange::Mode::kPercentile, 99, 0, 1}, {}};
};
// The field the view colours by (kSigma3 for the octree view, which colours by depth or status: no range).
Field shown_field(const ViewSettings& s);
bool has_range(const ViewSettings& s);  // false for the octree view
nlohmann::json settings_to_json(const ViewSettings& s);
// Reads what settings_to_json wrote; unknown or missing keys keep `s`'s values; bad types throw InputError.
void settings_from_json(const nlohmann::json& j, ViewSettings& s, const std::string& where);

// Whether the Lipschitz/octree view `s` draws leaf `l` (clip plane across the longest axis, min depth, "only
// refined or failed"). Drawn leaves are cubes of kLeafDrawnSide times their side about their center.
bool leaf_shown(const CertLeaf& l, const Model& model, const ViewSettings& s);
constexpr double kLeafDrawnSide = 0.97;

// The extras a view needs from the engine.
ExtrasRequest extras_for(const ViewSettings& s);

// The faces of the rest mesh (#F by 3) within `rings` face rings of the given faces (sharing a vertex with
// the ring before), sorted: the neighbourhoods of an overlap's two triangles, drawn red.
std::vector<int> faces_near(const MatX3i& F, const std::vector<int>& faces, int rings);
constexpr int kOverlapRings = 6;

// A point cloud's own colours, RGB bytes per point: a Gaussian splat's degree-0 colour (0.5 + C0 f_dc, C0 the
// degree-0 spherical harmonic, clamped to [0, 1]) or the PLY's red green blue (bytes, or floats in [0, 1]);
// empty when the cloud has neither.
std::vector<unsigned char> point_cloud_colors(const PlyCloud& cloud);

class Scene {
 public:
  // The colour bar goes into `bar_renderer` (a viewport beside the model's, so it never covers the model)
  // when given, else into `renderer`.
  explicit Scene(vtkRenderer* renderer, vtkRenderer* bar_renderer = nullptr);
  ~Scene();
  // Rebuilds the actors of `s.view` from the frame (cheap for the mesh view; the leaves/field views rebuild
  // only when their extras changed). A frame without a map shows the status line only.
  void show(const SessionFrame& frame, const ViewSettings& s);
  // The deformed mesh actor (picking: cell ids index the model's faces) and its data.
  vtkActor* mesh_actor() const;
  vtkPolyData* mesh_data() const;
  // Text shown in the top-left corner of the view (what is shown, and when extras lag the map).
  std::string caption() const;
  // The colour-bar range of the last shown view ({0, 0} before a map is shown or in the octree view).
  std::pair<double, double> shown_range() const;
  // The certified domain of the session's parameters: with kMesh (the mesh and its solid) the σ3 view draws
  // the mesh surface where it crosses the slices, the domain's boundary.
  void set_certified_domain(DomainKind d);
  // The name of the model shown (first words of the caption: what the caption's verdict is about).
  void set_model_name(const std::string& name);
  // Handles whose image is farther from the target than `fraction` of the model size (Frame::scale: half the
  // largest extent of the cage's bounding box; DeformParams::handle_tolerance) get a red line from the image
  // to the target in the mesh view; unreached_handles() counts them in the last shown frame.
  void set_handle_tolerance(double fraction);
  int unreached_handles() const;
  // The picked point, marked by an orange sphere: at f(p) in the deformed-space views, at p in rest space.
  void set_picked(bool valid, const Vec3& rest, const Vec3& image);
  // Colours of a point cloud's points (#P by 3 bytes, RGB, the model's mesh vertex order; empty: none). Shown
  // in the mesh view when ViewSettings::point_colors is set. Kept until the next call.
  void set_point_colors(std::vector<unsigned char> rgb);
  // The last shown frame's global verdict as drawn: the red faces of an overlap (empty when none is drawn)
  // and whether the marker is shown at `overlap_marker_at()`.
  const std::vector<int>& overlap_faces() const;
  bool overlap_marker_shown() const;
  Vec3 overlap_marker_at() const;
  // The leaves glyph actor (Lipschitz/octree views) and the σ3 slices, for picking.
  vtkActor* leaves_actor() const;
  vtkActor* slices_actor() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lidef::studio
