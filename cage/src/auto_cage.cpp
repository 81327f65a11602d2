// Automatic cages: input checks, attempts and retries, validation, model folder output and the cage cache.
// The CGAL work is in auto_cage_cgal.cpp.
#include "lidef/cage/auto_cage.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "auto_cage_cgal.h"
#include "lidef/atomic_file.h"
#include "lidef/errors.h"
#include "lidef/hash.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/point_cloud_io.h"
#include "lidef/subspace.h"
#include "ply_check.h"

namespace lidef {
namespace {

namespace fs = std::filesystem;

constexpr int kMaxFaces = 4000;
constexpr const char* kFormats[] = {"obj", "off", "ply", "stl", "xyz"};

// "ply" for "a/B.PLY" (without the dot, as the formats are named in messages).
std::string lower_extension(const std::string& path) {
  const std::string ext = lowercase_extension(path);
  return ext.empty() ? ext : ext.substr(1);
}

bool supported_format(const std::string& ext) {
  return std::find(std::begin(kFormats), std::end(kFormats), ext) != std::end(kFormats);
}

// fnv1a64 of the file's bytes, read in blocks (mesh files can be large).
std::uint64_t file_hash(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open the file");
  std::uint64_t h = kFnv1a64Offset;
  std::vector<char> block(1 << 16);
  while (in.read(block.data(), static_cast<std::streamsize>(block.size())) || in.gcount() > 0)
    h = fnv1a64(block.data(), static_cast<std::size_t>(in.gcount()), h);
  if (in.bad()) throw InputError(path, "cannot read the file");
  return h;
}

double diagonal_of(const MatX3d& V) {
  return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
}

// Zero area in the validator's sense (model_check.h, CheckTolerances::degenerate): a sliver whose normal is
// round-off.
bool zero_area(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  return !((b - a).cross(c - a).norm() > CheckTolerances{}.degenerate * longest2);
}

// The first reason the cage cannot be used: a validation error, or a self-intersection (only a warning for
// hand-made cages, but a made cage must have none).
std::string first_problem(const ValidationReport& r) {
  if (!r.errors.empty())
    return r.errors.front().str() +
           (r.errors.size() > 1 ? " (and " + std::to_string(r.errors.size() - 1) + " more)" : "");
  if (!r.self_intersections.empty())
    return "the cage intersects itself in " + std::to_string(r.self_intersections.size()) + " face pairs";
  return "";
}

std::string count_str(long n) {
  std::string s = std::to_string(n);
  for (int i = static_cast<int>(s.size()) - 3; i > (n < 0 ? 1 : 0); i -= 3)
    s.insert(static_cast<size_t>(i), ",");
  return s;
}

// "OFF BINARY" (or [ST][C][N]OFF BINARY) on the first line.
bool is_binary_off(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string first;
  std::getline(in, first);
  return first.find("BINARY") != std::string::npos;
}

// Binary OFF is refused, with a reason, before CGAL sees it. CGAL 5.5's binary OFF reader (1) multiplies the
// header's counts as int without checking them — undefined behaviour for a negative count, found by CI's
// libFuzzer run (fuzz/regressions/cgal_off/) — and (2) does not read the per-face colour count of Geomview's
// binary format, so a standard file comes back with faces missing (measured: a tetrahedron written per the
// format read back with 2 of its 4 faces) — a wrong mesh without an error.
void refuse_binary_off(const std::string& path) {
  throw InputError(
      path,
      "binary OFF ('OFF BINARY') is not supported: CGAL 5.5's reader drops faces of standard binary "
      "OFF files; convert the mesh to ASCII OFF, OBJ, PLY or STL");
}

// Whether an OBJ file has an `f` statement. CGAL's OBJ reader fails on a file of `v` lines only, so a point
// cloud in OBJ form goes to lidef's own reader (mesh_io.h, read_mesh_or_points).
bool obj_has_faces(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  for (std::string line; std::getline(in, line);) {
    const std::size_t k = line.find_first_not_of(" \t");
    if (k != std::string::npos && line[k] == 'f' && k + 1 < line.size() &&
        (line[k + 1] == ' ' || line[k + 1] == '\t'))
      return true;
  }
  return false;
}

}  // namespace

TriMesh read_any_mesh(const std::string& path, MeshReadInfo* info) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "file not found");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, expected a mesh file");
  const std::string ext = lower_extension(path);
  if (!supported_format(ext))
    throw InputError(path,
                     "unsupported mesh format '." + ext + "' (expected .obj, .off, .ply, .stl or .xyz)");
  if (fs::file_size(path, ec) == 0 && !ec) throw InputError(path, "file is empty");
  // The PLY header checks (ply_check.h) hold for point clouds too: refused before either reader sees it.
  if (ext == "ply") check_ply_before_cgal(path, fs::file_size(path, ec));
  // Point clouds (a PLY without faces, Gaussian splats included; an XYZ file) are read by lidef's own
  // readers (point_cloud_io.h): every vertex is kept, in the file's order.
  if (ext == "xyz" || (ext == "ply" && ply_face_count(path) == 0) || (ext == "obj" && !obj_has_faces(path))) {
    TriMesh cloud;
    cloud.source = path;
    cloud.V = ext == "xyz"   ? read_points_xyz(path)
              : ext == "ply" ? read_ply_cloud(path).points()
                             : read_mesh_or_points(path).V;
    cloud.F.resize(0, 3);
    if (info) {
      *info = MeshReadInfo{};
      info->format = ext;
      info->file_vertices = static_cast<int>(cloud.V.rows());
      info->file_hash = file_hash(path);
    }
    return cloud;
  }
  if (ext == "off" && is_binary_off(path)) refuse_binary_off(path);
  MeshReadInfo inf;
  inf.format = ext;
  inf.file_hash = file_hash(path);

  cage_cgal::PolygonSoup soup;
  if (ext == "off" && !is_binary_off(path)) {
    // lidef's own OFF parser (mesh_io.h), not CGAL's: CGAL 5.5's scanner reads a vertex's colour from entries
    // it never filled when a coordinate does not parse (a COFF line "x 0 0 255 0 0 255": out-of-bounds read,
    // a crash; found by the deterministic mutants of fuzz/replay_main.cpp), and converts out-of-range colours
    // to unsigned char (undefined behaviour). Errors then name the line.
    PolygonSoupMesh m = read_off_polygons(path);
    soup.points = std::move(m.V);
    soup.polygons = std::move(m.polygons);
  } else if (!cage_cgal::read_polygon_soup(path, ext, soup))
    throw InputError(path, "cannot read the file as " + ext + " (CGAL's reader failed: not a valid ." + ext +
                               " file, or truncated)");
  inf.file_vertices = static_cast<int>(soup.points.rows());
  inf.file_polygons = static_cast<int>(soup.polygons.size());
  if (soup.points.rows() == 0) throw InputError(path, "no vertices");
  for (Eigen::Index i = 0; i < soup.points.rows(); ++i)
    if (!soup.points.row(i).allFinite())
      throw InputError(path, "vertex " + std::to_string(i + 1) + ": coordinate is NaN or infinite (" +
                                 format_g(soup.points(i, 0)) + ", " + format_g(soup.points(i, 1)) + ", " +
                                 format_g(soup.points(i, 2)) + ")");
  if (soup.polygons.empty()) {
    // Vertices only (an OBJ point cloud): every point kept, no faces.
    if (ext == "off")
      throw InputError(path, "no faces (only points; a point cloud is read from .ply, .xyz or .obj)");
    TriMesh cloud;
    cloud.source = path;
    cloud.V = std::move(soup.points);
    cloud.F.resize(0, 3);
    if (info) *info = inf;
    return cloud;
  }

  // Fan triangulation; drop polygons with < 3 corners and triangles using a vertex twice.
  std::vector<std::array<int, 3>> tris;
  const auto nv = static_cast<std::size_t>(soup.points.rows());
  for (std::size_t p = 0; p < soup.polygons.size(); ++p) {
    const auto& poly = soup.polygons[p];
    for (std::size_t v : poly)
      if (v >= nv)
        throw InputError(path, "face " + std::to_string(p + 1) + ": vertex index " + std::to_string(v) +
                                   " is out of range (" + std::to_string(nv) + " vertices)");
    if (poly.size() < 3) {
      ++inf.dropped_faces;
      continue;
    }
    for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
      const std::array<int, 3> t = {static_cast<int>(poly[0]), static_cast<int>(poly[k]),
                                    static_cast<int>(poly[k + 1])};
      if (k > 1) ++inf.fan_triangles;
      if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) {
        ++inf.dropped_faces;
        continue;
      }
      tris.push_back(t);
    }
  }
  // Keep the used points, in the file's order.
  std::vector<int> new_index(nv, -1);
  for (const auto& t : tris)
    for (int v : t) new_index[static_cast<std::size_t>(v)] = 0;
  int used = 0;
  for (int& k : new_index)
    if (k == 0) k = used++;
  TriMesh mesh;
  mesh.source = path;
  mesh.V.resize(used, 3);
  for (std::size_t i = 0; i < nv; ++i)
    if (new_index[i] >= 0) mesh.V.row(new_index[i]) = soup.points.row(static_cast<Eigen::Index>(i));
  inf.dropped_vertices = static_cast<int>(nv) - used;
  mesh.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (std::size_t f = 0; f < tris.size(); ++f)
    for (int k = 0; k < 3; ++k)
      mesh.F(static_cast<Eigen::Index>(f), k) =
          new_index[static_cast<std::size_t>(tris[f][static_cast<std::size_t>(k)])];
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    if (zero_area(mesh.V.row(mesh.F(f, 0)), mesh.V.row(mesh.F(f, 1)), mesh.V.row(mesh.F(f, 2))))
      ++inf.degenerate_faces;
  if (mesh.F.rows() == 0 || inf.degenerate_faces == mesh.F.rows())
    throw InputError(path, "all " + std::to_string(inf.file_polygons) +
                               " faces are degenerate (zero area or a repeated vertex): nothing to wrap");
  if (info) *info = inf;
  return mesh;
}

