// Global injectivity on the mesh's solid (docs/certificate.md, "Global injectivity"): stages
//   1. map-dependent constants: ‖δ_e‖ per cage edge, the mapped mesh vertices, the rounding allowance ε;
//   2. one piece per surface triangle (ball, L₁, tube radius ρ) and per mesh vertex its star ball;
//   3. candidate pairs: triangles whose tube boxes overlap (a sorted cell list, deterministic);
//   4. per pair: separate, cover by an injectivity ball, prove a crossing, or split (bounded);
//   5. the verdict (the first overlap in pair order, else the first undecided pair, else — for a surface of
//      several components — the nesting of their images, else injective);
//   6. for a map proven injective, the margins a later check reuses (Step G6).
#include "lidef/global_injectivity.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>

#include "lidef/errors.h"
#include "lidef/exact_winding.h"
#include "lidef/geometry.h"
#include "lidef/green_coordinates.h"
#include "lidef/internal/edge_jet.h"
#include "lidef/internal/float_rows.h"
#include "lidef/internal/mesh_queries.h"
#include "lidef/internal/rest_solid.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/lipschitz_bound.h"
#include "lidef/number_format.h"
#include "lidef/self_intersections.h"
#include "lidef/signed_svd.h"

namespace lidef {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative allowance for the double-precision evaluation of f at a point (the closed-form basis and the sum
// over the coefficients), relative to the magnitudes of the coefficients' contributions
// (docs/certificate.md).
constexpr double kValueRel = 1e-8;
// Relative allowance for J and the bounds (as the local certificate's kRoundingRel).
constexpr double kRoundingRel = 1e-9;
// A piece's corners are rounded midpoints: at split depth d each lies within d · kCornerRel · C of the exact
// point of the mesh triangle (C the largest coordinate magnitude; one rounding of a + b per level, the
// halving is exact: |fl(a + b)/2 − (a + b)/2| ≤ 2⁻⁵³ C per coordinate, √3 · 2⁻⁵³ = 1.93e-16 in norm). Balls
// are widened by the error of kDepthCap levels, which covers every piece and its descendants.
constexpr double kCornerRel = 2e-16;
constexpr int kDepthCap = 32;
// Relative slack of the geometric predicates on the affine image triangles (dot products, distances of
// points of magnitude M carry errors of a few 1e-16 M; 1e-12 M is far above them).
constexpr double kGeomRel = 1e-12;

// Sorts entries key · 2³² + index (key < 2³⁰), made in increasing index, by key: a stable LSD radix sort on
// the key's two 15-bit halves, which leaves them as sorting the whole 64-bit values would.
void sort_by_key(std::vector<std::uint64_t>& v) {
  std::vector<std::uint64_t> tmp(v.size());
  std::vector<size_t> count;
  for (const int shift : {32, 47}) {
    count.assign((size_t{1} << 15) + 1, 0);
    for (const std::uint64_t e : v) ++count[((e >> shift) & 0x7fff) + 1];
    for (size_t i = 1; i < count.size(); ++i) count[i] += count[i - 1];
    for (const std::uint64_t e : v) tmp[count[(e >> shift) & 0x7fff]++] = e;
    v.swap(tmp);
  }
}

// A triangle piece of the rest surface: corners p, their computed images q, the ball (c, R) ⊇ piece, the
// Lipschitz constant L1 of J on that ball, and the tube radius rho.
struct Piece {
  std::array<Vec3, 3> p, q;
  Vec3 c = Vec3::Zero();
  double R = 0, diam = 0, L1 = kInf, rho = kInf;
  double r_enc = 0;  // triangle_enclosing_radius of the corners
  double jb = kInf;  // depth > 0: an upper bound of ‖J‖₂ on a ball containing the piece (its ancestor's)
  int face = -1, depth = 0;
  int top = -1;  // the top piece it was split from (index into the check's top pieces; -1 before)
  // Which piece of its mesh triangle it is, the same in every check (Step G6): the face, the depth and the
  // path of child indices (2 bits per level); kNoPiece below kMaxIdDepth levels.
  std::uint64_t id = 0;
};
constexpr std::uint64_t kNoPiece = ~std::uint64_t{0};
constexpr int kMaxIdDepth = 13;
std::uint64_t face_piece_id(long face) {
  return static_cast<std::uint64_t>(face) << 32;
}
std::uint64_t child_piece_id(std::uint64_t parent, int child) {
  if (parent == kNoPiece) return kNoPiece;
  const std::uint64_t depth = ((parent >> 26) & 63) + 1, path = parent & ((std::uint64_t{1} << 26) - 1);
  if (depth > kMaxIdDepth) return kNoPiece;
  return (parent >> 32 << 32) | (depth << 26) | (path * 4 + static_cast<std::uint64_t>(child));
}

double separation_lower_bound(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b, double slack);

// An injectivity ball of a proven map (Step G2) as a later check reuses it (Step G6): μ ≤ σ3(J(c)) − R L̂
// for an upper bound L̂ of ‖∇J‖ on the ball, and its radius. Its factors Γ_e are kept summed per group of
// nearby cage edges (ProvenMargins::group_sums): Σ_e ‖Δδ_e‖ Γ_e ≤ Σ_g (Σ_{e∈g} Γ_e) max_{e∈g} ‖Δδ_e‖ bounds
// the motion's L1 on the ball.
struct MarginBall {
  double mu, R;
  Vec3 c;
};
// Cage edges in groups of nearby edges (contiguous in Morton order of their midpoints): the motion of a later
// map is concentrated on a few groups, where one sum over all edges would spread it over the whole cage.
constexpr int kEdgeGroups = 64;

// What a map proven injective leaves for later checks (Step G6), in the normalized frame.
struct ProvenMargins {
  MatX3d y;   // its coefficients
  MatX3d fV;  // its computed mesh vertices' images, each within eps of the exact one
  double eps = 0;
  std::vector<double> A_abs;  // the rounding scales of its face matrices (per cage face)
  std::vector<Mat3> Jv;       // its computed J at the mesh vertices, ‖J̃ − J‖₂ ≤ 1e-9 sJv
  std::vector<double> sJv;
  // Per pair of top pieces (by Piece::id, a before b) whose piece pairs were all cleared by separation or by
  // injectivity balls: the smallest separation margin (+∞: none) and its balls [ball_begin, ball_end).
  struct Pair {
    std::uint64_t a, b;
    double sep;
    long ball_begin, ball_end;
    bool operator<(const Pair& o) const { return a != o.a ? a < o.a : b < o.b; }
  };
  std::vector<Pair> pairs;  // sorted
  std::vector<MarginBall> balls;
  std::vector<float> group_sums;  // per ball kEdgeGroups sums Σ_{e∈g} Γ_e, rounded up
  // Per top piece split from its mesh triangle (depth > 0): its corners' computed images, its bound of ‖J‖,
  // and J̃ at its ball's center with the rounding scale.
  struct Top {
    std::uint64_t id;
    std::array<Vec3, 3> q;
    double jb, sJ;
    Mat3 J;
    bool operator<(const Top& o) const { return id < o.id; }
  };
  std::vector<Top> tops;  // sorted by id
  const Pair* find(std::uint64_t a, std::uint64_t b) const {
    const Pair k{a, b, 0, 0, 0};
    auto it = std::lower_bound(pairs.begin(), pairs.end(), k);
    return it != pairs.end() && it->a == a && it->b == b ? &*it : nullptr;
  }
  const Top* find_top(std::uint64_t id) const {
    const Top k{id, {}, 0, 0, Mat3::Zero()};
    auto it = std::lower_bound(tops.begin(), tops.end(), k);
    return it != tops.end() && it->id == id ? &*it : nullptr;
  }
};

double tri_diameter(const std::array<Vec3, 3>& p) {
  return std::max({(p[0] - p[1]).norm(), (p[1] - p[2]).norm(), (p[2] - p[0]).norm()});
}

}  // namespace

const char* to_json_literal(GlobalInjectivity::Verdict v) {
  switch (v) {
    case GlobalInjectivity::Verdict::kInjective:
      return "true";
    case GlobalInjectivity::Verdict::kOverlap:
      return "false";
    default:
      return "null";
  }
}

std::string no_overlap_words(const GlobalInjectivity& g) {
  std::string words = "the shape does not pass through itself";
  if (g.rest_intersecting_pairs > 0)
    words += "; the rest mesh's own intersections (" + std::to_string(g.rest_intersecting_pairs) +
             " pairs of triangles) are mapped one-to-one";
  return words;
}

GlobalInjectivity global_injectivity_not_decided(const std::string& reason) {
  GlobalInjectivity g;
  g.reason = reason;
  return g;
}

struct GlobalInjectivityChecker::Impl {
  // Everything is computed in the cage's normalized frame (bounding-box center at the origin, diagonal 1), so
  // that the rounding allowances, relative to the coefficients' magnitudes, do not grow when the model is
  // moved away from the origin; points are reported in model units (center + scale · p).
  double cache_bytes;  // the budget of what no map changes (cache_map_independent_parts)
  Vec3 center;
  double scale;
  Cage cage;
  TriMesh mesh;
  HarmonicBasis basis;
  EdgeJet edge_jet;  // J at a point per cage edge (docs/certificate.md, Step 4b): the balls' centers
  EdgeArrays edges;
  TriangleGrid cage_grid;
  WindingNumber cage_winding;
  std::vector<std::vector<int>> vertex_faces;  // per mesh vertex the faces around it
  std::string structure_problem;               // why the surface argument does not apply ("" = it does)
  // The surface's connected components (numbered in the order of their first triangle) and their faces.
  std::vector<std::vector<int>> component_faces;
  double cage_diameter = 0;
  double corner_unit = 0;       // kCornerRel · the largest coordinate magnitude of the mesh (Step G3)
  std::vector<int> edge_group;  // per cage edge its group (Step G6), in [0, kEdgeGroups)
  void group_edges() {
    const int ne = cage.num_edges();
    std::vector<std::pair<std::uint64_t, int>> order(ne);
    const Vec3 lo = cage.bbox_min, ext = (cage.bbox_max - cage.bbox_min).cwiseMax(1e-300);
    for (int e = 0; e < ne; ++e) {
      const Vec3 m = 0.5 * (Vec3(cage.V.row(cage.edges[e].v0)) + Vec3(cage.V.row(cage.edges[e].v1)));
      std::uint64_t code = 0;
      for (int bit = 20; bit >= 0; --bit)
        for (int k = 0; k < 3; ++k) {
          const auto q =
              static_cast<std::uint64_t>(std::clamp((m(k) - lo(k)) / ext(k), 0.0, 1.0) * 2097151.0);
          code = (code << 1) | ((q >> bit) & 1);
        }
      order[e] = {code, e};
    }
    std::sort(order.begin(), order.end());
    edge_group.assign(ne, 0);
    for (int i = 0; i < ne; ++i)
      edge_group[order[i].second] = static_cast<int>(static_cast<long>(i) * kEdgeGroups / std::max(ne, 1));
  }
  // The margins of the last map proven injective (Step G6); replaced by each check that proves one.
  mutable std::mutex margins_mutex;
  mutable std::shared_ptr<const ProvenMargins> margins;

