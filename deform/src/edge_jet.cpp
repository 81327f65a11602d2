#include "lidef/edge_jet.h"

#include <cmath>
#include <limits>

#include "lidef/errors.h"
#include "lidef/lipschitz_bound.h"

namespace lidef {
namespace {

constexpr double kInv4Pi = 1.0 / (4.0 * M_PI);
constexpr double kInv2Pi = 1.0 / (2.0 * M_PI);
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
}

EdgeJet::MapData EdgeJet::prepare(const HarmonicBasis::FaceMatrices& fm) const {
  MapData md;
  const size_t nf = faces_.size();
  md.A = fm.A;
  md.scale_A.resize(nf);
  for (size_t t = 0; t < nf; ++t) md.scale_A[t] = std::max(fm.A[t].cwiseAbs().sum(), fm.A_abs[t]);
  for (const EdgeConst& c : edges_) {
    MapData::Edge e;
    e.norm = (fm.A[c.f0] - fm.A[c.f1]).norm();
    if (e.norm == 0) continue;  // no contribution to J, H or the bounds (as in the per-face code)
    e.delta = c.s0 * fm.A[c.f0] + c.s1 * fm.A[c.f1];
    e.delta_x = e.delta * cross_matrix(c.dhat);
    // The same rounding magnitudes the per-face evaluation adds for the two half-edges.
    e.scale_a = md.scale_A[c.f0] + md.scale_A[c.f1];
    e.scale_ad = std::max(fm.AD[c.f0][c.k0].cwiseAbs().sum(), 2.0 * fm.A_abs[c.f0]) +
                 std::max(fm.AD[c.f1][c.k1].cwiseAbs().sum(), 2.0 * fm.A_abs[c.f1]);
    e.v0 = c.v0;
    e.v1 = c.v1;
    e.d = c.d;
    md.edges.push_back(e);
  }
  return md;
}

// One pass: vertex distances, face solid angles, then per edge C_e, α_e, β_e and the distances of both
// bounds.
void EdgeJet::evaluate(const MapData& md, const Vec3& p, double r, bool hessian, bool want_first,
                       bool want_third, Values& out) const {
  const size_t nv = x_.size(), nf = faces_.size();
  thread_local std::vector<Vec3> l;
  thread_local std::vector<double> L;
  l.resize(nv);
  L.resize(nv);
  for (size_t v = 0; v < nv; ++v) {
    l[v] = x_[v] - p;
    L[v] = l[v].norm();
  }
  Mat3 J = Mat3::Zero();
  double sJ = 0, sH = 0, T1 = 0, T3 = 0;
  // Signed solid angle / 4π of each face (van Oosterom & Strackee, as HarmonicBasis::face_at_point).
  for (size_t t = 0; t < nf; ++t) {
    const auto& f = faces_[t];
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

}  // namespace lidef
