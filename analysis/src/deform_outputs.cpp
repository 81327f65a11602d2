#include "lidef/analysis/deform_outputs.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <map>
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

namespace {

// The columns of iterations.csv, each with the field of IterationRecord it shows: the header and every row
// come from this one list. Numbers are written so that they read back to the same double; times to 6 digits.
struct IterationColumn {
  const char* name;
  std::string (*cell)(const IterationRecord&);
};
std::string num(double x) {
  return format_double(x);
}
std::string ms(double x) {
  return format_g(x, 6);
}
const IterationColumn kIterationColumns[] = {
    {"iteration", [](const IterationRecord& r) { return std::to_string(r.iteration); }},
    {"energy_before", [](const IterationRecord& r) { return num(r.energy_before); }},
    {"energy", [](const IterationRecord& r) { return num(r.terms.total); }},
    {"e_dis", [](const IterationRecord& r) { return num(r.terms.dis); }},
    {"e_p2p", [](const IterationRecord& r) { return num(r.terms.p2p); }},
    {"e_smooth", [](const IterationRecord& r) { return num(r.terms.smooth); }},
    {"lambda_p2p", [](const IterationRecord& r) { return num(r.lambda_p2p); }},
    {"lambda_smooth", [](const IterationRecord& r) { return num(r.lambda_smooth); }},
    {"gradient_norm", [](const IterationRecord& r) { return num(r.gradient_norm); }},
    {"step", [](const IterationRecord& r) { return num(r.step); }},
    {"step_norm", [](const IterationRecord& r) { return num(r.step_norm); }},
    {"armijo_rejections", [](const IterationRecord& r) { return std::to_string(r.armijo_rejections); }},
    {"certificate_rejections",
     [](const IterationRecord& r) { return std::to_string(r.certificate_rejections); }},
    {"accepted", [](const IterationRecord& r) { return std::string(r.accepted ? "1" : "0"); }},
    {"certified", [](const IterationRecord& r) { return std::string(r.certified ? "1" : "0"); }},
    {"min_sigma3_sampled", [](const IterationRecord& r) { return num(r.min_sigma3); }},
    {"min_lower_bound", [](const IterationRecord& r) { return num(r.min_lower_bound); }},
    {"refined", [](const IterationRecord& r) { return std::to_string(r.refined); }},
    {"max_handle_error", [](const IterationRecord& r) { return num(r.max_handle_error); }},
    {"weight_action", [](const IterationRecord& r) { return '"' + r.weight_action + '"'; }},
    {"ms_gradient", [](const IterationRecord& r) { return ms(r.ms_gradient); }},
    {"ms_hessian", [](const IterationRecord& r) { return ms(r.ms_hessian); }},
    {"ms_solve", [](const IterationRecord& r) { return ms(r.ms_solve); }},
    {"ms_line_search", [](const IterationRecord& r) { return ms(r.ms_line_search); }},
    {"ms_certificate", [](const IterationRecord& r) { return ms(r.ms_certificate); }},
    {"ms_total", [](const IterationRecord& r) { return ms(r.ms_total); }},
    {"cg_steps", [](const IterationRecord& r) { return std::to_string(r.cg_steps); }},
    {"cg_scale", [](const IterationRecord& r) { return num(r.cg_scale); }},
    {"global_rejections", [](const IterationRecord& r) { return std::to_string(r.global_rejections); }},
    {"ms_global", [](const IterationRecord& r) { return ms(r.ms_global); }},
    {"hessian_reused", [](const IterationRecord& r) { return std::string(r.hessian_reused ? "1" : "0"); }},
    {"kept_factor_steps", [](const IterationRecord& r) { return std::to_string(r.kept_factor_steps); }},
};

}  // namespace

std::string iterations_header() {
  std::string h;
  for (const IterationColumn& c : kIterationColumns) h += (h.empty() ? "" : ",") + std::string(c.name);
  return h;
}

