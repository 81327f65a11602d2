#include "lidef/model_check.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <tuple>

#include "lidef/errors.h"
#include "lidef/geometry.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/number_format.h"
#include "lidef/self_intersections.h"
#include "lidef/staged_outputs.h"

namespace lidef {

std::string Issue::str() const {
  std::string s = file;
  if (line > 0) s += ":" + std::to_string(line);
  if (!s.empty()) s += ": ";
  if (!element.empty()) s += element + ": ";
  return s + message;
}

namespace {

namespace fs = std::filesystem;

constexpr int kMaxListed = 10;  // issues of one kind reported one by one; the rest are counted
constexpr int kMaxInline = 5;   // element numbers quoted inside one message

std::string point(const Vec3& p) {
  return "(" + format_g(p.x()) + ", " + format_g(p.y()) + ", " + format_g(p.z()) + ")";
}
std::string face_name(int t) {
  return "face " + std::to_string(t + 1);
}
std::string vertex_name(int v) {
  return "vertex " + std::to_string(v + 1);
}
long line_of(const std::vector<long>* lines, int i) {
  return lines && i >= 0 && i < static_cast<int>(lines->size()) ? (*lines)[i] : 0;
}

// Issues of one kind: the first kMaxListed individually, then one line counting the rest.
class IssueList {
 public:
  IssueList(std::vector<Issue>& out, std::string file, std::string kind)
      : out_(out), file_(std::move(file)), kind_(std::move(kind)) {}
  ~IssueList() {
    if (count_ > kMaxListed)
      out_.push_back({file_, "", 0, "... and " + std::to_string(count_ - kMaxListed) + " more " + kind_});
  }
  void add(std::string element, long line, std::string message) {
    if (count_++ < kMaxListed) out_.push_back({file_, std::move(element), line, std::move(message)});
  }
  int count() const { return count_; }

