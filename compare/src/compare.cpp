#include "lidef/compare/compare.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "lidef/blas_kernel.h"
#include "lidef/continuation.h"
#include "lidef/domain_sampling.h"
#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/internal/median.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_fields.h"
#include "lidef/mesh_io.h"
#include "lidef/normalization.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/projected_newton.h"
#include "lidef/sampling.h"
#include "lidef/signed_svd.h"
#include "lidef/symmetric_dirichlet.h"

namespace lidef {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

void summarize_fields(MethodResult& r) {
  double sum = 0, mx = -std::numeric_limits<double>::infinity();
  long n = 0, bad = 0;
  for (Eigen::Index i = 0; i < r.e_iso.size(); ++i) {
    if (std::isnan(r.e_iso(i))) {
      ++bad;
      continue;
    }
    sum += r.e_iso(i);
    mx = std::max(mx, r.e_iso(i));
    ++n;
  }
  r.inverted_vertices = bad;
  r.mean_e_iso = n ? sum / n : kNaN;
  r.max_e_iso = bad ? std::numeric_limits<double>::infinity() : (n ? mx : kNaN);
}

// The fields of a method's map at the mesh vertices (positions, E_iso − 6, det J) and their summary.
void set_fields(MeshFields m, MethodResult& r) {
  r.V = std::move(m.V);
  r.e_iso = std::move(m.e_iso);
  r.det_j = std::move(m.det_j);
  summarize_fields(r);
}

// min σ3 over the voxel centers of a full-coefficient map.
double min_sigma3_at(const HarmonicBasis& basis, const MatX3d& y, const MatX3d& centers) {
  double mn = std::numeric_limits<double>::infinity();
#pragma omp parallel for reduction(min : mn) schedule(dynamic, 64)
  for (Eigen::Index i = 0; i < centers.rows(); ++i)
    mn = std::min(mn, signed_singular_values(basis.map_jet(y, centers.row(i).transpose(), 1).J)(2));
  return mn;
}

// Volume-weighted mean of E_iso − 6 over a sampling for a full-coefficient harmonic map (#V+#F by 3, model
// units); +∞ if some sample has det J ≤ 0. Fixed chunks added in order: the same bits for every run.
double solid_mean_e_iso(const HarmonicBasis& basis, const MatX3d& y, const VoxelSampling& vs) {
  constexpr int kChunk = 256;
  const int n = vs.size();
  const int chunks = (n + kChunk - 1) / kChunk;
  std::vector<double> sum(chunks, 0.0), weight(chunks, 0.0);
#pragma omp parallel for schedule(dynamic, 1)
  for (int c = 0; c < chunks; ++c)
    for (int i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const double w = vs.weight_of(i);
      sum[c] += w * (sd_energy(basis.map_jet(y, vs.centers.row(i).transpose(), 1).J) - 6.0);
      weight[c] += w;
    }
  double total = 0, total_weight = 0;
  for (int c = 0; c < chunks; ++c) {
    total += sum[c];
    total_weight += weight[c];
  }
  return total_weight > 0 ? total / total_weight : kNaN;
}

// State shared by the methods of one run: the harmonic basis, lidef's voxel sampling (the paper's grid, where
// the other methods' settings come from) and lidef's certified domain, built when first needed.
struct Shared {
  const Scenario& sc;
  const Model& model;
  const CompareOptions& opt;
  const CompareProgress& progress;
  std::unique_ptr<HarmonicBasis> basis;
  std::optional<VoxelSampling> sampling;
  const HarmonicBasis& get_basis() {
    if (!basis) basis = std::make_unique<HarmonicBasis>(model.cage);
    return *basis;
  }
  const VoxelSampling& get_sampling() {
    if (!sampling) sampling = sample_voxels(model.cage, sampling_params_of(sc.params));
    return *sampling;
  }
  std::optional<VoxelSampling> domain;  // the samples of lidef's certified domain (sc.params.domain)
  const VoxelSampling& get_domain_sampling() {
    if (!domain)
      domain = sample_for_domain(to_string(sc.params.domain), model.cage, model.mesh.V, model.mesh.F,
                                 sampling_params_of(sc.params));
    return *domain;
  }
  void say(const std::string& m, const std::string& line) {
    if (progress) progress(m, line);
  }
  // A repeated run (CompareOptions::repeat): the solve is timed and its map kept for the comparison with the
  // first run; the fields, certificates and measures of the row come from the first run.
  bool again = false;
  // PWL(Tet)'s meshes (coarse, fine) and their descriptions, made once per comparison.
  std::map<bool, std::pair<TetMesh, std::string>> tets;
};

void run_lidef(Shared& s, MethodResult& r) {
  const auto t0 = Clock::now();
  DeformationSolver solver(s.model.cage, s.model.mesh, s.sc.params, s.opt.cache_dir,
                           [&](const std::string& l) { s.say(r.method, l); });
  solver.set_handles(s.sc.sources, s.sc.targets, s.sc.path);
  r.preprocess_seconds = seconds_since(t0);
  // The same parameters give the same grid; the mesh domain's leaves (several sizes, a base side set by the
  // leaf count) are not the grid the other methods' settings derive from (fine TetGen volume, samples).
  if (!s.sampling && solver.sampling().domain == "voxels") s.sampling = solver.sampling();
  if (!s.domain) s.domain = solver.sampling();  // the same parameters give the same samples
  std::ostringstream log;
  log << "iteration,energy,step,certified,min_lower_bound,max_handle_error,ms\n";
  // The same path to the targets as `lidef deform` (continuation.h): the direct solve, and the continuation
  // when the scenario has waypoints, rotates a handle group far, or the direct solve stops short.
  PathSolveReport path;
  const SolveResult res = solve_to_targets(
      solver, s.sc.waypoints, s.sc.targets, s.sc.groups,
      [&](const IterationRecord& it) {
        log << it.iteration << ',' << format_double(it.terms.total) << ',' << format_double(it.step) << ','
            << (it.certified ? 1 : 0) << ',' << format_double(it.min_lower_bound) << ','
            << format_double(it.max_handle_error) << ',' << format_g(it.ms_total, 6) << "\n";
        s.say(r.method, "it " + std::to_string(it.iteration) + "  E " + format_g(it.terms.total, 7) +
                            "  step " + format_g(it.step, 3) + "  handle err " +
                            format_g(it.max_handle_error, 3) + "  " + format_g(it.ms_total, 4) + " ms");
        return true;
      },
      nullptr, [&](const std::string& line) { s.say(r.method, "-- " + line); }, &path);
  r.seconds = res.seconds;
  r.iterations = static_cast<int>(solver.history().size());
  r.converged = res.converged();
  r.stop = std::string(to_string(res.reason)) + (res.message.empty() ? "" : ": " + res.message);
  r.dof = 3L * solver.subspace().size();
  if (s.again) {
    r.coefficients = solver.coefficients();
    return;
  }
  const VecXd he = solver.handle_errors();
  r.max_handle_error = he.size() ? he.maxCoeff() : 0.0;
  const MatX3d y = solver.coefficients();
  r.coefficients = y;
  set_fields(mesh_fields(solver.basis(), y, s.model.mesh.V), r);
  r.mean_e_iso_solid = solid_mean_e_iso(solver.basis(), y, s.get_domain_sampling());
  const Certificate& cert = solver.certificate();
  r.certified = cert.certified ? 1 : 0;
  r.min_sigma3 = cert.min_sigma3_center;
  r.min_sigma3_bound = cert.certified ? cert.min_lower_bound : kNaN;
  std::string strategies;
  for (const std::string& t : path.strategies) strategies += (strategies.empty() ? "" : ", ") + t;
  r.detail = std::to_string(solver.sampling().size()) + " samples, " +
             std::to_string(solver.subspace().size()) + " reduced coefficients per coordinate; " +
             (strategies.empty() ? std::string("direct") : strategies) +
             (path.stages ? " (" + std::to_string(path.stages) + " stages)" : "");
  r.log = log.str();
}

// PWL(Tet)'s tet mesh; r.detail says which.
TetMesh pwl_tet_mesh(Shared& s, MethodResult& r, bool fine) {
  // Coarse: the model's tet mesh (Table 1's DOF) or TetGen of the cage; fine: TetGen's refinement (-r) of the
  // coarse mesh, which also works where the cage self-intersects slightly (animal) and TetGen -p cannot run.
  TetMesh tets;
  const std::filesystem::path node = std::filesystem::path(s.model.dir) / "tet.node",
                              ele = std::filesystem::path(s.model.dir) / "tet.ele";
  bool have_tets = false;
  if (s.opt.use_model_tets && !s.model.dir.empty() && std::filesystem::exists(node) &&
      std::filesystem::exists(ele)) {
    tets = read_tet_mesh(node.string(), ele.string());
    r.detail = "model tet mesh";
    have_tets = 3L * tets.num_vertices() >= s.opt.coarse_min_dof;
    if (!have_tets)
      s.say(r.method, "the model's tet mesh has " + std::to_string(3L * tets.num_vertices()) +
                          " DOF, fewer than the " + std::to_string(s.opt.coarse_min_dof) +
                          " asked for: TetGen instead");
  }
  if (!have_tets) {
    const TriMesh cage{s.model.cage.V, s.model.cage.F, s.model.cage.source};
    if (s.opt.coarse_min_dof > 0) {
      const int min_vertices = static_cast<int>((s.opt.coarse_min_dof + 2) / 3);
      TetgenForVertices found = tetrahedralize_min_vertices(cage, s.opt.coarse_tet, min_vertices);
      tets = std::move(found.mesh);
      r.detail = "TetGen " + tetgen_switches(found.options) + " (max volume searched in " +
                 std::to_string(found.meshings) + " meshings for >= " + std::to_string(s.opt.coarse_min_dof) +
                 " DOF)";
    } else {
      tets = tetrahedralize(cage, s.opt.coarse_tet);
      r.detail = "TetGen " + tetgen_switches(s.opt.coarse_tet);
    }
  }
  if (fine) {
    TetgenOptions o = s.opt.fine_tet;
    if (o.max_volume <= 0) o.max_volume = s.opt.fine_volume_factor * std::pow(s.get_sampling().side, 3);
    s.say(r.method, "TetGen " + tetgen_switches(o, true) + " of the " + r.detail);
    try {
      tets = refine_tet_mesh(tets, o);
      r.detail = "TetGen " + tetgen_switches(o, true) + " of the " + r.detail;
    } catch (const NumericalError& e) {
      // TetGen's refinement crashes on some meshes (the horse's: a failed assertion on coplanar points); the
      // cage itself may still be tetrahedralized directly.
      s.say(r.method, std::string(e.what()) + "; tetrahedralizing the cage instead");
      const TriMesh cage{s.model.cage.V, s.model.cage.F, s.model.cage.source};
      tets = tetrahedralize(cage, o);
      r.detail =
          "TetGen " + tetgen_switches(o) + " of the cage (refining the " + r.detail + " crashed TetGen)";
    }
  }
  r.detail +=
      ": " + std::to_string(tets.num_vertices()) + " vertices, " + std::to_string(tets.num_tets()) + " tets";
  return tets;
}

// CHOLMOD's BLAS threads for PWL(Tet) and PWL(Tri): by default the run's threads, as in a process that runs
// them alone (after lidef it would inherit one thread: use_blas_in_calling_thread).
int cholmod_blas_threads(const CompareOptions& opt) {
  return opt.blas_threads > 0 ? opt.blas_threads : omp_get_max_threads();
}

void run_pwl_tet(Shared& s, MethodResult& r, bool fine) {
  const ScopedBlasThreads blas(cholmod_blas_threads(s.opt));
  const auto t0 = Clock::now();
  auto kept = s.tets.find(fine);
  if (kept == s.tets.end()) {
    TetMesh made = pwl_tet_mesh(s, r, fine);
    kept = s.tets.emplace(fine, std::make_pair(std::move(made), r.detail)).first;
  }
  const TetMesh& tets = kept->second.first;
  r.detail = kept->second.second;
  s.say(r.method, r.detail);
  s.say(r.method, "CHOLMOD's BLAS threads: " + std::to_string(blas.active()));
  const TetEmbedding mesh_embedding =
      embed_points(tets, s.model.mesh.V, s.model.dir + ": PWL(Tet) mesh vertex");
  const auto W = mesh_embedding.weights();
  PwlTetParams p;
  p.lambda_p2p = s.sc.params.lambda_p2p;
  p.energy_tolerance = s.sc.params.energy_tolerance;
  p.step_tolerance = s.sc.params.step_tolerance;
  p.armijo = s.sc.params.armijo;
  p.max_iterations = s.opt.tet_max_iterations;
  PwlTetSolver solver(tets, p);
  solver.set_handles(s.sc.sources, s.sc.targets, s.sc.path);
  r.preprocess_seconds = seconds_since(t0);
  std::ostringstream log;
  log << "iteration,energy,e_dis,e_p2p,newton_decrement,direction_norm,step,halvings,max_handle_error,ms\n";
  const PwlTetResult res = solver.solve([&](const PwlTetIteration& it) {
    log << it.iteration << ',' << format_double(it.energy) << ',' << format_double(it.e_dis) << ','
        << format_double(it.e_p2p) << ',' << format_double(it.newton_decrement) << ','
        << format_double(it.direction_norm) << ',' << format_double(it.step) << ',' << it.halvings << ','
        << format_double(it.max_handle_error) << ',' << format_g(it.ms, 6) << "\n";
    s.say(r.method, "it " + std::to_string(it.iteration) + "  E " + format_g(it.energy, 7) + "  step " +
                        format_g(it.step, 3) + "  handle err " + format_g(it.max_handle_error, 3) + "  " +
                        format_g(it.ms, 4) + " ms");
    return true;
  });
  r.seconds = res.seconds;
  r.iterations = res.iterations;
  r.converged = res.converged;
  r.stop = res.message;
  r.dof = solver.dof();
  if (s.again) {
    r.V = W * solver.positions();
    return;
  }
  r.max_handle_error = solver.handle_errors().maxCoeff();
  const MatX3d& X = solver.positions();
  r.inverted = solver.inverted_count(X);
  const Eigen::Index n = s.model.mesh.V.rows();
  MatXd JT(3 * n, 3);  // J of the vertex's tet, transposed
  for (Eigen::Index i = 0; i < n; ++i)
    JT.middleRows(3 * i, 3) = solver.jacobian(X, mesh_embedding.tet(i)).transpose();
  set_fields(mesh_fields(W * X, JT), r);
  r.log = log.str();
}

void run_vhm(Shared& s, MethodResult& r) {
  const auto t0 = Clock::now();
  MatX3d anchors;
  const std::filesystem::path model_anchors = std::filesystem::path(s.model.dir) / "vhm_anchors.xyz";
  if (!s.opt.anchors.empty()) {
    anchors = read_points_xyz(s.opt.anchors);
    r.detail = std::to_string(anchors.rows()) + " anchors from " + s.opt.anchors;
  } else if (!s.model.dir.empty() && std::filesystem::exists(model_anchors)) {
    anchors = read_points_xyz(model_anchors.string());
    r.detail = std::to_string(anchors.rows()) + " anchors (vhm_anchors.xyz)";
  } else {
    // No medial samples: evenly spread voxel centers (the "modified VHM" of the paper's Fig. 11).
    const VoxelSampling& vs = s.get_sampling();
    const double frac = std::min(1.0, static_cast<double>(s.opt.anchor_count) / std::max(1, vs.size()));
    const std::vector<int> pick = select_hessian_subset(vs, frac);
    anchors.resize(static_cast<Eigen::Index>(pick.size()), 3);
    for (size_t k = 0; k < pick.size(); ++k)
      anchors.row(static_cast<Eigen::Index>(k)) = vs.centers.row(pick[k]);
    r.detail = std::to_string(anchors.rows()) + " anchors (evenly spread voxel centers)";
  }
  const HarmonicBasis& basis = s.get_basis();
  VhmParams p = s.opt.vhm;
  p.lambda_p2p = s.sc.params.lambda_p2p;
  // Boundary samples of the smoothness term: mesh vertices, every k-th so that there are at most
  // vhm_boundary.
  const Eigen::Index nm = s.model.mesh.V.rows();
  const Eigen::Index stride =
      std::max<Eigen::Index>(1, (nm + s.opt.vhm_boundary - 1) / std::max(1, s.opt.vhm_boundary));
  MatX3d boundary((nm + stride - 1) / stride, 3);
  for (Eigen::Index i = 0, k = 0; i < nm; i += stride, ++k) boundary.row(k) = s.model.mesh.V.row(i);
  r.detail += ", " + std::to_string(boundary.rows()) + " mesh vertices as boundary samples";
  VhmSolver solver(s.model.cage, basis, anchors, boundary, p, s.model.dir + "/vhm_anchors.xyz");
  solver.set_handles(s.sc.sources, s.sc.targets, s.sc.path);
  r.preprocess_seconds = seconds_since(t0);
  std::ostringstream log;
  log << "iteration,energy,e_rigid,e_smooth,e_p2p,max_handle_error,ms\n";
  const VhmResult res = solver.solve([&](const VhmIteration& it) {
    log << it.iteration << ',' << format_double(it.energy) << ',' << format_double(it.e_rigid) << ','
        << format_double(it.e_smooth) << ',' << format_double(it.e_p2p) << ','
        << format_double(it.max_handle_error) << ',' << format_g(it.ms, 6) << "\n";
    if (it.iteration <= 3 || it.iteration % 50 == 0)
      s.say(r.method, "it " + std::to_string(it.iteration) + "  E " + format_g(it.energy, 7) +
                          "  handle err " + format_g(it.max_handle_error, 3) + "  " + format_g(it.ms, 4) +
                          " ms");
    return true;
  });
  r.seconds = res.seconds;
  r.iterations = res.iterations;
  r.converged = res.converged;
  r.stop = res.message;
  r.dof = solver.dof();
  r.coefficients = solver.coefficients();
  if (s.again) return;
  r.max_handle_error = solver.handle_errors().maxCoeff();
  set_fields(mesh_fields(basis, solver.coefficients(), s.model.mesh.V), r);
  r.mean_e_iso_solid = solid_mean_e_iso(basis, solver.coefficients(), s.get_domain_sampling());
  // Fig. 11: lidef's certificate on lidef's voxels judges VHM's injectivity (not part of VHM's time).
  s.say(r.method, "certifying the result");
  const VoxelSampling& vs = s.get_sampling();
  r.min_sigma3 = min_sigma3_at(basis, solver.coefficients(), vs.centers);
  if (r.min_sigma3 > 0) {
    NormalizedCertifier certifier(s.model.cage, vs);  // in the frame lidef's own runs are certified in
    const Certificate cert =
        certifier.certify(solver.coefficients(), certify_params_of(s.sc.params, true, false));
    r.certified = cert.certified ? 1 : 0;
    if (cert.certified) r.min_sigma3_bound = cert.min_lower_bound;
  } else {
    r.certified = 0;  // σ3 ≤ 0 at a voxel center: not locally injective there
  }
  r.log = log.str();
}

void run_pwl_tri(Shared& s, MethodResult& r) {
  const ScopedBlasThreads blas(cholmod_blas_threads(s.opt));
  const auto t0 = Clock::now();
  PwlTriParams p = s.opt.tri;
  p.lambda_p2p = s.sc.params.lambda_p2p;
  SrArapSolver solver(s.model.mesh, p);
  solver.set_handles(s.sc.sources, s.sc.targets, s.sc.path);
  r.preprocess_seconds = seconds_since(t0);
  std::ostringstream log;
  log << "iteration,energy_after_rotations,energy,max_handle_error,ms\n";
  const PwlTriResult res = solver.solve([&](const PwlTriIteration& it) {
    log << it.iteration << ',' << format_double(it.energy_after_local) << ',' << format_double(it.energy)
        << ',' << format_double(it.max_handle_error) << ',' << format_g(it.ms, 6) << "\n";
    if (it.iteration <= 3 || it.iteration % 50 == 0)
      s.say(r.method, "it " + std::to_string(it.iteration) + "  E " + format_g(it.energy, 7) +
                          "  handle err " + format_g(it.max_handle_error, 3) + "  " + format_g(it.ms, 4) +
                          " ms");
    return true;
  });
  r.seconds = res.seconds;
  r.iterations = res.iterations;
  r.converged = res.converged;
  r.stop = res.message;
  r.dof = solver.dof();
  r.V = solver.positions();
  if (s.again) return;
  r.max_handle_error = solver.handle_errors().maxCoeff();
  r.detail = std::to_string(s.model.mesh.V.rows()) + " mesh vertices";
  r.log = log.str();
}

// "reached": the handles are within the tolerance although the method's own convergence test did not pass.
std::string status_of(const MethodResult& r) {
  return !r.ok ? "failed" : r.converged ? "converged" : r.reached == 1 ? "reached" : "stopped";
}
}  // namespace

