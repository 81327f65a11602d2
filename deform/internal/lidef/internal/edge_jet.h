// J, H and the per-ball Lipschitz factor sums of one map at new points (octree children), from the
// differential representation regrouped by undirected cage edge (docs/certificate.md, Step 4b):
//   J(p) = Σ_t ω_t A_t − Σ_e C_e δ_e [d̂_e]×,   H(p) = −Σ_e (δ_e ∘ α_e + (δ_e [d̂_e]×) ∘ β_e),
// δ_e = Σ_{t ∋ e} s_t A_t with s_t = ±1 the orientation of e in face t relative to e = (v0 → v1). The two
// faces of an edge share C_e, α_e (up to sign) and β_e, so one point costs #V norms, #F solid angles and #E
// edge terms (one log each) instead of 3#F half-edge terms (HarmonicBasis::differential_jet); the same
// per-edge distances give the factors of both Lipschitz bounds over the ball B(p, r) (lipschitz_bound.h) in
// the same pass.
#pragma once
#include <array>
#include <vector>

#include "lidef/cage.h"
#include "lidef/green_coordinates.h"
#include "lidef/types.h"

namespace lidef {

class EdgeJet {
 public:
  explicit EdgeJet(const Cage& cage);

  // Everything that depends on the map: per face A_t, per edge δ_e, δ_e[d̂_e]×, ‖δ_e‖_F and rounding scales.
  struct MapData {
    struct Edge {
      Mat3 delta, delta_x;  // δ_e and δ_e [d̂_e]× (oriented v0 → v1)
      double norm = 0;      // ‖A_{f0} − A_{f1}‖_F (the factor weight of both bounds)
      double scale_a = 0;  // Σ over its 2 faces of max(‖A_t‖₁, A_abs_t)    (rounding scale of α terms)
      double scale_ad = 0;  // Σ over its 2 faces of max(‖A_t[d̂]×‖₁, 2 A_abs_t) (rounding scale of C, β terms)
      int v0 = 0, v1 = 0;
      double d = 0;  // edge length
    };
    std::vector<Mat3> A;          // #F
    std::vector<double> scale_A;  // #F: max(‖A_t‖₁, A_abs_t)
    std::vector<Edge> edges;      // only the edges with δ_e ≠ 0: the others contribute nothing
  };
  MapData prepare(const HarmonicBasis::FaceMatrices& fm) const;

  struct Values {
    Mat3 J = Mat3::Zero();
    std::array<Mat3, 3> H{Mat3::Zero(), Mat3::Zero(), Mat3::Zero()};
    double scale_J = 0, scale_H = 0;  // as HarmonicBasis::differential_jet's scale_J / scale_H
    double T_first = 0;  // Σ_e ‖δ_e‖ Γ_e(B(p, r))   (first order, +∞ when the ball nears an edge)
    double T_third = 0;  // Σ_e ‖δ_e‖ Θ_e(B(p, r))   (third order, idem)
  };
  // J always; H (and scale_H) when `hessian`; T_first / T_third when asked (left 0 otherwise).
  void evaluate(const MapData& md, const Vec3& p, double r, bool hessian, bool want_first, bool want_third,
                Values& out) const;

  // The same values at n ≤ kLanes points at once (p[0..n), radii r[0..n) → out[0..n)), each point in its own
  // SIMD lane: one pass over the vertices, faces and edges for all of them, with the vectorizable log and
  // atan2 of lane_math.h (docs/certificate.md, Step 4c). Each lane's result depends only on its own point
  // (not on n or on the other points). Equal to evaluate() up to rounding.
  static constexpr int kLanes = 8;
  void evaluate_lanes(const MapData& md, const Vec3* p, const double* r, int n, bool hessian, bool want_first,
                      bool want_third, Values* out) const;

