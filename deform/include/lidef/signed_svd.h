// Signed singular value decomposition of a 3x3 Jacobian (paper App. B): J = U diag(σ) Vᵀ with U, V
// rotations and σ1 ≥ σ2 ≥ |σ3|, σ3 < 0 exactly when det J < 0.
//
// The sign of σ3 is the sign of det J, taken from an error-bounded determinant (det_sign): the cofactor
// determinant fl(det J) is trusted only when |fl(det J)| exceeds a rigorous bound on its rounding error
// (docs/certificate.md, "Step 5"). When it does not, the sign is *unresolved* and σ3 is reported as 0: its
// magnitude is then below what rounding can resolve anyway (|det J| = σ1 σ2 |σ3| is within twice the bound
// of 0).
// When det J = 0 exactly (every term of the expansion has a zero factor), σ3 is 0 as well, and resolved.
// Every case whose sign is resolved and nonzero is bit-identical to taking the sign of J.determinant().
#pragma once
#include "lidef/types.h"

namespace lidef {

// fl(det J) by cofactor expansion along the first row, in the evaluation order of Eigen's 3x3
// determinant, with a bound on its rounding error: |fl(det J) − det J| ≤ bound (round to nearest, gradual
// underflow; fused multiply-adds only lower the error).
struct DetSign {
  int sign = 0;           // +1 / −1: the sign of the exact det J; 0: det J = 0 exactly, or unresolved
  bool resolved = false;  // sign proven (±1), or det J = 0 exactly
  double det = 0;         // fl(det J)
  double bound = 0;       // |fl(det J) − det J| ≤ bound (+∞ when an entry or the result is not finite)
};
DetSign det_sign_bounded(const Mat3& J);

// +1 or −1 when the sign of the exact det J is proven in double precision, 0 otherwise ("unresolved",
// which includes det J = 0 exactly).
int det_sign(const Mat3& J);

struct SignedSvd {
  Mat3 U, V;   // rotations (det = +1)
  Vec3 sigma;  // σ1 ≥ σ2 ≥ |σ3|; σ3 = 0 when the sign of det J is unresolved (see above)
};

SignedSvd signed_svd(const Mat3& J);

// Only the signed singular values (cheaper entry point for the certificate and reports). `sign_resolved`
// (optional) tells whether the sign of det J was resolved; when it is false, σ3 is reported as 0.
Vec3 signed_singular_values(const Mat3& J, bool* sign_resolved = nullptr);

}  // namespace lidef