const std::vector<std::string>& compare_methods() {
  static const std::vector<std::string> m = {"lidef", "pwl-tet", "pwl-tet-fine", "vhm", "pwl-tri"};
  return m;
}

double crease_measure(const TriMesh& rest, const MatX3d& X) {
  // Interior edges: pairs of faces sharing an (unordered) edge.
  std::map<std::pair<int, int>, std::vector<int>> edge_faces;
  for (Eigen::Index f = 0; f < rest.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = rest.F(f, k), b = rest.F(f, (k + 1) % 3);
      edge_faces[{std::min(a, b), std::max(a, b)}].push_back(static_cast<int>(f));
    }
  auto normal = [&](const MatX3d& V, int f) {
    const Vec3 a = V.row(rest.F(f, 0)), b = V.row(rest.F(f, 1)), c = V.row(rest.F(f, 2));
    return Vec3((b - a).cross(c - a).normalized());
  };
  double sum = 0;
  long n = 0;
  for (const auto& [e, fs] : edge_faces) {
    if (fs.size() != 2) continue;
    const double a0 = std::acos(std::clamp(normal(rest.V, fs[0]).dot(normal(rest.V, fs[1])), -1.0, 1.0));
    const double a1 = std::acos(std::clamp(normal(X, fs[0]).dot(normal(X, fs[1])), -1.0, 1.0));
    if (!std::isfinite(a0) || !std::isfinite(a1)) continue;
    sum += (a1 - a0) * (a1 - a0);
    ++n;
  }
  return n ? std::sqrt(sum / n) * 180.0 / M_PI : kNaN;
}