  static TriMesh normalized(const MatX3d& V, const MatX3i& F, const Vec3& center, double scale) {
    TriMesh t;
    t.V = (V.rowwise() - center.transpose()) / scale;
    t.F = F;
    return t;
  }
  Impl(const Cage& c, const TriMesh& m, double cache_mb)
      : cache_bytes(std::max(0.0, cache_mb) * 1048576.0),
        center(0.5 * (c.bbox_min + c.bbox_max)),
        scale(std::max((c.bbox_max - c.bbox_min).norm(), 1e-300)),
        cage(normalized(c.V, c.F, center, scale)),
        mesh(normalized(m.V, m.F, center, scale)),
        basis(cage),
        edge_jet(cage),
        edges(edge_endpoints(cage, true), edge_endpoints(cage, false)),
        cage_grid(cage.V, cage.F, (cage.bbox_max - cage.bbox_min).norm() / 64.0),
        cage_winding(cage.V, cage.F) {
    cage_diameter = (cage.bbox_max - cage.bbox_min).norm();
    if (mesh.V.rows() > 0) corner_unit = kCornerRel * mesh.V.cwiseAbs().maxCoeff() * (1 + 1e-9);
    reach = 2 * (kDepthCap * corner_unit);
    vertex_faces = faces_around_vertices(mesh.F, static_cast<int>(mesh.V.rows()));
    structure_problem = check_structure();
    group_edges();
    // Exact predicates on the model's own coordinates (normalizing them would round).
    if (structure_problem.empty()) {
      rest_intersections = find_self_intersections(m.V, m.F);
      if (!rest_intersections.empty())
        rest_problem = check_rest_solid(m.V);
      else if (component_faces.size() > 1)
        rest_nesting_problem = check_rest_nesting(m.V);
      cache_map_independent_parts(cache_bytes);
    }
  }

  // The degree argument (true) needs ∂D to be an embedded surface; where the rest mesh's triangles already
  // intersect, ∂D is computed (check_rest_solid), and rest_problem says why it could not be. A crossing
  // (false) is only proven between triangles that are disjoint at rest: they share no vertex and are not
  // among these pairs (sorted, i < j), so x ≠ y with f(x) = f(y).
  std::vector<std::pair<int, int>> rest_intersections;
  std::string rest_problem;

  // A rest mesh that intersects itself (Step G1): "true" is still proven on D = closure{w ≥ 1} when ∂D,
  // computed exactly, is one closed connected manifold — the pair stage then proves f injective on the whole
  // mesh, ∂D included. Returns "" or why not.
  std::string check_rest_solid(const MatX3d& V) {
    std::string why;
    if (component_faces.size() > 1) {
      why = "the mesh has " + std::to_string(component_faces.size()) + " surface components";
    } else {
      const RestSolidBoundary b = rest_solid_boundary(V, mesh.F, rest_intersections);
      why = b.problem;
      if (why.empty()) {
        const auto around = faces_around_vertices(b.F, b.num_points);
        if (std::string problem = closed_manifold_problem(b.F, around); !problem.empty())
          why = "its pieces do not form a manifold: " + problem + " (numbered among the pieces' corners)";
        else if (const auto comps = face_components(b.F, around); comps.size() != 1)
          why = "it has " + std::to_string(comps.size()) + " components";
      }
    }
    if (why.empty()) return "";
    return "the rest-state mesh intersects itself (" + std::to_string(rest_intersections.size()) +
           " pairs of triangles, the first " + std::to_string(rest_intersections[0].first) + " and " +
           std::to_string(rest_intersections[0].second) +
           ") and the boundary of its solid is not decided: " + why;
  }
  bool intersect_at_rest(int a, int b) const {
    const std::pair<int, int> key{std::min(a, b), std::max(a, b)};
    return std::binary_search(rest_intersections.begin(), rest_intersections.end(), key);
  }

  static std::vector<Vec3> edge_endpoints(const Cage& c, bool first) {
    std::vector<Vec3> out;
    for (const CageEdge& e : c.edges) out.push_back(c.V.row(first ? e.v0 : e.v1));
    return out;
  }

  // The degree argument needs ∂D to be closed surfaces: every undirected edge used once in each direction,
  // and every vertex one fan (Jordan–Brouwer needs a manifold, Step G1); several components go to the
  // nesting stage (Step G5).
  std::string check_structure() {
    const long nf = mesh.F.rows();
    if (std::string problem = closed_manifold_problem(mesh.F, vertex_faces); !problem.empty()) return problem;
    component_faces = face_components(mesh.F, vertex_faces);
    // The nesting stage costs (#components) × #F triangle tests.
    const double nesting_work = static_cast<double>(component_faces.size()) * static_cast<double>(nf);
    if (component_faces.size() > 1 && nesting_work > kMaxNestingWork)
      return "the mesh surface has " + std::to_string(component_faces.size()) +
             " connected components; comparing their nesting would take too many triangle tests";
    return "";
  }

  // --- The nesting of several surface components (docs/certificate.md, Step G5).
  static constexpr double kMaxNestingWork = 4e8;
  std::string rest_nesting_problem;  // the rest components do not bound one solid as oriented ("" = they do)

  // The image of each component and the windings that decide the mapping degree next to it: (W #V' by 3,
  // F #F' by 3) the surface, or a conforming refinement of it, under the map, comps its faces per component,
  // rho (per face of F, nullptr at rest) the tube radii of the faces' images about their affine triangles on
  // W, eps the evaluation error of a point of W, slack the rounding slack.
  struct Nesting {
    std::vector<int> outside;  // per component i: Σ_{j≠i} w(f(S_j), f(S_i)), the degree beside f(S_i) outside
    std::vector<int> sign;     // per component: its image's winding number on its bounded side (±1)
    std::vector<int> encloser;  // per component: the first j whose image winds about it (-1: none)
    std::vector<Vec3> point;    // per component: the point of its image used for that j
    std::string problem;        // why the nesting is not decided ("" = decided)
  };
  std::string component_name(int i) const {
    return "surface component " + std::to_string(i) + " (mesh triangle " +
           std::to_string(component_faces[i].front()) + ")";
  }
  // Is p farther than rho_f + extra from the affine image of every face of component j (always at rest)?
  static bool clear_of_tubes(const MatX3d& W, const MatX3i& F, const std::vector<int>& faces,
                             const std::vector<double>* rho, const Vec3& p, double extra, double slack) {
    if (!rho) return true;
    for (int f : faces) {
      const double r = (*rho)[f] + extra;
      if (!std::isfinite(r)) return false;
      const std::array<Vec3, 3> t{W.row(F(f, 0)).transpose(), W.row(F(f, 1)).transpose(),
                                  W.row(F(f, 2)).transpose()};
      const Vec3 lo = t[0].cwiseMin(t[1]).cwiseMin(t[2]), hi = t[0].cwiseMax(t[1]).cwiseMax(t[2]);
      const double gap = std::max((lo - p).maxCoeff(), (p - hi).maxCoeff());
      if (gap - slack > r) continue;
      if (!(separation_lower_bound({p, p, p}, t, slack) > r)) return false;
    }
    return true;
  }
  Nesting nesting(const MatX3d& W, const MatX3i& F, const std::vector<std::vector<int>>& comps,
                  const std::vector<double>* rho, double eps, double slack) const;
  std::string check_rest_nesting(const MatX3d& V) const;
  struct MapCheck;  // one check of one map (check())
  // The surface (P #V' by 3 at rest, W its image under coefficients y, F #F' by 3, comps its faces per
  // component) refined 1-to-4, conforming: one new vertex per edge, whose image is evaluated like the split
  // pieces' corners (within the same ε).
  void refine_image(const MatX3d& y, MatX3d& P, MatX3d& W, MatX3i& F,
                    std::vector<std::vector<int>>& comps) const;

  // f(p) for coefficients y (the basis values times y).
  Vec3 eval_f(const MatX3d& y, const Vec3& p, std::vector<double>& buf) const {
    buf.resize(basis.size());
    basis.evaluate(p, 0, buf.data(), nullptr, nullptr);
    Vec3 out = Vec3::Zero();
    for (int k = 0; k < basis.size(); ++k) out += buf[k] * y.row(k).transpose();
    return out;
  }
  // f at the three points P (3 by 3) in one pass of the SIMD kernel (HarmonicBasis::evaluate_rows); the
  // basis values as eval_f's up to the contraction of multiply-adds, summed in another order: the same ε.
  std::array<Vec3, 3> eval_f3(const MatX3d& y, const MatX3d& P, MatXdR& rows) const {
    basis.evaluate_rows(P, true, false, false, rows);
    std::array<Vec3, 3> out;
    for (int k = 0; k < 3; ++k) out[k] = (rows.row(k) * y).transpose();
    return out;
  }

  // The factors Γ_e(B) of every cage edge for the ball B(c, R) (factor_row, sharp first order), or false when
  // the ball is not clear of the cage (then no L1). They depend on the ball only, not on the map.
  bool ball_factors(const Vec3& c, double R, float* row) const {
    if (!c.allFinite() || !(R >= 0)) return false;
    if (cage_grid.any_within(c, R * (1 + 1e-9)) || std::abs(cage_winding.at(c) - 1.0) > 1e-6) return false;
    return factor_row(edges, EdgeFactor::kSharpFirstOrder, c, R, row);
  }
  // L1 ≥ max over the ball of the full Hessian tensor norm (docs/certificate.md Steps 1–3, first order):
  // Σ_e ‖δ_e‖ Γ_e(B) for the ball's factors `row`.
  double lipschitz_from(const VecXd& delta, const float* row) const {
    const double* dl = delta.data();
    const long n = edges.size();
    double L = 0;
    // In SIMD lanes (partial sums added at the end): another order of the same nonnegative terms, whose
    // rounding (n·2⁻⁵³ relative) the factor 1 + kRoundingRel covers as before.
#pragma omp simd reduction(+ : L)
    for (long e = 0; e < n; ++e) L += dl[e] * static_cast<double>(row[e]);
    return L * (1 + kRoundingRel);
  }
  // L1 of B(c, R); +∞ when the ball is not clear of the cage.
  double lipschitz(const VecXd& delta, const Vec3& c, double R, std::vector<float>& row) const {
    row.resize(edges.size());
    return ball_factors(c, R, row.data()) ? lipschitz_from(delta, row.data()) : kInf;
  }

  // The ball of a mesh triangle's piece (its centroid, through its farthest corner, widened by `reach`) and
  // the star ball of a mesh vertex (through the farthest corner of its triangles): the same in every check.
  double reach = 0;  // 2 · the corner error of kDepthCap levels (Step G3)
  void piece_ball(const std::array<Vec3, 3>& p, Vec3* c, double* R) const {
    *c = (p[0] + p[1] + p[2]) / 3.0;
    *R = 0;
    for (const Vec3& v : p) *R = std::max(*R, (v - *c).norm());
    *R = (*R + reach) * (1 + 1e-12) + 1e-15 * c->cwiseAbs().maxCoeff();
  }
  std::array<Vec3, 3> triangle(long f) const {
    return {mesh.V.row(mesh.F(f, 0)).transpose(), mesh.V.row(mesh.F(f, 1)).transpose(),
            mesh.V.row(mesh.F(f, 2)).transpose()};
  }
  void star_ball(long v, Vec3* c, double* R) const {
    *c = mesh.V.row(v);
    *R = 0;
    for (int f : vertex_faces[v])
      for (int k = 0; k < 3; ++k) *R = std::max(*R, (Vec3(mesh.V.row(mesh.F(f, k))) - *c).norm());
    *R = (*R + reach) * (1 + 1e-12);
  }

