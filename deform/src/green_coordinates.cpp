#include "lidef/green_coordinates.h"

#include <cmath>
#include <cstring>

#include "lidef/geometry.h"

namespace lidef {
namespace {

constexpr double kInv4Pi = 1.0 / (4.0 * M_PI);
constexpr double kInv2Pi = 1.0 / (2.0 * M_PI);

// Adds the symmetric part of M (3x3) into a 6-entry row (xx,xy,xz,yy,yz,zz) with weight s.
inline void add_sym(double* h, const Mat3& M, double s) {
  h[0] += s * M(0, 0);
  h[1] += s * 0.5 * (M(0, 1) + M(1, 0));
  h[2] += s * 0.5 * (M(0, 2) + M(2, 0));
  h[3] += s * M(1, 1);
  h[4] += s * 0.5 * (M(1, 2) + M(2, 1));
  h[5] += s * M(2, 2);
}

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

void HarmonicBasis::evaluate(const Vec3& p, int order, double* value, double* grad, double* hess) const {
  const int n = size();
  if (value) std::memset(value, 0, sizeof(double) * n);
  if (grad) std::memset(grad, 0, sizeof(double) * 3 * n);
  if (hess) std::memset(hess, 0, sizeof(double) * kSym * n);
  const bool want_val = value != nullptr;
  const bool want_grad = order >= 1 && grad != nullptr;
  const bool want_hess = order >= 2 && hess != nullptr;

  FaceAtPoint fp;
  for (int t = 0; t < nf_; ++t) {
    const Face& fc = faces_[t];
    face_at_point(t, p, want_hess, fp);
    const double omega = fp.omega, triple = fp.triple;
    const double* C = fp.C;
    const Vec3* luxlw = fp.luxlw;
    const Vec3* alpha = fp.alpha;
    const Vec3* beta = fp.beta;
    // P_t = n × Σ_k d̂_k C_k − ω n;  ∇ψ_t = −P_t.
    const Vec3 P = fc.n.cross(C[0] * fc.dhat[0] + C[1] * fc.dhat[1] + C[2] * fc.dhat[2]) - omega * fc.n;
    const double inv2s = 1.0 / fc.two_area;
    const int ft = nv_ + t;

    if (want_val) {
      // ψ_t = −Σ_k C_k/|d_k| (l_u × l_w)·n − (3/s) ω vol_t, vol_t = l0·(l1×l2)/6.
      double psi = -(3.0 * 2.0 * inv2s) * omega * (triple / 6.0);
      for (int k = 0; k < 3; ++k) psi -= C[k] / fc.dlen[k] * luxlw[k].dot(fc.n);
      value[ft] = psi;
      // φ_v gets 1/(2s) (l_u × l_w)·P_t from each face around v.
      for (int k = 0; k < 3; ++k) value[fc.vid[k]] += inv2s * luxlw[k].dot(P);
    }
    if (want_grad) {
      for (int b = 0; b < 3; ++b) grad[3 * ft + b] = -P(b);
      for (int k = 0; k < 3; ++k) {
        const Vec3 g = inv2s * P.cross(fc.d[k]);
        double* gv = grad + 3 * fc.vid[k];
        gv[0] += g(0);
        gv[1] += g(1);
        gv[2] += g(2);
      }
    }
    if (want_hess) {
      // J(P_t) = Σ_k (n × d̂_k) β_kᵀ + n α_kᵀ  (rows: components of P, columns: ∂/∂p).
      Mat3 JP = Mat3::Zero();
      for (int k = 0; k < 3; ++k)
        JP.noalias() += fc.n_x_dhat[k] * beta[k].transpose() + fc.n * alpha[k].transpose();
      add_sym(hess + kSym * ft, JP, -1.0);
      // ∇φ_v ∋ (1/2s) P × d_k = −(1/2s) [d_k]× P  ⇒  Hessian contribution −(1/2s) [d_k]× J(P).
      for (int k = 0; k < 3; ++k) add_sym(hess + kSym * fc.vid[k], cross_matrix(fc.d[k]) * JP, -inv2s);
    }
  }
}

MapJet HarmonicBasis::map_jet(const MatX3d& y, const Vec3& p, int order) const {
  const int n = size();
  std::vector<double> val(n), grad(order >= 1 ? 3 * n : 0), hess(order >= 2 ? kSym * n : 0);
  evaluate(p, order, val.data(), order >= 1 ? grad.data() : nullptr, order >= 2 ? hess.data() : nullptr);
  MapJet jet;
  for (int i = 0; i < n; ++i) {
    const Vec3 yi = y.row(i).transpose();
    jet.f += yi * val[i];
    if (order >= 1) jet.J += yi * Eigen::Map<const Eigen::RowVector3d>(&grad[3 * i]);
    if (order >= 2) {
      const double* h = &hess[kSym * i];
      Mat3 Hb;
      Hb << h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5];
      for (int a = 0; a < 3; ++a) jet.H[a] += yi(a) * Hb;
    }
  }
  return jet;
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
  const int n = size();
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> D(P.rows(), n);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    evaluate(P.row(i).transpose(), 0, D.row(i).data(), nullptr, nullptr);
  return D;
}

MatXd HarmonicBasis::gradient_matrix(const MatX3d& P) const {
  const int n = size();
  MatXd G(3 * P.rows(), n);
#pragma omp parallel
  {
    std::vector<double> grad(3 * n);
#pragma omp for schedule(static)
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      evaluate(P.row(i).transpose(), 1, nullptr, grad.data(), nullptr);
      for (int k = 0; k < n; ++k)
        for (int b = 0; b < 3; ++b) G(3 * i + b, k) = grad[3 * k + b];
    }
  }
  return G;
}

MatXd HarmonicBasis::hessian_matrix(const MatX3d& P) const {
  const int n = size();
  MatXd Hm(kSym * P.rows(), n);
#pragma omp parallel
  {
    std::vector<double> hess(kSym * n);
#pragma omp for schedule(static)
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      evaluate(P.row(i).transpose(), 2, nullptr, nullptr, hess.data());
      for (int k = 0; k < n; ++k)
        for (int b = 0; b < kSym; ++b) Hm(kSym * i + b, k) = hess[kSym * k + b];
    }
  }
  return Hm;
}

MatX3d HarmonicBasis::map_values(const MatX3d& y, const MatX3d& P) const {
  const int n = size();
  MatX3d out(P.rows(), 3);
#pragma omp parallel
  {
    std::vector<double> val(n);
#pragma omp for schedule(static)
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
      evaluate(P.row(i).transpose(), 0, val.data(), nullptr, nullptr);
      out.row(i) = Eigen::Map<const Eigen::RowVectorXd>(val.data(), n) * y;
    }
  }
  return out;
}

}  // namespace lidef