namespace {
// Runs method m once into r (a failure is caught into the row).
void run_method(Shared& s, const std::string& m, MethodResult& r) {
  r.method = m;
  try {
    if (m == "lidef")
      run_lidef(s, r);
    else if (m == "pwl-tet")
      run_pwl_tet(s, r, false);
    else if (m == "pwl-tet-fine")
      run_pwl_tet(s, r, true);
    else if (m == "vhm")
      run_vhm(s, r);
    else
      run_pwl_tri(s, r);
    r.ok = true;
  } catch (const std::exception& e) {
    r = MethodResult();
    r.method = m;
    r.ok = false;
    r.error = e.what();
  }
}

// A repeated run of first's method: its time, and whether it ended where the first run did (the harmonic
// methods' coefficients, the others' mesh vertices).
void add_repeat(MethodResult& first, const MethodResult& again) {
  if (!first.ok) return;
  const bool harmonic = first.coefficients.size() > 0;
  const MatX3d& a = harmonic ? first.coefficients : first.V;
  const MatX3d& b = harmonic ? again.coefficients : again.V;
  const bool same = again.ok && again.iterations == first.iterations && a.rows() == b.rows() && a == b;
  if (again.ok) first.run_seconds.push_back(again.seconds);  // a failed run has no time to count
  if (!same) first.repeats_identical = 0;
}

}  // namespace