  // What every check needs and no map changes, kept in this order while it fits in the budget: the basis
  // values at the mesh vertices (doubles; f at the vertices is then one product per check), the basis
  // gradients there (floats; J at the vertices is then one product per check instead of a pass over the cage
  // faces per vertex), and the factor rows of the mesh triangles' balls and of the star balls (floats; L1 is
  // then one dot product with the map's ‖δ_e‖). A part that does not fit is evaluated in every check.
  MatXdR vertex_values;                        // #V by #V+#F of the cage, or empty
  FloatRows vertex_gradients;                  // #V blocks of 3 rows (∂x, ∂y, ∂z) by #V+#F, or empty
  std::vector<double> vertex_gradient_abs;     // per vertex Σ|G̃| over its block
  FloatRows face_rows, star_rows;              // #F by #E and #V by #E (cage edges), or empty
  std::vector<char> face_row_ok, star_row_ok;  // the ball is clear of the cage
  void cache_map_independent_parts(double budget) {
    const long nv = mesh.V.rows(), nf = mesh.F.rows(), ne = edges.size();
    // Takes count · size bytes from the budget where they fit.
    auto fits = [&budget](double count, size_t size) {
      const double bytes = count * static_cast<double>(size);
      return bytes <= budget ? (budget -= bytes, true) : false;
    };
    const double nb = static_cast<double>(basis.size());
    if (fits(nv * nb, sizeof(double))) basis.evaluate_rows(mesh.V, true, false, false, vertex_values);
    if (fits(3 * nv * nb, sizeof(float))) cache_vertex_gradients();
    if (!fits(static_cast<double>(nv + nf) * static_cast<double>(ne), sizeof(float))) return;
    face_rows.resize(nf * ne), star_rows.resize(nv * ne);
    face_row_ok.assign(nf, 0), star_row_ok.assign(nv, 0);
#pragma omp parallel for schedule(dynamic, 256)
    for (long f = 0; f < nf; ++f) {
      Vec3 c;
      double R;
      piece_ball(triangle(f), &c, &R);
      face_row_ok[f] = ball_factors(c, R, &face_rows[f * ne]);
    }
#pragma omp parallel for schedule(dynamic, 256)
    for (long v = 0; v < nv; ++v) {
      Vec3 c;
      double R;
      star_ball(v, &c, &R);
      star_row_ok[v] = ball_factors(c, R, &star_rows[v * ne]);
    }
  }
  // The basis gradients at the mesh vertices as floats (docs/certificate.md, Step G2: stored like the
  // certificate's derivatives), evaluated a block of vertices at a time so that the doubles stay small.
  void cache_vertex_gradients() {
    const long nv = mesh.V.rows(), nb = basis.size(), block = 1024;
    vertex_gradients.resize(static_cast<size_t>(nv) * 3 * nb);
    vertex_gradient_abs.assign(nv, 0.0);
    MatXdR G;
    for (long v0 = 0; v0 < nv; v0 += block) {
      const long n = std::min(block, nv - v0);
      basis.evaluate_rows(mesh.V.middleRows(v0, n), false, true, false, G);
#pragma omp parallel for schedule(static)
      for (long i = 0; i < n; ++i) {
        float* dst = &vertex_gradients[static_cast<size_t>(v0 + i) * 3 * nb];
        double sum = 0;
        for (long k = 0; k < 3 * nb; ++k) {
          dst[k] = static_cast<float>(G.data()[i * 3 * nb + k]);
          sum += std::abs(static_cast<double>(dst[k]));
        }
        vertex_gradient_abs[v0 + i] = sum * (1 + 1e-12);
      }
    }
  }
  // J̃ at mesh vertex v for coefficients ycols (#V+#F by 3 as 3 contiguous columns, largest magnitude cmax)
  // from the kept gradients, and sJ with ‖J̃ − J‖₂ ≤ kRoundingRel sJ: the product's rounding (kRoundingRel
  // of its summed magnitudes Σ_ab Σ_k |y_ka||g̃_kb| ≤ 3 cmax Σ|G̃|) and the float storage (each g̃ within
  // 2⁻²⁴ of the double value: Σ_ab |ΔJ_ab| ≤ 2⁻²³ · 3 cmax Σ|G̃|). False where no gradients are kept.
  bool vertex_jacobian(const std::vector<double>& ycols, double cmax, long v, Mat3* J, double* sJ) const {
    if (vertex_gradients.empty()) return false;
    const long nb = basis.size();
    const float* blk = &vertex_gradients[static_cast<size_t>(v) * 3 * nb];
    double cols[3][3];
    float_rows_times_columns(blk, 3, ycols.data(), nb, cols);
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a) (*J)(a, b) = cols[b][a];
    *sJ = 3 * cmax * vertex_gradient_abs[v] * (1 + 0x1p-23 / kRoundingRel) * (1 + 1e-12);
    return true;
  }
  // f at the mesh vertices (#V by 3) for coefficients y: from the kept basis values where there are, else by
  // map_values (the same kernel and the same product per vertex).
  MatX3d mapped_vertices(const MatX3d& y) const {
    if (vertex_values.rows() != mesh.V.rows()) return basis.map_values(y, mesh.V);
    MatX3d out(mesh.V.rows(), 3);
#pragma omp parallel for schedule(static)
    for (long i = 0; i < out.rows(); ++i) out.row(i) = vertex_values.row(i) * y;
    return out;
  }
  // L1 of mesh triangle i's ball (star: of vertex i's star ball) from the cache; NaN where not cached.
  double cached_lipschitz(const VecXd& delta, bool star, long i) const {
    const FloatRows& rows = star ? star_rows : face_rows;
    if (rows.empty()) return std::numeric_limits<double>::quiet_NaN();
    if (!(star ? star_row_ok : face_row_ok)[i]) return kInf;
    return lipschitz_from(delta, &rows[i * edges.size()]);
  }

  // Is f injective on B(c, R)? ‖J(z) − J(c)‖₂ ≤ R L1 < σ3(J(c)) − rounding (docs/certificate.md), for
  // the computed J̃(c) and its rounding scale; *mu (where given and the ball is one): a lower
  // bound of σ3(J(c)) − R L1, rounded down (Step G6).
  static bool injective_ball(const Mat3& J, double sJ, double R, double L, double* mu = nullptr) {
    if (!std::isfinite(L)) return false;
    bool resolved = false;
    const double s3 = signed_singular_values(J, &resolved)(2);
    if (!resolved || !(s3 > 0)) return false;
    const double tau = kRoundingRel * (sJ + s3 + R * L);
    if (!(s3 - tau > R * L)) return false;
    if (mu) *mu = (s3 - tau - R * L) - 1e-12 * (s3 + tau + R * L);
    return true;
  }
};

GlobalInjectivityChecker::GlobalInjectivityChecker(const Cage& cage, const TriMesh& mesh, double cache_mb)
    : impl_(std::make_unique<Impl>(cage, mesh, cache_mb)) {}
GlobalInjectivityChecker::~GlobalInjectivityChecker() = default;

namespace {

// Lower bound of the distance between two affine triangles a and b (separating axes: both normals, the
// in-plane edge normals, the 9 edge cross products and the centroid difference; each axis' gap is a lower
// bound of the distance, minus the rounding slack).
double separation_lower_bound(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b, double slack) {
  std::array<Vec3, 3> ea{a[1] - a[0], a[2] - a[1], a[0] - a[2]}, eb{b[1] - b[0], b[2] - b[1], b[0] - b[2]};
  const Vec3 na = ea[0].cross(ea[1]), nb = eb[0].cross(eb[1]);
  std::array<Vec3, 18> axes;
  int n = 0;
  axes[n++] = na;
  axes[n++] = nb;
  axes[n++] = (b[0] + b[1] + b[2] - a[0] - a[1] - a[2]);
  for (int i = 0; i < 3; ++i) {
    axes[n++] = na.cross(ea[i]);
    axes[n++] = nb.cross(eb[i]);
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) axes[n++] = ea[i].cross(eb[j]);
  double best = -kInf;
  for (int k = 0; k < n; ++k) {
    const double len = axes[k].norm();
    if (!(len > 0)) continue;
    const Vec3 u = axes[k] / len;
    double amin = kInf, amax = -kInf, bmin = kInf, bmax = -kInf;
    for (int i = 0; i < 3; ++i) {
      const double da = u.dot(a[i]), db = u.dot(b[i]);
      amin = std::min(amin, da), amax = std::max(amax, da);
      bmin = std::min(bmin, db), bmax = std::max(bmax, db);
    }
    best = std::max(best, std::max(bmin - amax, amin - bmax));
  }
  return best - slack;
}

// A proven crossing: segment s0 s1 pierces triangle t with margins above m (docs/certificate.md, "A proven
// overlap"). On success, x = the crossing point.
bool robust_pierce(const Vec3& s0, const Vec3& s1, const std::array<Vec3, 3>& t, double m, double slack,
                   Vec3* x) {
  const Vec3 n = (t[1] - t[0]).cross(t[2] - t[0]);
  const double nn = n.norm();
  if (!(nn > 0)) return false;
  const Vec3 u = n / nn;
  const double h0 = u.dot(s0 - t[0]), h1 = u.dot(s1 - t[0]);
  if (!(h0 * h1 < 0) || std::abs(h0) <= m + slack || std::abs(h1) <= m + slack) return false;
  const double tt = h0 / (h0 - h1);
  const Vec3 X = s0 + tt * (s1 - s0);
  // In-plane distance from X to each edge line, positive inside.
  double dX = kInf;
  for (int k = 0; k < 3; ++k) {
    const Vec3 e = t[(k + 1) % 3] - t[k];
    const Vec3 inward = u.cross(e);
    const double len = inward.norm();
    if (!(len > 0)) return false;
    dX = std::min(dX, inward.dot(X - t[k]) / len);
  }
  if (!(dX > slack)) return false;
  dX -= slack;
  // Distance from the segment to ∂t ≥ dX·H/(H+P): H = |h0 − h1| (height change), P = in-plane length.
  const Vec3 d = s1 - s0;
  const double H = std::abs(h0 - h1);
  const double P = (d - u.dot(d) * u).norm();
  if (!(dX * H / (H + P) > (m + slack) * (1 + 1e-9))) return false;
  *x = X;
  return true;
}

}  // namespace

