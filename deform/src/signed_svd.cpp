#include "lidef/signed_svd.h"

#include <Eigen/SVD>
#include <cmath>
#include <limits>

#include "lidef/internal/jacobi_singular_values.h"

namespace lidef {

// The bound (docs/certificate.md, "Step 5"): each of the 6 Leibniz products J0j·J1a·J2b reaches fl(det)
// through at most 5 roundings (2 in the minor, 1 in the outer product, 2 in the outer sum), so
//   |fl(det) − det| ≤ γ5 · P,   P = Σ_j |J0j| (|J1a J2b| + |J1b J2a|),   γ5 = 5u/(1 − 5u),  u = 2⁻⁵³,
// and P ≤ fl(P)/(1 − γ5). We take 2⁻⁵⁰ · fl(P) = 8u · fl(P) ≥ γ5/(1 − γ5) · fl(P) (exact: a power of two),
// plus 2⁻¹⁰⁷⁰ · (Σ_j |J0j| + 2) for the absolute error (≤ 2⁻¹⁰⁷⁵ each) of products that underflow.
DetSign det_sign_bounded(const Mat3& J) {
  DetSign out;
  const double m0 = J(1, 1) * J(2, 2) - J(1, 2) * J(2, 1);
  const double m1 = J(1, 0) * J(2, 2) - J(1, 2) * J(2, 0);
  const double m2 = J(1, 0) * J(2, 1) - J(1, 1) * J(2, 0);
  out.det = J(0, 0) * m0 - J(0, 1) * m1 + J(0, 2) * m2;
  const Mat3 A = J.cwiseAbs();
  const double P = A(0, 0) * (A(1, 1) * A(2, 2) + A(1, 2) * A(2, 1)) +
                   A(0, 1) * (A(1, 0) * A(2, 2) + A(1, 2) * A(2, 0)) +
                   A(0, 2) * (A(1, 0) * A(2, 1) + A(1, 1) * A(2, 0));
  out.bound = 0x1p-50 * P + 0x1p-1070 * (A(0, 0) + A(0, 1) + A(0, 2) + 2.0);
  if (!std::isfinite(out.det) || !std::isfinite(out.bound)) {
    out.bound = std::numeric_limits<double>::infinity();
    return out;
  }
  if (std::abs(out.det) > out.bound) {
    out.sign = out.det > 0 ? 1 : -1;
    out.resolved = true;
    return out;
  }
  // det J = 0 exactly when each of the 6 Leibniz products has a zero factor.
  auto zero2 = [&](int a, int b) { return J(1, a) == 0 || J(2, b) == 0; };
  const bool t0 = J(0, 0) == 0 || (zero2(1, 2) && zero2(2, 1));
  const bool t1 = J(0, 1) == 0 || (zero2(0, 2) && zero2(2, 0));
  const bool t2 = J(0, 2) == 0 || (zero2(0, 1) && zero2(1, 0));
  out.resolved = t0 && t1 && t2;
  return out;
}

int det_sign(const Mat3& J) {
  return det_sign_bounded(J).sign;
}

SignedSvd signed_svd(const Mat3& J) {
  Eigen::JacobiSVD<Mat3> svd(J, Eigen::ComputeFullU | Eigen::ComputeFullV);
  SignedSvd out{svd.matrixU(), svd.matrixV(), svd.singularValues()};
  // Make U and V rotations; each reflection removed flips the sign of the smallest singular value.
  if (out.U.determinant() < 0) {
    out.U.col(2) *= -1;
    out.sigma(2) *= -1;
  }
  if (out.V.determinant() < 0) {
    out.V.col(2) *= -1;
    out.sigma(2) *= -1;
  }
  // det J = σ1 σ2 σ3, so σ3 must carry the proven sign of det J. When that sign is not proven (or det J = 0
  // exactly), σ3 is reported as 0. When the reflections above disagree with a proven sign, the computed |σ3|
  // is below the SVD's own accuracy (~u σ1; e.g. subnormal entries): its sign is flipped, which moves the
  // reconstruction by 2|σ3|, within that accuracy. Otherwise (every usual case) nothing changes.
  const int s = det_sign(J);
  if (s == 0)
    out.sigma(2) = 0;
  else if (out.sigma(2) != 0 && (out.sigma(2) < 0) != (s < 0))
    out.sigma(2) = -out.sigma(2);
  return out;
}

namespace {
// σ3 takes the proven sign of det J (0 when unresolved or det J = 0 exactly).
void apply_det_sign(const Mat3& J, Vec3& s, bool* sign_resolved) {
  const DetSign d = det_sign_bounded(J);
  if (sign_resolved) *sign_resolved = d.resolved;
  if (d.sign == 0)
    s(2) = 0;
  else if (d.sign < 0)
    s(2) = -s(2);
}
}  // namespace

Vec3 signed_singular_values(const Mat3& J, bool* sign_resolved) {
  Vec3 s;
  jacobi_singular_values(&J, 1, &s);
  apply_det_sign(J, s, sign_resolved);
  return s;
}

void signed_singular_values_lanes(const Mat3* J, int n, Vec3* out, bool* resolved) {
  jacobi_singular_values(J, n, out);
  for (int k = 0; k < n; ++k) apply_det_sign(J[k], out[k], resolved + k);
}

}  // namespace lidef