std::vector<MethodResult> run_comparison(const Scenario& sc, const Model& model, const CompareOptions& opt,
                                         const CompareProgress& progress) {
  for (const std::string& m : opt.methods)
    if (std::find(compare_methods().begin(), compare_methods().end(), m) == compare_methods().end())
      throw InputError("--methods",
                       "unknown method '" + m + "' (known: lidef, pwl-tet, pwl-tet-fine, vhm, pwl-tri)");
  if (opt.repeat < 1) throw InputError("--repeat", "must be at least 1, not " + std::to_string(opt.repeat));
  std::vector<std::string> order;
  for (const std::string& m : compare_methods())  // table order; lidef first
    if (std::find(opt.methods.begin(), opt.methods.end(), m) != opt.methods.end()) order.push_back(m);
  Shared s{sc, model, opt, progress, nullptr, std::nullopt, std::nullopt, false, {}};
  std::vector<MethodResult> rows;
  const double rest_volume = signed_volume(model.mesh.V, model.mesh.F);
  // "Reached" means what `lidef deform` means: max handle error within handle_tolerance of the model's size.
  const double handle_tolerance = sc.params.handle_tolerance * Frame::of(model.cage).scale;
  for (const std::string& m : order) {
    MethodResult r;
    s.say(m, opt.repeat > 1 ? "starting (run 1 of " + std::to_string(opt.repeat) + ")" : "starting");
    run_method(s, m, r);
    if (r.ok) {
      r.reached = r.max_handle_error <= handle_tolerance ? 1 : 0;
      r.volume_ratio = signed_volume(r.V, model.mesh.F) / rest_volume;
      r.crease_deg = crease_measure(model.mesh, r.V);
      s.say(m, status_of(r) + " (" + r.stop + ") after " + std::to_string(r.iterations) + " iterations, " +
                   format_g(r.seconds, 3) + " s");
    } else {
      s.say(m, "FAILED: " + r.error);
    }
    rows.push_back(std::move(r));
  }
  // The repeats, the methods interleaved: run k of every method before run k + 1 of any.
  s.again = true;
  for (MethodResult& r : rows)
    if (r.ok && opt.repeat > 1) {
      r.run_seconds = {r.seconds};
      r.repeats_identical = 1;
    }
  for (int k = 2; k <= opt.repeat; ++k)
    for (MethodResult& r : rows) {
      if (!r.ok) continue;
      MethodResult again;
      run_method(s, r.method, again);
      add_repeat(r, again);
      s.say(r.method,
            "run " + std::to_string(k) + " of " + std::to_string(opt.repeat) + ": " +
                (again.ok ? std::to_string(again.iterations) + " iterations, " + format_g(again.seconds, 3) +
                                " s" + (r.repeats_identical == 0 ? " (NOT the first run's map)" : "")
                          : "FAILED: " + again.error));
    }
  for (MethodResult& r : rows)
    if (r.ok && r.run_seconds.size() > 1) r.seconds = median(r.run_seconds);
  double lidef_s = kNaN;
  for (const MethodResult& r : rows)
    if (r.method == "lidef" && r.ok) lidef_s = r.seconds;
  for (MethodResult& r : rows)
    if (r.ok) r.time_ratio = r.seconds / lidef_s;
  return rows;
}

