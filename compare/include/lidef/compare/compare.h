// `lidef compare`: every method of the paper's comparison (Sec. 8, Table 1, Figs. 11-12) on the same handles,
// in one run, and a Table-1-shaped table of the results (docs/compare.md).
//
// Methods (names as on the command line):
//   lidef         this project's certified projected Newton in the harmonic subspace (projected_newton.h)
//   pwl-tet       PWL(Tet) on a coarse tet mesh: the model's tet.node/tet.ele (Table 1's DOF), else TetGen
//                 (coarse_min_dof: at least that many DOF, TetGen's volume searched where the model's is
//                 coarser)
//   pwl-tet-fine  PWL(Tet) on a fine TetGen mesh (max tet volume = factor × lidef's voxel volume; Fig. 3)
//   vhm           Variational Harmonic Maps (vhm.h) on the model's vhm_anchors.xyz; its result is certified
//                 with lidef's certificate on lidef's voxels (Fig. 11)
//   pwl-tri       SR-ARAP on the full-resolution surface (sr_arap.h)
// A method that fails (bad tet mesh, handle outside every tet, TetGen error, ...) gets a row with its error
// and the others still run.
#pragma once
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "lidef/compare/pwl_tet.h"
#include "lidef/compare/sr_arap.h"
#include "lidef/compare/tet_mesh.h"
#include "lidef/compare/vhm.h"
#include "lidef/model_check.h"
#include "lidef/scenario.h"