GlobalInjectivityChecker::Impl::Nesting GlobalInjectivityChecker::Impl::nesting(
    const MatX3d& W, const MatX3i& F, const std::vector<std::vector<int>>& comps,
    const std::vector<double>* rho, double eps, double slack) const {
  const int nc = static_cast<int>(comps.size());
  Nesting out;
  out.outside.assign(nc, 0);
  out.sign.assign(nc, 0);
  out.encloser.assign(nc, -1);
  out.point.assign(nc, Vec3::Zero());
  std::vector<std::string> problem(nc);
  // At most this many points of a component are tried (spread over its triangles) before giving up.
  constexpr int kTries = 32;
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < nc; ++i) {
    const std::vector<int>& faces = comps[i];
    const size_t stride = std::max<size_t>(1, faces.size() / kTries);
    // The sign: the winding number of f(S_i) at a point beside one of its triangles, off every tube of S_i,
    // that is not 0 (f(S_i) embedded: 0 outside, ±1 on its bounded side).
    for (size_t k = 0; k < faces.size() && out.sign[i] == 0 && problem[i].empty(); k += stride) {
      const int f = faces[k];
      const Vec3 a = W.row(F(f, 0)), b = W.row(F(f, 1)), c = W.row(F(f, 2));
      const Vec3 n = (b - a).cross(c - a);
      if (!(n.norm() > 0)) continue;
      const double h = (rho ? 1.5 * ((*rho)[f] + eps) + 4 * slack : 0) + 1e-3 * tri_diameter({a, b, c});
      if (!std::isfinite(h)) continue;
      for (const double side : {1.0, -1.0}) {
        const Vec3 q = (a + b + c) / 3.0 + side * h * n.normalized();
        if (!clear_of_tubes(W, F, faces, rho, q, eps, slack)) continue;
        const std::optional<int> w = exact_winding_number(W, F, faces, q);
        if (!w || *w == 0) continue;
        if (std::abs(*w) != 1 || (out.sign[i] != 0 && out.sign[i] != *w)) {
          problem[i] = "the image of " + component_name(i) + " has winding number " + std::to_string(*w) +
                       " beside it, which an embedded surface cannot have";
          break;
        }
        out.sign[i] = *w;
      }
    }
    if (problem[i].empty() && out.sign[i] == 0)
      problem[i] =
          "no point beside the image of " + component_name(i) + " clear of its tubes has a winding number";
    // The others' winding numbers about a point f(v) of f(S_i) off their tubes.
    for (int j = 0; j < nc && problem[i].empty(); ++j) {
      if (j == i) continue;
      bool found = false;
      for (size_t k = 0; k < faces.size() && !found; k += stride) {
        // A vertex of the mesh itself (a refinement's midpoints are rounded, a hair off S): f(v) ∈ f(S_i).
        int v = -1;
        for (int c = 0; c < 3 && v < 0; ++c)
          if (F(faces[k], c) < mesh.V.rows()) v = F(faces[k], c);
        if (v < 0) continue;
        const Vec3 p = W.row(v);
        if (!clear_of_tubes(W, F, comps[j], rho, p, eps, slack)) continue;
        const std::optional<int> w = exact_winding_number(W, F, comps[j], p);
        if (!w) continue;
        if (std::abs(*w) > 1) {
          problem[i] = "the image of " + component_name(j) + " has winding number " + std::to_string(*w) +
                       ", which an embedded surface cannot have";
          break;
        }
        found = true;
        out.outside[i] += *w;
        if (*w != 0 && out.encloser[i] < 0) out.encloser[i] = j, out.point[i] = p;
      }
      if (!found && problem[i].empty())
        problem[i] = "no point of the image of " + component_name(i) + " lies clear of the tubes of " +
                     component_name(j);
    }
    if (out.encloser[i] < 0) out.point[i] = W.row(F(faces.front(), 0));
  }
  for (int i = 0; i < nc && out.problem.empty(); ++i) out.problem = problem[i];
  return out;
}

void GlobalInjectivityChecker::Impl::refine_image(const MatX3d& y, MatX3d& P, MatX3d& W, MatX3i& F,
                                                  std::vector<std::vector<int>>& comps) const {
  const MatX3i F0 = F;
  std::vector<std::array<long, 3>> edge_keys;  // (min, max, face·3 + k): one new vertex per edge
  for (long f = 0; f < F0.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F0(f, k), b = F0(f, (k + 1) % 3);
      edge_keys.push_back({std::min(a, b), std::max(a, b), 3 * f + k});
    }
  std::sort(edge_keys.begin(), edge_keys.end());
  std::vector<int> mid(3 * F0.rows(), -1);
  const long nv0 = P.rows();
  long nv1 = nv0;
  for (size_t i = 0; i < edge_keys.size(); ++i) {
    if (i == 0 || edge_keys[i][0] != edge_keys[i - 1][0] || edge_keys[i][1] != edge_keys[i - 1][1]) ++nv1;
    mid[edge_keys[i][2]] = static_cast<int>(nv1 - 1);
  }
  MatX3d P1(nv1, 3), W1(nv1, 3);
  P1.topRows(nv0) = P;
  W1.topRows(nv0) = W;
  for (long f = 0; f < F0.rows(); ++f)
    for (int k = 0; k < 3; ++k) P1.row(mid[3 * f + k]) = 0.5 * (P.row(F0(f, k)) + P.row(F0(f, (k + 1) % 3)));
#pragma omp parallel
  {
    std::vector<double> buf;
#pragma omp for schedule(dynamic, 256)
    for (long v = nv0; v < nv1; ++v) W1.row(v) = eval_f(y, P1.row(v).transpose(), buf).transpose();
  }
  MatX3i F1(4 * F0.rows(), 3);
  for (long f = 0; f < F0.rows(); ++f) {
    const int a = F0(f, 0), b = F0(f, 1), c = F0(f, 2);
    const int ab = mid[3 * f], bc = mid[3 * f + 1], ca = mid[3 * f + 2];
    F1.row(4 * f) << a, ab, ca;
    F1.row(4 * f + 1) << ab, b, bc;
    F1.row(4 * f + 2) << ca, bc, c;
    F1.row(4 * f + 3) << ab, bc, ca;
  }
  for (std::vector<int>& faces : comps) {
    std::vector<int> sub;
    for (int f : faces)
      for (int k = 0; k < 4; ++k) sub.push_back(4 * f + k);
    faces.swap(sub);
  }
  P = std::move(P1), W = std::move(W1), F = std::move(F1);
}

// At rest (the identity: W the model's own vertices, the PL surface is S itself, winding numbers exact):
// every component must have degree 0 on one side and 1 on the other, i.e. S oriented as the boundary of
// D = {winding number ≥ 1/2}, the solid the local certificate covers.
std::string GlobalInjectivityChecker::Impl::check_rest_nesting(const MatX3d& V) const {
  const Nesting n = nesting(V, mesh.F, component_faces, nullptr, 0, 0);
  if (!n.problem.empty())
    return "the nesting of the rest-state surface components is not decided: " + n.problem;
  for (size_t i = 0; i < component_faces.size(); ++i) {
    const int out = n.outside[i], in = n.outside[i] + n.sign[i];
    if (!((out == 0 && in == 1) || (out == 1 && in == 0)))
      return "the rest-state " + component_name(static_cast<int>(i)) + " has winding numbers " +
             std::to_string(out) + " and " + std::to_string(in) +
             " on its two sides, not 0 and 1: the components are not oriented as the boundary of one solid";
  }
  return "";
}

// One check of one map (the stages of the file comment, one method each); the per-cage data is the Impl's.
// Everything here is in the cage's normalized frame.
struct GlobalInjectivityChecker::Impl::MapCheck {
  enum Outcome : char { kCleared, kCrossing, kOpen };
  struct PairResult {
    Outcome outcome = kCleared;
    Vec3 where = Vec3::Zero();
    long tests = 0;
    int depth = 0;
    // Step G6: a pair of top pieces all of whose piece pairs were cleared by separation or by an injectivity
    // ball is recordable: the smallest separation margin and the balls, for later checks.
    bool recordable = false, replayed = false;
    std::uint64_t a = kNoPiece, b = kNoPiece;  // the top pieces' ids
    double sep = kInf;
    std::vector<MarginBall> balls;
    std::vector<float> sums;  // kEdgeGroups per ball
  };
  // A piece pair to clear, or (self) one piece whose own points must be shown to have distinct images;
  // touching: the pieces may share points in the rest state (no crossing is reported for them).
  struct Task {
    Piece P, Q;
    bool self, touching;
  };
  // Per thread: the factor row and basis buffers.
  struct Scratch {
    std::vector<float> row;
    MatXdR basis_rows;  // eval_f3's
  };
  // One pair's examination (stage 4), run until the current task needs J at the center of an injectivity
  // ball (Step G2) or the pair is done. The pair stage evaluates the balls of EdgeJet::kLanes such runs in
  // one pass over the cage (Step 4c) and resumes each where it stopped, so that every run's steps and
  // results are those of examining its pair alone.
  struct PairRun {
    long k = -1;              // the pair
    std::vector<Task> stack;  // its tasks still to examine
    bool waiting = false;     // for the ball (c, R) of `task`, with L1 (finite) and the factors `row`
    Task task;
    Vec3 c = Vec3::Zero();
    double R = 0, L1 = kInf;
    std::vector<float> row;
  };

  const Impl& im;
  const GlobalInjectivityParams& params;
  const TriMesh& mesh;
  const long nv, nf;
  MatX3d y;  // the coefficients in the normalized frame
  HarmonicBasis::FaceMatrices fm;
  EdgeJet::MapData ej;  // fm per cage edge: J at the balls' centers and the pieces' (Step 4b)
  VecXd delta;          // per cage edge ‖δ_e‖ with its rounding
  MatX3d fV;            // the mapped mesh vertices
  double eps = 0, slack = 0;
  std::vector<double> ycols;  // y as 3 contiguous columns, and its largest magnitude (J from kept gradients)
  double ymax = 0;
  // Step G6: the margins of the last map proven injective (null: none), the motion Δ since then (per cage
  // edge ‖δ_e(Δ)‖ with its rounding, and per edge group the largest), per mesh triangle and per top piece
  // sup |f − f_ref| (move) and sup ‖J − J_ref‖₂ (jmove) on it (+∞: unknown); J̃ at the mesh vertices and at
  // the split top pieces' centers with their rounding scales.
  std::shared_ptr<const ProvenMargins> base;
  VecXd ddelta;
  std::array<double, kEdgeGroups> dgroup{};  // per edge group the largest ‖δ_e(Δ)‖
  std::vector<double> move, jmove;           // per mesh triangle
  std::vector<double> move_top, jmove_top;   // per top piece
  std::vector<Mat3> Jv, Jtop;                // J̃ at the mesh vertices and at split top pieces' centers
  std::vector<double> sJv, sJtop;
  // Rounded corners (docs/certificate.md, Step G3): a piece of depth d has its corners within corner_error(d)
  // of the exact points; every ball is widened by `reach`, which covers the exact points of the piece and of
  // its descendants, and the tube of a piece of depth d by jb · corner_error(d), the motion of f between the
  // exact and the computed points.
  double corner_unit = 0, reach = 0;
  std::vector<Piece> pieces;  // per mesh triangle
  std::vector<char> star_ok;  // per mesh vertex: its star ball is an injectivity ball
  std::vector<char> face_ok;  // per mesh triangle: it lies in one injectivity ball
  std::vector<Piece> top;     // the top pieces (stage 2b)
  // Per top piece: its 1-to-4 split, made once by whichever thread needs it first (a top piece is split in
  // many of its pairs, always into the same children) — null until then.
  using Children = std::array<Piece, 4>;
  std::vector<std::atomic<Children*>> top_children;
  std::vector<std::pair<int, int>> pairs;  // pairs of top pieces (stage 3), then of mesh triangles (stage 5)
  std::vector<PairResult> results;         // per pair (stage 4)
  // The smallest index of a pair with a proven crossing so far: pairs after it cannot change the verdict
  // (the first crossing in pair order), so they are skipped — the verdict stays independent of the threads.
  std::atomic<long> first_crossing{std::numeric_limits<long>::max()};
  GlobalInjectivity out;

  ~MapCheck() {
    for (auto& c : top_children) delete c.load();
  }

