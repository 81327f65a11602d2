#include "lidef/green_coordinates.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "lidef/geometry.h"
#include "lidef/internal/lane_math.h"

namespace lidef {
namespace {

constexpr double kInv4Pi = 1.0 / (4.0 * M_PI);
constexpr double kInv2Pi = 1.0 / (2.0 * M_PI);

inline Mat3 cross_matrix(const Vec3& d) {
  Mat3 m;
  m << 0, -d.z(), d.y(), d.z(), 0, -d.x(), -d.y(), d.x(), 0;
  return m;
}

// Per-face quantities at a point shared by the basis and the differential representation: l_k = x_k − p, the
// solid angle ω_t, and per edge (opposite vertex k, (u, k, w) in cage order so d_k = x_w − x_u) C_k, l_u ×
// l_w and, when asked, α_k and β_k.
}  // namespace

struct HarmonicBasis::FaceAtPoint {
  Vec3 l[3];
  double L[3];
  double triple, omega;
  double C[3];
  Vec3 luxlw[3], alpha[3], beta[3];
};

EdgeAlphaBeta edge_alpha_beta(const Vec3& u, const Vec3& w, const Vec3& p) {
  const Vec3 lu = u - p, lw = w - p;
  const double Lu = lu.norm(), Lw = lw.norm(), d = (w - u).norm();
  const double m = Lu + Lw;
  // m² − d² = 2(|l_u||l_w| + l_u·l_w), computed without the cancellation of m² − d².
  const double md = 2.0 * (Lu * Lw + lu.dot(lw));
  return {m * kInv2Pi / md * lu.cross(lw) / (Lu * Lw), d * kInv2Pi / md * (lu / Lu + lw / Lw)};
}

HarmonicBasis::HarmonicBasis(const Cage& cage) : nv_(cage.num_vertices()), nf_(cage.num_faces()) {
  faces_.resize(nf_);
  for (int t = 0; t < nf_; ++t) {
    Face& fc = faces_[t];
    for (int k = 0; k < 3; ++k) {
      fc.vid[k] = cage.F(t, k);
      fc.x[k] = cage.V.row(fc.vid[k]).transpose();
    }
    fc.n = cage.N.row(t).transpose();
    fc.two_area = 2.0 * cage.area(t);
    for (int k = 0; k < 3; ++k) {
      fc.d[k] = fc.x[(k + 1) % 3] - fc.x[(k + 2) % 3];
      fc.dlen[k] = fc.d[k].norm();
      fc.dhat[k] = fc.d[k] / fc.dlen[k];
      fc.n_x_dhat[k] = fc.n.cross(fc.dhat[k]);
    }
  }
}

void HarmonicBasis::face_at_point(int t, const Vec3& p, bool with_alpha_beta, FaceAtPoint& o) const {
  const Face& fc = faces_[t];
  for (int k = 0; k < 3; ++k) {
    o.l[k] = fc.x[k] - p;
    o.L[k] = o.l[k].norm();
  }
  const Vec3* l = o.l;
  const double* L = o.L;
  // Signed solid angle / 4π, positive on the inner side (van Oosterom & Strackee).
  o.triple = l[0].dot(l[1].cross(l[2]));
  const double den =
      L[0] * L[1] * L[2] + l[0].dot(l[1]) * L[2] + l[1].dot(l[2]) * L[0] + l[2].dot(l[0]) * L[1];
  o.omega = std::atan2(o.triple, den) * (2.0 * kInv4Pi);
  for (int k = 0; k < 3; ++k) {
    const int u = (k + 2) % 3, w = (k + 1) % 3;
    const double m = L[u] + L[w];
    const double md = 2.0 * (L[u] * L[w] + l[u].dot(l[w]));  // m² − d², cancellation-free
    const double d = fc.dlen[k];
    // C_k = 1/(4π) ∫_edge 1/|ξ−p| ds = 1/(4π) log((m+d)/(m−d)), with m − d = (m² − d²)/(m + d).
    o.C[k] = kInv4Pi * std::log((m + d) * (m + d) / md);
    o.luxlw[k] = l[u].cross(l[w]);
    if (with_alpha_beta) {
      o.alpha[k] = (m * kInv2Pi / (md * L[u] * L[w])) * o.luxlw[k];
      o.beta[k] = (d * kInv2Pi / md) * (l[u] / L[u] + l[w] / L[w]);
    }
  }
}

// The basis kernel: for each face, the quantities of face_at_point() and their contributions to the face's
// function and its 3 vertex functions, for W points at once (the loop over the points vectorizes; the
// per-face constants are loaded once for all of them). Face functions are assigned, vertex functions
// accumulate over their faces (zeroed first). Formulas as in face_at_point(), with lane_log/lane_atan2
// (lane_math.h) for the C library's log/atan2.
template <int W, bool Val, bool Grad, bool Hess>
void HarmonicBasis::lanes(const double* px, const double* py, const double* pz, const LaneOut& vo,
                          const LaneOut& go, const LaneOut& ho) const {
  constexpr bool kNeedP = Val || Grad;  // P_t needs the solid angle and the edge logarithms
  for (int v = 0; v < nv_; ++v) {
    for (int j = 0; j < W; ++j) {
      if (Val) vo.data[v * vo.ld + j] = 0;
      if (Grad)
        for (int c = 0; c < 3; ++c) go.data[v * go.ld + c * go.stride + j] = 0;
      if (Hess)
        for (int c = 0; c < kSym; ++c) ho.data[v * ho.ld + c * ho.stride + j] = 0;
    }
  }
  for (int t = 0; t < nf_; ++t) {
    const Face& fc = faces_[t];
    const long ft = nv_ + t;
    const double inv2s = 1.0 / fc.two_area;
    double* vf = Val ? vo.data + ft * vo.ld : nullptr;
    double* gf = Grad ? go.data + ft * go.ld : nullptr;
    double* hf = Hess ? ho.data + ft * ho.ld : nullptr;
    double *vv[3], *gv[3], *hv[3];
    for (int k = 0; k < 3; ++k) {
      vv[k] = Val ? vo.data + fc.vid[k] * vo.ld : nullptr;
      gv[k] = Grad ? go.data + fc.vid[k] * go.ld : nullptr;
      hv[k] = Hess ? ho.data + fc.vid[k] * ho.ld : nullptr;
    }
    const long gs = go.stride, hs = ho.stride;
#pragma omp simd
    for (int j = 0; j < W; ++j) {
      const double p[3] = {px[j], py[j], pz[j]};
      // Reciprocals once, multiplications after: the divider is what limits this loop.
      double l[3][3], L[3], invL[3];
#pragma GCC unroll 6
      for (int k = 0; k < 3; ++k) {
#pragma GCC unroll 6
        for (int c = 0; c < 3; ++c) l[k][c] = fc.x[k](c) - p[c];
        L[k] = std::sqrt(l[k][0] * l[k][0] + l[k][1] * l[k][1] + l[k][2] * l[k][2]);
        invL[k] = 1.0 / L[k];
      }
      double luxlw[3][3], C[3] = {0, 0, 0}, alpha[3][3], beta[3][3];
#pragma GCC unroll 6
      for (int k = 0; k < 3; ++k) {
        const int u = (k + 2) % 3, w = (k + 1) % 3;
        luxlw[k][0] = l[u][1] * l[w][2] - l[u][2] * l[w][1];
        luxlw[k][1] = l[u][2] * l[w][0] - l[u][0] * l[w][2];
        luxlw[k][2] = l[u][0] * l[w][1] - l[u][1] * l[w][0];
        const double m = L[u] + L[w];
        const double md = 2.0 * (L[u] * L[w] + (l[u][0] * l[w][0] + l[u][1] * l[w][1] + l[u][2] * l[w][2]));
        const double d = fc.dlen[k], inv_md = 1.0 / md;
        if (kNeedP) C[k] = kInv4Pi * lane_log((m + d) * (m + d) / md);
        if (Hess) {
          const double sa = (m * kInv2Pi) * inv_md * (invL[u] * invL[w]), sb = (d * kInv2Pi) * inv_md;
#pragma GCC unroll 6
          for (int c = 0; c < 3; ++c) {
            alpha[k][c] = sa * luxlw[k][c];
            beta[k][c] = sb * (l[u][c] * invL[u] + l[w][c] * invL[w]);
          }
        }
      }
      if (kNeedP) {
        // Signed solid angle / 4π (van Oosterom & Strackee); l1 × l2 = −luxlw[0] (l2 × l1).
        const double triple = -(l[0][0] * luxlw[0][0] + l[0][1] * luxlw[0][1] + l[0][2] * luxlw[0][2]);
        const double d01 = l[0][0] * l[1][0] + l[0][1] * l[1][1] + l[0][2] * l[1][2];
        const double d12 = l[1][0] * l[2][0] + l[1][1] * l[2][1] + l[1][2] * l[2][2];
        const double d20 = l[2][0] * l[0][0] + l[2][1] * l[0][1] + l[2][2] * l[0][2];
        const double den = L[0] * L[1] * L[2] + d01 * L[2] + d12 * L[0] + d20 * L[1];
        const double omega = lane_atan2(triple, den) * (2.0 * kInv4Pi);
        // P_t = n × Σ_k d̂_k C_k − ω n;  ∇ψ_t = −P_t.
        double s[3], P[3];
#pragma GCC unroll 6
        for (int c = 0; c < 3; ++c) s[c] = C[0] * fc.dhat[0](c) + C[1] * fc.dhat[1](c) + C[2] * fc.dhat[2](c);
        const Vec3& n = fc.n;
        P[0] = n(1) * s[2] - n(2) * s[1] - omega * n(0);
        P[1] = n(2) * s[0] - n(0) * s[2] - omega * n(1);
        P[2] = n(0) * s[1] - n(1) * s[0] - omega * n(2);
        if (Val) {
          // ψ_t = −Σ_k C_k/|d_k| (l_u × l_w)·n − (3/s) ω vol_t, vol_t = l0·(l1×l2)/6.
          double psi = -(3.0 * 2.0 * inv2s) * omega * (triple / 6.0);
#pragma GCC unroll 6
          for (int k = 0; k < 3; ++k)
            psi -= C[k] / fc.dlen[k] * (luxlw[k][0] * n(0) + luxlw[k][1] * n(1) + luxlw[k][2] * n(2));
          vf[j] = psi;
          // φ_v gets 1/(2s) (l_u × l_w)·P_t from each face around v.
#pragma GCC unroll 6
          for (int k = 0; k < 3; ++k)
            vv[k][j] += inv2s * (luxlw[k][0] * P[0] + luxlw[k][1] * P[1] + luxlw[k][2] * P[2]);
        }
        if (Grad) {
#pragma GCC unroll 6
          for (int c = 0; c < 3; ++c) gf[c * gs + j] = -P[c];
#pragma GCC unroll 6
          for (int k = 0; k < 3; ++k) {
            const Vec3& dk = fc.d[k];
            gv[k][j] += inv2s * (P[1] * dk(2) - P[2] * dk(1));
            gv[k][gs + j] += inv2s * (P[2] * dk(0) - P[0] * dk(2));
            gv[k][2 * gs + j] += inv2s * (P[0] * dk(1) - P[1] * dk(0));
          }
        }
      }
      if (Hess) {
        // J(P_t) = Σ_k (n × d̂_k) β_kᵀ + n α_kᵀ  (rows: components of P, columns: ∂/∂p).
        double JP[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
#pragma GCC unroll 6
        for (int k = 0; k < 3; ++k)
#pragma GCC unroll 6
          for (int r = 0; r < 3; ++r)
#pragma GCC unroll 6
            for (int c = 0; c < 3; ++c) JP[r][c] += fc.n_x_dhat[k](r) * beta[k][c] + fc.n(r) * alpha[k][c];
        // ∇ψ_t = −P_t: the symmetric part of −J(P).
        hf[j] = -JP[0][0];
        hf[hs + j] = -0.5 * (JP[0][1] + JP[1][0]);
        hf[2 * hs + j] = -0.5 * (JP[0][2] + JP[2][0]);
        hf[3 * hs + j] = -JP[1][1];
        hf[4 * hs + j] = -0.5 * (JP[1][2] + JP[2][1]);
        hf[5 * hs + j] = -JP[2][2];
        // ∇φ_v ∋ (1/2s) P × d_k = −(1/2s) [d_k]× P  ⇒  Hessian contribution −(1/2s) [d_k]× J(P).
#pragma GCC unroll 6
        for (int k = 0; k < 3; ++k) {
          const double dx = fc.d[k](0), dy = fc.d[k](1), dz = fc.d[k](2);
          double M[3][3];
#pragma GCC unroll 6
          for (int c = 0; c < 3; ++c) {
            M[0][c] = dy * JP[2][c] - dz * JP[1][c];
            M[1][c] = dz * JP[0][c] - dx * JP[2][c];
            M[2][c] = dx * JP[1][c] - dy * JP[0][c];
          }
          const double s1 = -inv2s, s2 = -inv2s * 0.5;
          double* h = hv[k];
          h[j] += s1 * M[0][0];
          h[hs + j] += s2 * (M[0][1] + M[1][0]);
          h[2 * hs + j] += s2 * (M[0][2] + M[2][0]);
          h[3 * hs + j] += s1 * M[1][1];
          h[4 * hs + j] += s2 * (M[1][2] + M[2][1]);
          h[5 * hs + j] += s1 * M[2][2];
        }
      }
    }
  }
}

template <int W>
void HarmonicBasis::run_lanes(const double* px, const double* py, const double* pz, const LaneOut& v,
                              const LaneOut& g, const LaneOut& h) const {
  const int what = (v.data ? 1 : 0) | (g.data ? 2 : 0) | (h.data ? 4 : 0);
  switch (what) {
    case 1:
      return lanes<W, true, false, false>(px, py, pz, v, g, h);
    case 2:
      return lanes<W, false, true, false>(px, py, pz, v, g, h);
    case 3:
      return lanes<W, true, true, false>(px, py, pz, v, g, h);
    case 4:
      return lanes<W, false, false, true>(px, py, pz, v, g, h);
    case 5:
      return lanes<W, true, false, true>(px, py, pz, v, g, h);
    case 6:
      return lanes<W, false, true, true>(px, py, pz, v, g, h);
    case 7:
      return lanes<W, true, true, true>(px, py, pz, v, g, h);
    default:
      return;
  }
}

void HarmonicBasis::evaluate(const Vec3& p, int order, double* value, double* grad, double* hess) const {
  const int n = size();
  const bool want_grad = order >= 1 && grad != nullptr;
  const bool want_hess = order >= 2 && hess != nullptr;
  if (grad && !want_grad) std::memset(grad, 0, sizeof(double) * 3 * n);
  if (hess && !want_hess) std::memset(hess, 0, sizeof(double) * kSym * n);
  // One lane: the layouts (#V+#F) by 3 and by 6 row-major are the lane layout with W = 1.
  run_lanes<1>(&p(0), &p(1), &p(2), {value, 1, 0}, {want_grad ? grad : nullptr, 3, 1},
               {want_hess ? hess : nullptr, kSym, 1});
}

void HarmonicBasis::evaluate_rows(const MatX3d& P, bool values, bool gradients, bool hessians, MatXdR& out,
                                  bool drop_zz) const {
  const long n = size(), rows = P.rows();
  const int r = (values ? 1 : 0) + (gradients ? 3 : 0) + (hessians ? kSym : 0);
  const int r_out = r - (hessians && drop_zz ? 1 : 0);  // zz is the last row of the block
  out.resize(r_out * rows, n);
  if (rows == 0 || r == 0) return;
  const int rg = values ? 1 : 0, rh = rg + (gradients ? 3 : 0);  // first gradient / Hessian row
#pragma omp parallel
  {
    // The kernel's output for one batch, row c of the block by function by lane: the lanes' entries are
    // contiguous (vector stores), and copying a row out reads it in order.
    std::vector<double> buf(static_cast<size_t>(r) * n * kLanes);
    const long nW = n * kLanes;
#pragma omp for schedule(static)
    for (long i0 = 0; i0 < rows; i0 += kLanes) {
      alignas(64) double px[kLanes], py[kLanes], pz[kLanes];
      for (int j = 0; j < kLanes; ++j) {
        const long i = std::min(i0 + j, rows - 1);  // a last, partial batch repeats its last point
        px[j] = P(i, 0);
        py[j] = P(i, 1);
        pz[j] = P(i, 2);
      }
      run_lanes<kLanes>(px, py, pz, {values ? buf.data() : nullptr, kLanes, nW},
                        {gradients ? buf.data() + rg * nW : nullptr, kLanes, nW},
                        {hessians ? buf.data() + rh * nW : nullptr, kLanes, nW});
      for (long j = 0; j < std::min<long>(kLanes, rows - i0); ++j)
        for (int c = 0; c < r_out; ++c) {
          const double* src = buf.data() + c * nW + j;
          double* dst = out.data() + ((i0 + j) * r_out + c) * n;
          for (long k = 0; k < n; ++k) dst[k] = src[k * kLanes];
        }
    }
  }
}

namespace {
// f = Σ_i y_i φ_i and J = Σ_i y_i ∇φ_iᵀ in the order of i, for the values val[i] and the gradients
// (gx, gy, gz)[i · gstride] of one point: map_jet's sums, shared by map_jets.
void contract_jet(const MatX3d& y, const double* val, const double* gx, const double* gy, const double* gz,
                  long gstride, Vec3& f, Mat3& J) {
  f.setZero(), J.setZero();
  for (Eigen::Index i = 0; i < y.rows(); ++i) {
    const Vec3 yi = y.row(i).transpose();
    f += yi * val[i];
    J += yi * Eigen::RowVector3d(gx[i * gstride], gy[i * gstride], gz[i * gstride]);
  }
}
// The batched maps' loop: the points P in blocks of 64 (small rows, a task per block), each block's basis
// values (and gradients) by the SIMD kernel, then each(first point, count, rows) on the block.
template <class Each>
void in_blocks(const HarmonicBasis& basis, const MatX3d& P, bool gradients, Each&& each) {
  constexpr Eigen::Index kBlock = 64;
  const Eigen::Index n = P.rows();
#pragma omp parallel
  {
    MatXdR rows;
#pragma omp for schedule(dynamic, 1)
    for (Eigen::Index b = 0; b < (n + kBlock - 1) / kBlock; ++b) {
      const Eigen::Index i0 = b * kBlock, m = std::min(kBlock, n - i0);
      basis.evaluate_rows(P.middleRows(i0, m), true, gradients, false, rows);
      each(i0, m, rows);
    }
  }
}
}  // namespace

MapJet HarmonicBasis::map_jet(const MatX3d& y, const Vec3& p, int order) const {
  const int n = size();
  std::vector<double> val(n), grad(order >= 1 ? 3 * n : 0), hess(order >= 2 ? kSym * n : 0);
  evaluate(p, order, val.data(), order >= 1 ? grad.data() : nullptr, order >= 2 ? hess.data() : nullptr);
  MapJet jet;
  if (order >= 1) {
    contract_jet(y, val.data(), &grad[0], &grad[1], &grad[2], 3, jet.f, jet.J);
  } else {
    for (int i = 0; i < n; ++i) jet.f += y.row(i).transpose() * val[i];
  }
  if (order >= 2)
    for (int i = 0; i < n; ++i) {
      const Vec3 yi = y.row(i).transpose();
      const double* h = &hess[kSym * i];
      Mat3 Hb;
      Hb << h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5];
      for (int a = 0; a < 3; ++a) jet.H[a] += yi(a) * Hb;
    }
  return jet;
}

void HarmonicBasis::map_jets(const MatX3d& y, const MatX3d& P, MatX3d& f, MatXd& JT) const {
  f.resize(P.rows(), 3);
  JT.resize(3 * P.rows(), 3);
  in_blocks(*this, P, true, [&](Eigen::Index i0, Eigen::Index m, const MatXdR& rows) {
    for (Eigen::Index i = 0; i < m; ++i) {
      Vec3 fi;
      Mat3 J;
      contract_jet(y, &rows(4 * i, 0), &rows(4 * i + 1, 0), &rows(4 * i + 2, 0), &rows(4 * i + 3, 0), 1, fi,
                   J);
      f.row(i0 + i) = fi.transpose();
      JT.middleRows(3 * (i0 + i), 3) = J.transpose();
    }
  });
}

HarmonicBasis::FaceMatrices HarmonicBasis::face_matrices(const MatX3d& y) const {
  FaceMatrices fm;
  fm.A.resize(nf_);
  fm.AD.resize(nf_);
  fm.A_abs.resize(nf_);
  for (int t = 0; t < nf_; ++t) {
    const Face& fc = faces_[t];
    // Lemma 5.1: A_t = y_t nᵀ − Σ_k y_k (n × d_k)ᵀ / (2 s_t), d_k = x_{k+1} − x_{k−1}.
    Mat3 A = y.row(nv_ + t).transpose() * fc.n.transpose();
    double abs_sum = y.row(nv_ + t).cwiseAbs().sum() * fc.n.cwiseAbs().sum();
    for (int k = 0; k < 3; ++k) {
      const Vec3 g = fc.n.cross(fc.d[k]) / fc.two_area;
      A.noalias() -= y.row(fc.vid[k]).transpose() * g.transpose();
      abs_sum += y.row(fc.vid[k]).cwiseAbs().sum() * g.cwiseAbs().sum();
    }
    fm.A[t] = A;
    fm.A_abs[t] = abs_sum;
    for (int k = 0; k < 3; ++k) fm.AD[t][k] = A * cross_matrix(fc.dhat[k]);
  }
  return fm;
}

MapJet HarmonicBasis::differential_jet(const FaceMatrices& fm, const Vec3& p, int order, double* scale_J,
                                       double* scale_H) const {
  MapJet jet;
  double sJ = 0, sH = 0;
  FaceAtPoint fp;
  for (int t = 0; t < nf_; ++t) {
    face_at_point(t, p, order >= 2, fp);
    const Mat3& A = fm.A[t];
    // Magnitudes for the rounding scale: A_t's own rounding is relative to the terms that formed it.
    const double a1 = std::max(A.cwiseAbs().sum(), fm.A_abs[t]);
    jet.J.noalias() += fp.omega * A;
    sJ += std::abs(fp.omega) * a1;
    for (int k = 0; k < 3; ++k) {
      const Mat3& AD = fm.AD[t][k];
      const double ad1 = std::max(AD.cwiseAbs().sum(), 2.0 * fm.A_abs[t]);
      jet.J.noalias() -= fp.C[k] * AD;
      sJ += std::abs(fp.C[k]) * ad1;
      if (order >= 2) {
        for (int a = 0; a < 3; ++a)
          jet.H[a].noalias() -=
              A.row(a).transpose() * fp.alpha[k].transpose() + AD.row(a).transpose() * fp.beta[k].transpose();
        sH += a1 * fp.alpha[k].cwiseAbs().sum() + ad1 * fp.beta[k].cwiseAbs().sum();
      }
    }
  }
  if (scale_J) *scale_J = sJ;
  if (scale_H) *scale_H = sH;
  return jet;
}

MatXd HarmonicBasis::value_matrix(const MatX3d& P) const {
  MatXdR M;
  evaluate_rows(P, true, false, false, M);
  return M;
}

MatXd HarmonicBasis::gradient_matrix(const MatX3d& P) const {
  MatXdR M;
  evaluate_rows(P, false, true, false, M);
  return M;
}

MatXd HarmonicBasis::hessian_matrix(const MatX3d& P) const {
  MatXdR M;
  evaluate_rows(P, false, false, true, M);
  return M;
}

MatX3d HarmonicBasis::map_values(const MatX3d& y, const MatX3d& P) const {
  MatX3d out(P.rows(), 3);
  in_blocks(*this, P, false, [&](Eigen::Index i0, Eigen::Index m, const MatXdR& rows) {
    for (Eigen::Index i = 0; i < m; ++i) out.row(i0 + i) = rows.row(i) * y;
  });
  return out;
}

}  // namespace lidef
