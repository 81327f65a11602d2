#include "lidef/analysis/certificate_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lidef/atomic_file.h"
#include "lidef/domain_sampling.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/staged_outputs.h"
#include "lidef/subspace.h"

namespace lidef {
namespace {

using ojson = nlohmann::ordered_json;
constexpr const char* kFormat = "lidef-certificate";
constexpr int kVersion = 1;

// A double as a JSON value: a number when finite, else the string "nan" / "inf" / "-inf".
ojson num(double x) {
  if (std::isfinite(x)) return x;
  return format_double(x);
}

ojson leaf_json(const CertLeaf& l) {
  ojson j;
  j["center"] = ojson::array({num(l.center.x()), num(l.center.y()), num(l.center.z())});
  j["side"] = num(l.side);
  j["depth"] = l.depth;
  j["sigma3"] = num(l.sigma3);
  j["L"] = num(l.L);
  j["margin"] = num(l.margin);
  j["sigma3_error"] = num(l.sigma3_error);
  j["sigma1"] = num(l.sigma1);
  j["sigma1_upper"] = num(l.sigma1_upper);
  j["distortion_upper"] = num(l.distortion_upper);
  return j;
}

// Typed access to certificate.json with errors that name the file and the key.
struct Reader {
  const std::string& path;
  const nlohmann::json& root;

