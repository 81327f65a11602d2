#include "lidef/internal/edge_jet.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "lidef/errors.h"
#include "lidef/internal/lane_math.h"
#include "lidef/lipschitz_bound.h"

namespace lidef {
namespace {

constexpr double kInv4Pi = 1.0 / (4.0 * M_PI);
constexpr double kInv2Pi = 1.0 / (2.0 * M_PI);
constexpr double kInvPi = 1.0 / M_PI;
// (a, b, c) with b ≤ c: the entries H[a](b, c) of a symmetric Hessian tensor the batched pass sums.
constexpr int kSymIdx[18][3] = {{0, 0, 0}, {0, 0, 1}, {0, 0, 2}, {0, 1, 1}, {0, 1, 2}, {0, 2, 2},
                                {1, 0, 0}, {1, 0, 1}, {1, 0, 2}, {1, 1, 1}, {1, 1, 2}, {1, 2, 2},
                                {2, 0, 0}, {2, 0, 1}, {2, 0, 2}, {2, 1, 1}, {2, 1, 2}, {2, 2, 2}};
constexpr double kInf = std::numeric_limits<double>::infinity();

Mat3 cross_matrix(const Vec3& d) {
  Mat3 m;
  m << 0, -d.z(), d.y(), d.z(), 0, -d.x(), -d.y(), d.x(), 0;
  return m;
}

}  // namespace

EdgeJet::EdgeJet(const Cage& cage) {
  x_.resize(cage.num_vertices());
  for (int v = 0; v < cage.num_vertices(); ++v) x_[v] = cage.V.row(v).transpose();
  faces_.resize(cage.num_faces());
  for (int t = 0; t < cage.num_faces(); ++t) faces_[t] = {cage.F(t, 0), cage.F(t, 1), cage.F(t, 2)};
  // HarmonicBasis's half-edge opposite local vertex k of a face runs u → w with u = (k+2)%3, w = (k+1)%3.
  auto orientation = [&](int t, int k, int v0, int v1) {
    const int u = faces_[t][(k + 2) % 3], w = faces_[t][(k + 1) % 3];
    if (u == v0 && w == v1) return 1;
    if (u == v1 && w == v0) return -1;
    throw Error("EdgeJet: cage edge does not match its face");
  };
  for (const CageEdge& e : cage.edges) {
    EdgeConst c;
    c.v0 = e.v0;
    c.v1 = e.v1;
    c.f0 = e.f0;
    c.f1 = e.f1;
    c.k0 = e.lv0;
    c.k1 = e.lv1;
    c.s0 = orientation(e.f0, e.lv0, e.v0, e.v1);
    c.s1 = orientation(e.f1, e.lv1, e.v0, e.v1);
    const Vec3 dv = x_[e.v1] - x_[e.v0];
    c.d = dv.norm();
    c.dhat = dv / c.d;
    edges_.push_back(c);
  }
  face_edges_.assign(faces_.size(), {-1, -1, -1});
  auto add_edge = [&](int t, int e) {
    for (int& slot : face_edges_[t])
      if (slot < 0) {
        slot = e;
        return;
      }
    throw Error("EdgeJet: a face with more than 3 edges");
  };
  for (size_t e = 0; e < edges_.size(); ++e) {
    add_edge(edges_[e].f0, static_cast<int>(e));
    add_edge(edges_[e].f1, static_cast<int>(e));
  }
  face_center_.resize(faces_.size());
  face_radius_.resize(faces_.size());
  for (size_t t = 0; t < faces_.size(); ++t) {
    const Vec3 g = (x_[faces_[t][0]] + x_[faces_[t][1]] + x_[faces_[t][2]]) / 3.0;
    double R = 0;
    for (int k = 0; k < 3; ++k) R = std::max(R, (x_[faces_[t][k]] - g).norm());
    face_center_[t] = g;
    // Rounded up by a relative 1e-12 (and the centroid's rounding): the sphere must contain the face.
    face_radius_[t] = R * (1 + 1e-12) + 1e-15 * g.norm();
  }
}

void EdgeJet::faces_near(const Vec3& c, double radius, const std::vector<int>* candidates,
                         std::vector<int>& out) const {
  out.clear();
  auto near = [&](int t) { return (face_center_[t] - c).norm() - face_radius_[t] <= radius; };
  if (candidates) {
    for (int t : *candidates)
      if (near(t)) out.push_back(t);
  } else {
    for (int t = 0; t < static_cast<int>(faces_.size()); ++t)
      if (near(t)) out.push_back(t);
  }
}

void EdgeJet::make_patch(const HarmonicBasis::FaceMatrices& fm, const std::vector<int>& faces,
                         Patch& out) const {
  // Marks, reset before returning: local vertex index, and whether a face lies in S.
  thread_local std::vector<int> vmap;
  thread_local std::vector<char> in_s, edge_seen;
  if (vmap.size() != x_.size()) vmap.assign(x_.size(), -1);
  if (in_s.size() != faces_.size()) in_s.assign(faces_.size(), 0);
  if (edge_seen.size() != edges_.size()) edge_seen.assign(edges_.size(), 0);
  out.x.clear();
  out.faces.clear();
  out.md.A.clear();
  out.md.scale_A.clear();
  out.md.edges.clear();
  for (int t : faces) in_s[t] = 1;
  auto local = [&](int v) {
    if (vmap[v] < 0) {
      vmap[v] = static_cast<int>(out.x.size());
      out.x.push_back(x_[v]);
    }
    return vmap[v];
  };
  for (int t : faces) {
    out.faces.push_back({local(faces_[t][0]), local(faces_[t][1]), local(faces_[t][2])});
    out.md.A.push_back(fm.A[t]);
    out.md.scale_A.push_back(face_scale(fm, t));
  }
  for (int t : faces)
    for (int e : face_edges_[t]) {
      if (edge_seen[e]) continue;
      edge_seen[e] = 1;
      const EdgeConst& c = edges_[e];
      MapData::Edge me;
      if (!edge_terms(fm, c, in_s[c.f0] != 0, in_s[c.f1] != 0, me)) continue;
      me.v0 = local(c.v0);
      me.v1 = local(c.v1);
      out.md.edges.push_back(me);
    }
  // Reset only what was touched (a patch is small; the marks span the cage).
  for (int t : faces) {
    in_s[t] = 0;
    for (int k = 0; k < 3; ++k) vmap[faces_[t][k]] = -1;
    for (int e : face_edges_[t]) edge_seen[e] = 0;
  }
}

double EdgeJet::face_scale(const HarmonicBasis::FaceMatrices& fm, int t) {
  return std::max(fm.A[t].cwiseAbs().sum(), fm.A_abs[t]);
}

bool EdgeJet::edge_terms(const HarmonicBasis::FaceMatrices& fm, const EdgeConst& c, bool in0, bool in1,
                         MapData::Edge& e) {
  // ‖δ_e‖: for both faces ‖A_f0 − A_f1‖ (= ‖s0 A_f0 + s1 A_f1‖, s0 = −s1 on an oriented cage), for one ‖A_t‖.
  e.norm = in0 && in1 ? (fm.A[c.f0] - fm.A[c.f1]).norm()
           : in0      ? fm.A[c.f0].norm()
           : in1      ? fm.A[c.f1].norm()
                      : 0.0;
  if (e.norm == 0) return false;  // no contribution to J, H or the bounds (as in the per-face code)
  e.delta = Mat3::Zero();
  if (in0) e.delta += c.s0 * fm.A[c.f0];
  if (in1) e.delta += c.s1 * fm.A[c.f1];
  e.delta_x = e.delta * cross_matrix(c.dhat);
  // The same rounding magnitudes the per-face evaluation adds for the half-edges.
  e.scale_a = (in0 ? face_scale(fm, c.f0) : 0.0) + (in1 ? face_scale(fm, c.f1) : 0.0);
  e.scale_ad = (in0 ? std::max(fm.AD[c.f0][c.k0].cwiseAbs().sum(), 2.0 * fm.A_abs[c.f0]) : 0.0) +
               (in1 ? std::max(fm.AD[c.f1][c.k1].cwiseAbs().sum(), 2.0 * fm.A_abs[c.f1]) : 0.0);
  e.v0 = c.v0;
  e.v1 = c.v1;
  e.d = c.d;
  return true;
}

EdgeJet::MapData EdgeJet::prepare(const HarmonicBasis::FaceMatrices& fm) const {
  MapData md;
  const size_t nf = faces_.size();
  md.A = fm.A;
  md.scale_A.resize(nf);
  for (size_t t = 0; t < nf; ++t) md.scale_A[t] = face_scale(fm, static_cast<int>(t));
  for (const EdgeConst& c : edges_) {
    MapData::Edge e;
    if (edge_terms(fm, c, true, true, e)) md.edges.push_back(e);
  }
  return md;
}

// One pass: vertex distances, face solid angles, then per edge C_e, α_e, β_e and the distances of both
// bounds.
void EdgeJet::evaluate(const MapData& md, const Vec3& p, double r, bool hessian, bool want_first,
                       bool want_third, Values& out) const {
  evaluate_view(whole(), md, p, r, hessian, want_first, want_third, out);
}

void EdgeJet::evaluate(const Patch& s, const Vec3& p, double r, bool hessian, bool want_first,
                       bool want_third, Values& out) const {
  evaluate_view(view_of(s), s.md, p, r, hessian, want_first, want_third, out);
}

void EdgeJet::evaluate_view(const View& g, const MapData& md, const Vec3& p, double r, bool hessian,
                            bool want_first, bool want_third, Values& out) const {
  const size_t nv = g.nv, nf = g.nf;
  thread_local std::vector<Vec3> l;
  thread_local std::vector<double> L;
  l.resize(nv);
  L.resize(nv);
  for (size_t v = 0; v < nv; ++v) {
    l[v] = g.x[v] - p;
    L[v] = l[v].norm();
  }
  Mat3 J = Mat3::Zero();
  double sJ = 0, sH = 0, T1 = 0, T3 = 0;
  // Signed solid angle / 4π of each face (van Oosterom & Strackee, as HarmonicBasis::face_at_point).
  for (size_t t = 0; t < nf; ++t) {
    const auto& f = g.faces[t];
    const Vec3 &l0 = l[f[0]], &l1 = l[f[1]], &l2 = l[f[2]];
    const double L0 = L[f[0]], L1 = L[f[1]], L2 = L[f[2]];
    const double triple = l0.dot(l1.cross(l2));
    const double den = L0 * L1 * L2 + l0.dot(l1) * L2 + l1.dot(l2) * L0 + l2.dot(l0) * L1;
    const double omega = std::atan2(triple, den) * (2.0 * kInv4Pi);
    J.noalias() += omega * md.A[t];
    sJ += std::abs(omega) * md.scale_A[t];
  }
  std::array<Mat3, 3> H{Mat3::Zero(), Mat3::Zero(), Mat3::Zero()};
  for (const MapData::Edge& e : md.edges) {
    const Vec3 &lu = l[e.v0], &lw = l[e.v1];
    const double Lu = L[e.v0], Lw = L[e.v1], d = e.d;
    const double m = Lu + Lw;
    const double mdd = 2.0 * (Lu * Lw + lu.dot(lw));  // m² − d², cancellation-free
    const double C = kInv4Pi * std::log((m + d) * (m + d) / mdd);
    J.noalias() -= C * e.delta_x;
    sJ += std::abs(C) * e.scale_ad;
    const Vec3 luxlw = lu.cross(lw);
    if (hessian) {
      const Vec3 alpha = (m * kInv2Pi / (mdd * Lu * Lw)) * luxlw;
      const Vec3 beta = (d * kInv2Pi / mdd) * (lu / Lu + lw / Lw);
      // H[a](b, c) −= δ(a, b) α(c) + (δ[d̂]×)(a, b) β(c), written out so that it stays in registers.
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          const double da = e.delta(a, b), dx = e.delta_x(a, b);
          for (int c = 0; c < 3; ++c) H[a](b, c) -= da * alpha(c) + dx * beta(c);
        }
      sH += e.scale_a * alpha.cwiseAbs().sum() + e.scale_ad * beta.cwiseAbs().sum();
    }
    if (want_first || want_third) {
      // edge_sum_lower_bound with |p−u|, |p−w| and dist(p, line uw) = |l_u × l_w| / d from this pass.
      const double a = Lu - r, b = Lw - r;
      const double rho = std::max(0.0, luxlw.norm() / d - r);
      const double h =
          std::max(std::max(a, 0.0) + std::max(b, 0.0), 2.0 * std::sqrt(rho * rho + 0.25 * d * d));
      const bool finite = h > d && a > 0 && b > 0;
      if (want_first) T1 += finite ? e.norm * first_order_factor(h, d) : kInf;
      if (want_third) T3 += finite ? e.norm * third_order_factor(h, d, a, b) : kInf;
    }
  }
  out.J = J;
  out.H = H;
  out.scale_J = sJ;
  out.scale_H = sH;
  out.T_first = T1;
  out.T_third = T3;
}

