// lidef-studio's main window: the VTK view with handle widgets, the view/parameter/plot panels, menus, status
// bar. All solving happens in lidef::InteractiveSession (engine thread); this class only forwards user edits
// to it and renders the newest certified frame it publishes (older frames that arrive while a render is
// pending are dropped, so neither side waits for the other).
#pragma once
#include <vtkSmartPointer.h>

#include <QMainWindow>
#include <QStringList>
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "lidef/analysis/interactive_session.h"
#include "pick.h"
#include "scene.h"

class QCheckBox;
class QMenu;
class vtkOrientationMarkerWidget;
class QLabel;
class QTimer;
class QDockWidget;
class QProgressBar;
class QPushButton;
class QVTKOpenGLNativeWidget;
class vtkGenericOpenGLRenderWindow;
class vtkRenderer;
class vtkRenderWindow;
class vtkHandleWidget;
class vtkSphereHandleRepresentation;
class vtkCallbackCommand;
class vtkObject;
class vtkPolyData;

namespace lidef::studio {

class ParamsPanel;
class PlotsPanel;

class StudioWindow : public QMainWindow {
  Q_OBJECT
 public:
  explicit StudioWindow(QWidget* parent = nullptr);
  ~StudioWindow() override;

  // Opens a model folder, a mesh file (.obj/.off/.ply/.stl: its automatic cage, made once and cached,
  // docs/cages.md) or a scenario/session JSON (by what `path` is). Returns false after reporting the loader's
  // message (error dialog, or the error sink), or when the cage making was cancelled; the current session is
  // kept. On true the engine prepares the model; the window goes on showing the model before (mesh, cage,
  // handles, title, camera, panels) until the engine has the new one ready, then swaps all of it at once. A
  // cancelled or failed preparation leaves the window as it was: what is on screen is always the model the
  // engine's solver holds (InteractiveSession::solver_model()).
  // `coefficients` (a scenario only): start from that map instead of solving
  // (InteractiveSession::open_scenario).
  bool open_path(const std::string& path, const std::string& coefficients = "");
  // Cancel (status bar, cage dialog): stops the cage maker at its next step, else the engine's preparation.
  void cancel_opening();
  // Test hook: called on the cage maker's thread with each of its progress lines, before the cancel is
  // polled there (cancel_opening() from inside lands the cancel at that line).
  void set_cage_line_hook(std::function<void(const std::string&)> hook) { cage_line_hook_ = std::move(hook); }
  // The model the view shows (nullptr: none), its name (title, badge, caption, plots), whether an opening is
  // being prepared, and the newest preparing frame while one is (progress; nullptr otherwise).
  std::shared_ptr<const Model> shown_model() const { return shown_model_; }
  const std::string& shown_name() const { return shown_name_; }
  bool opening() const { return !opens_.empty(); }
  std::shared_ptr<const SessionFrame> preparing_frame() const { return preparing_; }
  // Points of the drawn mesh (the scene's polydata), to check it against the shown model.
  long drawn_mesh_points() const;
  // What the last opening said about the model (e.g. "reused cached cage ...", "cage: 498 faces ..."); empty
  // for a model folder.
  const std::string& model_note() const { return model_note_; }
  bool save_session(const std::string& path);
  // Opens the side-by-side picture of a `lidef compare --out` folder in its own window (compare_view.h).
  bool open_comparison(const std::string& dir);  // scenario JSON with a "studio" object (camera, views)
  // Renders the 3D view now and writes it as PNG (atomically: temporary file, then rename). width/height > 0:
  // the view is rendered at that size (then restored); transparent: RGBA with a transparent background.
  bool save_screenshot(const std::string& path, int width = 0, int height = 0, bool transparent = false);
  // Writes what the CLI writes for the map on screen into `dir` (created): coefficients.txt, deformed.vtp
  // (lidef deform's point data), and, when the frame has them, the certificate's leaves.vtu and the σ3
  // field's field.vti (the CLI's writers, vtk_export.h). Returns false after reporting the problem.
  bool export_current(const std::string& dir);