const std::vector<std::string>& comparison_table_columns() {
  static const std::vector<std::string> c = {"method",
                                             "status",
                                             "dof",
                                             "time_s",
                                             "preprocess_s",
                                             "iterations",
                                             "converged",
                                             "max_handle_error",
                                             "reached",
                                             "mean_e_iso_minus_6",
                                             "max_e_iso_minus_6",
                                             "mean_e_iso_minus_6_solid",
                                             "global_volume_ratio",
                                             "inverted_elements",
                                             "inverted_mesh_vertices",
                                             "certified",
                                             "min_sigma3",
                                             "min_sigma3_lower_bound",
                                             "crease_deg",
                                             "local_volume_ratio_min",
                                             "local_volume_ratio_max",
                                             "local_volume_change_mean",
                                             "time_ratio_to_lidef",
                                             "detail",
                                             "error",
                                             "repeats",
                                             "time_s_min",
                                             "time_s_max",
                                             "repeats_identical"};
  return c;
}

namespace {
std::string num(double x) {
  if (std::isnan(x)) return "";
  if (std::isinf(x)) return x > 0 ? "inf" : "-inf";
  return format_g(x, 6);
}
std::string csv_quote(const std::string& s) {
  std::string q = "\"";
  for (char c : s) {
    if (c == '"') q += '"';
    q += (c == '\n' ? ' ' : c);
  }
  return q + "\"";
}
// det J over the mesh vertices (the local volume ratio of Fig. 12): min, max and mean |det J − 1|; NaN for
// the surface method, which has no det J.
struct LocalVolume {
  double min = std::numeric_limits<double>::quiet_NaN(), max = min, mean_change = min;
};
LocalVolume local_volume(const MethodResult& r) {
  LocalVolume v;
  if (!r.ok || r.det_j.size() == 0) return v;
  v.min = r.det_j.minCoeff();
  v.max = r.det_j.maxCoeff();
  v.mean_change = (r.det_j.array() - 1.0).abs().mean();
  return v;
}

// The fastest and slowest run's solve time (the one run's when not repeated).
double min_of(const MethodResult& r) {
  return r.run_seconds.empty() ? r.seconds : *std::min_element(r.run_seconds.begin(), r.run_seconds.end());
}
double max_of(const MethodResult& r) {
  return r.run_seconds.empty() ? r.seconds : *std::max_element(r.run_seconds.begin(), r.run_seconds.end());
}
}  // namespace