// The batched pass: arrays [row][lane] of kLanes doubles, every loop over the lanes a `#pragma omp simd` loop
// (2 AVX2 registers per row). Same formulas as evaluate(), with these changes, each within a few rounding
// units of the term it replaces (docs/certificate.md, Step 4c): lane_atan2 / lane_log_ratio for std::atan2 /
// std::log((m+d)²/(m²−d²)); α and β from 1/(m²−d²) and the per-vertex 1/|l| (one division per edge);
// dist(p, line uw) = |l_u × l_w| · (1/d); the third-order factor as sqrt(n² + 2.5h²d²)/(π n (h²−d²)) and,
// with both bounds, the first-order one from the same reciprocal. Returns false when an argument leaves the
// domain of lane_math (a point on a face's plane inside it, or at a vertex): the caller then evaluates the
// points one by one.
template <bool kHessian, bool kFirst, bool kThird>
bool EdgeJet::lanes(const View& g, const MapData& md, const double* px, const double* py, const double* pz,
                    const double* r, Values* out, int n) {
  using namespace lane_math;
  constexpr int W = kLanes;
  const size_t nv = g.nv, nf = g.nf;
  // Per vertex 5 rows: l = x_v − p (3), |l|, 1/|l|.
  thread_local std::vector<double> vbuf;
  vbuf.resize(nv * 5 * W);
  double* const vb = vbuf.data();
  for (size_t v = 0; v < nv; ++v) {
    double* b = vb + v * 5 * W;
    const double x0 = g.x[v].x(), x1 = g.x[v].y(), x2 = g.x[v].z();
#pragma omp simd
    for (int k = 0; k < W; ++k) {
      const double lx = x0 - px[k], ly = x1 - py[k], lz = x2 - pz[k];
      const double L = std::sqrt(lx * lx + ly * ly + lz * lz);
      b[k] = lx;
      b[W + k] = ly;
      b[2 * W + k] = lz;
      b[3 * W + k] = L;
      b[4 * W + k] = 1.0 / L;
    }
  }
  alignas(64) double J[9][W] = {}, sJ[W] = {};
  alignas(64) double omega[W];
  for (size_t t = 0; t < nf; ++t) {
    const double* b0 = vb + g.faces[t][0] * 5 * W;
    const double* b1 = vb + g.faces[t][1] * 5 * W;
    const double* b2 = vb + g.faces[t][2] * 5 * W;
    int bad = 0;
#pragma omp simd reduction(| : bad)
    for (int k = 0; k < W; ++k) {
      const double x0 = b0[k], y0 = b0[W + k], z0 = b0[2 * W + k], L0 = b0[3 * W + k];
      const double x1 = b1[k], y1 = b1[W + k], z1 = b1[2 * W + k], L1 = b1[3 * W + k];
      const double x2 = b2[k], y2 = b2[W + k], z2 = b2[2 * W + k], L2 = b2[3 * W + k];
      const double triple = x0 * (y1 * z2 - z1 * y2) + y0 * (z1 * x2 - x1 * z2) + z0 * (x1 * y2 - y1 * x2);
      const double den = L0 * L1 * L2 + (x0 * x1 + y0 * y1 + z0 * z1) * L2 +
                         (x1 * x2 + y1 * y2 + z1 * z2) * L0 + (x2 * x0 + y2 * y0 + z2 * z0) * L1;
      bad |= !atan2_in_domain(triple, den);
      omega[k] = lane_math::lane_atan2(triple, den) * kInv2Pi;
    }
    if (bad) return false;
    const double* A = md.A[t].data();  // column-major, as J
    const double sa = md.scale_A[t];
#pragma omp simd
    for (int k = 0; k < W; ++k) {
      for (int i = 0; i < 9; ++i) J[i][k] += omega[k] * A[i];
      sJ[k] += std::abs(omega[k]) * sa;
    }
  }
  // H is symmetric in (b, c) (a Hessian), so only b ≤ c is summed: H[j][lane] = H[a](b, c) = H[a](c, b) for
  // the j-th (a, b, c) of kSymIdx (i = 3b + a: δ's column-major index).
  alignas(64) double H[kHessian ? 18 : 1][W] = {}, sH[W] = {}, T1[W] = {}, T3[W] = {};
  for (const MapData::Edge& e : md.edges) {
    const double* bu = vb + e.v0 * 5 * W;
    const double* bw = vb + e.v1 * 5 * W;
    const double d = e.d, inv_d = 1.0 / e.d, d2 = e.d * e.d;
    const double* D = e.delta.data();
    const double* DX = e.delta_x.data();
    const double sa = e.scale_a, sad = e.scale_ad, wn = e.norm;
    int bad = 0;
#pragma omp simd reduction(| : bad)
    for (int k = 0; k < W; ++k) {
      const double ux = bu[k], uy = bu[W + k], uz = bu[2 * W + k], Lu = bu[3 * W + k], iu = bu[4 * W + k];
      const double wx = bw[k], wy = bw[W + k], wz = bw[2 * W + k], Lw = bw[3 * W + k], iw = bw[4 * W + k];
      const double m = Lu + Lw;
      const double mdd = 2.0 * (Lu * Lw + (ux * wx + uy * wy + uz * wz));  // m² − d², cancellation-free
      const double mpd = m + d;
      bad |= !log_ratio_in_domain(mpd * mpd, mdd);
      const double C = kInv4Pi * lane_log_ratio(mpd * mpd, mdd);
      for (int i = 0; i < 9; ++i) J[i][k] -= C * DX[i];
      sJ[k] += std::abs(C) * sad;
      const double cx = uy * wz - uz * wy, cy = uz * wx - ux * wz, cz = ux * wy - uy * wx;  // l_u × l_w
      if constexpr (kHessian) {
        const double imdd = 1.0 / mdd;
        const double ca = m * kInv2Pi * imdd * (iu * iw), cb = d * kInv2Pi * imdd;
        const double ax = ca * cx, ay = ca * cy, az = ca * cz;
        const double bx = cb * (ux * iu + wx * iw), by = cb * (uy * iu + wy * iw),
                     bz = cb * (uz * iu + wz * iw);
        // Written out (kSymIdx order) so that every index is a constant and the loop vectorizes.
        for (int a2 = 0; a2 < 3; ++a2) {
          double* Ha = &H[6 * a2][0];
          const double g0 = D[a2], g1 = D[3 + a2], g2 = D[6 + a2];     // δ(a, b), b = 0, 1, 2
          const double h0 = DX[a2], h1 = DX[3 + a2], h2 = DX[6 + a2];  // (δ[d̂]×)(a, b)
          Ha[0 * W + k] -= g0 * ax + h0 * bx;                          // (b, c) = (0, 0)
          Ha[1 * W + k] -= g0 * ay + h0 * by;                          // (0, 1)
          Ha[2 * W + k] -= g0 * az + h0 * bz;                          // (0, 2)
          Ha[3 * W + k] -= g1 * ay + h1 * by;                          // (1, 1)
          Ha[4 * W + k] -= g1 * az + h1 * bz;                          // (1, 2)
          Ha[5 * W + k] -= g2 * az + h2 * bz;                          // (2, 2)
        }
        sH[k] += sa * (std::abs(ax) + std::abs(ay) + std::abs(az)) +
                 sad * (std::abs(bx) + std::abs(by) + std::abs(bz));
      }
      if constexpr (kFirst || kThird) {
        const double rk = r[k];
        const double a = Lu - rk, b = Lw - rk;
        const double rho0 = std::sqrt(cx * cx + cy * cy + cz * cz) * inv_d - rk;
        const double rho = rho0 > 0 ? rho0 : 0.0;
        const double s1 = (a > 0 ? a : 0.0) + (b > 0 ? b : 0.0);
        const double s2 = 2.0 * std::sqrt(rho * rho + 0.25 * d2);
        const double h = s1 > s2 ? s1 : s2;
        const bool finite = h > d && a > 0 && b > 0;
        const double md2 = h * h - d2;
        if constexpr (kThird) {
          const double ab = a * b;
          const double inv = 1.0 / (ab * md2);
          const double f3 = std::sqrt(ab * ab + 2.5 * (h * h * d2)) * inv * kInvPi;
          T3[k] += finite ? wn * f3 : kInf;
          if constexpr (kFirst) {
            const double f1 = std::sqrt(h * h + 4.0 * d2) * (ab * inv) * (0.5 * kInvPi);
            T1[k] += finite ? wn * f1 : kInf;
          }
        } else {
          const double f1 = std::sqrt(h * h + 4.0 * d2) / (2.0 * M_PI * md2);
          T1[k] += finite ? wn * f1 : kInf;
        }
      }
    }
    if (bad) return false;
  }
  for (int k = 0; k < n; ++k) {
    Values& o = out[k];
    for (int i = 0; i < 9; ++i) o.J.data()[i] = J[i][k];
    o.scale_J = sJ[k];
    for (int a = 0; a < 3; ++a) o.H[a].setZero();
    if constexpr (kHessian)
      for (int j = 0; j < 18; ++j) {
        const int a = kSymIdx[j][0], b = kSymIdx[j][1], c = kSymIdx[j][2];
        o.H[a](b, c) = o.H[a](c, b) = H[j][k];
      }
    o.scale_H = sH[k];
    o.T_first = kFirst ? T1[k] : 0.0;
    o.T_third = kThird ? T3[k] : 0.0;
  }
  return true;
}