 private:
  std::vector<Issue>& out_;
  std::string file_, kind_;
  int count_ = 0;
};

// "5, 9, 12, ... (1-based)" for the first few of a list of 0-based indices.
std::string first_few(const std::vector<int>& idx) {
  std::string s;
  for (int i = 0; i < static_cast<int>(idx.size()) && i < kMaxInline; ++i)
    s += (i ? ", " : "") + std::to_string(idx[i] + 1);
  if (static_cast<int>(idx.size()) > kMaxInline) s += ", ...";
  return s;
}

double bbox_diagonal(const MatX3d& V) {
  return V.rows() ? (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm() : 0.0;
}

// Degenerate: a sliver whose normal is round-off, or a triangle negligibly small against the model.
bool is_degenerate(const Vec3& a, const Vec3& b, const Vec3& c, double diag, const CheckTolerances& tol,
                   double* area) {
  const double twice = (b - a).cross(c - a).norm();
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  *area = 0.5 * twice;
  return !(twice > tol.degenerate * longest2) || !(std::sqrt(longest2) > tol.tiny_edge * diag);
}

// Bounding-volume hierarchy over triangles, for point-to-surface distances (median split on the longest
// axis).
class FaceTree {
 public:
  FaceTree(const MatX3d& V, const MatX3i& F) : V_(V), F_(F), order_(F.rows()) {
    std::iota(order_.begin(), order_.end(), 0);
    centroid_.resize(F.rows());
    for (int t = 0; t < F.rows(); ++t)
      centroid_[t] = (V.row(F(t, 0)) + V.row(F(t, 1)) + V.row(F(t, 2))).transpose() / 3;
    nodes_.reserve(2 * F.rows());
    build(0, static_cast<int>(F.rows()));
  }

  double distance(const Vec3& p) const {
    double best = std::numeric_limits<double>::infinity();
    int stack[128], top = 0;
    stack[top++] = 0;
    while (top) {
      const Node& n = nodes_[stack[--top]];
      if (n.box.squaredExteriorDistance(p) >= best) continue;
      if (n.left < 0) {
        for (int i = n.begin; i < n.end; ++i) {
          const int t = order_[i];
          best =
              std::min(best, point_triangle_dist2(p, V_.row(F_(t, 0)), V_.row(F_(t, 1)), V_.row(F_(t, 2))));
        }
        continue;
      }
      // Push the farther child first so the nearer one is searched first and prunes more.
      const double dl = nodes_[n.left].box.squaredExteriorDistance(p),
                   dr = nodes_[n.right].box.squaredExteriorDistance(p);
      stack[top++] = dl < dr ? n.right : n.left;
      stack[top++] = dl < dr ? n.left : n.right;
    }
    return std::sqrt(best);
  }

 private:
  struct Node {
    Eigen::AlignedBox3d box;
    int left = -1, right = -1, begin = 0, end = 0;
  };
  int build(int begin, int end) {
    const int id = static_cast<int>(nodes_.size());
    nodes_.emplace_back();
    Eigen::AlignedBox3d box, cbox;
    for (int i = begin; i < end; ++i) {
      for (int k = 0; k < 3; ++k) box.extend(V_.row(F_(order_[i], k)).transpose());
      cbox.extend(centroid_[order_[i]]);
    }
    nodes_[id].box = box;
    nodes_[id].begin = begin;
    nodes_[id].end = end;
    if (end - begin <= 4) return id;
    int axis;
    cbox.sizes().maxCoeff(&axis);
    const int mid = (begin + end) / 2;
    std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                     [&](int a, int b) { return centroid_[a][axis] < centroid_[b][axis]; });
    const int l = build(begin, mid), r = build(mid, end);  // depth ~log2(#F), far below the stack size
    nodes_[id].left = l;
    nodes_[id].right = r;
    return id;
  }
  const MatX3d& V_;
  const MatX3i& F_;
  std::vector<int> order_;
  std::vector<Vec3> centroid_;
  std::vector<Node> nodes_;
};

// Index range and finite coordinates: the preconditions of every other check.
bool check_indices_and_values(const TriMesh& m, const std::string& file, const MeshLines* lines,
                              std::vector<Issue>& errors) {
  const int nv = static_cast<int>(m.V.rows());
  bool ok = true;
  {
    IssueList bad(errors, file, "faces with a vertex index out of range");
    for (int t = 0; t < m.F.rows(); ++t)
      for (int k = 0; k < 3; ++k)
        if (m.F(t, k) < 0 || m.F(t, k) >= nv) {
          bad.add(face_name(t), line_of(lines ? &lines->face : nullptr, t),
                  "vertex index " + std::to_string(m.F(t, k) + 1) + " is out of range (" +
                      std::to_string(nv) + " vertices)");
          ok = false;
          break;
        }
  }
  {
    IssueList bad(errors, file, "vertices with a NaN or infinite coordinate");
    for (int v = 0; v < nv; ++v)
      if (!m.V.row(v).allFinite()) {
        bad.add(vertex_name(v), line_of(lines ? &lines->vertex : nullptr, v),
                "coordinate is NaN or infinite " + point(m.V.row(v).transpose()));
        ok = false;
      }
  }
  return ok;
}

// The cage under check: its file (the name its issues carry), its arrays and the OBJ lines of its elements.
struct CageInput {
  std::string file;
  const MatX3d& V;                        // #V by 3
  const MatX3i& F;                        // #F by 3
  const std::vector<long>* vertex_lines;  // per vertex, or null
  const std::vector<long>* face_lines;    // per face, or null
};

// The undirected edges of the cage, as the orientation and component stages need them.
struct CageEdges {
  std::vector<std::vector<std::pair<int, bool>>> adjacent;  // per face: (neighbour, orientation agrees)
  std::vector<int> parent;  // union-find over faces: connected through shared edges (also non-manifold ones)
  bool closed = true, manifold = true;
};

int find_root(std::vector<int>& parent, int x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

// Faces: repeated vertices, degenerate shape, duplicates; signed volume.
void check_cage_faces(const CageInput& c, double diag, const CheckTolerances& tol, ValidationReport& r) {
  IssueList degenerate(r.errors, c.file, "degenerate faces");
  IssueList duplicate(r.errors, c.file, "duplicate faces");
  std::map<std::array<int, 3>, int> seen;
  const MatX3i& F = c.F;
  for (int t = 0; t < F.rows(); ++t) {
    const Vec3 a = c.V.row(F(t, 0)), b = c.V.row(F(t, 1)), cc = c.V.row(F(t, 2));
    double area;
    if (F(t, 0) == F(t, 1) || F(t, 1) == F(t, 2) || F(t, 0) == F(t, 2))
      degenerate.add(face_name(t), line_of(c.face_lines, t), "degenerate face: it uses a vertex twice");
    else if (is_degenerate(a, b, cc, diag, tol, &area))
      degenerate.add(
          face_name(t), line_of(c.face_lines, t),
          "degenerate face (area " + format_g(area) + "): its corners are (nearly) collinear or coincide");
    std::array<int, 3> key{F(t, 0), F(t, 1), F(t, 2)};
    std::sort(key.begin(), key.end());
    const auto [it, fresh] = seen.emplace(key, t);
    if (!fresh)
      duplicate.add(face_name(t), line_of(c.face_lines, t),
                    "duplicate of " + face_name(it->second) + " (same vertices)");
  }
  r.cage_volume = signed_volume(c.V, F);
}

// Unused vertices would add coefficient rows whose basis function is zero. Starts the Euler characteristic
// (used vertices + faces; the edge stage subtracts the edges).
void check_unused_vertices(const CageInput& c, ValidationReport& r) {
  const int nv = static_cast<int>(c.V.rows()), nf = static_cast<int>(c.F.rows());
  std::vector<char> used(nv, 0);
  for (int t = 0; t < nf; ++t)
    for (int k = 0; k < 3; ++k) used[c.F(t, k)] = 1;
  IssueList unused(r.warnings, c.file, "vertices not used by any face");
  for (int v = 0; v < nv; ++v)
    if (!used[v]) unused.add(vertex_name(v), line_of(c.vertex_lines, v), "not used by any face");
  r.euler_characteristic = static_cast<int>(std::count(used.begin(), used.end(), 1)) + nf;
}

// Undirected edges: sort the 3F directed half-edges by their vertex pair; equal pairs form one edge. Open
// (one face) and non-manifold (more than two faces) edges are errors.
CageEdges check_cage_edges(const CageInput& c, ValidationReport& r) {
  const MatX3i& F = c.F;
  const int nf = static_cast<int>(F.rows());
  struct HalfEdge {
    int lo, hi, face;
    bool forward;  // the face traverses lo -> hi
  };
  std::vector<HalfEdge> he;
  he.reserve(3 * nf);
  for (int t = 0; t < nf; ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = F(t, k), b = F(t, (k + 1) % 3);
      if (a != b) he.push_back({std::min(a, b), std::max(a, b), t, a < b});
    }
  std::sort(he.begin(), he.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return std::tie(x.lo, x.hi, x.face) < std::tie(y.lo, y.hi, y.face);
  });
  CageEdges e;
  e.adjacent.resize(nf);
  e.parent.resize(nf);
  std::iota(e.parent.begin(), e.parent.end(), 0);
  int num_edges = 0;
  {
    IssueList open(r.errors, c.file, "edges with only one face");
    IssueList nonmanifold(r.errors, c.file, "edges with more than two faces");
    for (size_t i = 0; i < he.size();) {
      size_t j = i;
      while (j < he.size() && he[j].lo == he[i].lo && he[j].hi == he[i].hi) ++j;
      ++num_edges;
      const std::string edge = "edge " + std::to_string(he[i].lo + 1) + "-" + std::to_string(he[i].hi + 1);
      const size_t n = j - i;
      if (n == 1) {
        e.closed = false;
        open.add(edge, line_of(c.face_lines, he[i].face),
                 "has only one face (" + face_name(he[i].face) +
                     "): the cage is not closed (a hole or a missing face)");
      } else if (n > 2) {
        e.manifold = false;
        std::string faces;
        for (size_t k = i; k < j && k < i + kMaxInline; ++k)
          faces += (k > i ? ", " : "") + std::to_string(he[k].face + 1);
        nonmanifold.add(edge, line_of(c.face_lines, he[i].face),
                        "is shared by " + std::to_string(n) + " faces (" + faces +
                            "): the cage is not edge-manifold (every edge needs exactly 2 faces)");
      } else {
        // Two faces agree in orientation iff they traverse the shared edge in opposite directions.
        const bool agree = he[i].forward != he[i + 1].forward;
        e.adjacent[he[i].face].push_back({he[i + 1].face, agree});
        e.adjacent[he[i + 1].face].push_back({he[i].face, agree});
      }
      for (size_t k = i + 1; k < j; ++k)
        e.parent[find_root(e.parent, he[k].face)] = find_root(e.parent, he[i].face);
      i = j;
    }
  }
  r.cage_edges = num_edges;
  r.euler_characteristic -= num_edges;
  return e;
}

// Orientation: propagate a flip flag across manifold edges from each component's first face; the faces in
// the minority class of a component are the flipped ones. Returns {orientable, consistently oriented}.
std::pair<bool, bool> check_cage_orientation(const CageInput& c, const CageEdges& e, ValidationReport& r) {
  const int nf = static_cast<int>(c.F.rows());
  std::vector<int> flip(nf, -1);
  bool orientable = true, consistent = true;
  IssueList flipped(r.errors, c.file, "flipped faces");
  for (int seed = 0; seed < nf; ++seed) {
    if (flip[seed] >= 0) continue;
    std::vector<int> comp{seed};
    flip[seed] = 0;
    bool conflict = false;
    for (size_t q = 0; q < comp.size(); ++q) {
      const int f = comp[q];
      for (const auto& [g, agree] : e.adjacent[f]) {
        const int want = agree ? flip[f] : 1 - flip[f];
        if (flip[g] < 0) {
          flip[g] = want;
          comp.push_back(g);
        } else if (flip[g] != want) {
          conflict = true;
        }
      }
    }
    if (conflict) {
      orientable = false;
      r.errors.push_back({c.file, face_name(seed), line_of(c.face_lines, seed),
                          "the cage cannot be oriented consistently (the surface containing this face is "
                          "non-orientable, e.g. a Moebius strip)"});
      continue;
    }
    const int n1 =
        static_cast<int>(std::count_if(comp.begin(), comp.end(), [&](int f) { return flip[f] == 1; }));
    const int bad = 2 * n1 <= static_cast<int>(comp.size()) ? 1 : 0;
    std::vector<int> bad_faces;
    for (int f : comp)
      if (flip[f] == bad) bad_faces.push_back(f);
    std::sort(bad_faces.begin(), bad_faces.end());
    for (int f : bad_faces) {
      consistent = false;
      std::vector<int> nb;
      for (const auto& [g, agree] : e.adjacent[f])
        if (!agree) nb.push_back(g);
      flipped.add(face_name(f), line_of(c.face_lines, f),
                  "flipped: its vertex order disagrees with its neighbours (" + first_few(nb) +
                      "); the cage is inconsistently oriented");
    }
  }
  return {orientable, consistent};
}

// Connected components through shared edges (also across non-manifold edges): a warning when there are
// several; the genus of a closed, manifold, orientable cage.
void check_cage_components(const CageInput& c, CageEdges& e, bool orientable, ValidationReport& r) {
  std::map<int, int> sizes;
  for (int t = 0; t < c.F.rows(); ++t) ++sizes[find_root(e.parent, t)];
  std::vector<int> comp_sizes;
  for (const auto& kv : sizes) comp_sizes.push_back(kv.second);
  r.cage_components = static_cast<int>(comp_sizes.size());
  if (r.cage_components > 1) {
    std::string s;
    for (int i = 0; i < static_cast<int>(comp_sizes.size()) && i < kMaxInline; ++i)
      s += (i ? ", " : "") + std::to_string(comp_sizes[i]);
    r.warnings.push_back({c.file, "", 0,
                          "the cage has " + std::to_string(r.cage_components) + " connected components (" +
                              s + " faces); fine for nested shells, otherwise check for stray faces"});
  }
  if (e.closed && e.manifold && orientable) r.genus = r.cage_components - r.euler_characteristic / 2;
}

// Outward orientation: meaningful only for a closed, consistently oriented surface.
void check_cage_outward(const CageInput& c, ValidationReport& r) {
  if (r.cage_volume > 0) return;
  if (r.cage_volume < 0)
    r.errors.push_back(
        {c.file, "", 0,
         "the cage is inverted: signed volume " + format_g(r.cage_volume) +
             " < 0, its faces are clockwise seen from outside (reverse the vertex order of every face)"});
  else
    r.errors.push_back({c.file, "", 0, "the cage encloses zero volume"});
}

// Self-intersections are a warning: near the crossing the winding number is 2 or 0 instead of 1.
void check_cage_self_intersections(const CageInput& c, ValidationReport& r) {
  r.self_intersections = find_self_intersections(c.V, c.F);
  if (r.self_intersections.empty()) return;
  const auto& si = r.self_intersections;
  std::string pairs;
  for (size_t i = 0; i < si.size() && i < 20; ++i)
    pairs += (i ? ", " : "") + std::to_string(si[i].first + 1) + " & " + std::to_string(si[i].second + 1);
  if (si.size() > 20) pairs += ", ...";
  r.warnings.push_back(
      {c.file, "faces " + std::to_string(si[0].first + 1) + " and " + std::to_string(si[0].second + 1),
       line_of(c.face_lines, si[0].first),
       "the cage intersects itself in " + std::to_string(si.size()) + " face pair" +
           (si.size() > 1 ? "s" : "") + " (" + pairs +
           "); near the crossing the winding number is 2 or 0 instead of 1"});
}

// All cage checks, in this order. Returns true when the cage passed every check (the mesh-in-cage test may
// then run).
bool check_cage(const TriMesh& cage, const MeshLines* lines, const CheckTolerances& tol,
                ValidationReport& r) {
  const CageInput c{cage.source.empty() ? "cage" : cage.source, cage.V, cage.F,
                    lines ? &lines->vertex : nullptr, lines ? &lines->face : nullptr};
  const int nv = static_cast<int>(cage.V.rows()), nf = static_cast<int>(cage.F.rows());
  const size_t errors_before = r.errors.size();
  r.cage_file = c.file;
  r.cage_vertices = nv;
  r.cage_faces = nf;
  if (nv < 4 || nf < 4) {
    r.errors.push_back({c.file, "", 0,
                        "a cage needs at least 4 vertices and 4 faces, found " + std::to_string(nv) +
                            " and " + std::to_string(nf)});
    return false;
  }
  if (!check_indices_and_values(cage, c.file, lines, r.errors)) return false;
  r.cage_bbox_min = cage.V.colwise().minCoeff().transpose();
  r.cage_bbox_max = cage.V.colwise().maxCoeff().transpose();

  check_cage_faces(c, bbox_diagonal(cage.V), tol, r);
  check_unused_vertices(c, r);
  CageEdges edges = check_cage_edges(c, r);
  const auto [orientable, consistent] = check_cage_orientation(c, edges, r);
  check_cage_components(c, edges, orientable, r);
  if (edges.closed && edges.manifold && orientable && consistent) check_cage_outward(c, r);
  check_cage_self_intersections(c, r);
  return r.errors.size() == errors_before;
}

// Winding number of the cage at every mesh vertex, without O(#V #F) work: the winding number is constant on
// each connected region of space off the cage, and the open ball of radius dist[u] around vertex u contains
// no cage point. So a mesh neighbour v with |u - v| < dist[u] has u's winding number; the exact sum
// (Cage::winding_number) is evaluated only at one seed per region the mesh edges cannot bridge (usually one
// per mesh component). Vertices on the cage (dist <= on_tol) get 0.5 and are not propagated.
std::vector<double> winding_numbers(const Cage& c, const TriMesh& mesh, const std::vector<double>& dist,
                                    double on_tol) {
  const int nv = static_cast<int>(mesh.V.rows());
  std::vector<std::vector<int>> nbr(nv);
  for (int t = 0; t < mesh.F.rows(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(t, k), b = mesh.F(t, (k + 1) % 3);
      nbr[a].push_back(b);
      nbr[b].push_back(a);
    }
  std::vector<double> wind(nv, 0.5);
  std::vector<char> known(nv, 0);
  std::vector<int> queue;
  constexpr double kSafety = 0.99;  // margin for round-off in the distances
  for (int seed = 0; seed < nv; ++seed) {
    if (known[seed] || dist[seed] <= on_tol) continue;
    const Vec3 p = mesh.V.row(seed).transpose();
    // Outside the cage's bounding box the winding number of a closed surface is exactly 0.
    const bool in_box = (p.array() >= c.bbox_min.array()).all() && (p.array() <= c.bbox_max.array()).all();
    wind[seed] = in_box ? c.winding_number(p) : 0.0;
    known[seed] = 1;
    queue.assign(1, seed);
    while (!queue.empty()) {
      const int u = queue.back();
      queue.pop_back();
      for (int v : nbr[u])
        if (!known[v] && dist[v] > on_tol &&
            (mesh.V.row(v) - mesh.V.row(u)).norm() < kSafety * std::max(dist[u], dist[v])) {
          wind[v] = wind[seed];
          known[v] = 1;
          queue.push_back(v);
        }
    }
  }
  return wind;
}

// Mesh checks; the mesh-in-cage test runs only when `cage` (already validated) is given.
void check_mesh(const TriMesh& mesh, const MeshLines* lines, const TriMesh* cage, const CheckTolerances& tol,
                ValidationReport& r) {
  const std::string file = mesh.source.empty() ? "mesh" : mesh.source;
  const auto* vl = lines ? &lines->vertex : nullptr;
  const auto* fl = lines ? &lines->face : nullptr;
  const int nv = static_cast<int>(mesh.V.rows()), nf = static_cast<int>(mesh.F.rows());
  r.mesh_file = file;
  r.mesh_vertices = nv;
  r.mesh_faces = nf;
  // A mesh without faces is a point set (a point cloud's model): its domain is the points.
  if (nv == 0) {
    r.errors.push_back({file, "", 0, "the mesh has no vertices"});
    return;
  }
  if (!check_indices_and_values(mesh, file, lines, r.errors)) return;
  r.mesh_bbox_min = mesh.V.colwise().minCoeff().transpose();
  r.mesh_bbox_max = mesh.V.colwise().maxCoeff().transpose();
  {
    const double diag = bbox_diagonal(mesh.V);
    IssueList degenerate(r.warnings, file, "degenerate mesh faces");
    for (int t = 0; t < nf; ++t) {
      double area;
      const Vec3 a = mesh.V.row(mesh.F(t, 0)), b = mesh.V.row(mesh.F(t, 1)), c = mesh.V.row(mesh.F(t, 2));
      if (is_degenerate(a, b, c, diag, tol, &area))
        degenerate.add(face_name(t), line_of(fl, t), "degenerate face (area " + format_g(area) + ")");
    }
  }
  if (!cage) return;

  // Mesh inside the cage: distance to the surface (BVH) for "on the cage", winding number for inside/outside.
  const Cage c(*cage);
  const FaceTree tree(c.V, c.F);
  const double on_tol = tol.on_cage * bbox_diagonal(c.V);
  std::vector<double> dist(nv);
#pragma omp parallel for schedule(dynamic, 256)
  for (int v = 0; v < nv; ++v) dist[v] = tree.distance(mesh.V.row(v).transpose());
  const std::vector<double> wind = winding_numbers(c, mesh, dist, on_tol);
  std::vector<int> on, outside, pocket;
  for (int v = 0; v < nv; ++v) {
    if (dist[v] <= on_tol)
      on.push_back(v);
    else if (wind[v] < 0.5)
      outside.push_back(v);
    else if (wind[v] >= 1.5)
      pocket.push_back(v);
  }
  r.inside_checked = true;
  r.mesh_vertices_on_cage = static_cast<int>(on.size());
  r.mesh_vertices_outside = static_cast<int>(outside.size());
  const auto imin = std::min_element(dist.begin(), dist.end()) - dist.begin();
  r.min_distance = dist[imin];
  r.min_distance_vertex = static_cast<int>(imin);
  auto count_of = [&](const std::vector<int>& list, const char* what) {
    return list.size() == 1 ? std::string()
                            : "; " + std::to_string(list.size()) + " of " + std::to_string(nv) +
                                  " mesh vertices " + what + " (first: " + first_few(list) + ")";
  };
  if (!on.empty())
    r.errors.push_back({file, vertex_name(on[0]), line_of(vl, on[0]),
                        "lies on the cage at " + point(mesh.V.row(on[0]).transpose()) + " (distance " +
                            format_g(dist[on[0]]) + "); the mesh must be strictly inside the cage" +
                            count_of(on, "are on the cage")});
  if (!outside.empty())
    r.errors.push_back({file, vertex_name(outside[0]), line_of(vl, outside[0]),
                        "is outside the cage at " + point(mesh.V.row(outside[0]).transpose()) +
                            " (winding number " + format_g(wind[outside[0]]) + ")" +
                            count_of(outside, "are outside")});
  if (!pocket.empty())
    r.warnings.push_back({file, vertex_name(pocket[0]), line_of(vl, pocket[0]),
                          "lies where the cage overlaps itself (winding number " + format_g(wind[pocket[0]]) +
                              ")" + count_of(pocket, "are in overlaps")});
}

}  // namespace

ValidationReport validate_model(const TriMesh& cage, const TriMesh& mesh, const MeshLines* cage_lines,
                                const MeshLines* mesh_lines, const CheckTolerances& tol) {
  const auto t0 = Clock::now();
  ValidationReport r;
  const bool cage_ok = check_cage(cage, cage_lines, tol, r);
  check_mesh(mesh, mesh_lines, cage_ok ? &cage : nullptr, tol, r);
  r.seconds = seconds_since(t0);
  return r;
}

ValidationReport check_model_dir(const std::string& dir, TriMesh* cage_out, TriMesh* mesh_out) {
  const auto t0 = Clock::now();
  ValidationReport r;
  std::error_code ec;
  if (!fs::exists(dir, ec)) {
    r.errors.push_back({dir, "", 0, "model folder not found"});
    return r;
  }
  if (!fs::is_directory(dir, ec)) {
    r.errors.push_back({dir, "", 0, "is not a folder; a model is a folder with cage.obj and mesh.obj"});
    return r;
  }
  try {  // a `lidef cage --out` killed while it moved its files in: its journal says what is left to do
    finish_interrupted_commit(dir);
  } catch (const InputError& e) {
    r.errors.push_back({e.file(), "", 0, e.message()});
    return r;
  }
  auto locate = [&](const std::string& name) -> std::string {
    const std::string obj = (fs::path(dir) / (name + ".obj")).string();
    const std::string off = (fs::path(dir) / (name + ".off")).string();
    const bool has_obj = fs::exists(obj, ec), has_off = fs::exists(off, ec);
    if (has_obj && has_off)
      r.warnings.push_back(
          {off, "", 0, "both " + name + ".obj and " + name + ".off exist; using " + name + ".obj"});
    if (has_obj) return obj;
    if (has_off) return off;
    r.errors.push_back({dir, "", 0, "no " + name + ".obj or " + name + ".off in the model folder"});
    return "";
  };
  TriMesh cage, mesh;
  MeshLines cage_lines, mesh_lines;
  auto read = [&](const std::string& path, TriMesh& m, MeshLines& lines, bool allow_points) {
    if (path.empty()) return false;
    try {
      m = allow_points ? read_mesh_or_points(path, &lines) : read_mesh(path, &lines);
      return true;
    } catch (const InputError& e) {
      r.errors.push_back({e.file(), "", e.line(), e.message()});
      return false;
    }
  };
  const bool have_cage = read(locate("cage"), cage, cage_lines, false);
  const bool have_mesh = read(locate("mesh"), mesh, mesh_lines, true);
  const CheckTolerances tol;
  const bool cage_ok = have_cage && check_cage(cage, &cage_lines, tol, r);
  if (have_mesh) check_mesh(mesh, &mesh_lines, cage_ok && r.errors.empty() ? &cage : nullptr, tol, r);
  if (cage_out) *cage_out = std::move(cage);
  if (mesh_out) *mesh_out = std::move(mesh);
  r.seconds = seconds_since(t0);
  return r;
}

Model load_model(const std::string& dir) {
  TriMesh cage, mesh;
  ValidationReport report = check_model_dir(dir, &cage, &mesh);
  if (!report.usable()) {
    std::string msg = "model is not usable (" + std::to_string(report.errors.size()) + " error" +
                      (report.errors.size() > 1 ? "s" : "") + "):";
    for (const Issue& e : report.errors) msg += "\n  " + e.str();
    throw InputError(dir, msg);
  }
  return Model{Cage(cage), std::move(mesh), dir, std::move(report)};
}

std::string report_to_json(const ValidationReport& r) {
  using nlohmann::ordered_json;
  auto issues = [](const std::vector<Issue>& list) {
    ordered_json a = ordered_json::array();
    for (const Issue& i : list)
      a.push_back({{"file", i.file},
                   {"element", i.element},
                   {"line", i.line},
                   {"message", i.message},
                   {"text", i.str()}});
    return a;
  };
  auto vec = [](const Vec3& v) { return ordered_json::array({v.x(), v.y(), v.z()}); };
  auto number = [](double x) { return std::isfinite(x) ? ordered_json(x) : ordered_json(nullptr); };
  ordered_json si = ordered_json::array();
  for (const auto& [a, b] : r.self_intersections) si.push_back({a + 1, b + 1});
  ordered_json j;
  j["usable"] = r.usable();
  j["errors"] = issues(r.errors);
  j["warnings"] = issues(r.warnings);
  j["cage"] = {{"file", r.cage_file},
               {"vertices", r.cage_vertices},
               {"faces", r.cage_faces},
               {"edges", r.cage_edges},
               {"components", r.cage_components},
               {"euler_characteristic", r.euler_characteristic},
               {"genus", r.genus},
               {"volume", r.cage_volume},
               {"bbox_min", vec(r.cage_bbox_min)},
               {"bbox_max", vec(r.cage_bbox_max)},
               {"self_intersecting_face_pairs", si}};
  j["mesh"] = {{"file", r.mesh_file},
               {"vertices", r.mesh_vertices},
               {"faces", r.mesh_faces},
               {"bbox_min", vec(r.mesh_bbox_min)},
               {"bbox_max", vec(r.mesh_bbox_max)},
               {"inside_checked", r.inside_checked},
               {"vertices_outside", r.mesh_vertices_outside},
               {"vertices_on_cage", r.mesh_vertices_on_cage},
               {"min_distance_to_cage", number(r.min_distance)},
               {"min_distance_vertex", r.min_distance_vertex >= 0 ? ordered_json(r.min_distance_vertex + 1)
                                                                  : ordered_json(nullptr)}};
  j["seconds"] = r.seconds;
  return j.dump(2) + "\n";
}

}  // namespace lidef