std::string comparison_table_csv(const std::vector<MethodResult>& rows) {
  std::ostringstream s;
  const auto& cols = comparison_table_columns();
  for (size_t k = 0; k < cols.size(); ++k) s << (k ? "," : "") << cols[k];
  s << "\n";
  for (const MethodResult& r : rows) {
    const LocalVolume lv = local_volume(r);
    s << r.method << ',' << status_of(r) << ',' << (r.ok ? std::to_string(r.dof) : "") << ','
      << num(r.seconds) << ',' << num(r.preprocess_seconds) << ','
      << (r.ok ? std::to_string(r.iterations) : "") << ',' << (r.ok ? (r.converged ? "1" : "0") : "") << ','
      << num(r.max_handle_error) << ',' << (r.ok ? std::to_string(r.reached) : "") << ',' << num(r.mean_e_iso)
      << ',' << num(r.max_e_iso) << ',' << num(r.mean_e_iso_solid) << ',' << num(r.volume_ratio) << ','
      << (r.inverted >= 0 ? std::to_string(r.inverted) : "") << ','
      << (r.inverted_vertices >= 0 ? std::to_string(r.inverted_vertices) : "") << ','
      << (r.certified >= 0 ? std::to_string(r.certified) : "") << ',' << num(r.min_sigma3) << ','
      << num(r.min_sigma3_bound) << ',' << num(r.crease_deg) << ',' << num(lv.min) << ',' << num(lv.max)
      << ',' << num(lv.mean_change) << ',' << num(r.time_ratio) << ',' << csv_quote(r.detail) << ','
      << csv_quote(r.error) << ',' << (r.ok ? std::to_string(std::max<size_t>(1, r.run_seconds.size())) : "")
      << ',' << num(min_of(r)) << ',' << num(max_of(r)) << ','
      << (r.repeats_identical >= 0 ? std::to_string(r.repeats_identical) : "") << "\n";
  }
  return s.str();
}

