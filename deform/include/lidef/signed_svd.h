// Signed singular value decomposition of a 3x3 Jacobian (paper App. B): J = U diag(σ) Vᵀ with U, V
// rotations and σ1 ≥ σ2 ≥ |σ3|, σ3 < 0 exactly when det J < 0.
#pragma once
#include "lidef/types.h"

namespace lidef {

struct SignedSvd {
  Mat3 U, V;   // rotations (det = +1)
  Vec3 sigma;  // σ1 ≥ σ2 ≥ |σ3|
};

SignedSvd signed_svd(const Mat3& J);

// Only the signed singular values (cheaper entry point for the certificate and reports).
Vec3 signed_singular_values(const Mat3& J);

}  // namespace lidef
