#include "lidef/compare/tet_mesh.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/number_format.h"

namespace lidef {

namespace {
// Next non-empty, non-comment line; false at end of file.
bool next_line(std::istream& in, std::string& line, long& lineno) {
  while (std::getline(in, line)) {
    ++lineno;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    if (line.find_first_not_of(" \t\r") != std::string::npos) return true;
  }
  return false;
}

double signed_volume6(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  return (b - a).cross(c - a).dot(d - a);
}
}  // namespace

TetMesh read_tet_mesh(const std::string& node_path, const std::string& ele_path) {
  TetMesh m;
  m.source = ele_path;
  int base = 1;
  {
    std::ifstream in(node_path);
    if (!in) throw InputError(node_path, "cannot open the tet .node file");
    std::string line;
    long ln = 0;
    if (!next_line(in, line, ln)) throw InputError(node_path, "empty .node file");
    long n = 0, dim = 0;
    std::istringstream h(line);
    if (!(h >> n >> dim) || dim != 3 || n < 0)
      throw InputError(node_path, "bad header (expected 'n 3 ...')", ln);
    if (n == 0) throw InputError(node_path, "the tet mesh has no vertices", ln);
    m.V.resize(n, 3);
    for (long i = 0; i < n; ++i) {
      if (!next_line(in, line, ln))
        throw InputError(node_path, "expected " + std::to_string(n) + " vertices", ln);
      std::istringstream s(line);
      long id;
      double x, y, z;
      if (!(s >> id >> x >> y >> z) || !std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
        throw InputError(node_path, "expected 'index x y z' with finite coordinates", ln);
      if (i == 0) base = static_cast<int>(id);
      if (id != i + base) throw InputError(node_path, "vertex numbers must be consecutive", ln);
      m.V.row(i) << x, y, z;
    }
  }
  std::ifstream in(ele_path);
  if (!in) throw InputError(ele_path, "cannot open the tet .ele file");
  std::string line;
  long ln = 0;
  if (!next_line(in, line, ln)) throw InputError(ele_path, "empty .ele file");
  long n = 0, corners = 0;
  std::istringstream h(line);
  if (!(h >> n >> corners) || corners != 4 || n < 0)
    throw InputError(ele_path, "bad header (expected 'n 4 ...'; only linear tets)", ln);
  if (n == 0) throw InputError(ele_path, "the tet mesh has no tetrahedra", ln);
  m.T.resize(n, 4);
  for (long t = 0; t < n; ++t) {
    if (!next_line(in, line, ln))
      throw InputError(ele_path, "expected " + std::to_string(n) + " tetrahedra", ln);
    std::istringstream s(line);
    long id, v[4];
    if (!(s >> id >> v[0] >> v[1] >> v[2] >> v[3]))
      throw InputError(ele_path, "expected 'index a b c d'", ln);
    for (int k = 0; k < 4; ++k) {
      if (v[k] - base < 0 || v[k] - base >= m.V.rows())
        throw InputError(ele_path, "vertex index " + std::to_string(v[k]) + " out of range", ln);
      m.T(t, k) = static_cast<int>(v[k] - base);
    }
    const Vec3 a = m.V.row(m.T(t, 0)), b = m.V.row(m.T(t, 1)), c = m.V.row(m.T(t, 2)), d = m.V.row(m.T(t, 3));
    const double v6 = signed_volume6(a, b, c, d);
    const double scale = std::max({(b - a).norm(), (c - a).norm(), (d - a).norm()});
    if (!(std::abs(v6) > 1e-12 * scale * scale * scale))
      throw InputError(ele_path, "degenerate (zero-volume) tetrahedron " + std::to_string(id), ln);
    if (v6 < 0) std::swap(m.T(t, 2), m.T(t, 3));
  }
  return m;
}

Eigen::SparseMatrix<double, Eigen::RowMajor> TetEmbedding::weights() const {
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(4 * tet.size());
  for (Eigen::Index p = 0; p < tet.size(); ++p)
    for (int k = 0; k < 4; ++k) trip.emplace_back(static_cast<int>(p), corners(p, k), bary(p, k));
  Eigen::SparseMatrix<double, Eigen::RowMajor> W(tet.size(), num_vertices);
  W.setFromTriplets(trip.begin(), trip.end());
  return W;
}

TetEmbedding embed_points(const TetMesh& mesh, const MatX3d& P, const std::string& where, double tolerance) {
  if (mesh.num_tets() == 0) throw InputError(where, "the tet mesh is empty");
  const int nt = mesh.num_tets();
  // Per tet: inverse of [v1-v0, v2-v0, v3-v0] for barycentric coordinates, and its bounding box.
  std::vector<Mat3> inv(nt);
  Vec3 lo = mesh.V.colwise().minCoeff().transpose(), hi = mesh.V.colwise().maxCoeff().transpose();
  const double diag = (hi - lo).norm();
  // Grid of about nt cells over the bounding box; each cell lists the tets whose box overlaps it.
  const double cell = std::cbrt((hi - lo).prod() / std::max(1, nt)) + 1e-12 * diag;
  int dims[3];
  for (int k = 0; k < 3; ++k)
    dims[k] = std::max(1, std::min(512, static_cast<int>(std::ceil((hi(k) - lo(k)) / cell))));
  auto clampi = [&](double x, int k) {
    return std::max(0, std::min(dims[k] - 1, static_cast<int>(std::floor((x - lo(k)) / cell))));
  };
  std::vector<std::vector<int>> grid(static_cast<size_t>(dims[0]) * dims[1] * dims[2]);
  for (int t = 0; t < nt; ++t) {
    Mat3 D;
    const Vec3 a = mesh.V.row(mesh.T(t, 0));
    Vec3 tlo = a, thi = a;
    for (int k = 1; k < 4; ++k) {
      const Vec3 b = mesh.V.row(mesh.T(t, k));
      D.col(k - 1) = b - a;
      tlo = tlo.cwiseMin(b);
      thi = thi.cwiseMax(b);
    }
    inv[t] = D.inverse();
    const double pad = 1e-9 * diag;
    for (int i = clampi(tlo(0) - pad, 0); i <= clampi(thi(0) + pad, 0); ++i)
      for (int j = clampi(tlo(1) - pad, 1); j <= clampi(thi(1) + pad, 1); ++j)
        for (int k = clampi(tlo(2) - pad, 2); k <= clampi(thi(2) + pad, 2); ++k)
          grid[(static_cast<size_t>(k) * dims[1] + j) * dims[0] + i].push_back(t);
  }
  TetEmbedding e;
  e.num_vertices = mesh.num_vertices();
  e.tet.resize(P.rows());
  e.bary.resize(P.rows(), 4);
  e.corners.resize(P.rows(), 4);
  long outside = 0, first_outside = -1;
  for (Eigen::Index p = 0; p < P.rows(); ++p) {
    const Vec3 x = P.row(p);
    int best = -1;
    double best_min = -std::numeric_limits<double>::infinity();
    Eigen::Vector4d best_b;
    bool in_box = true;
    for (int k = 0; k < 3; ++k) in_box = in_box && x(k) >= lo(k) - 1e-9 * diag && x(k) <= hi(k) + 1e-9 * diag;
    if (in_box) {
      const auto& list = grid[(static_cast<size_t>(clampi(x(2), 2)) * dims[1] + clampi(x(1), 1)) * dims[0] +
                              clampi(x(0), 0)];
      for (int t : list) {
        const Vec3 l = inv[t] * (x - mesh.V.row(mesh.T(t, 0)).transpose());
        const Eigen::Vector4d b(1 - l.sum(), l(0), l(1), l(2));
        const double mn = b.minCoeff();
        if (mn > best_min) {
          best_min = mn;
          best = t;
          best_b = b;
        }
        if (mn >= 0)
          break;  // strictly or on the boundary inside: good enough, any containing tet gives the same map
      }
    }
    if (best < 0 || best_min < -tolerance) {
      if (outside++ == 0) first_outside = p;
      continue;
    }
    e.tet(p) = best;
    e.bary.row(p) = best_b.transpose();
    e.corners.row(p) = mesh.T.row(best);
  }
  if (outside > 0) {
    std::ostringstream s;
    s.precision(9);
    s << "point " << first_outside << " (" << P.row(first_outside) << ") lies outside every tetrahedron";
    if (outside > 1) s << " (" << outside << " of " << P.rows() << " points do)";
    throw InputError(where, s.str());
  }
  return e;
}

namespace {
// x rounded to 3 significant digits (x > 0).
double round3(double x) {
  const double scale = std::pow(10.0, std::floor(std::log10(x)) - 2);
  return std::round(x / scale) * scale;
}
}  // namespace

TetgenForVertices tetrahedralize_min_vertices(const TriMesh& cage, TetgenOptions options, int min_vertices) {
  const std::string where = cage.source.empty() ? "cage" : cage.source;
  if (min_vertices < 4) throw InputError(where, "tetrahedralize: the target vertex count must be >= 4");
  const double volume = std::abs(signed_volume(cage.V, cage.F));
  if (!(volume > 0)) throw InputError(where, "tetrahedralize: the cage encloses no volume");
  TetgenForVertices best;
  int meshings = 0;
  // `enough`: the largest volume tried whose mesh reached the target; `short_of`: the smallest tried whose
  // mesh did not (infinite until one is tried).
  double enough = 0, short_of = std::numeric_limits<double>::infinity();
  // A quality tet mesh has about 6 tets per vertex: the first guess aims at the target directly.
  double v = round3(volume / (6.0 * min_vertices));
  constexpr int kMaxMeshings = 40;
  while (meshings < kMaxMeshings) {
    options.max_volume = v;
    TetMesh m = tetrahedralize(cage, options);
    ++meshings;
    if (m.num_vertices() >= min_vertices) {
      enough = v;
      best.mesh = std::move(m);
      best.options = options;
    } else {
      short_of = v;
    }
    const bool bracketed = enough > 0 && std::isfinite(short_of);
    if (bracketed && short_of <= 1.1 * enough) break;
    // No tet is larger than the cage: beyond its volume the switch changes nothing, and the target is met.
    if (!bracketed && enough > 0 && v >= volume) break;
    const double next = bracketed    ? round3(std::sqrt(enough * short_of))
                        : enough > 0 ? round3(2 * v)
                                     : round3(v / 2);
    // Rounding can land on an end of the bracket: the bracket is then as narrow as 3 digits allow.
    if (next == enough || next == short_of) break;
    v = next;
  }
  if (enough <= 0)
    throw NumericalError(where + ": TetGen reached no mesh with " + std::to_string(min_vertices) +
                         " vertices in " + std::to_string(meshings) +
                         " meshings (smallest max volume tried " + format_g(v) + ")");
  best.meshings = meshings;
  return best;
}

}  // namespace lidef