  // A subset S of the cage's faces: F_S(p) = Σ_{t∈S} f_t(p), the part of J that the faces of S contribute
  // in the per-face representation (Step 2), and its derivatives. J, H and the factor sums of F_S are those
  // of Step 4b with δ_e summed over the faces of e that lie in S (docs/certificate.md, Step 4d: the far-field
  // refinement evaluates children on the faces near them only). The vertices of S are renumbered compactly.
  struct Patch {
    std::vector<Vec3> x;                    // the vertices of the faces of S
    std::vector<std::array<int, 3>> faces;  // |S|, local vertex indices
    MapData md;                             // A, scale_A per face of S; edges with local v0, v1
  };
  // `faces`: indices of S (distinct). Fills `out` (reused storage).
  void make_patch(const HarmonicBasis::FaceMatrices& fm, const std::vector<int>& faces, Patch& out) const;
  void evaluate(const Patch& s, const Vec3& p, double r, bool hessian, bool want_first, bool want_third,
                Values& out) const;
  void evaluate_lanes(const Patch& s, const Vec3* p, const double* r, int n, bool hessian, bool want_first,
                      bool want_third, Values* out) const;

  // The faces among `candidates` (all faces when nullptr; ascending order kept) whose bounding sphere
  // (centroid, largest centroid–vertex distance) comes within `radius` of c: every other face lies farther
  // than `radius` from c. Monotone: with radius' + |c' − c| ≤ radius, the faces near (c', radius') are among
  // those near (c, radius).
  void faces_near(const Vec3& c, double radius, const std::vector<int>* candidates,
                  std::vector<int>& out) const;
  int num_faces() const { return static_cast<int>(faces_.size()); }
  // The 3 undirected edges (indices into Cage::edges) of face t.
  const std::array<int, 3>& face_edges(int t) const { return face_edges_[t]; }

 private:
  // Vertices and faces a pass runs over: the whole cage (x_, faces_) or a patch.
  struct View {
    const Vec3* x;
    size_t nv;
    const std::array<int, 3>* faces;
    size_t nf;
  };
  View whole() const { return {x_.data(), x_.size(), faces_.data(), faces_.size()}; }
  static View view_of(const Patch& s) { return {s.x.data(), s.x.size(), s.faces.data(), s.faces.size()}; }
  void evaluate_view(const View& g, const MapData& md, const Vec3& p, double r, bool hessian, bool want_first,
                     bool want_third, Values& out) const;
  void evaluate_lanes_view(const View& g, const MapData& md, const Vec3* p, const double* r, int n,
                           bool hessian, bool want_first, bool want_third, Values* out) const;
  std::vector<std::array<int, 3>> face_edges_;  // #F
  std::vector<Vec3> face_center_;               // #F: centroid
  std::vector<double> face_radius_;             // #F: largest centroid–vertex distance
  std::vector<Vec3> x_;                    // #V vertex positions
  std::vector<std::array<int, 3>> faces_;  // #F
  struct EdgeConst {
    int v0, v1, f0, f1;
    int s0, s1;  // orientation of (v0 → v1) in f0 / f1 as HarmonicBasis's half-edge (u → w): ±1
    int k0, k1;  // local index of the opposite vertex in f0 / f1
    Vec3 dhat;
    double d;
  };
  std::vector<EdgeConst> edges_;
  // max(‖A_t‖₁, A_abs_t): face t's rounding scale.
  static double face_scale(const HarmonicBasis::FaceMatrices& fm, int t);
  // Edge c's terms for the faces of c in the set (in0: f0, in1: f1): δ_e, δ_e[d̂]×, ‖δ_e‖, rounding scales,
  // global vertex indices. False when δ_e = 0 (the edge contributes nothing).
  static bool edge_terms(const HarmonicBasis::FaceMatrices& fm, const EdgeConst& c, bool in0, bool in1,
                         MapData::Edge& e);
  template <bool kHessian, bool kFirst, bool kThird>
  static bool lanes(const View& g, const MapData& md, const double* px, const double* py, const double* pz,
                    const double* r, Values* out, int n);
};

}  // namespace lidef
