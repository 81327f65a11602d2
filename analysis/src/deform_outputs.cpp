#include "lidef/analysis/deform_outputs.h"

#include <omp.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/mesh_export.h"
#include "lidef/analysis/vtk_export.h"
#include "lidef/atomic_file.h"
#include "lidef/coefficients.h"
#include "lidef/gaussian_splats.h"
#include "lidef/geometry.h"
#include "lidef/green_coordinates.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/point_cloud_io.h"
#include "lidef/staged_outputs.h"

namespace lidef {

namespace fs = std::filesystem;

const char* const kIterationsHeader =
    "iteration,energy_before,energy,e_dis,e_p2p,e_smooth,lambda_p2p,lambda_smooth,gradient_norm,step,step_"
    "norm,"
    "armijo_rejections,certificate_rejections,accepted,certified,min_sigma3_sampled,min_lower_bound,refined,"
    "max_handle_error,weight_action,ms_gradient,ms_hessian,ms_solve,ms_line_search,ms_certificate,ms_total,"
    "cg_steps,cg_scale";

std::string iteration_row(const IterationRecord& r) {
  std::ostringstream s;
  auto d = [](double x) { return format_double(x); };
  s << r.iteration << ',' << d(r.energy_before) << ',' << d(r.terms.total) << ',' << d(r.terms.dis) << ','
    << d(r.terms.p2p) << ',' << d(r.terms.smooth) << ',' << d(r.lambda_p2p) << ',' << d(r.lambda_smooth)
    << ',' << d(r.gradient_norm) << ',' << d(r.step) << ',' << d(r.step_norm) << ',' << r.armijo_rejections
    << ',' << r.certificate_rejections << ',' << (r.accepted ? 1 : 0) << ',' << (r.certified ? 1 : 0) << ','
    << d(r.min_sigma3) << ',' << d(r.min_lower_bound) << ',' << r.refined << ',' << d(r.max_handle_error)
    << ',' << '"' << r.weight_action << '"' << ',' << format_g(r.ms_gradient, 6) << ','
    << format_g(r.ms_hessian, 6) << ',' << format_g(r.ms_solve, 6) << ',' << format_g(r.ms_line_search, 6)
    << ',' << format_g(r.ms_certificate, 6) << ',' << format_g(r.ms_total, 6) << ',' << r.cg_steps << ','
    << d(r.cg_scale);
  return s.str();
}

namespace {

nlohmann::ordered_json summary_json(const Scenario& sc, const DeformResult& r,
                                    const CertificateReport& report, double volume_ratio,
                                    double total_seconds) {
  const Certificate& cert = r.certificate;
  nlohmann::ordered_json sj;
  sj["scenario"] = sc.name;
  sj["model"] = sc.model;
  sj["converged"] = r.solve.converged();
  sj["stop_reason"] = to_string(r.solve.reason);
  const PathSolveReport& path = r.path;
  sj["continuation"] = {
      {"strategies", path.strategies},          {"intermediate_stages", path.stages},
      {"shortened_stages", path.stage_retries}, {"max_group_rotation_deg", path.max_angle_deg},
      {"path_segments", path.segments},         {"path_reached", path.path_reached}};
  const UnreachabilityProof& un = path.unreachable;
  sj["unreachable"] = {{"proven", un.proven},
                       {"kind", un.kind},
                       {"reason", un.reason},
                       {"handle_matrix_condition", un.condition},
                       {"least_squares_residual", un.residual},
                       {"least_squares_residual_lower_bound", un.residual_lower},
                       {"least_squares_residual_upper_bound", un.residual_upper},
                       {"residual_rounding_floor", un.rounding_floor}};
  if (un.kind == "orientation")
    sj["unreachable"]["fold"] = {{"point", {un.point.x(), un.point.y(), un.point.z()}},
                                 {"sigma_min_least_squares", un.sigma_min},
                                 {"jacobian_change_bound", un.jacobian_bound}};
  sj["message"] = r.solve.message;
  sj["iterations"] = r.iterations;
  sj["certified"] = cert.certified;
  // Global injectivity on D (certificate.json has the same three fields).
  const GlobalInjectivity& g = report.global;
  sj["globally_injective"] =
      g.verdict == GlobalInjectivity::Verdict::kInjective ? nlohmann::ordered_json(true)
      : g.verdict == GlobalInjectivity::Verdict::kOverlap ? nlohmann::ordered_json(false)
                                                          : nlohmann::ordered_json();
  sj["global_reason"] = g.reason;
  sj["overlap_point"] =
      g.verdict == GlobalInjectivity::Verdict::kOverlap
          ? nlohmann::ordered_json{g.overlap_point.x(), g.overlap_point.y(), g.overlap_point.z()}
          : nlohmann::ordered_json();
  sj["min_sigma3_lower_bound"] = cert.min_lower_bound;
  sj["min_sigma3_sampled"] = cert.min_sigma3_center;
  // Bounded distortion: the certified upper bounds over the leaves, the sampled maximum over the mesh
  // vertices, and the target (max_distortion, 0: none).
  sj["max_sigma1_upper_bound"] = cert.max_sigma1_upper_bound;
  sj["max_distortion_upper_bound"] = cert.max_distortion_upper_bound;
  double max_k_vertices = 0;  // NaN (σ3 ≤ 0) never occurs at a certified map's covered vertices
  for (Eigen::Index i = 0; i < r.distortion.size(); ++i)
    if (std::isfinite(r.distortion(i))) max_k_vertices = std::max(max_k_vertices, r.distortion(i));
  sj["max_distortion_vertices"] = max_k_vertices;
  sj["max_distortion"] = sc.params.max_distortion;
  sj["mesh_coverage"] = report.mesh_coverage;
  sj["domain"] = report.domain;
  if (report.domain == "mesh") sj["domain_statement"] = report.domain_statement;
  sj["max_handle_error"] = r.max_handle_error;
  sj["handles_reached"] = r.handles_reached;
  sj["handle_tolerance"] = sc.params.handle_tolerance;
  sj["handle_tolerance_model_units"] = r.handle_tolerance;
  sj["frame"] = {{"center", {r.frame.center.x(), r.frame.center.y(), r.frame.center.z()}},
                 {"scale", r.frame.scale}};
  sj["global_volume_ratio"] = volume_ratio;
  sj["energy"] = {
      {"total", r.energy.total}, {"dis", r.energy.dis}, {"p2p", r.energy.p2p}, {"smooth", r.energy.smooth}};
  sj["final_weights"] = {{"lambda_p2p", r.weights.p2p}, {"lambda_smooth", r.weights.smooth}};
  sj["dof"] = r.dof;
  sj["samples"] = r.sampling.size();
  sj["hessian_samples"] = r.hessian_samples;
  sj["handles"] = static_cast<int>(r.handle_errors.size());
  sj["time_s"] = {{"preprocess", r.preprocess_seconds},
                  {"solve", r.solve.seconds},
                  {"final_certificate_and_fields", r.finish_seconds},
                  {"total", total_seconds >= 0 ? total_seconds
                                               : r.preprocess_seconds + r.solve.seconds + r.finish_seconds}};
  sj["threads"] = omp_get_max_threads();
  sj["backend"] = r.backend;
  sj["parameters"] = params_to_json(sc.params);
  return sj;
}

// J(p_i)ᵀ at the points P (#P by 3) as 3#P by 3 (mesh_fields.h's layout), a block of points at a time so that
// the basis gradients (3 rows per point, #V+#F columns) stay small for large clouds.
MatXd jacobians_at(const HarmonicBasis& basis, const MatX3d& y, const MatX3d& P) {
  MatXd JT(3 * P.rows(), 3);
  const Eigen::Index block = 4096;
  for (Eigen::Index b = 0; b < P.rows(); b += block) {
    const Eigen::Index n = std::min(block, P.rows() - b);
    JT.middleRows(3 * b, 3 * n) = basis.gradient_matrix(P.middleRows(b, n)) * y;
  }
  return JT;
}

// deformed.ply's content: the input PLY with its points mapped (mapped: f at the model's mesh vertices),
// normals by the cofactor matrix, Gaussian splats' covariances and view-dependent colour by J
// (gaussian_splats.h); every other property as read. False (nothing to write) when the PLY's vertices are not
// the model's mesh vertices in the same order (a PLY mesh whose unused vertices the cage maker dropped).
bool deformed_ply(const std::string& ply, const Model& model, const MatX3d& y, const MatX3d& mapped,
                  PlyCloud* cloud) {
  *cloud = read_ply_cloud(ply);
  const MatX3d P = cloud->points();
  if (P.rows() != model.mesh.V.rows() || P != model.mesh.V) return false;
  const MatXd JT = jacobians_at(HarmonicBasis(model.cage), y, P);
  if (is_gaussian_splat_cloud(*cloud))
    map_gaussian_splats(*cloud, mapped, JT);
  else
    map_point_cloud(*cloud, mapped, JT);
  return true;
}

}  // namespace

std::string source_ply(const Model& model, const Scenario& scenario) {
  auto is_ply = [](const std::string& p) {
    std::string ext = fs::path(p).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    return ext == ".ply";
  };
  std::error_code ec;
  if (is_ply(scenario.model_dir) && fs::is_regular_file(scenario.model_dir, ec)) return scenario.model_dir;
  const fs::path json = fs::path(model.dir) / "model.json";
  if (model.dir.empty() || !fs::is_regular_file(json, ec)) return "";
  std::ifstream in(json);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.contains("input") || !j["input"].contains("file") ||
      !j["input"]["file"].is_string())
    return "";
  const std::string file = j["input"]["file"];
  return is_ply(file) && fs::is_regular_file(file, ec) ? file : "";
}