  const nlohmann::json& at(const nlohmann::json& obj, const char* key) const {
    if (!obj.is_object() || !obj.contains(key))
      throw InputError(path, std::string("missing key '") + key + "'");
    return obj.at(key);
  }
  double number(const nlohmann::json& obj, const char* key) const { return value(at(obj, key), key); }
  double value(const nlohmann::json& v, const char* key) const {
    if (v.is_number()) return v.get<double>();
    if (v.is_string()) {
      const std::string s = v.get<std::string>();
      if (s == "nan") return std::numeric_limits<double>::quiet_NaN();
      if (s == "inf") return std::numeric_limits<double>::infinity();
      if (s == "-inf") return -std::numeric_limits<double>::infinity();
    }
    throw InputError(path, std::string("key '") + key + "' is not a number");
  }
  long integer(const nlohmann::json& obj, const char* key) const {
    const nlohmann::json& v = at(obj, key);
    if (!v.is_number_integer()) throw InputError(path, std::string("key '") + key + "' is not an integer");
    return v.get<long>();
  }
  bool boolean(const nlohmann::json& obj, const char* key) const {
    const nlohmann::json& v = at(obj, key);
    if (!v.is_boolean()) throw InputError(path, std::string("key '") + key + "' is not true/false");
    return v.get<bool>();
  }
  std::string string(const nlohmann::json& obj, const char* key) const {
    const nlohmann::json& v = at(obj, key);
    if (!v.is_string()) throw InputError(path, std::string("key '") + key + "' is not a string");
    return v.get<std::string>();
  }
  std::uint64_t hash(const nlohmann::json& obj, const char* key) const {
    const std::string s = string(obj, key);
    char* end = nullptr;
    const unsigned long long h = std::strtoull(s.c_str(), &end, 16);
    if (s.size() != 16 || *end != '\0')
      throw InputError(path, std::string("key '") + key + "' is not a 16-digit hex hash");
    return h;
  }
  Vec3 vec3(const nlohmann::json& obj, const char* key) const {
    const nlohmann::json& v = at(obj, key);
    if (!v.is_array() || v.size() != 3)
      throw InputError(path, std::string("key '") + key + "' is not [x, y, z]");
    Vec3 p;
    for (int k = 0; k < 3; ++k) p(k) = value(v[k], key);
    return p;
  }
};

std::string read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw InputError(path, std::filesystem::exists(path) ? "cannot open for reading" : "file not found");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

std::uint64_t coefficients_hash(const MatX3d& y) {
  std::string bytes(sizeof(long long) + sizeof(double) * static_cast<size_t>(y.size()), '\0');
  const long long rows = y.rows();
  std::memcpy(&bytes[0], &rows, sizeof rows);
  size_t pos = sizeof rows;
  for (Eigen::Index i = 0; i < y.rows(); ++i)
    for (int k = 0; k < 3; ++k, pos += sizeof(double)) {
      const double v = y(i, k);
      std::memcpy(&bytes[pos], &v, sizeof v);
    }
  return fnv1a64(bytes);
}

std::string global_injectivity_undecidable(const Certificate& cert, const std::string& domain,
                                           const TriMesh& mesh) {
  if (!cert.certified) return "the local certificate failed";
  if (domain != "mesh")
    return "the certified domain is the voxel grid, not the mesh's solid (use the mesh domain)";
  if (mesh.F.rows() == 0) return "a point cloud has no surface whose image could be checked";
  return "";
}

GlobalInjectivity decide_global_injectivity(const Certificate& cert, const std::string& domain,
                                            const Cage& cage, const TriMesh& mesh, const MatX3d& y) {
  const std::string why = global_injectivity_undecidable(cert, domain, mesh);
  if (!why.empty()) return global_injectivity_not_decided(why);
  return check_global_injectivity(cage, mesh, y);
}

CertificateReport make_certificate_report(const Certificate& cert, const Cage& cage, const TriMesh& mesh,
                                          const MatX3d& y, const std::string& model,
                                          const std::string& coefficients,
                                          const SamplingParams& sampling_params,
                                          const VoxelSampling& sampling, const CertifyParams& params,
                                          const GlobalInjectivity* known_global) {
  CertificateReport r;
  r.cert = cert;
  r.model = model;
  r.coefficients = coefficients;
  r.cage_hash = subspace_cage_hash(cage);
  r.coefficients_hash = coefficients_hash(y);
  r.cage_vertices = cage.num_vertices();
  r.cage_faces = cage.num_faces();
  r.cage_edges = cage.num_edges();
  const MatX3d& mesh_V = mesh.V;
  r.mesh_vertices = mesh_V.rows();
  const VecXi where = containing_voxel(sampling, mesh_V);
  long uncovered = 0;
  for (Eigen::Index i = 0; i < where.size(); ++i) uncovered += where(i) < 0;
  r.mesh_vertices_uncovered = uncovered;
  r.mesh_coverage = mesh_V.rows() > 0 ? static_cast<double>(mesh_V.rows() - uncovered) / mesh_V.rows() : 1.0;
  r.sampling_params = sampling_params;
  r.sampling_radius = sampling.radius();
  r.sampling_origin = sampling.origin;
  r.sampling_target_met = sampling.target_met;
  r.sampling_search_iterations = sampling.search_iterations;
  r.hessian_subset = static_cast<int>(sampling.hessian_subset.size());
  r.params = params;
  r.domain = sampling.domain;
  r.uncleared_voxels = cert.uncleared_voxels;
  // Leaves meeting D, exactly; without the leaves (keep_leaves off) the base voxels stand for them.
  const bool all = cert.leaves.size() == static_cast<size_t>(cert.num_leaves) && cert.num_leaves > 0;
  MatX3d C(all ? cert.leaves.size() : sampling.size(), 3);
  VecXd S(C.rows());
  for (Eigen::Index i = 0; i < C.rows(); ++i) {
    if (all) {
      C.row(i) = cert.leaves[i].center.transpose();
      S(i) = cert.leaves[i].side;
    } else {
      C.row(i) = sampling.centers.row(i);
      S(i) = sampling.side_of(static_cast<int>(i));
    }
  }
  const std::vector<char> meets = cubes_meeting_mesh_domain(mesh_V, mesh.F, C, S);
  if (r.domain == "mesh") {
    const MeshDomain dom = mesh_domain_of(mesh_V, mesh.F);
    r.domain_statement = dom.description();
    r.domain_definition = dom.definition();
  }
  r.leaves_meeting_domain = std::count(meets.begin(), meets.end(), 1);
  // A verdict already computed for this very map (the solver's, global mode) is the one a new check would
  // give: the check is deterministic.
  r.global = known_global && global_injectivity_undecidable(cert, r.domain, mesh).empty()
                 ? *known_global
                 : decide_global_injectivity(cert, r.domain, cage, mesh, y);
  return r;
}

// sigma3_error (since the far-field refinement): |sigma3 − the true σ3 at the center| ≤ it (0: exact).
// sigma1, sigma1_upper, distortion_upper (since the distortion bounds): σ1 at the center and the leaf's upper
// bounds of σ1 and σ1/σ3 ("inf" where none). Files written before them have the first 9 or 10 columns only;
// they are still read.
std::string distortion_targets_summary(const Certificate& cert) {
  const DistortionTargets t = cert.targets();
  if (!t.any()) return "";
  const std::string head = "distortion targets (" + t.describe() + ") ";
  if (!cert.distortion_met) return head + "not proven" + (cert.reason.empty() ? "" : ": " + cert.reason);
  return head + "proven: sigma1 <= " + format_bound(cert.max_sigma1_upper_bound, true, 4) +
         ", sigma3 >= " + format_bound(cert.min_lower_bound, false, 4) +
         ", sigma1/sigma3 <= " + format_bound(cert.max_distortion_upper_bound, true, 4);
}

const char* voxels_csv_header() {
  return "cx,cy,cz,side,depth,sigma3,L,margin,certified,sigma3_error,sigma1,sigma1_upper,distortion_upper";
}
namespace {
const char* kVoxelsCsvHeader9 = "cx,cy,cz,side,depth,sigma3,L,margin,certified";
const char* kVoxelsCsvHeader10 = "cx,cy,cz,side,depth,sigma3,L,margin,certified,sigma3_error";
}  // namespace

std::string voxels_csv(const std::vector<CertLeaf>& leaves) {
  std::string s = voxels_csv_header();
  s += '\n';
  s.reserve(s.size() + leaves.size() * 120);
  for (const CertLeaf& l : leaves) {
    for (int k = 0; k < 3; ++k) s += format_double(l.center(k)) + ',';
    s += format_double(l.side) + ',' + std::to_string(l.depth) + ',' + format_double(l.sigma3) + ',' +
         format_double(l.L) + ',' + format_double(l.margin) + ',' + (l.certified ? "1" : "0") + ',' +
         format_double(l.sigma3_error) + ',' + format_double(l.sigma1) + ',' + format_double(l.sigma1_upper) +
         ',' + format_double(l.distortion_upper) + '\n';
  }
  return s;
}

namespace {
std::vector<CertLeaf> parse_voxels_csv(const std::string& text, const std::string& path) {
  std::istringstream in(text);
  std::string line;
  long lineno = 1;
  if (!std::getline(in, line) ||
      (line != voxels_csv_header() && line != kVoxelsCsvHeader9 && line != kVoxelsCsvHeader10))
    throw InputError(path, std::string("bad header (expected '") + voxels_csv_header() + "')", 1);
  const int nfields = line == kVoxelsCsvHeader9 ? 9 : line == kVoxelsCsvHeader10 ? 10 : 13;
  std::vector<CertLeaf> leaves;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty()) throw InputError(path, "empty line", lineno);
    double f[13] = {};
    int k = 0;
    size_t start = 0;
    while (true) {
      const size_t comma = line.find(',', start);
      const std::string field =
          line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      if (k >= nfields) throw InputError(path, "more than " + std::to_string(nfields) + " fields", lineno);
      char* end = nullptr;
      f[k] = std::strtod(field.c_str(), &end);
      if (field.empty() || *end != '\0')
        throw InputError(path, "field " + std::to_string(k + 1) + " is not a number: '" + field + "'",
                         lineno);
      ++k;
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
    if (k != nfields)
      throw InputError(path, "expected " + std::to_string(nfields) + " fields, found " + std::to_string(k),
                       lineno);
    if (!(f[9] >= 0)) throw InputError(path, "sigma3_error must be a number >= 0", lineno);
    if (!(f[3] > 0) || !std::isfinite(f[3])) throw InputError(path, "side must be a positive number", lineno);
    if (f[4] != std::floor(f[4]) || f[4] < 0 || f[4] > 64)
      throw InputError(path, "depth must be an integer in 0..64", lineno);
    if (f[8] != 0 && f[8] != 1) throw InputError(path, "certified must be 0 or 1", lineno);
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(f[c])) throw InputError(path, "center is not finite", lineno);
    CertLeaf l;
    l.center = Vec3(f[0], f[1], f[2]);
    l.side = f[3];
    l.depth = static_cast<int>(f[4]);
    l.sigma3 = f[5];
    l.L = f[6];
    l.margin = f[7];
    l.certified = f[8] == 1;
    l.sigma3_error = f[9];
    if (nfields == 13) {
      // An upper bound is a number or inf, never below 0 or NaN; σ1 at the center is NaN where not evaluated.
      if (!(f[11] >= 0) || !(f[12] >= 0))
        throw InputError(path, "sigma1_upper and distortion_upper must be numbers >= 0 or inf", lineno);
      l.sigma1 = f[10];
      l.sigma1_upper = f[11];
      l.distortion_upper = f[12];
    }
    l.base = -1;  // not stored
    leaves.push_back(l);
  }
  return leaves;
}
}  // namespace