  // --- 1. Map constants.
  MapCheck(const Impl& impl, const MatX3d& y_model, const GlobalInjectivityParams& p,
           std::shared_ptr<const ProvenMargins> reference)
      : im(impl),
        params(p),
        mesh(impl.mesh),
        nv(impl.mesh.V.rows()),
        nf(impl.mesh.F.rows()),
        base(std::move(reference)) {
    // The map in the normalized frame: f'(p') = (f(center + scale p') − center) / scale, so y_v' = (y_v −
    // center) / scale and y_t' = y_t (the face rows are linear parts, unchanged).
    y = y_model;
    const int ncv = im.cage.num_vertices();
    y.topRows(ncv) = (y_model.topRows(ncv).rowwise() - im.center.transpose()) / im.scale;
    fm = im.basis.face_matrices(y);
    ej = im.edge_jet.prepare(fm);
    delta.resize(im.cage.num_edges());
    for (int e = 0; e < im.cage.num_edges(); ++e) {
      const CageEdge& ce = im.cage.edges[e];
      delta(e) = (fm.A[ce.f0] - fm.A[ce.f1]).norm() * (1 + kRoundingRel) +
                 kRoundingRel * (fm.A_abs[ce.f0] + fm.A_abs[ce.f1]);
    }
    fV = im.mapped_vertices(y);
    const double yv = y.topRows(ncv).cwiseAbs().maxCoeff();
    const double yt = y.bottomRows(y.rows() - ncv).cwiseAbs().maxCoeff();
    ymax = std::max(yv, yt);
    ycols.resize(3 * y.rows());
    for (long k = 0; k < y.rows(); ++k)
      for (int a = 0; a < 3; ++a) ycols[a * y.rows() + k] = y(k, a);
    // ε: the evaluation error of a mapped point, relative to the coefficients' contributions (y_v φ_v with
    // Σ|φ_v| of order one, y_t ψ_t with ψ_t at most of the order of the cage's size).
    eps = kValueRel * (yv + yt * im.cage_diameter) * 8;
    slack = kGeomRel * (fV.cwiseAbs().maxCoeff() + eps);
    corner_unit = im.corner_unit;
    reach = im.reach;
    if (base) motion_since_base();
  }
  // Step G6: ‖δ_e‖ of the motion Δ = y − y_ref. Δ is formed in floating point: its error (relative 2⁻⁵³ of
  // the coefficients) is covered by 1e-9 of both maps' face-matrix magnitudes.
  void motion_since_base() {
    const MatX3d dy = y - base->y;
    const HarmonicBasis::FaceMatrices fd = im.basis.face_matrices(dy);
    ddelta.resize(im.cage.num_edges());
    for (int e = 0; e < im.cage.num_edges(); ++e) {
      const CageEdge& ce = im.cage.edges[e];
      const double mag = fd.A_abs[ce.f0] + fd.A_abs[ce.f1] + fm.A_abs[ce.f0] + fm.A_abs[ce.f1] +
                         base->A_abs[ce.f0] + base->A_abs[ce.f1];
      ddelta(e) = ((fd.A[ce.f0] - fd.A[ce.f1]).norm() + kRoundingRel * mag) * (1 + kRoundingRel);
    }
    dgroup.fill(0.0);
    for (int e = 0; e < im.cage.num_edges(); ++e)
      dgroup[im.edge_group[e]] = std::max(dgroup[im.edge_group[e]], ddelta(e));
  }
  // An upper bound of Σ_e ‖δ_e(Δ)‖ Γ_e(B) (the motion's L1 on a ball) from its factors' group sums.
  double motion_lipschitz(const float* sums) const {
    double L = 0;
    for (int g = 0; g < kEdgeGroups; ++g) L += static_cast<double>(sums[g]) * dgroup[g];
    return L * (1 + 1e-9);
  }

  bool cancelled() const { return params.cancel && params.cancel->load(std::memory_order_relaxed); }
  Vec3 to_model(const Vec3& p) const { return im.center + im.scale * p; }
  static std::string where(const Vec3& p) {
    return "(" + format_g(p.x()) + ", " + format_g(p.y()) + ", " + format_g(p.z()) + ")";
  }
  double corner_error(int depth) const { return depth * corner_unit; }
  // J̃(c) and its rounding scale by the per-edge evaluation (Step 4b: #V distances, #F solid angles and #E
  // logarithms instead of 3#F per-face terms), the same claim as the per-face differential_jet's (within
  // kRoundingRel of the scale of the exact J); with audit_violations also checked against that one.
  Mat3 jacobian(const Vec3& c, double* sJ) const {
    EdgeJet::Values v;
    im.edge_jet.evaluate(ej, c, 0, false, false, false, v);
    *sJ = v.scale_J;
    if (params.audit_violations) audit_jacobian(v.J, v.scale_J, c);
    return v.J;
  }
  bool injective_ball(const Vec3& c, double R, double L, double* mu = nullptr) const {
    if (!std::isfinite(L)) return false;
    double sJ = 0;
    const Mat3 J = jacobian(c, &sJ);
    return Impl::injective_ball(J, sJ, R, L, mu);
  }
  // An upper bound of ‖J‖₂ on B(c, R): ‖J̃(c)‖_F, its rounding, and R L1 (mean value); +∞ where L1 is.
  double jacobian_bound(const Vec3& c, double R, double L1) const {
    if (!std::isfinite(L1)) return kInf;
    double sJ = 0;
    const Mat3 J = jacobian(c, &sJ);
    return (J.norm() + kRoundingRel * sJ + R * L1) * (1 + 1e-9);
  }
  // jb: for depth > 0 a bound of ‖J‖ on a ball containing the piece (its parent's), else +∞ (then the
  // piece's own ball gives one).
  // known_L1: the L1 of the piece's ball where the caller has it (NaN: computed here).
  Piece make_piece(const std::array<Vec3, 3>& p, const std::array<Vec3, 3>& q, int face, int depth, double jb,
                   std::vector<float>& row,
                   double known_L1 = std::numeric_limits<double>::quiet_NaN()) const {
    Piece P;
    P.p = p, P.q = q, P.face = face, P.depth = depth;
    im.piece_ball(p, &P.c, &P.R);
    P.diam = tri_diameter(p);
    P.r_enc = triangle_enclosing_radius(p[0], p[1], p[2]);
    P.L1 = std::isnan(known_L1) ? im.lipschitz(delta, P.c, P.R, row) : known_L1;
    if (depth > 0 && !std::isfinite(jb)) jb = jacobian_bound(P.c, P.R, P.L1);
    P.jb = depth > 0 ? jb : kInf;
    const double moved = depth > 0 ? P.jb * corner_error(depth) : 0.0;
    P.rho = std::isfinite(P.L1) && std::isfinite(moved)
                ? (0.5 * P.L1 * P.r_enc * P.r_enc + moved) * (1 + 1e-9) + eps
                : kInf;
    return P;
  }
  // A piece split 1-to-4 at its edges' midpoints (their images evaluated): the corners' pieces, then the
  // middle one; the children keep the parent's bound of ‖J‖ (its ball contains them).
  void split(const Piece& P, std::array<Piece, 4>* ch, Scratch& s) {
    if (P.depth > 0 || P.top < 0) return split_now(P, ch, s);
    std::atomic<Children*>& slot = top_children[P.top];
    if (const Children* done = slot.load(std::memory_order_acquire)) {
      *ch = *done;
      return;
    }
    split_now(P, ch, s);  // two threads may both get here: they make the same children, one is kept
    auto* made = new Children(*ch);
    Children* expected = nullptr;
    if (!slot.compare_exchange_strong(expected, made, std::memory_order_acq_rel)) delete made;
  }
  void split_now(const Piece& P, std::array<Piece, 4>* ch, Scratch& s) const {
    std::array<Vec3, 3> mp;
    MatX3d M(3, 3);
    for (int k = 0; k < 3; ++k) {
      mp[k] = 0.5 * (P.p[k] + P.p[(k + 1) % 3]);
      M.row(k) = mp[k].transpose();
    }
    const std::array<Vec3, 3> mq = im.eval_f3(y, M, s.basis_rows);
    const double jb = P.depth == 0 ? jacobian_bound(P.c, P.R, P.L1) : P.jb;
    const int f = P.face, d = P.depth + 1;
    (*ch)[0] = make_piece({P.p[0], mp[0], mp[2]}, {P.q[0], mq[0], mq[2]}, f, d, jb, s.row);
    (*ch)[1] = make_piece({mp[0], P.p[1], mp[1]}, {mq[0], P.q[1], mq[1]}, f, d, jb, s.row);
    (*ch)[2] = make_piece({mp[2], mp[1], P.p[2]}, {mq[2], mq[1], P.q[2]}, f, d, jb, s.row);
    (*ch)[3] = make_piece({mp[0], mp[1], mp[2]}, {mq[0], mq[1], mq[2]}, f, d, jb, s.row);
    for (int i = 0; i < 4; ++i) (*ch)[i].top = P.top, (*ch)[i].id = child_piece_id(P.id, i);
  }

  // --- 2. One piece per mesh triangle and per mesh vertex its star ball; which triangles lie in one
  // injectivity ball (a triangle's own points: its ball, or the star ball of one of its corners).
  void pieces_and_star_balls() {
    pieces.resize(nf);
    star_ok.assign(nv, 0);
    Jv.assign(nv, Mat3::Zero()), sJv.assign(nv, 0.0);
    std::vector<double> motion_L1(base ? nf : 0, kInf);  // per mesh triangle: the motion's L1 on its ball
#pragma omp parallel
    {
      std::vector<float> row;
#pragma omp for schedule(dynamic, 256)
      for (long f = 0; f < nf; ++f) {
        if (cancelled()) continue;  // the result is dropped by the caller
        std::array<Vec3, 3> q;
        for (int k = 0; k < 3; ++k) q[k] = fV.row(mesh.F(f, k));
        const double cached = im.cached_lipschitz(delta, false, f);
        pieces[f] = make_piece(im.triangle(f), q, static_cast<int>(f), 0, kInf, row, cached);
        pieces[f].id = face_piece_id(f);
        if (base && std::isfinite(pieces[f].L1))  // make_piece left the ball's factors in `row` if not cached
          motion_L1[f] = std::isnan(cached) ? im.lipschitz_from(ddelta, row.data())
                                            : im.cached_lipschitz(ddelta, false, f);
      }
      // J at every vertex (the star ball's center), kept for Step G6 also where the star ball is not used:
      // from the kept gradients, else per cage edge for EdgeJet::kLanes vertices at once (Step 4c).
      constexpr int kLanes = EdgeJet::kLanes;
      std::array<Vec3, kLanes> c;
      std::array<double, kLanes> R, zero{};
      std::array<EdgeJet::Values, kLanes> at;
#pragma omp for schedule(dynamic, 32)
      for (long g = 0; g < (nv + kLanes - 1) / kLanes; ++g) {
        if (cancelled()) continue;
        const long v0 = g * kLanes;
        const int n = static_cast<int>(std::min<long>(kLanes, nv - v0));
        bool kept = true;
        for (int i = 0; i < n; ++i) {
          im.star_ball(v0 + i, &c[i], &R[i]);
          kept = im.vertex_jacobian(ycols, ymax, v0 + i, &Jv[v0 + i], &sJv[v0 + i]) && kept;
        }
        if (!kept) {
          im.edge_jet.evaluate_lanes(ej, c.data(), zero.data(), n, false, false, false, at.data());
          for (int i = 0; i < n; ++i) Jv[v0 + i] = at[i].J, sJv[v0 + i] = at[i].scale_J;
        }
        for (int i = 0; i < n; ++i) {
          const long v = v0 + i;
          if (params.audit_violations) audit_jacobian(Jv[v], sJv[v], c[i]);
          double L = im.cached_lipschitz(delta, true, v);
          if (std::isnan(L)) L = im.lipschitz(delta, c[i], R[i], row);
          star_ok[v] = Impl::injective_ball(Jv[v], sJv[v], R[i], L);
        }
      }
    }
    if (cancelled()) return;
    if (base) motion_per_triangle(motion_L1);
    face_ok.assign(nf, 0);
#pragma omp parallel for schedule(dynamic, 256)
    for (long f = 0; f < nf; ++f)  // the triangle's own ball: the piece's, whose L1 is known
      face_ok[f] = star_ok[mesh.F(f, 0)] || star_ok[mesh.F(f, 1)] || star_ok[mesh.F(f, 2)] ||
                   injective_ball(pieces[f].c, pieces[f].R, pieces[f].L1);
    double max_rho = 0;
    for (const Piece& P : pieces)
      if (std::isfinite(P.rho)) max_rho = std::max(max_rho, P.rho);
    out.max_tube_radius = max_rho * im.scale;
  }

