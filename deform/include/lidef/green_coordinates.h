// The cage-based harmonic basis of Ben-Chen et al. 2009 / Lipman et al. 2008 (paper Sec. 3.2, App. A):
//   f(p) = Σ_v y_v φ_v(p) + Σ_t y_t ψ_t(p)
// with ψ_t(p) = 1/(4π) ∫_t 1/|ξ−p| dA and φ_v(p) = 1/(4π) ∫ hat_v(ξ) (ξ−p)·n/|ξ−p|³ dA.
// Closed forms (with the sign corrections of docs/math.md) for values, gradients and Hessians.
#pragma once
#include <array>
#include <vector>

#include "lidef/cage.h"
#include "lidef/types.h"

namespace lidef {

// Number of stored entries of a symmetric 3x3 Hessian, in the order xx, xy, xz, yy, yz, zz.
constexpr int kSym = 6;

// f, J and H of a map at one point: J(a,b) = ∂f_a/∂p_b, H[a](b,c) = ∂²f_a/∂p_b∂p_c.
struct MapJet {
  Vec3 f = Vec3::Zero();
  Mat3 J = Mat3::Zero();
  std::array<Mat3, 3> H{Mat3::Zero(), Mat3::Zero(), Mat3::Zero()};
  // Full Frobenius norm of the 3x3x3 Hessian tensor (all 27 entries; MATH-NOTES).
  double hessian_norm() const {
    return std::sqrt(H[0].squaredNorm() + H[1].squaredNorm() + H[2].squaredNorm());
  }
};

// Per-edge functions of the differential representation (paper Thm. 5.2, App. A (42)) for one
// directed edge e = (u -> w) of triangle t, opposite vertex v: α_e and β_e at a point p.
// ∇ω_t = −Σ_e α_e (MATH-NOTES erratum of (51)), ∇C_e = β_e.
struct EdgeAlphaBeta {
  Vec3 alpha, beta;
};
EdgeAlphaBeta edge_alpha_beta(const Vec3& u, const Vec3& w, const Vec3& p);

// The basis of one cage. Construction precomputes all per-face constants once; evaluation is
// thread-safe (const) and allocation-free when the caller provides buffers.
class HarmonicBasis {
 public:
  explicit HarmonicBasis(const Cage& cage);

  int num_vertices() const { return nv_; }
  int num_faces() const { return nf_; }
  int size() const { return nv_ + nf_; }  // #V+#F basis functions, vertex functions first

  // Evaluates all basis functions at p. order 0: values; 1: + gradients; 2: + Hessians.
  // Buffers (may be null when not wanted; otherwise sized as noted, overwritten):
  //   value #V+#F;  grad (#V+#F) by 3 row-major;  hess (#V+#F) by 6 row-major (xx,xy,xz,yy,yz,zz).
  void evaluate(const Vec3& p, int order, double* value, double* grad, double* hess) const;

  // Points one kernel call evaluates together (SIMD lanes; AVX2 holds 4 doubles).
  static constexpr int kLanes = 4;
  // Basis values, gradients and/or Hessians at many points P (#P by 3), kLanes points at a time (the per-face
  // work shared by the points and vectorized over them), in parallel, into `out` (resized; its memory is
  // reused when the shape is the same). Row-major, one block of r rows per point, r = (values ? 1 : 0) +
  // (gradients ? 3 : 0) + (hessians ? 6 : 0): rows r·i .. r·i + r − 1 hold the values at p_i, then ∂/∂p_x,
  // ∂/∂p_y, ∂/∂p_z, then the symmetric Hessian entries xx, xy, xz, yy, yz, zz (#V+#F columns). The numbers
  // are evaluate()'s at each point (the same arithmetic; a point's numbers do not depend on the other points
  // of its batch), to the compiler's contraction of multiply-adds. `drop_zz`: the Hessian block has 5 rows
  // (no zz): the basis functions are harmonic, so zz = −xx − yy, and a caller that multiplies the rows by a
  // matrix saves a ninth of the product (the certifier's precomputation).
  void evaluate_rows(const MatX3d& P, bool values, bool gradients, bool hessians, MatXdR& out,
                     bool drop_zz = false) const;