namespace lidef {

// Every known method, in the table's order.
const std::vector<std::string>& compare_methods();

struct CompareOptions {
  std::vector<std::string> methods = compare_methods();
  std::string cache_dir;  // subspace cache of lidef ("" = none)
  // PWL(Tet)
  bool use_model_tets = true;  // coarse mesh: the model's tet.node/tet.ele when present
  TetgenOptions coarse_tet;    // otherwise TetGen with these switches
  // > 0: the coarse mesh has at least this many DOF (3 × vertices): the model's tet mesh when it has them,
  // else TetGen with its max volume searched for them (tetrahedralize_min_vertices; coarse_tet.max_volume is
  // not used). Table 1 at the paper's resolution.
  long coarse_min_dof = 0;
  TetgenOptions fine_tet;  // fine mesh; fine_tet.max_volume <= 0: fine_volume_factor × voxel side³
  double fine_volume_factor = 1.0;
  int tet_max_iterations = 200;
  // VHM
  std::string anchors;      // anchor file; "" = <model>/vhm_anchors.xyz, else evenly spread voxel centers
  int anchor_count = 300;   // number of voxel centers used when the model has no anchors
  int vhm_boundary = 1000;  // at most this many mesh vertices as boundary samples of VHM's smoothness term
  VhmParams vhm;
  // PWL(Tri)
  PwlTriParams tri;
  // Each method's solve this many times, the methods interleaved (lidef, PWL(Tet), lidef, PWL(Tet), ...) so
  // that a slow spell of the machine falls on all of them; the row's time is the median. The first run
  // gives the row's results; the others only time the solve (their meshing and preprocessing are not redone
  // where they are the same: the tet meshes are kept) and check that they end at the same map.
  int repeat = 1;
  // OpenBLAS threads of PWL(Tet)'s and PWL(Tri)'s CHOLMOD factorizations; 0: the run's threads, as in a
  // process that runs them alone. 1 runs BLAS in the calling thread, as lidef's own BLAS calls do: with
  // OpenBLAS's pthread workers beside the OpenMP loops either can be the faster, depending on the machine
  // (docs/compare.md, "Threads").
  int blas_threads = 0;
};

struct MethodResult {
  std::string method;
  bool ok = false;    // ran to a result (converged or not)
  std::string error;  // why not (when !ok)
  bool converged = false;
  std::string stop;  // its stop reason / message
  long dof = 0;
  double seconds = std::numeric_limits<double>::quiet_NaN();  // solve time (the table's "time")
  double preprocess_seconds =
      std::numeric_limits<double>::quiet_NaN();  // meshing, basis, subspace, factor setup
  int iterations = 0;
  double max_handle_error = std::numeric_limits<double>::quiet_NaN();
  // 1 when max_handle_error ≤ handle_tolerance × the model's size (as `lidef deform` judges), 0 not, -1
  // failed.
  int reached = -1;
  double mean_e_iso = std::numeric_limits<double>::quiet_NaN();  // mean of E_iso − 6 over mesh vertices
  double max_e_iso = std::numeric_limits<double>::quiet_NaN();   // max (+∞ if some vertex is inverted)
  // Harmonic methods (lidef, VHM): the volume-weighted mean of E_iso − 6 over the samples of lidef's
  // certified domain (the mesh's solid, or the grid with domain "voxels") — what lidef minimizes, on the same
  // samples for both; +∞ if some sample is inverted; NaN for the other methods.
  double mean_e_iso_solid = std::numeric_limits<double>::quiet_NaN();
  double volume_ratio = std::numeric_limits<double>::quiet_NaN();  // deformed / rest mesh volume (Fig. 12)
  double crease_deg = std::numeric_limits<double>::quiet_NaN();    // smoothness: see crease_measure
  long inverted = -1;           // PWL(Tet): tets with det J ≤ 0 (-1 = not applicable)
  long inverted_vertices = -1;  // volumetric methods: mesh vertices where det J ≤ 0 (-1 = not applicable)
  int certified = -1;  // harmonic methods: 1 certified locally injective, 0 not (-1 = not applicable)
  double min_sigma3 = std::numeric_limits<double>::quiet_NaN();  // min σ3 at the voxel centers
  double min_sigma3_bound =
      std::numeric_limits<double>::quiet_NaN();                  // certified lower bound (when certified)
  double time_ratio = std::numeric_limits<double>::quiet_NaN();  // seconds / lidef's seconds (same run)
  // CompareOptions::repeat > 1: every run's solve time in run order (`seconds` is their median), and whether
  // every run ended at the same map (bit for bit) in the same number of iterations (1 yes, 0 no, -1 one run).
  std::vector<double> run_seconds;
  int repeats_identical = -1;
  std::string detail;  // e.g. the tet mesh used
  // The deformed mesh (#V by 3) and, for volumetric methods, E_iso − 6 and det J (local volume ratio) per
  // vertex.
  MatX3d V;
  VecXd e_iso, det_j;
  MatX3d coefficients;  // harmonic methods (lidef, vhm): the map's #V+#F by 3 cage coefficients; else empty
  std::string log;      // one line per iteration
};

// Progress: (method, line) for every iteration and stage.
using CompareProgress = std::function<void(const std::string&, const std::string&)>;

// Runs opt.methods (lidef first when present, so the ratios are available) on the scenario's handles.
// Throws InputError for an unknown method name; a method's own failure is caught into its row.
std::vector<MethodResult> run_comparison(const Scenario& scenario, const Model& model,
                                         const CompareOptions& opt, const CompareProgress& progress = {});

// Smoothness of a deformed surface: root mean square over interior mesh edges of the change of the dihedral
// angle (deformed − rest), in degrees. A smooth map bending the surface by curvature κ changes each angle by
// about κh (h: mesh edge length); a piecewise-linear map with tets of size H puts the same bending into
// creases κH at a fraction h/H of the edges, so its RMS is larger by about √(H/h) (the mean would not tell
// them apart). rest: the mesh, deformed: #V by 3.
double crease_measure(const TriMesh& rest, const MatX3d& deformed);

// The table (one row per method, in run order): CSV with a header, and Markdown shaped like Table 1.
std::string comparison_table_csv(const std::vector<MethodResult>& rows);
std::string comparison_table_md(const std::vector<MethodResult>& rows, const Scenario& scenario);
// The CSV header's column names.
const std::vector<std::string>& comparison_table_columns();

}  // namespace lidef