  // For tests (GlobalInjectivityParams::audit_violations): a J̃(c) with its scale sJ (from the kept
  // gradients, or per edge) against the per-face evaluation at the same point; both claim to be within
  // kRoundingRel of their scale of the exact J, so a difference beyond the sum proves one claim wrong.
  void audit_jacobian(const Mat3& Jc, double sJ, const Vec3& c) const {
    double s = 0;
    const Mat3 J = im.basis.differential_jet(fm, c, 1, &s).J;
    const double diff = Eigen::JacobiSVD<Mat3>(Jc - J).singularValues()(0);  // ‖·‖₂, as the claims
    if (!(diff <= kRoundingRel * (sJ + s))) params.audit_violations->fetch_add(1);
  }
  // Step G6, per mesh triangle T with the motion's L1 on its ball (L^Δ): sup_T |f − f_ref| ≤ max over the
  // corners |Δf(v)| + ½ L^Δ r² (Step G3 applied to Δf) with the corners' evaluation errors of both maps, and
  // sup_T ‖J − J_ref‖₂ ≤ min over the corners ‖ΔJ(v)‖ + diam(T) L^Δ (mean value inside the ball).
  void motion_per_triangle(const std::vector<double>& motion_L1) {
    move.assign(nf, kInf), jmove.assign(nf, kInf);
#pragma omp parallel for schedule(static)
    for (long f = 0; f < nf; ++f) {
      const double Ld = motion_L1[f];
      if (!std::isfinite(Ld)) continue;
      double dmax = 0, jmin = kInf;
      for (int k = 0; k < 3; ++k) {
        const int v = mesh.F(f, k);
        dmax = std::max(dmax, (fV.row(v) - base->fV.row(v)).norm());
        jmin = std::min(jmin,
                        (Jv[v] - base->Jv[v]).norm() * (1 + 1e-12) + kRoundingRel * (sJv[v] + base->sJv[v]));
      }
      const Piece& P = pieces[f];
      move[f] = (dmax + eps + base->eps + 0.5 * Ld * P.r_enc * P.r_enc) * (1 + 1e-9);
      jmove[f] = (jmin + P.diam * Ld) * (1 + 1e-9);
    }
  }

  // --- 2b. The top pieces: the triangles, a triangle whose ball is not clear of the cage (no finite tube)
  // replaced by its 1-to-4 splits until each has one (in face order, depth first: deterministic). A tube
  // wider than a quarter of its piece (a triangle near the cage, where L₁ is large) would pair the piece
  // with most of the surface: such pieces are split first too. Returns why nothing can be decided ("" =
  // the top pieces are made).
  std::string top_pieces() {
    auto thin = [](const Piece& P) { return std::isfinite(P.rho) && P.rho <= 0.25 * P.diam; };
    top.reserve(nf);
    Scratch s;
    std::vector<Piece> todo;
    for (long f = 0; f < nf; ++f) {
      if (thin(pieces[f])) {
        top.push_back(pieces[f]);
        continue;
      }
      todo.assign(1, pieces[f]);
      while (!todo.empty()) {
        const Piece P = todo.back();
        todo.pop_back();
        if (thin(P) || (P.depth >= params.max_depth && std::isfinite(P.rho))) {
          top.push_back(P);
          continue;
        }
        if (P.depth >= params.max_depth)
          return "mesh triangle " + std::to_string(f) + " lies too close to the cage for a bound near " +
                 where(to_model(P.c));
        std::array<Piece, 4> ch;
        split(P, &ch, s);
        for (int i = 3; i >= 0; --i) todo.push_back(ch[i]);
      }
    }
    const long nt = static_cast<long>(top.size());
    top_children = std::vector<std::atomic<Children*>>(nt);
    for (long i = 0; i < nt; ++i) {
      top[i].top = static_cast<int>(i);
      top_children[i].store(nullptr, std::memory_order_relaxed);
    }
    return "";
  }

  // --- 2c. Step G6 per top piece: J̃ at the center of each split top piece (kept for later checks), and
  // where margins are reused, sup |f − f_ref| (move_top) and sup ‖J − J_ref‖₂ (jmove_top) on it: a whole
  // triangle's from motion_per_triangle; a split piece P of depth d (its ball B, L^Δ the motion's L1 on B,
  // κ = corner_error(d)) by Step G3 on Δf over the exact piece: max over the computed corners |Δq|, plus
  // ε + ε_ref, plus (jb + jb_ref) κ (the exact corners lie within κ), plus ½ L^Δ (r + κ)²; and
  // ‖ΔJ(c)‖ + R L^Δ.
  void top_motion() {
    const long nt = static_cast<long>(top.size());
    if (!params.reuse_margins) return;  // nothing is kept, nothing reused
    Jtop.assign(nt, Mat3::Zero()), sJtop.assign(nt, 0.0);
    if (base) move_top.assign(nt, kInf), jmove_top.assign(nt, kInf);
#pragma omp parallel
    {
      std::vector<float> row;
#pragma omp for schedule(dynamic, 64)
      for (long i = 0; i < nt; ++i) {
        const Piece& P = top[i];
        if (P.depth == 0) {
          if (base) move_top[i] = move[P.face], jmove_top[i] = jmove[P.face];
          continue;
        }
        Jtop[i] = jacobian(P.c, &sJtop[i]);
        const ProvenMargins::Top* ref = base ? base->find_top(P.id) : nullptr;
        if (!ref) continue;
        const double Ld = im.lipschitz(ddelta, P.c, P.R, row);
        if (!std::isfinite(Ld) || !std::isfinite(P.jb) || !std::isfinite(ref->jb)) continue;
        const double kappa = corner_error(P.depth);
        double dmax = 0;
        for (int k = 0; k < 3; ++k) dmax = std::max(dmax, (P.q[k] - ref->q[k]).norm());
        const double r = P.r_enc + kappa;
        move_top[i] = (dmax + (P.jb + ref->jb) * kappa + 0.5 * Ld * r * r) * (1 + 1e-9) + eps + base->eps;
        jmove_top[i] =
            ((Jtop[i] - ref->J).norm() * (1 + 1e-12) + kRoundingRel * (sJtop[i] + ref->sJ) + P.R * Ld) *
            (1 + 1e-9);
      }
    }
  }

  // --- 3. Candidate pairs: boxes of the top pieces' tubes. A sorted list of (cell, piece) entries groups the
  // pieces by cell.
  void candidate_pairs() {
    const long nt = static_cast<long>(top.size());
    Vec3 lo = fV.colwise().minCoeff().transpose(), hi = fV.colwise().maxCoeff().transpose();
    std::vector<Vec3> blo(nt), bhi(nt);
    double mean_extent = 0;
    for (long f = 0; f < nt; ++f) {
      const Piece& P = top[f];
      Vec3 a = P.q[0].cwiseMin(P.q[1]).cwiseMin(P.q[2]), b = P.q[0].cwiseMax(P.q[1]).cwiseMax(P.q[2]);
      a.array() -= P.rho + slack, b.array() += P.rho + slack;
      blo[f] = a, bhi[f] = b;
      mean_extent += (b - a).maxCoeff();
    }
    mean_extent /= static_cast<double>(nt);
    const double span = std::max((hi - lo).maxCoeff(), 1e-300);
    const double cell = std::max(mean_extent, span / 256.0);
    // The cell of a coordinate, clamped to the grid's margin (monotone in x: a box's cells are those of its
    // clamped corners, and a point of a box lies in one of them).
    auto cell_of = [&](double x, int k) {
      return static_cast<long>(
          std::floor((std::min(std::max(x, lo(k) - cell), hi(k) + cell) - lo(k)) / cell));
    };
    // A cell's key: its three indices + 1, each in [0, 259] (a clamped coordinate's cell is in [−1, 258]), 10
    // bits each; an entry is key · 2³² + piece, so that sorting the entries groups the pieces by cell.
    auto key = [](long i, long j, long k) {
      return static_cast<std::uint64_t>(((i + 1) << 20) | ((j + 1) << 10) | (k + 1));
    };
    auto entry_key = [](std::uint64_t e) { return e >> 32; };
    auto entry_piece = [](std::uint64_t e) { return static_cast<int>(e & 0xffffffffu); };
    // The (cell, piece) entries, counted first so that the threads write their own ranges.
    std::vector<std::array<long, 6>> range(nt);
    std::vector<size_t> first(nt + 1, 0);
#pragma omp parallel for schedule(static)
    for (long f = 0; f < nt; ++f)
      for (int k = 0; k < 3; ++k)
        range[f][k] = cell_of(blo[f](k), k), range[f][3 + k] = cell_of(bhi[f](k), k);
    for (long f = 0; f < nt; ++f) {
      const auto& r = range[f];
      first[f + 1] =
          first[f] + static_cast<size_t>((r[3] - r[0] + 1) * (r[4] - r[1] + 1) * (r[5] - r[2] + 1));
    }
    std::vector<std::uint64_t> entries(first[nt]);
#pragma omp parallel for schedule(static)
    for (long f = 0; f < nt; ++f) {
      const auto& r = range[f];
      size_t at = first[f];
      for (long i = r[0]; i <= r[3]; ++i)
        for (long j = r[1]; j <= r[4]; ++j)
          for (long k = r[2]; k <= r[5]; ++k)
            entries[at++] = key(i, j, k) << 32 | static_cast<std::uint64_t>(f);
    }
    sort_by_key(entries);  // the entries are in piece order
    // Pairs of two triangles in the star ball of a common vertex where f is injective are cleared (step 4's
    // first test); they are counted and not kept: the verdict and the counts are those of examining them,
    // without the memory of millions of cleared pairs (a tight cage's wide tubes).
    auto in_common_star = [&](int a, int b) {
      const int fa = top[a].face, fb = top[b].face;
      if (fa == fb) return false;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          if (mesh.F(fa, i) == mesh.F(fb, j) && star_ok[mesh.F(fa, i)]) return true;
      return false;
    };
    // Two overlapping boxes share the cells of the corner max(lo_a, lo_b) of their intersection: the pair is
    // taken there only, once. The cells are scanned in parallel, each from a copy of its boxes side by side;
    // the pairs are sorted afterwards, so the result does not depend on the threads.
    std::vector<size_t> cells;
    for (size_t i = 0; i < entries.size(); ++i)
      if (i == 0 || entry_key(entries[i]) != entry_key(entries[i - 1])) cells.push_back(i);
    cells.push_back(entries.size());
    long candidates = 0;
#pragma omp parallel reduction(+ : candidates)
    {
      std::vector<std::pair<int, int>> mine;
      std::vector<int> piece;  // the cell's pieces, and their boxes side by side (lo, hi)
      std::vector<std::array<double, 6>> box;
#pragma omp for schedule(dynamic, 256) nowait
      for (long c = 0; c < static_cast<long>(cells.size()) - 1; ++c) {
        const size_t i = cells[c], j = cells[c + 1];
        piece.clear(), box.clear();
        for (size_t a = i; a < j; ++a) {
          const int f = entry_piece(entries[a]);
          piece.push_back(f);
          box.push_back({blo[f](0), blo[f](1), blo[f](2), bhi[f](0), bhi[f](1), bhi[f](2)});
        }
        const int n = static_cast<int>(piece.size());
        for (int a = 0; a < n; ++a)
          for (int b = a + 1; b < n; ++b) {
            const std::array<double, 6>& A = box[a];
            const std::array<double, 6>& B = box[b];
            if (!((A[0] <= B[3]) & (A[1] <= B[4]) & (A[2] <= B[5]) & (B[0] <= A[3]) & (B[1] <= A[4]) &
                  (B[2] <= A[5])))
              continue;
            if (key(cell_of(std::max(A[0], B[0]), 0), cell_of(std::max(A[1], B[1]), 1),
                    cell_of(std::max(A[2], B[2]), 2)) != entry_key(entries[i]))
              continue;
            ++candidates;
            const int fa = piece[a], fb = piece[b];
            if (!in_common_star(fa, fb)) mine.emplace_back(std::min(fa, fb), std::max(fa, fb));
          }
      }
#pragma omp critical(global_injectivity_pairs)
      pairs.insert(pairs.end(), mine.begin(), mine.end());
    }
    std::sort(pairs.begin(), pairs.end());
    out.candidate_pairs = candidates;
    // A triangle not covered by one injectivity ball is a work item of its own (split until its pieces are).
    for (long i = 0; i < nt; ++i)
      if (!face_ok[top[i].face]) pairs.emplace_back(static_cast<int>(i), static_cast<int>(i));
  }