std::vector<CertLeaf> read_voxels_csv(const std::string& path) {
  return parse_voxels_csv(read_all(path), path);
}

std::string certificate_json(const CertificateReport& r) {
  const Certificate& c = r.cert;
  ojson j;
  j["format"] = kFormat;
  j["version"] = kVersion;
  j["certified"] = c.certified;
  j["reason"] = c.reason;
  // Global injectivity on D: true (proven), false (the shape overlaps itself at overlap.point, where the
  // images of the mesh triangles overlap.faces meet), null (not decided: global_reason says why).
  const GlobalInjectivity& g = r.global;
  j["globally_injective"] = g.verdict == GlobalInjectivity::Verdict::kInjective ? ojson(true)
                            : g.verdict == GlobalInjectivity::Verdict::kOverlap ? ojson(false)
                                                                                : ojson();
  j["global_reason"] = g.reason;
  j["overlap"] =
      g.verdict == GlobalInjectivity::Verdict::kOverlap
          ? ojson{{"point", {num(g.overlap_point.x()), num(g.overlap_point.y()), num(g.overlap_point.z())}},
                  {"faces", {g.overlap_face_a, g.overlap_face_b}}}
          : ojson();
  j["global_check"] = {
      {"candidate_pairs", g.candidate_pairs},      {"pair_tests", g.pair_tests},
      {"replayed_pairs", g.replayed_pairs},        {"max_depth_used", g.max_depth_used},
      {"max_tube_radius", num(g.max_tube_radius)}, {"rest_intersecting_pairs", g.rest_intersecting_pairs}};
  j["model"] = r.model;
  j["coefficients"] = r.coefficients;
  j["cage"] = {{"vertices", r.cage_vertices},
               {"faces", r.cage_faces},
               {"edges", r.cage_edges},
               {"fnv1a64", hex64(r.cage_hash)}};
  j["coefficients_fnv1a64"] = hex64(r.coefficients_hash);
  j["bound"] = to_string(c.bound);
  // Third order: whether base voxels it left unproven took the spectral bound (Step 4f), and how many did.
  j["spectral_fallback"] = c.spectral_fallback;
  j["max_depth"] = r.params.max_depth;
  j["max_refined_voxels"] = r.params.max_refined_voxels;
  j["max_children_per_voxel"] = r.params.max_children_per_voxel;
  j["rounding_allowance"] = num(OctreeCertifier::kRoundingRel);
  ojson s;
  s["target_count"] = r.sampling_params.target_count;
  s["count_tolerance"] = num(r.sampling_params.count_tolerance);
  s["voxel_side_requested"] = num(r.sampling_params.voxel_side);
  s["safety"] = num(r.sampling_params.safety);
  s["hessian_fraction"] = num(r.sampling_params.hessian_fraction);
  s["voxel_side"] = num(c.voxel_side);
  s["radius"] = num(r.sampling_radius);
  s["origin"] =
      ojson::array({num(r.sampling_origin.x()), num(r.sampling_origin.y()), num(r.sampling_origin.z())});
  s["voxels"] = c.voxels;
  s["hessian_subset"] = r.hessian_subset;
  s["target_met"] = r.sampling_target_met;
  s["search_iterations"] = r.sampling_search_iterations;
  j["sampling"] = s;
  j["voxel_side"] = num(c.voxel_side);
  j["voxels"] = c.voxels;
  j["leaves"] = c.num_leaves;
  long certified_leaves = 0;
  for (const CertLeaf& l : c.leaves) certified_leaves += l.certified;
  j["leaves_certified"] =
      c.leaves.size() == static_cast<size_t>(c.num_leaves) ? ojson(certified_leaves) : ojson();
  j["refined"] = c.refined;
  j["spectral_fallback_voxels"] = c.fallback_voxels;
  j["max_depth_used"] = c.max_depth_used;
  j["min_sigma3_center"] = num(c.min_sigma3_center);
  j["min_margin"] = num(c.min_margin);
  j["min_lower_bound"] = num(c.min_lower_bound);
  // The tight-lower-bound stage (bound_tolerance > 0): the tolerance asked for and whether it was reached.
  j["bound_tolerance"] = num(c.bound_tolerance);
  j["bound_tolerance_met"] = c.bound_tolerance > 0 ? ojson(c.bound_tolerance_met) : ojson();
  // Bounded distortion: over the leaves, the largest upper bound of σ1 and of σ1/σ3 ("inf" when a leaf has
  // none), and the targets asked for (max_distortion, max_sigma1, min_sigma3; 0: off) with whether all were
  // proven (null when none was asked for).
  j["max_sigma1_upper_bound"] = num(c.max_sigma1_upper_bound);
  j["max_distortion_upper_bound"] = num(c.max_distortion_upper_bound);
  j["max_distortion"] = num(c.max_distortion);
  j["max_sigma1"] = num(c.max_sigma1);
  j["min_sigma3"] = num(c.min_sigma3);
  j["distortion_met"] = c.targets().any() ? ojson(c.distortion_met) : ojson();
  j["mesh_vertices"] = r.mesh_vertices;
  j["mesh_coverage"] = num(r.mesh_coverage);
  j["mesh_vertices_uncovered"] = r.mesh_vertices_uncovered;
  ojson d;
  d["kind"] = r.domain;
  if (r.domain == "mesh") d["statement"] = r.domain_statement;
  d["definition"] =
      r.domain == "mesh" ? r.domain_definition : "the union of the paper's grid voxels clear of the cage";
  d["leaves_meeting_mesh_domain"] = r.leaves_meeting_domain;
  d["uncleared_voxels"] = r.uncleared_voxels;
  j["domain"] = d;
  ojson failing = ojson::array();
  for (const CertLeaf& l : c.failing) failing.push_back(leaf_json(l));
  j["failing"] = failing;
  j["voxels_csv"] = r.voxels_csv;
  j["voxels_csv_fnv1a64"] = hex64(r.voxels_csv_hash);
  return j.dump(2) + "\n";
}