  // Window layout: dock state and geometry saved with QSettings (organization and application names of the
  // QApplication; tests point QSettings at a temporary folder). restore_layout() returns false on a first
  // run (no saved state): the window keeps its first-run size, a share of the screen.
  bool restore_layout();
  void save_layout();

  // Camera (View > Camera). Presets look along -axis (positive = from the + side).
  void reset_camera();
  // Which axis points up (0 x, 1 y, 2 z; View > Up axis): the camera's up after R or opening a model. Kept
  // between runs (QSettings). Meshes modelled with z up (dino, bull, elk) stand upright with 2.
  void set_up_axis(int axis);
  int up_axis() const { return up_axis_; }
  // The orientation axes in the lower-left corner (View > Orientation axes; off in view-only mode).
  void set_orientation_axes(bool on);
  bool orientation_axes() const;
  // File > Open recent: the last kRecentFiles paths opened (QSettings), newest first.
  static constexpr int kRecentFiles = 8;
  QStringList recent_files() const;
  void camera_preset(int axis, bool positive);
  void set_orthographic(bool on);
  bool orthographic() const;
  // {"camera": {position, focal_point, view_up, view_angle, parallel_projection, parallel_scale}}; the same
  // object saved sessions hold. set_camera_json throws InputError on bad JSON; copy/paste use the clipboard.
  std::string camera_json() const;
  void set_camera_json(const std::string& json);
  void copy_camera();
  bool paste_camera();  // false (and a message) when the clipboard holds no camera
  // The keyboard/mouse cheat sheet (F1 or H).
  static std::string cheat_sheet();
  void show_cheat_sheet();

  // Colour range of a field (View panel, "Colour range").
  void set_color_range(Field f, const ColorRange& r);
  std::pair<double, double> shown_color_range() const { return scene_->shown_range(); }

  // Picking: the point under display position (x, y) in the current view (mesh surface, σ3 slices in rest
  // space, leaf voxels); fills the Picked panel. False when nothing is there.
  bool pick_at_display(int x, int y);
  const PickedValues& picked() const { return picked_; }
  // Hover: mouse moves with no button held pick the point under the cursor (throttled to one pick per
  // kHoverMs, run from the event loop) into the same panel, "hover: " before `where`; nothing under the
  // cursor keeps the last values. On by default; the panel's checkbox turns it off.
  static constexpr int kHoverMs = 60;
  void set_hover(bool on);
  bool hover_enabled() const { return hover_enabled_; }
  bool hover_at_display(int x, int y);

  void set_settings(const ViewSettings& s);
  // The solver parameters (panel and engine); used for models opened without a scenario.
  void set_params(const DeformParams& p);
  const ViewSettings& settings() const { return settings_; }

  // Handle edits (what the mouse does; also called by tests). Sources in rest space.
  bool add_handle(const Vec3& source);  // target = its current image; false (and a message) when refused
  bool add_handle_at_display(int x,
                             int y);  // picks the deformed mesh at VTK display coords (origin bottom left)
  void delete_handle(int i);
  bool delete_handle_at_display(int x, int y);  // the target within 12 pixels, if any
  void move_target(int i, const Vec3& target);
  void undo();
  void redo();
  int num_handles() const { return static_cast<int>(sources_.rows()); }
  const MatX3d& targets() const { return targets_; }
  const MatX3d& sources() const { return sources_; }
  // Display position (VTK, origin bottom left) of a handle's target sphere, for scripted interaction.
  bool target_display_position(int i, double xy[2]);