  // Map jet for coefficients y (#V+#F by 3) at p; order as in evaluate().
  MapJet map_jet(const MatX3d& y, const Vec3& p, int order = 2) const;

  // Batched matrices for many points P (#P by 3), evaluated in parallel:
  //   values    #P by #V+#F                 (row i: basis values at p_i; f(P) = D y)
  //   gradients 3#P by #V+#F                (row 3i+b: ∂/∂p_b at p_i;   J(p_i)ᵀ = rows 3i..3i+2 times y)
  //   hessians  6#P by #V+#F                (row 6i+k: k-th symmetric entry at p_i)
  MatXd value_matrix(const MatX3d& P) const;
  MatXd gradient_matrix(const MatX3d& P) const;
  MatXd hessian_matrix(const MatX3d& P) const;

  // Map values at many points: #P by 3. By the SIMD kernel (evaluate_rows) a block of points at a time, each
  // point's row times y.
  MatX3d map_values(const MatX3d& y, const MatX3d& P) const;
  // f (#P by 3) and J transposed (3#P by 3: rows 3i..3i+2 are J(p_i)ᵀ) at many points: map_jet's numbers
  // (order 1, its sums in its order) from the SIMD kernel a block of points at a time.
  void map_jets(const MatX3d& y, const MatX3d& P, MatX3d& f, MatXd& JT) const;

  // --- The differential representation (paper (49) and (53) with the MATH-NOTES signs):
  //   J(p) = Σ_t ω_t A_t − Σ_t Σ_k C_k A_t [d̂_k]×,   H(p) = −Σ_t Σ_k (A_t ∘ α_k + A_t [d̂_k]× ∘ β_k),
  // with A_t the linear part of face t's affine map (Lemma 5.1). Per point it costs one pass over the faces
  // and no per-coefficient work, so it is the fast way to evaluate one map at many new points (octree
  // children).
  struct FaceMatrices {
    std::vector<Mat3> A;                  // #F: A_t
    std::vector<std::array<Mat3, 3>> AD;  // #F: A_t [d̂_k]× for the edge opposite vertex k
    std::vector<double> A_abs;  // #F: Σ of |terms| forming A_t (its rounding scale; large under translations)
  };
  FaceMatrices face_matrices(const MatX3d& y) const;  // y: #V+#F by 3
  // J (order ≥ 1) and H (order 2) at p; `scale_J`/`scale_H` (optional) receive the sums of the magnitudes of
  // the terms added (Σ|ω|‖A‖₁ + Σ|C|‖AD‖₁ and Σ ‖A‖₁‖α‖₁ + ‖AD‖₁‖β‖₁), which bound the rounding error.
  MapJet differential_jet(const FaceMatrices& fm, const Vec3& p, int order, double* scale_J = nullptr,
                          double* scale_H = nullptr) const;

 private:
  struct FaceAtPoint;  // per-face quantities at a point (green_coordinates.cpp)
  // Fills `out` for face t at p; α, β only when asked.
  void face_at_point(int t, const Vec3& p, bool with_alpha_beta, FaceAtPoint& out) const;
  // The basis kernel for W points (px, py, pz: W coordinates each), writing point j's entry of function k,
  // component c at data + k·ld + c·stride + j (green_coordinates.cpp).
  struct LaneOut {
    double* data = nullptr;
    long ld = 0, stride = 0;
  };
  template <int W, bool Val, bool Grad, bool Hess>
  void lanes(const double* px, const double* py, const double* pz, const LaneOut& val, const LaneOut& grad,
             const LaneOut& hess) const;
  // lanes<W, ...> for the outputs that are wanted (their data non-null).
  template <int W>
  void run_lanes(const double* px, const double* py, const double* pz, const LaneOut& val,
                 const LaneOut& grad, const LaneOut& hess) const;

  struct Face {
    int vid[3];
    Vec3 x[3];        // vertex positions
    Vec3 n;           // unit outward normal
    double two_area;  // 2 s_t
    Vec3 d[3];        // d_k = x_{k+1} − x_{k−1}: edge opposite vertex k, in cage order
    double dlen[3];
    Vec3 dhat[3];
    Vec3 n_x_dhat[3];  // n × d̂_k
  };
  int nv_, nf_;
  std::vector<Face> faces_;
};

}  // namespace lidef