void check_cage_options(const CageOptions& o) {
  if (!(o.faces >= 4 && o.faces <= kMaxFaces))
    throw InputError("--faces",
                     "must be in 4.." + std::to_string(kMaxFaces) + " (got " + std::to_string(o.faces) + ")");
  if (!(o.clearance > 0 && o.clearance < 0.5))
    throw InputError("--clearance", "must be in (0, 0.5) (a fraction of the bounding-box diagonal; got " +
                                        format_g(o.clearance) + ")");
  if (!(o.offset > o.clearance && o.offset < 1))
    throw InputError("--offset", "must be greater than the clearance (" + format_g(o.clearance) +
                                     ") and less than 1 (got " + format_g(o.offset) + ")");
  if (!(o.alpha > 0 && o.alpha < 1))
    throw InputError("--alpha", "must be in (0, 1) (got " + format_g(o.alpha) + ")");
  if (!(o.max_retries >= 0 && o.max_retries <= 10)) throw InputError("--retries", "must be in 0..10");
}

CageResult make_cage(const TriMesh& mesh, const CageOptions& options, const CageLog& log) {
  check_cage_options(options);
  const auto t_start = Clock::now();
  auto say = [&](const std::string& s) {
    if (log) log(s);
  };
  CageResult result;
  result.mesh = mesh;
  CageReport& report = result.report;
  report.diagonal = diagonal_of(mesh.V);
  if (!(report.diagonal > 0))
    throw InputError(mesh.source, "the mesh has zero extent (all vertices coincide)");

  double offset = options.offset;
  int faces = options.faces;
  for (int attempt = 0; attempt <= options.max_retries; ++attempt) {
    CageAttempt a;
    a.alpha = options.alpha * report.diagonal;
    a.offset = offset * report.diagonal;
    a.clearance = options.clearance * report.diagonal;
    a.target_faces = faces;
    say("attempt " + std::to_string(attempt + 1) + ": alpha " + format_g(a.alpha, 4) + ", offset " +
        format_g(a.offset, 4) + ", clearance " + format_g(a.clearance, 4) + ", target " + count_str(faces) +
        " faces");
    cage_cgal::WrapResult w = cage_cgal::wrap_and_simplify(mesh, a.alpha, a.offset, a.clearance, faces);
    a.wrap_faces = w.wrap_faces;
    a.cage_faces = static_cast<int>(w.cage.F.rows());
    a.faces_within_clearance = w.faces_within_clearance;
    a.seconds_wrap = w.seconds_wrap;
    a.seconds_simplify = w.seconds_simplify;
    say("alpha wrap: " + count_str(a.wrap_faces) + " triangles in " + format_g(a.seconds_wrap, 3) +
        " s; simplified to " + count_str(a.cage_faces) + " in " + format_g(a.seconds_simplify, 3) + " s" +
        (a.faces_within_clearance > 0 ? " (" + count_str(a.faces_within_clearance) +
                                            " faces not proven clear of the mesh by the clearance)"
                                      : ""));
    const auto t_check = Clock::now();
    w.cage.source = "cage.obj";
    ValidationReport v = validate_model(w.cage, mesh);
    a.seconds_check = seconds_since(t_check);
    a.failure = first_problem(v);
    if (a.failure.empty() && !(v.min_distance > 0)) a.failure = "a mesh vertex lies on the cage";
    // Wrap faces that no collapse touched may chord in closer than the clearance: retry with a larger offset
    // while attempts remain; the last attempt is accepted with the count recorded (the model checks passed).
    const bool checks_failed = !a.failure.empty();
    if (!checks_failed && a.faces_within_clearance > 0 && attempt < options.max_retries)
      a.failure = count_str(a.faces_within_clearance) + " cage faces closer than the clearance to the mesh";
    report.attempts.push_back(a);
    if (a.failure.empty()) {
      say("checks passed in " + format_g(a.seconds_check, 3) + " s: cage " + count_str(v.cage_vertices) +
          " vertices / " + count_str(v.cage_faces) + " faces, min distance mesh -> cage " +
          format_g(v.min_distance, 4) + " (" + format_g(v.min_distance / report.diagonal, 3) +
          " x diagonal)");
      result.cage = std::move(w.cage);
      report.validation = std::move(v);
      report.seconds = seconds_since(t_start);
      return result;
    }
    say("checks failed: " + a.failure);
    offset *= 1.5;
    if (checks_failed) faces = std::min(kMaxFaces, faces * 3 / 2);  // a finer cage for a failed model check
    if (offset >= 1) break;
  }
  std::string why;
  for (size_t k = 0; k < report.attempts.size(); ++k)
    why += "\n  attempt " + std::to_string(k + 1) + ": " + report.attempts[k].failure;
  throw NumericalError((mesh.source.empty() ? std::string("mesh") : mesh.source) + ": no valid cage after " +
                       std::to_string(report.attempts.size()) + " attempts:" + why);
}