  InteractiveSession& session() { return *session_; }
  // The frame shown last, and how many frames were rendered (benchmark).
  std::shared_ptr<const SessionFrame> shown_frame() const { return shown_; }
  long rendered_frames() const { return rendered_; }
  double last_render_ms() const { return last_render_ms_; }
  vtkRenderWindow* render_window() const;
  QVTKOpenGLNativeWidget* view_widget() const { return view_; }
  std::string caption() const { return scene_->caption(); }
  // The deformed mesh as drawn: points f(v), the shown field as point scalars.
  vtkPolyData* mesh_data() const { return scene_->mesh_data(); }
  // Handles of the shown frame whose image misses the target (red lines in the mesh view).
  int unreached_handles() const { return scene_->unreached_handles(); }
  // The badge's words about the map on screen (certificate and global injectivity) and the overlap as drawn
  // (red rest-mesh faces, the marker), for tests.
  std::string badge_text() const;
  const std::vector<int>& overlap_faces() const { return scene_->overlap_faces(); }
  bool overlap_marker_shown() const { return scene_->overlap_marker_shown(); }
  Vec3 overlap_marker_at() const { return scene_->overlap_marker_at(); }
  // Whether the shown point cloud has colours from its file (a splat's f_dc, a PLY's red green blue).
  bool has_point_colors() const { return has_point_colors_; }
  // MSAA samples of the 3D view (0 by default: interaction speed; call before the window is first shown).
  void set_multisamples(int n);
  // Headless use (--screenshot): only the 3D view, no docks or bars.
  void set_view_only(bool on);
  // A solver iteration with no new frame for kLongWaitSeconds shows a busy bar and Stop in the status bar
  // (a timer calls this with the engine's state and the seconds since its last frame; tests call it too).
  static constexpr double kLongWaitSeconds = 1.5;
  void update_long_wait(SessionState state, double seconds_since_frame);
  // Where error messages go: by default a modal dialog; tests collect them instead.
  void set_error_sink(std::function<void(const std::string&)> sink) { error_sink_ = std::move(sink); }
  // The one place the studio reports a problem to the user.
  void report_error(const std::string& title, const std::string& message);

 signals:
  void frame_shown();

 protected:
  void dragEnterEvent(QDragEnterEvent* e) override;
  void dropEvent(QDropEvent* e) override;
  void closeEvent(QCloseEvent* e) override;

 private:
  struct HandleSet {
    MatX3d sources, targets;
  };
  // An opening the engine is preparing: what the window adopts when its model arrives.
  struct OpenRecord {
    std::shared_ptr<const Model> model;
    std::string path, name, note;
    std::string
        source;  // the file the model came from (a mesh file, not the cage cache folder it was caged into)
    std::string camera;  // a session's "studio" object
    bool has_views = false;
    ViewSettings views;
    DeformParams params;
  };
  std::vector<OpenRecord> opens_;
  std::shared_ptr<const Model> shown_model_;
  std::string shown_name_, shown_source_;
  std::shared_ptr<const SessionFrame> preparing_;
  bool camera_to_reset_ = false;
  std::atomic<bool> cage_cancel_{false};
  std::atomic<bool> cage_running_{false};
  std::function<void(const std::string&)> cage_line_hook_;
  void forget_dropped_opens();
  void adopt_shown_model(const SessionFrame& f);  // title, handles, panels, camera of f's model at once
  // False (and a status message) while an opening is pending: handles belong to the shown model, and the
  // engine has already switched its handle checks to the model being prepared.
  bool edits_allowed();
  void set_status_line(const std::string& text);  // the status bar's text, whole in its tooltip
  void reset_camera_pose(bool rest_cage);         // three-quarter view with up_axis_ up (no render)
  // Picked values follow the map: recomputed at the same rest point for frame f when its map differs
  // from the one they were computed for; the marker moves with them.
  void refresh_picked(const SessionFrame& f);
  void show_picked(bool render);  // the panel's text and the marker from picked_; render: draw now
  long picked_map_version_ = -1;
  int up_axis_ = 1;  // 0 x, 1 y, 2 z: what points up after R or opening a model
  void build_ui();
  void build_view_menu(QMenu* before);
  void add_recent(const std::string& path);
  void fill_recent_menu(QMenu* menu);
  vtkSmartPointer<vtkOrientationMarkerWidget> axes_widget_;
  QWidget* build_view_panel();
  void refresh_view_panel();
  void on_frame(std::shared_ptr<const SessionFrame> f);  // any thread
  void render_pending();                                 // UI thread
  void update_status(const SessionFrame& f);
  void update_badge(const SessionFrame& f, const std::string& name);
  void sync_widgets();  // handle widgets from sources_/targets_
  void push_undo();
  void send_handles();
  void settings_changed();
  void apply_camera_json(const std::string& studio_json);
  void apply_camera_object(const nlohmann::json& camera);  // throws
  QWidget* build_range_controls();
  QLabel* range_used_ = nullptr;  // the range the colour bar spans now (View panel)
  void show_range_used();
  QObject* wheel_guard_ = nullptr;
  // The rest-space point under display (x, y) on the deformed mesh (barycentric pull-back); needs a frame.
  bool mesh_rest_point_at_display(int x, int y, Vec3& rest);
  std::string studio_json() const;