std::string iteration_row(const IterationRecord& r) {
  std::string row;
  for (const IterationColumn& c : kIterationColumns) row += (row.empty() ? "" : ",") + c.cell(r);
  return row;
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
  // vertices, and the targets (max_distortion, max_sigma1, min_sigma3; 0: off).
  sj["max_sigma1_upper_bound"] = cert.max_sigma1_upper_bound;
  sj["max_distortion_upper_bound"] = cert.max_distortion_upper_bound;
  double max_k_vertices = 0;  // NaN (σ3 ≤ 0) never occurs at a certified map's covered vertices
  for (Eigen::Index i = 0; i < r.distortion.size(); ++i)
    if (std::isfinite(r.distortion(i))) max_k_vertices = std::max(max_k_vertices, r.distortion(i));
  sj["max_distortion_vertices"] = max_k_vertices;
  sj["max_sigma1_vertices"] = r.sigma1.size() > 0 ? r.sigma1.maxCoeff() : 0.0;
  sj["min_sigma3_vertices"] = r.sigma3.size() > 0 ? r.sigma3.minCoeff() : 0.0;
  sj["max_distortion"] = sc.params.max_distortion;
  sj["max_sigma1"] = sc.params.max_sigma1;
  sj["min_sigma3"] = sc.params.min_sigma3;
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
  // The written map's global injectivity check runs with the outputs, after `total_seconds` was taken: on a
  // tight cage it can cost more than the solve, and a user reading "total" expects it counted.
  const double global_seconds = report.global.ms / 1000;
  sj["time_s"] = {{"preprocess", r.preprocess_seconds},
                  {"solve", r.solve.seconds},
                  {"local_global", r.path.local_global_seconds},
                  {"final_certificate_and_fields", r.finish_seconds},
                  {"global_injectivity", global_seconds},
                  {"total", (total_seconds >= 0 ? total_seconds
                                                : r.preprocess_seconds + r.solve.seconds + r.finish_seconds) +
                                global_seconds}};
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

// The input's points under the map, in input order: a point that is a vertex of the model's mesh takes that
// vertex's mapped position (the numbers of deformed.obj); any other point (a PLY mesh's unused vertex, which
// the cage maker drops) is evaluated here and lies outside the certified domain unless it happens to be
// inside it. `evaluated` gets the count of those.
MatX3d map_input_points(const MatX3d& P, const Model& model, const HarmonicBasis& basis, const MatX3d& y,
                        const MatX3d& mapped, long* evaluated) {
  std::map<std::array<double, 3>, Eigen::Index> vertex_of;
  for (Eigen::Index i = 0; i < model.mesh.V.rows(); ++i)
    vertex_of.emplace(std::array<double, 3>{model.mesh.V(i, 0), model.mesh.V(i, 1), model.mesh.V(i, 2)}, i);
  MatX3d out(P.rows(), 3);
  std::vector<Eigen::Index> others;
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const auto it = vertex_of.find({P(i, 0), P(i, 1), P(i, 2)});
    if (it != vertex_of.end())
      out.row(i) = mapped.row(it->second);
    else
      others.push_back(i);
  }
  if (!others.empty()) {
    MatX3d Q(static_cast<Eigen::Index>(others.size()), 3);
    for (size_t k = 0; k < others.size(); ++k) Q.row(k) = P.row(others[k]);
    const MatX3d fQ = basis.map_values(y, Q);
    for (size_t k = 0; k < others.size(); ++k) out.row(others[k]) = fQ.row(k);
  }
  *evaluated = static_cast<long>(others.size());
  return out;
}