void write_cage_model(const CageResult& result, const std::string& input_path, const MeshReadInfo& info,
                      const CageOptions& options,
                      const std::function<std::string(const std::string&)>& path_of) {
  const std::string header = "made by lidef cage from " + fs::path(input_path).filename().string();
  write_file_atomic(path_of("cage.obj"), [&](std::ostream& o) {
    write_obj(o, result.cage.V, result.cage.F,
              header + "\ncage: closed, outward-oriented triangle mesh (alpha wrap, simplified)");
  });
  write_file_atomic(path_of("mesh.obj"), [&](std::ostream& o) {
    write_obj(o, result.mesh.V, result.mesh.F,
              header + (result.mesh.F.rows() == 0
                            ? std::string("\nmesh: the input's points (a point cloud: no faces)")
                            : std::string("\nmesh: the input's vertices, polygons fan-triangulated")));
  });
  using nlohmann::ordered_json;
  const CageReport& r = result.report;
  const ValidationReport& v = r.validation;
  ordered_json j;
  j["name"] = fs::path(input_path).stem().string();
  j["source"] = "automatic cage, made by 'lidef cage' (cage/src/auto_cage.cpp; docs/cages.md)";
  j["input"] = {{"file", input_path},
                {"format", info.format},
                {"fnv1a64", hex64(info.file_hash)},
                {"vertices", info.file_vertices},
                {"polygons", info.file_polygons},
                {"fan_triangles", info.fan_triangles},
                {"dropped_faces", info.dropped_faces},
                {"dropped_vertices", info.dropped_vertices},
                {"degenerate_faces", info.degenerate_faces}};
  j["options"] = {{"faces", options.faces},
                  {"clearance", options.clearance},
                  {"offset", options.offset},
                  {"alpha", options.alpha},
                  {"max_retries", options.max_retries},
                  {"relative_to", "bounding-box diagonal of the mesh"}};
  j["diagonal"] = r.diagonal;
  const CageAttempt& last = r.attempts.back();
  j["alpha"] = last.alpha;
  j["offset"] = last.offset;
  j["clearance"] = last.clearance;
  j["target_faces"] = last.target_faces;
  j["retries"] = r.retries();
  ordered_json attempts = ordered_json::array();
  for (const CageAttempt& a : r.attempts)
    attempts.push_back({{"alpha", a.alpha},
                        {"offset", a.offset},
                        {"clearance", a.clearance},
                        {"target_faces", a.target_faces},
                        {"wrap_faces", a.wrap_faces},
                        {"cage_faces", a.cage_faces},
                        {"faces_within_clearance", a.faces_within_clearance},
                        {"failure", a.failure}});
  j["attempts"] = attempts;
  j["cage"] = {{"vertices", v.cage_vertices},
               {"triangles", v.cage_faces},
               {"genus", v.genus},
               {"components", v.cage_components}};
  j["mesh"] = {{"vertices", v.mesh_vertices}, {"triangles", v.mesh_faces}};
  j["min_distance_mesh_to_cage"] = v.min_distance;
  // Times vary run to run; they are the only part of the folder that does (cage.obj and mesh.obj do not).
  ordered_json times = ordered_json::array();
  for (const CageAttempt& a : r.attempts)
    times.push_back({{"wrap", a.seconds_wrap}, {"simplify", a.seconds_simplify}, {"check", a.seconds_check}});
  j["seconds"] = {{"total", r.seconds}, {"attempts", times}};
  write_file_atomic(path_of("model.json"), [&](std::ostream& o) { o << j.dump(2) << "\n"; });
}