void write_certificate_files(const std::string& dir, CertificateReport& r) {
  const std::string csv = voxels_csv(r.cert.leaves);
  r.voxels_csv_hash = fnv1a64(csv);
  const std::filesystem::path d(dir);
  write_file_atomic((d / r.voxels_csv).string(), [&](std::ostream& out) { out << csv; });
  const std::string json = certificate_json(r);
  write_file_atomic((d / "certificate.json").string(), [&](std::ostream& out) { out << json; });
}

CertificateReport read_certificate_json(const std::string& path) {
  // A run killed while it moved its outputs in withdrew the certificate first; its journal completes it.
  finish_interrupted_commit(std::filesystem::path(path).parent_path().string());
  const std::string text = read_all(path);
  nlohmann::json root;
  try {
    root = nlohmann::json::parse(text);
  } catch (
      const nlohmann::json::exception& e) {  // parse_error, and out_of_range 406 for a number such as 1e999
    throw InputError(path, std::string("not valid JSON: ") + e.what());
  }
  const Reader rd{path, root};
  if (!root.is_object() || !root.contains("format") || root["format"] != kFormat)
    throw InputError(path, std::string("not a lidef certificate (missing \"format\": \"") + kFormat + "\")");
  if (rd.integer(root, "version") != kVersion)
    throw InputError(path, "unsupported certificate version " + std::to_string(rd.integer(root, "version")));

  CertificateReport r;
  Certificate& c = r.cert;
  c.certified = rd.boolean(root, "certified");
  c.reason = rd.string(root, "reason");
  r.model = rd.string(root, "model");
  r.coefficients = rd.string(root, "coefficients");
  const nlohmann::json& cage = rd.at(root, "cage");
  r.cage_vertices = static_cast<int>(rd.integer(cage, "vertices"));
  r.cage_faces = static_cast<int>(rd.integer(cage, "faces"));
  r.cage_edges = static_cast<int>(rd.integer(cage, "edges"));
  r.cage_hash = rd.hash(cage, "fnv1a64");
  r.coefficients_hash = rd.hash(root, "coefficients_fnv1a64");
  try {
    c.bound = lipschitz_bound_from_string(rd.string(root, "bound"));
  } catch (const InputError& e) {
    throw InputError(path, e.message());
  }
  r.params.bound = c.bound;
  r.params.max_depth = static_cast<int>(rd.integer(root, "max_depth"));
  if (root.contains("spectral_fallback")) {  // absent in certificates written before it (none used it)
    c.spectral_fallback = rd.boolean(root, "spectral_fallback");
    r.params.base_spectral_fallback = c.spectral_fallback;
    c.fallback_voxels = rd.integer(root, "spectral_fallback_voxels");
  }
  r.params.max_refined_voxels = rd.integer(root, "max_refined_voxels");
  r.params.max_children_per_voxel = rd.integer(root, "max_children_per_voxel");
  const nlohmann::json& s = rd.at(root, "sampling");
  r.sampling_params.target_count = static_cast<int>(rd.integer(s, "target_count"));
  r.sampling_params.count_tolerance = rd.number(s, "count_tolerance");
  r.sampling_params.voxel_side = rd.number(s, "voxel_side_requested");
  r.sampling_params.safety = rd.number(s, "safety");
  r.sampling_params.hessian_fraction = rd.number(s, "hessian_fraction");
  r.sampling_radius = rd.number(s, "radius");
  r.sampling_origin = rd.vec3(s, "origin");
  r.hessian_subset = static_cast<int>(rd.integer(s, "hessian_subset"));
  r.sampling_target_met = rd.boolean(s, "target_met");
  r.sampling_search_iterations = static_cast<int>(rd.integer(s, "search_iterations"));
  c.voxel_side = rd.number(root, "voxel_side");
  c.voxels = static_cast<int>(rd.integer(root, "voxels"));
  c.num_leaves = rd.integer(root, "leaves");
  c.refined = rd.integer(root, "refined");
  c.max_depth_used = static_cast<int>(rd.integer(root, "max_depth_used"));
  c.min_sigma3_center = rd.number(root, "min_sigma3_center");
  c.min_margin = rd.number(root, "min_margin");
  c.min_lower_bound = rd.number(root, "min_lower_bound");
  if (root.contains("bound_tolerance")) {  // absent in certificates written before it
    c.bound_tolerance = rd.number(root, "bound_tolerance");
    c.bound_tolerance_met = c.bound_tolerance > 0 && rd.boolean(root, "bound_tolerance_met");
  }
  if (root.contains("max_sigma1_upper_bound")) {  // absent in certificates written before the bounds
    c.max_sigma1_upper_bound = rd.number(root, "max_sigma1_upper_bound");
    c.max_distortion_upper_bound = rd.number(root, "max_distortion_upper_bound");
    c.max_distortion = rd.number(root, "max_distortion");
    if (root.contains("max_sigma1")) {  // absent in certificates written before the isometric bounds
      c.max_sigma1 = rd.number(root, "max_sigma1");
      c.min_sigma3 = rd.number(root, "min_sigma3");
    }
    c.distortion_met = c.targets().any() && rd.boolean(root, "distortion_met");
  }
  r.mesh_vertices = rd.integer(root, "mesh_vertices");
  r.mesh_coverage = rd.number(root, "mesh_coverage");
  r.mesh_vertices_uncovered = rd.integer(root, "mesh_vertices_uncovered");
  if (root.contains("domain")) {  // absent in certificates written before the mesh domain
    const nlohmann::json& d = rd.at(root, "domain");
    r.domain = rd.string(d, "kind");
    if (r.domain == "mesh") {
      // "statement" is absent in certificates written before point clouds and open meshes were accepted.
      r.domain_statement = d.contains("statement") ? rd.string(d, "statement") : "mesh and its solid";
      r.domain_definition = rd.string(d, "definition");
    }
    r.leaves_meeting_domain = rd.integer(d, "leaves_meeting_mesh_domain");
    r.uncleared_voxels = rd.integer(d, "uncleared_voxels");
  }
  const nlohmann::json& failing = rd.at(root, "failing");
  if (!failing.is_array()) throw InputError(path, "key 'failing' is not a list");
  for (const nlohmann::json& f : failing) {
    CertLeaf l;
    l.center = rd.vec3(f, "center");
    l.side = rd.number(f, "side");
    l.depth = static_cast<int>(rd.integer(f, "depth"));
    l.sigma3 = rd.number(f, "sigma3");
    l.L = rd.number(f, "L");
    l.margin = rd.number(f, "margin");
    l.certified = false;
    l.base = -1;
    c.failing.push_back(l);
  }
  r.voxels_csv = rd.string(root, "voxels_csv");
  r.voxels_csv_hash = rd.hash(root, "voxels_csv_fnv1a64");

  // The leaves, from the CSV beside the JSON; refused when it is not the file the certificate was written
  // with.
  const std::filesystem::path csv_rel(r.voxels_csv);
  if (r.voxels_csv.empty() || csv_rel.is_absolute() || csv_rel.has_parent_path())
    throw InputError(path, "key 'voxels_csv' must be a plain file name");
  const std::string csv_path = (std::filesystem::path(path).parent_path() / csv_rel).string();
  const std::string csv = read_all(csv_path);
  if (fnv1a64(csv) != r.voxels_csv_hash)
    throw InputError(csv_path, "does not match " + path + " (hash differs: stale or edited file)");
  c.leaves = parse_voxels_csv(csv, csv_path);
  if (static_cast<long>(c.leaves.size()) != c.num_leaves)
    throw InputError(csv_path, "has " + std::to_string(c.leaves.size()) + " leaves, " + path + " says " +
                                   std::to_string(c.num_leaves));
  return r;
}

}  // namespace lidef