  // --- 4. Per pair: separate, cover by an injectivity ball, prove a crossing, or split (bounded). Each
  // thread keeps EdgeJet::kLanes pairs under way (PairRun) and takes the next pair in turn where one ends.
  void examine_pairs() {
    results.assign(pairs.size(), PairResult{});
    const long n = static_cast<long>(pairs.size());
    std::atomic<long> next{0};
    constexpr int kLanes = EdgeJet::kLanes;
#pragma omp parallel
    {
      Scratch s;
      std::array<PairRun, kLanes> runs;
      std::array<bool, kLanes> live{};
      // Starts pairs in `run` until one waits for a ball; false when no pair is left.
      auto take = [&](PairRun& run) {
        for (long k = next.fetch_add(1); k < n; k = next.fetch_add(1)) {
          if (k > first_crossing.load(std::memory_order_relaxed) || cancelled()) continue;
          if (start_pair(k, run) && advance(run, s)) return true;
        }
        return false;
      };
      for (int i = 0; i < kLanes; ++i) live[i] = take(runs[i]);
      std::array<Vec3, kLanes> centers;
      std::array<double, kLanes> radii{};
      std::array<EdgeJet::Values, kLanes> values;
      std::array<int, kLanes> slot;
      for (;;) {
        int m = 0;
        for (int i = 0; i < kLanes; ++i)
          if (live[i]) slot[m] = i, centers[m] = runs[i].c, ++m;
        if (m == 0) break;
        im.edge_jet.evaluate_lanes(ej, centers.data(), radii.data(), m, false, false, false, values.data());
        for (int j = 0; j < m; ++j) {
          PairRun& run = runs[slot[j]];
          if (params.audit_violations) audit_jacobian(values[j].J, values[j].scale_J, run.c);
          live[slot[j]] = advance(run, s, &values[j]) || take(run);
        }
      }
    }
  }
  // The ball of the run's current task with J̃ at its center (`at`): is f injective on it (Step G2)? Where
  // it is and the pair is recordable, the ball's margin and its factors summed per edge group are kept for
  // Step G6.
  bool ball_clears(const PairRun& run, const EdgeJet::Values& at, PairResult& res) const {
    double mu = 0;
    if (!Impl::injective_ball(at.J, at.scale_J, run.R, run.L1, &mu)) return false;
    if (res.recordable) {
      if (mu > 0) {
        std::array<double, kEdgeGroups> sums{};
        for (size_t e = 0; e < run.row.size(); ++e) sums[im.edge_group[e]] += run.row[e];
        res.balls.push_back({mu, run.R, run.c});
        for (const double x : sums) {  // rounded up to a float (the sum's own rounding: a relative 1e-12)
          const double up = x * (1 + 1e-12);
          float f = static_cast<float>(up);
          if (f < up) f = std::nextafter(f, std::numeric_limits<float>::infinity());
          res.sums.push_back(f);
        }
      } else {
        res.recordable = false;
      }
    }
    return true;
  }
  // Step G6: are all piece pairs of top pieces a ≤ b (indices; res.a, res.b their ids) still cleared by the
  // margins of the last proven map? Separated pairs: dist(f(P), f(Q)) ≥ m − move_a − move_b. Balls: with
  // L̂' = L̂ + L^Δ on B and ‖ΔJ(c)‖ ≤ jmove_a + R L^Δ (a point of piece P ⊆ top piece a lies in B),
  // σ3(J(c)) − R L̂' ≥ μ − jmove_a − 2 R L^Δ. On success the pair keeps the reduced margins for the next
  // check.
  bool replay(int a, int b, PairResult& res) const {
    const ProvenMargins::Pair* e = base->find(res.a, res.b);
    if (!e) return false;
    double sep = kInf;
    if (std::isfinite(e->sep)) {
      const double used = move_top[a] + move_top[b];
      sep = (e->sep - used) - 1e-12 * (e->sep + used);
      if (!(sep > 0)) return false;
    }
    std::vector<MarginBall> balls;
    balls.reserve(e->ball_end - e->ball_begin);
    for (long i = e->ball_begin; i < e->ball_end; ++i) {
      MarginBall m = base->balls[i];
      const double used = jmove_top[a] + 2 * m.R * motion_lipschitz(&base->group_sums[i * kEdgeGroups]);
      m.mu = (m.mu - used) - 1e-12 * (m.mu + used);
      if (!(m.mu > 0)) return false;
      balls.push_back(m);
    }
    if (params.audit_violations) audit(a, b, sep, balls);
    res.replayed = true, res.sep = sep, res.balls = std::move(balls);
    res.sums.assign(base->group_sums.begin() + e->ball_begin * kEdgeGroups,
                    base->group_sums.begin() + e->ball_end * kEdgeGroups);
    return true;
  }
  // For tests (GlobalInjectivityParams::audit_violations): each reused claim against the map itself — a
  // ball's μ' against σ3(J(c)) − R L1 evaluated now (L̂' ≥ Σ_e ‖δ_e‖ Γ_e by the triangle inequality, so μ' may
  // not exceed it), and where every piece pair was separated (no ball), the separation margin against the
  // smallest distance of the images of points spread over both top pieces (a sampled distance is at least
  // the true one).
  void audit(int a, int b, double sep, const std::vector<MarginBall>& balls) const {
    long bad = 0;
    std::vector<float> row;
    for (const MarginBall& m : balls) {
      double mu = -kInf, sJ = 0;  // J by the per-face code: independent of the per-edge one that made m
      const Mat3 J = im.basis.differential_jet(fm, m.c, 1, &sJ).J;
      Impl::injective_ball(J, sJ, m.R, im.lipschitz(delta, m.c, m.R, row), &mu);
      bad += !(m.mu <= mu + 1e-9 * (1 + std::abs(mu)));
    }
    if (std::isfinite(sep) && balls.empty()) {
      std::vector<double> buf;
      auto samples = [&](const Piece& P) {
        std::vector<Vec3> out;
        constexpr int n = 12;
        for (int i = 0; i <= n; ++i)
          for (int j = 0; i + j <= n; ++j) {
            const double u = double(i) / n, v = double(j) / n;
            out.push_back(im.eval_f(y, (1 - u - v) * P.p[0] + u * P.p[1] + v * P.p[2], buf));
          }
        return out;
      };
      const std::vector<Vec3> pa = samples(top[a]), pb = samples(top[b]);
      double d = kInf;
      for (const Vec3& x : pa)
        for (const Vec3& z : pb) d = std::min(d, (x - z).norm());
      bad += !(sep <= d + 2 * eps);
    }
    if (bad) params.audit_violations->fetch_add(bad);
  }
  int shared_vertices(int fa, int fb, std::array<int, 3>* sv) const {
    int n = 0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (mesh.F(fa, i) == mesh.F(fb, j)) (*sv)[n++] = mesh.F(fa, i);
    return n;
  }
  // The pair's first steps (a common star ball, the kept margins); true when its tasks remain to examine.
  bool start_pair(long k, PairRun& run) {
    const int fa = pairs[k].first, fb = pairs[k].second;
    PairResult& res = results[k];
    std::array<int, 3> sv;
    const int ffa = top[fa].face, ffb = top[fb].face;
    int nshared = 3;
    if (ffa == ffb)
      for (int i = 0; i < 3; ++i) sv[i] = mesh.F(ffa, i);
    else
      nshared = shared_vertices(ffa, ffb, &sv);
    if (fa != fb) {
      bool star = false;
      for (int i = 0; i < nshared; ++i) star = star || star_ok[sv[i]];
      if (star) return false;  // both triangles lie in the star ball of a shared vertex, where f is injective
    }
    res.a = top[fa].id, res.b = top[fb].id;
    res.recordable = params.reuse_margins && res.a != kNoPiece && res.b != kNoPiece;
    if (res.recordable && base && replay(fa, fb, res)) return false;
    run.k = k;
    run.waiting = false;
    run.stack.clear();
    run.stack.push_back({top[fa], top[fb], fa == fb, nshared > 0 || im.intersect_at_rest(ffa, ffb)});
    return true;
  }
  // Asks for the ball B(c, R) of `task`: true when the run now waits for J̃(c); false when the ball is not
  // clear of the cage (no L1: it clears nothing, and no J is needed).
  bool wait_for_ball(PairRun& run, const Task& task, const Vec3& c, double R) const {
    run.L1 = im.lipschitz(delta, c, R, run.row);
    if (!std::isfinite(run.L1)) return false;
    run.waiting = true, run.task = task, run.c = c, run.R = R;
    return true;
  }
  // After the task's ball did not clear it: split (a piece's own points), or prove a crossing, give up at
  // the limits, or split the larger piece (a pair). True when the pair is done.
  bool after_failed_ball(long k, const Task& task, Scratch& s, std::vector<Task>& stack, PairResult& res) {
    const Piece &P = task.P, &Q = task.Q;
    std::array<Piece, 4> ch;
    if (task.self) {
      if (P.depth >= params.max_depth || res.tests >= params.max_tests_per_pair) {
        res.outcome = kOpen;
        res.where = (P.q[0] + P.q[1] + P.q[2]) / 3.0;
        return true;
      }
      split(P, &ch, s);
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) stack.push_back({ch[i], ch[j], false, true});
      for (int i = 0; i < 4; ++i) stack.push_back({ch[i], ch[i], true, true});
      return false;
    }
    const bool tubes = std::isfinite(P.rho) && std::isfinite(Q.rho);
    if (tubes && !task.touching) {
      const double m = P.rho + Q.rho;
      Vec3 x;
      bool found = false;
      for (int e = 0; e < 3 && !found; ++e) {
        found = robust_pierce(P.q[e], P.q[(e + 1) % 3], Q.q, m, slack, &x) ||
                robust_pierce(Q.q[e], Q.q[(e + 1) % 3], P.q, m, slack, &x);
      }
      if (found) {
        res.outcome = kCrossing;
        res.where = x;
        long cur = first_crossing.load();
        while (k < cur && !first_crossing.compare_exchange_weak(cur, k)) {
        }
        return true;
      }
    }
    const bool can_split = P.depth < params.max_depth || Q.depth < params.max_depth;
    if (!can_split || res.tests >= params.max_tests_per_pair) {
      res.outcome = kOpen;
      res.where = 0.5 * (P.q[0] + Q.q[0]);
      return true;
    }
    // Split the larger piece (one that may still be split).
    const bool split_p = Q.depth >= params.max_depth || (P.depth < params.max_depth && P.diam >= Q.diam);
    if (split_p) {
      split(P, &ch, s);
      for (int i = 3; i >= 0; --i) stack.push_back({ch[i], Q, false, task.touching});
    } else {
      split(Q, &ch, s);
      for (int i = 3; i >= 0; --i) stack.push_back({P, ch[i], false, task.touching});
    }
    return false;
  }
  // Examines the run's tasks in order (depth first), `at` answering the ball it waits for; true when it
  // waits for the next ball, false when the pair is done.
  bool advance(PairRun& run, Scratch& s, const EdgeJet::Values* at = nullptr) {
    const long k = run.k;
    PairResult& res = results[k];
    std::vector<Task>& stack = run.stack;
    if (run.waiting) {
      run.waiting = false;
      if (!ball_clears(run, *at, res) && after_failed_ball(k, run.task, s, stack, res)) return false;
    }
    while (!stack.empty()) {
      if ((res.tests & 63) == 63 && (k > first_crossing.load(std::memory_order_relaxed) || cancelled()))
        return false;
      const Task task = stack.back();
      stack.pop_back();
      const Piece &P = task.P, &Q = task.Q;
      ++res.tests;
      res.depth = std::max({res.depth, P.depth, Q.depth});
      if (task.self) {  // the piece's own points: one injectivity ball, or split
        if (wait_for_ball(run, task, P.c, P.R)) return true;
        if (after_failed_ball(k, task, s, stack, res)) return false;
        continue;
      }
      if (std::isfinite(P.rho) && std::isfinite(Q.rho)) {
        const double gap = separation_lower_bound(P.q, Q.q, slack);
        if (gap > P.rho + Q.rho) {  // Step G6 keeps dist(f(P), f(Q)) ≥ gap − ρ_P − ρ_Q, rounded down
          res.sep = std::min(res.sep, (gap - P.rho - Q.rho) - 1e-12 * (gap + P.rho + Q.rho));
          continue;
        }
      }
      // One ball around both pieces.
      const Vec3 c = 0.5 * (P.c + Q.c);
      double R = 0;
      for (int i = 0; i < 3; ++i) R = std::max({R, (P.p[i] - c).norm(), (Q.p[i] - c).norm()});
      if (wait_for_ball(run, task, c, (R + reach) * (1 + 1e-12) + 1e-15 * c.cwiseAbs().maxCoeff()))
        return true;
      if (after_failed_ball(k, task, s, stack, res)) return false;
    }
    return false;
  }

  // --- 5. The verdict: the first overlap in pair order, else the first undecided pair, else — for a surface
  // of several components — the nesting of their images, else injective.
  GlobalInjectivity verdict() {
    // Over the pairs up to the first crossing (all of them when there is none): processed in full whatever
    // the thread schedule, so these counts are deterministic.
    for (size_t k = 0; k < results.size() && static_cast<long>(k) <= first_crossing.load(); ++k) {
      out.pair_tests += results[k].tests;
      out.replayed_pairs += results[k].replayed;
      out.max_depth_used = std::max(out.max_depth_used, results[k].depth);
    }
    for (auto& pr : pairs) pr = {top[pr.first].face, top[pr.second].face};
    // The verdict `v` named by pair k: its place and its two mesh triangles.
    auto at_pair = [&](GlobalInjectivity::Verdict v, size_t k) {
      out.verdict = v;
      out.overlap_point = to_model(results[k].where);
      out.overlap_face_a = pairs[k].first;
      out.overlap_face_b = pairs[k].second;
    };
    for (size_t k = 0; k < results.size(); ++k)
      if (results[k].outcome == kCrossing) {
        at_pair(GlobalInjectivity::Verdict::kOverlap, k);
        out.reason = "the shape overlaps itself near " + where(out.overlap_point) + " (mesh triangles " +
                     std::to_string(pairs[k].first) + " and " + std::to_string(pairs[k].second) + ")";
        return out;
      }
    if (!im.rest_problem.empty()) {  // no crossing proven, and "true" needs ∂D to be one closed manifold
      out.verdict = GlobalInjectivity::Verdict::kNotDecided;
      out.reason = im.rest_problem;
      return out;
    }
    for (size_t k = 0; k < results.size(); ++k)
      if (results[k].outcome == kOpen) {
        at_pair(GlobalInjectivity::Verdict::kNotDecided, k);
        out.reason = pairs[k].first == pairs[k].second
                         ? "could not prove the map injective on mesh triangle " +
                               std::to_string(pairs[k].first) + " near " + where(to_model(results[k].where)) +
                               " (depth " + std::to_string(params.max_depth) + ")"
                         : "could not separate the images of mesh triangles " +
                               std::to_string(pairs[k].first) + " and " + std::to_string(pairs[k].second) +
                               " near " + where(to_model(results[k].where)) + " (depth " +
                               std::to_string(params.max_depth) + ")";
        return out;
      }
    if (im.component_faces.size() > 1) return nesting_verdict();
    out.verdict = GlobalInjectivity::Verdict::kInjective;
    return out;
  }

  // --- 6. The margins of a map proven injective (Step G6): per recordable pair (the pairs hold mesh
  // triangles after stage 5) its separation margin and balls; J and f at the vertices.
  std::shared_ptr<const ProvenMargins> margins() const {
    auto m = std::make_shared<ProvenMargins>();
    m->y = y, m->fV = fV, m->eps = eps, m->A_abs = fm.A_abs, m->Jv = Jv, m->sJv = sJv;
    for (size_t k = 0; k < results.size(); ++k) {
      const PairResult& r = results[k];
      if (!r.recordable || r.outcome != kCleared) continue;
      const long b0 = static_cast<long>(m->balls.size());
      m->balls.insert(m->balls.end(), r.balls.begin(), r.balls.end());
      m->group_sums.insert(m->group_sums.end(), r.sums.begin(), r.sums.end());
      m->pairs.push_back({r.a, r.b, r.sep, b0, static_cast<long>(m->balls.size())});
    }
    std::sort(m->pairs.begin(), m->pairs.end());
    for (size_t i = 0; i < top.size(); ++i)
      if (top[i].depth > 0 && top[i].id != kNoPiece)
        m->tops.push_back({top[i].id, top[i].q, top[i].jb, sJtop[i], Jtop[i]});
    std::sort(m->tops.begin(), m->tops.end());
    return m;
  }

  // --- 5b. f|S is injective and S has several components: the nesting of their images decides (Step G5).
  GlobalInjectivity nesting_verdict() {
    if (!im.rest_nesting_problem.empty()) {
      out.reason = im.rest_nesting_problem;
      return out;
    }
    // Where the tubes of the mesh triangles are too wide or infinite (triangles near the cage), the image
    // surface is refined 1-to-4 (refine_image), at most kNestingDepth times.
    constexpr int kNestingDepth = 2;
    MatX3d P = mesh.V, W = fV;
    MatX3i F = mesh.F;
    std::vector<std::vector<int>> comps = im.component_faces;
    std::vector<double> rho(nf);
    for (long f = 0; f < nf; ++f) rho[f] = pieces[f].rho;
    Nesting n = im.nesting(W, F, comps, &rho, eps, slack);
    for (int depth = 1; depth <= kNestingDepth && !n.problem.empty() && !cancelled(); ++depth) {
      im.refine_image(y, P, W, F, comps);
      rho.assign(F.rows(), kInf);
#pragma omp parallel
      {
        std::vector<float> row;
#pragma omp for schedule(dynamic, 256)
        for (long f = 0; f < F.rows(); ++f) {
          std::array<Vec3, 3> p, q;
          for (int k = 0; k < 3; ++k) p[k] = P.row(F(f, k)), q[k] = W.row(F(f, k));
          rho[f] = make_piece(p, q, -1, depth, kInf, row).rho;
        }
      }
      n = im.nesting(W, F, comps, &rho, eps, slack);
    }
    if (cancelled()) return global_injectivity_not_decided("cancelled");
    if (!n.problem.empty()) {
      out.reason = "the nesting of the surface components' images is not decided: " + n.problem;
      return out;
    }
    const int nc = static_cast<int>(im.component_faces.size());
    for (int i = 0; i < nc; ++i) {  // |degree| ≥ 2 beside f(S_i): proven not injective
      const int d = std::abs(n.outside[i]) >= 2 ? n.outside[i] : n.outside[i] + n.sign[i];
      if (std::abs(d) < 2) continue;
      out.verdict = GlobalInjectivity::Verdict::kOverlap;
      out.overlap_point = to_model(n.point[i]);
      out.overlap_face_a = im.component_faces[i].front();
      out.overlap_face_b = n.encloser[i] >= 0 ? im.component_faces[n.encloser[i]].front() : -1;
      out.reason = "the shape overlaps itself near " + where(out.overlap_point) + ": the image of " +
                   im.component_name(i) + " lies inside the image of " + im.component_name(n.encloser[i]) +
                   ", where the mapping degree (the number of preimages) is " + std::to_string(d);
      return out;
    }
    for (int i = 0; i < nc; ++i) {
      const int out_deg = n.outside[i], in_deg = n.outside[i] + n.sign[i];
      if (out_deg >= 0 && out_deg <= 1 && in_deg >= 0 && in_deg <= 1) continue;
      out.reason = "the image of " + im.component_name(i) + " has mapping degree " + std::to_string(out_deg) +
                   " and " + std::to_string(in_deg) + " on its two sides (turned inside out)";
      return out;
    }
    out.verdict = GlobalInjectivity::Verdict::kInjective;
    return out;
  }
};