std::string comparison_table_md(const std::vector<MethodResult>& rows, const Scenario& sc) {
  std::ostringstream s;
  auto cell = [](double x, int p = 3) {
    return std::isnan(x) ? std::string("—") : std::isinf(x) ? std::string("∞") : format_g(x, p);
  };
  s << "# " << sc.name << " — comparison (paper Table 1)\n\n"
    << "| method | DOF | time (s) | time / lidef | iterations | status | max handle error | reached | mean "
       "E_iso−6 | "
       "max E_iso−6 | mean E_iso−6 (solid) | global volume ratio | inverted tets | mesh vertices det J ≤ 0 | "
       "certified | min σ3 (samples) | crease (°) |\n"
    << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const MethodResult& r : rows) {
    if (!r.ok) {
      s << "| " << r.method << " | — | — | — | — | FAILED: " << r.error
        << " | — | — | — | — | — | — | — | — | — | — | — |\n";
      continue;
    }
    s << "| " << r.method << " | " << r.dof << " | " << cell(r.seconds) << " | " << cell(r.time_ratio, 3)
      << " | " << r.iterations << " | " << status_of(r) << " | " << cell(r.max_handle_error) << " | "
      << (r.reached ? "yes" : "no") << " | " << cell(r.mean_e_iso) << " | " << cell(r.max_e_iso) << " | "
      << cell(r.mean_e_iso_solid) << " | " << cell(r.volume_ratio, 4) << " | "
      << (r.inverted >= 0 ? std::to_string(r.inverted) : "—") << " | "
      << (r.inverted_vertices >= 0 ? std::to_string(r.inverted_vertices) : "—") << " | "
      << (r.certified < 0 ? "—"
          : r.certified   ? "yes"
                          : "NO")
      << " | " << cell(r.min_sigma3) << " | " << cell(r.crease_deg) << " |\n";
  }
  size_t runs = 1;
  for (const MethodResult& r : rows) runs = std::max(runs, r.run_seconds.size());
  s << "\nTime = solve time "
    << (runs > 1 ? "(the median of " + std::to_string(runs) +
                       " runs, the methods interleaved; each run's time in "
                       "table.csv)"
                 : std::string("in this run"))
    << " (preprocessing excluded; see table.csv). Details:\n\n";
  for (const MethodResult& r : rows)
    if (r.ok) s << "- " << r.method << ": " << r.detail << "; " << r.stop << "\n";
  return s.str();
}

}  // namespace lidef