void EdgeJet::evaluate_lanes(const MapData& md, const Vec3* p, const double* r, int n, bool hessian,
                             bool want_first, bool want_third, Values* out) const {
  evaluate_lanes_view(whole(), md, p, r, n, hessian, want_first, want_third, out);
}

void EdgeJet::evaluate_lanes(const Patch& s, const Vec3* p, const double* r, int n, bool hessian,
                             bool want_first, bool want_third, Values* out) const {
  evaluate_lanes_view(view_of(s), s.md, p, r, n, hessian, want_first, want_third, out);
}

void EdgeJet::evaluate_lanes_view(const View& g, const MapData& md, const Vec3* p, const double* r, int n,
                                  bool hessian, bool want_first, bool want_third, Values* out) const {
  if (n < 1 || n > kLanes) throw Error("EdgeJet::evaluate_lanes: 1 to " + std::to_string(kLanes) + " points");
  // Unused lanes repeat the last point (each lane's result depends on its own point only).
  alignas(64) double px[kLanes], py[kLanes], pz[kLanes], pr[kLanes];
  for (int k = 0; k < kLanes; ++k) {
    const int q = std::min(k, n - 1);
    px[k] = p[q].x();
    py[k] = p[q].y();
    pz[k] = p[q].z();
    pr[k] = r[q];
  }
  using Lanes = bool (*)(const View&, const MapData&, const double*, const double*, const double*,
                         const double*, Values*, int);
  static constexpr Lanes kByFlags[8] = {
      &EdgeJet::lanes<false, false, false>, &EdgeJet::lanes<false, false, true>,
      &EdgeJet::lanes<false, true, false>,  &EdgeJet::lanes<false, true, true>,
      &EdgeJet::lanes<true, false, false>,  &EdgeJet::lanes<true, false, true>,
      &EdgeJet::lanes<true, true, false>,   &EdgeJet::lanes<true, true, true>};
  const bool ok = kByFlags[(hessian ? 4 : 0) + (want_first ? 2 : 0) + (want_third ? 1 : 0)](g, md, px, py, pz,
                                                                                            pr, out, n);
  if (!ok)
    for (int k = 0; k < n; ++k) evaluate_view(g, md, p[k], r[k], hessian, want_first, want_third, out[k]);
}

}  // namespace lidef