GlobalInjectivity GlobalInjectivityChecker::check(const MatX3d& y_model,
                                                  const GlobalInjectivityParams& params) const {
  const auto t_start = Clock::now();
  const Impl& im = *impl_;
  auto finish = [&](GlobalInjectivity g) {
    g.rest_intersecting_pairs = static_cast<long>(im.rest_intersections.size());
    g.ms = ms_since(t_start);
    return g;
  };
  if (y_model.rows() != im.basis.size())
    throw InputError("", "coefficients have " + std::to_string(y_model.rows()) +
                             " rows, expected #V+#F = " + std::to_string(im.basis.size()));
  if (!y_model.allFinite()) throw InputError("", "coefficients contain NaN or Inf");
  if (params.max_depth < 0 || params.max_depth > kDepthCap - 2)
    throw InputError("", "global injectivity: max_depth " + std::to_string(params.max_depth) +
                             " is outside [0, " + std::to_string(kDepthCap - 2) + "]");
  if (!im.structure_problem.empty()) return finish(global_injectivity_not_decided(im.structure_problem));
  std::shared_ptr<const ProvenMargins> base;
  if (params.reuse_margins) {
    std::lock_guard<std::mutex> lock(im.margins_mutex);
    base = im.margins;
  }
  Impl::MapCheck m(im, y_model, params, base);
  m.pieces_and_star_balls();
  if (m.cancelled()) return finish(global_injectivity_not_decided("cancelled"));
  const std::string too_close = m.top_pieces();
  if (!too_close.empty()) return finish(global_injectivity_not_decided(too_close));
  m.top_motion();
  m.candidate_pairs();
  m.examine_pairs();
  if (m.cancelled()) return finish(global_injectivity_not_decided("cancelled"));
  GlobalInjectivity g = m.verdict();
  if (params.reuse_margins && g.verdict == GlobalInjectivity::Verdict::kInjective) {
    std::shared_ptr<const ProvenMargins> kept = m.margins();
    std::lock_guard<std::mutex> lock(im.margins_mutex);
    im.margins = std::move(kept);
  }
  return finish(g);
}

GlobalInjectivity check_global_injectivity(const Cage& cage, const TriMesh& mesh, const MatX3d& y,
                                           const GlobalInjectivityParams& params) {
  GlobalInjectivityParams once = params;
  once.reuse_margins = false;  // the checker checks this one map: nothing to keep margins for
  const auto t0 = Clock::now();
  const GlobalInjectivityChecker checker(cage, mesh);
  const double setup_ms = ms_since(t0);
  GlobalInjectivity g = checker.check(y, once);
  g.ms += setup_ms;  // a check of one map costs its checker's set-up too
  return g;
}

}  // namespace lidef