// The deformed input in its own format (deformed.ply / deformed.xyz): the points mapped, normals by the
// cofactor matrix, Gaussian splats' covariances and colours (map_gaussian_splats); every other property kept.
struct DeformedInput {
  std::string name;  // "deformed.ply" or "deformed.xyz"
  PlyCloud cloud;
  long points_not_in_model = 0;
};
DeformedInput deformed_input(const std::string& file, const Model& model, const MatX3d& y,
                             const MatX3d& mapped) {
  DeformedInput d;
  if (lowercase_extension(file) == ".xyz") {
    MatX3d N;
    const MatX3d P = read_points_xyz(file, &N);
    d.name = "deformed.xyz";
    d.cloud.format = "ascii";
    d.cloud.names = {"x", "y", "z"};
    if (N.rows() > 0) d.cloud.names.insert(d.cloud.names.end(), {"nx", "ny", "nz"});
    d.cloud.types.assign(d.cloud.names.size(), "double");
    d.cloud.values.resize(P.rows(), static_cast<Eigen::Index>(d.cloud.names.size()));
    d.cloud.values.leftCols(3) = P;
    if (N.rows() > 0) d.cloud.values.rightCols(3) = N;
  } else {
    d.name = "deformed.ply";
    d.cloud = read_ply_cloud(file);
  }
  const MatX3d P = d.cloud.points();
  const HarmonicBasis basis(model.cage);
  const MatX3d Q = map_input_points(P, model, basis, y, mapped, &d.points_not_in_model);
  const MatXd JT = jacobians_at(basis, y, P);
  if (is_gaussian_splat_cloud(d.cloud))
    map_gaussian_splats(d.cloud, Q, JT);
  else
    map_point_cloud(d.cloud, Q, JT);
  return d;
}

}  // namespace

std::string source_points_file(const Model& model, const Scenario& scenario) {
  auto is_points = [](const std::string& p) {
    const std::string ext = lowercase_extension(p);
    return ext == ".ply" || ext == ".xyz";
  };
  std::error_code ec;
  if (is_points(scenario.model_dir) && fs::is_regular_file(scenario.model_dir, ec)) return scenario.model_dir;
  const fs::path json = fs::path(model.dir) / "model.json";
  if (model.dir.empty() || !fs::is_regular_file(json, ec)) return "";
  std::ifstream in(json);
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.contains("input") || !j["input"].contains("file") ||
      !j["input"]["file"].is_string())
    return "";
  const std::string file = j["input"]["file"];
  return is_points(file) && fs::is_regular_file(file, ec) ? file : "";
}

DeformOutputs write_deform_outputs(const std::string& dir, const Model& model, const Scenario& scenario,
                                   const DeformResult& r, const DeformOutputOptions& options) {
  const MatX3d& y = r.coefficients;
  CertificateReport report = make_certificate_report(
      r.certificate, model.cage, model.mesh, y, scenario.model_dir, "coefficients.txt", r.sampling_params,
      r.sampling, r.certify_params, r.global ? &*r.global : nullptr);
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
  const std::string input = source_points_file(model, scenario);
  DeformedInput deformed;
  if (!input.empty()) {
    deformed = deformed_input(input, model, y, r.deformed_vertices);
    write_file_atomic(out.path(deformed.name), [&](std::ostream& s) {
      if (deformed.name == "deformed.xyz")
        write_points_xyz(s, deformed.cloud.points(),
                         deformed.cloud.has_normals() ? deformed.cloud.columns3("nx", "ny", "nz") : MatX3d());
      else
        write_ply_cloud(s, deformed.cloud);
    });
    names.push_back(deformed.name);
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
    s << iterations_header() << "\n";
    for (const IterationRecord& rec : r.history) s << iteration_row(rec) << "\n";
  });
  write_scenario(out.path("scenario.json"), scenario);
  nlohmann::ordered_json sj = summary_json(scenario, r, report, volume_ratio, options.total_seconds);
  if (!deformed.name.empty())
    sj["deformed_input"] = {{"file", deformed.name},
                            {"points", deformed.cloud.values.rows()},
                            {"points_not_in_model", deformed.points_not_in_model}};
  const std::string summary = sj.dump(2) + "\n";
  write_file_atomic(out.path("summary.json"), [&](std::ostream& s) { s << summary; });
  std::vector<std::string> stale;  // files of an earlier run that this one does not write
  if (options.grid <= 0) stale.push_back("field.vti");
  for (const char* name : {"deformed.ply", "deformed.xyz"})
    if (std::find(names.begin(), names.end(), name) == names.end()) stale.push_back(name);
  out.commit(stale);
  return written;
}

}  // namespace lidef