  std::unique_ptr<InteractiveSession> session_;
  QVTKOpenGLNativeWidget* view_ = nullptr;
  vtkGenericOpenGLRenderWindow* window_ = nullptr;
  vtkRenderer* renderer_ = nullptr;
  vtkRenderer* bar_renderer_ = nullptr;  // the colour bar's viewport, right of the model's
  std::unique_ptr<Scene> scene_;
  bool has_point_colors_ = false;
  void load_point_colors(const Model& model);
  ParamsPanel* params_ = nullptr;
  PlotsPanel* plots_ = nullptr;
  // A mesh file's model folder (lidef/cage/auto_cage.h), made on a worker thread while a progress dialog
  // shows its stages; a folder is returned unchanged. Throws what the cage maker throws.
  std::string resolve_model(const std::string& path);
  std::string model_note_;
  QLabel *badge_ = nullptr, *status_ = nullptr, *picked_label_ = nullptr;
  PickedValues picked_;
  // The rest-space point under display position (x, y) in the current view and what it lies on; `quiet`:
  // no status message when the view cannot pick.
  bool rest_point_at_display(int x, int y, Vec3& rest, std::string& where, bool quiet);
  bool hover_enabled_ = true;
  QTimer* hover_timer_ = nullptr;
  QCheckBox* hover_check_ = nullptr;
  int hover_xy_[2] = {0, 0};
  // Preprocessing of an opened model: stage and percent, and Cancel (shown only while preparing).
  QProgressBar* prepare_bar_ = nullptr;
  QPushButton* prepare_cancel_ = nullptr;
  QProgressBar* wait_bar_ = nullptr;
  QPushButton* wait_stop_ = nullptr;
  std::atomic<long long> last_frame_ns_{0};  // steady clock of the newest frame (set on the engine thread)
  std::vector<QWidget*> chrome_;             // docks and bars hidden in view-only mode
  QWidget* view_panel_ = nullptr;
  ViewSettings settings_;
  MatX3d sources_, targets_;
  std::vector<HandleSet> undo_, redo_;
  struct Widget;
  std::vector<std::unique_ptr<Widget>> widgets_;
  int dragging_ = -1;
  bool view_only_ = false;
  std::mutex pending_mutex_;
  std::shared_ptr<const SessionFrame> pending_;
  bool render_scheduled_ = false;
  std::shared_ptr<const SessionFrame> shown_;
  long shown_model_version_ = -1;
  long shown_verification_version_ = -1;
  long rendered_ = 0;
  double last_render_ms_ = 0;
  std::string pending_camera_;  // camera of an opened session, applied with its first frame
  std::string scenario_name_;
  std::function<void(const std::string&)> error_sink_;
};

}  // namespace lidef::studio