bool is_mesh_file(const std::string& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec) && supported_format(lower_extension(path));
}

std::string resolve_model_path(const std::string& path, const CageLog& log, const std::string& cache_dir) {
  if (!is_mesh_file(path)) return path;
  std::string cache = cache_dir == "<default>" ? default_cache_dir() : cache_dir;
  if (cache.empty()) cache = (fs::temp_directory_path() / "lidef-cache").string();
  const CageOptions options;
  std::uint64_t h = file_hash(path);
  const std::string key_text =
      "faces=" + std::to_string(options.faces) + " clearance=" + format_double(options.clearance) +
      " offset=" + format_double(options.offset) + " alpha=" + format_double(options.alpha) +
      " retries=" + std::to_string(options.max_retries);
  h = fnv1a64(key_text, h);
  const fs::path dir = fs::path(cache) / "cages" / hex64(h);
  std::error_code ec;
  if (fs::is_regular_file(dir / "cage.obj", ec) && fs::is_regular_file(dir / "mesh.obj", ec) &&
      fs::is_regular_file(dir / "model.json", ec)) {
    if (log) log("reused cached cage " + dir.string() + " for " + path);
    return dir.string();
  }
  if (log) log("making a cage for " + path + " (cached in " + dir.string() + ")");
  MeshReadInfo info;
  const TriMesh mesh = read_any_mesh(path, &info);
  const CageResult result = make_cage(mesh, options, log);
  // Written into a private folder beside the entry, then renamed into place: a reader never sees a half-made
  // entry, and a concurrent maker of the same entry loses the rename harmlessly.
  ensure_directory(dir.parent_path().string());
  std::string tmpl = (dir.parent_path() / (".tmp-" + hex64(h) + "-XXXXXX")).string();
  if (!::mkdtemp(tmpl.data()))
    throw InputError(dir.parent_path().string(), "cannot create a folder in the cage cache");
  try {
    write_cage_model(result, fs::absolute(path).string(), info, options,
                     [&](const std::string& name) { return (fs::path(tmpl) / name).string(); });
    fs::rename(tmpl, dir, ec);
  } catch (...) {
    fs::remove_all(tmpl, ec);
    throw;
  }
  if (ec) fs::remove_all(tmpl, ec);  // another process made it meanwhile
  if (!fs::is_regular_file(dir / "cage.obj", ec))
    throw InputError(dir.string(), "cannot write the cage cache entry");
  return dir.string();
}

}  // namespace lidef