DeformOutputs write_deform_outputs(const std::string& dir, const Model& model, const Scenario& scenario,
                                   const DeformResult& r, const DeformOutputOptions& options) {
  const MatX3d& y = r.coefficients;
  CertificateReport report =
      make_certificate_report(r.certificate, model.cage, model.mesh, y, scenario.model_dir,
                              "coefficients.txt", r.sampling_params, r.sampling, r.certify_params);
  const double volume_ratio =
      signed_volume(r.deformed_vertices, model.mesh.F) / signed_volume(model.mesh.V, model.mesh.F);
  DeformOutputs written;
  written.mesh_coverage = report.mesh_coverage;
  written.global = report.global;
  written.volume_ratio = volume_ratio;
  written.dir = dir;
  std::vector<std::string>& names = written.files;
  names = {"coefficients.txt", "deformed.obj",   "deformed.vtp", "certificate.json", "voxels.csv",
           "leaves.vtu",       "iterations.csv", "summary.json", "scenario.json"};
  StagedOutputs out(dir);
  write_file_atomic(out.path("coefficients.txt"), [&](std::ostream& s) { write_coefficients(s, y); });
  // The cage the coefficients belong to, so that the folder can be used on its own.
  write_file_atomic(out.path("cage.obj"), [&](std::ostream& s) {
    write_obj(s, model.cage.V, model.cage.F,
              "lidef deform " + scenario.name + ": the cage of coefficients.txt");
  });
  names.insert(names.begin() + 1, "cage.obj");
  const std::string ply = source_ply(model, scenario);
  PlyCloud cloud;
  if (!ply.empty() && deformed_ply(ply, model, y, r.deformed_vertices, &cloud)) {
    write_file_atomic(out.path("deformed.ply"), [&](std::ostream& s) { write_ply_cloud(s, cloud); });
    names.push_back("deformed.ply");
  }
  write_file_atomic(out.path("deformed.obj"), [&](std::ostream& s) {
    write_obj(s, r.deformed_vertices, model.mesh.F, "lidef deform " + scenario.name + ": last certified map");
  });
  write_mesh_vtp(out.path("deformed.vtp"), r.deformed_vertices, model.mesh.F,
                 {{"E_iso_minus_6", r.e_iso},
                  {"detJ", r.det_j},
                  {"sigma3", r.sigma3},
                  {"sigma1", r.sigma1},
                  {"distortion", r.distortion}});
  out.path("certificate.json");
  out.path("voxels.csv");
  write_certificate_files(out.staging_dir(), report);
  write_leaves_vtu(out.path("leaves.vtu"), r.certificate.leaves);
  if (options.grid > 0) {
    write_field_vti(out.path("field.vti"), model.cage, HarmonicBasis(model.cage), y, r.sampling,
                    options.grid);
    names.push_back("field.vti");
  }
  write_file_atomic(out.path("iterations.csv"), [&](std::ostream& s) {
    s << kIterationsHeader << "\n";
    for (const IterationRecord& rec : r.history) s << iteration_row(rec) << "\n";
  });
  write_scenario(out.path("scenario.json"), scenario);
  const std::string summary =
      summary_json(scenario, r, report, volume_ratio, options.total_seconds).dump(2) + "\n";
  write_file_atomic(out.path("summary.json"), [&](std::ostream& s) { s << summary; });
  std::vector<std::string> stale;  // files of an earlier run that this one does not write
  if (options.grid <= 0) stale.push_back("field.vti");
  if (std::find(names.begin(), names.end(), "deformed.ply") == names.end()) stale.push_back("deformed.ply");
  out.commit(stale);
  return written;
}

}  // namespace lidef
