// Singular values of 3x3 Jacobians by one-sided (Hestenes) Jacobi, several matrices in SIMD lanes: the
// certificate's σ1 and σ3 at every base center (tens of thousands of Jacobians per certificate) cost about a
// quarter of Eigen's JacobiSVD this way (docs/certificate.md, Step 5, "The singular values").
//
// Each lane's arithmetic is that lane's alone (a converged lane only takes exact identity rotations while the
// others converge), and the source is compiled without floating-point contraction, so a matrix's singular
// values do not depend on the lane, the other lanes, their number or the thread that computes them.
#pragma once
#include "lidef/types.h"

namespace lidef {

constexpr int kSvdLanes = 8;

// out[k] = (σ1, σ2, σ3) of J[k], σ1 ≥ σ2 ≥ σ3 ≥ 0, for k < n ≤ kSvdLanes (unsigned: signed_singular_values
// takes σ3's sign from the error-bounded determinant). A matrix with an entry that is not finite gives values
// that are not finite or 0 (its determinant's sign is then unresolved, and σ3 is reported as 0).
void jacobi_singular_values(const Mat3* J, int n, Vec3* out);

// signed_singular_values (signed_svd.h) of J[k] for k < n ≤ kSvdLanes; resolved[k] as its sign_resolved.
void signed_singular_values_lanes(const Mat3* J, int n, Vec3* out, bool* resolved);

}  // namespace lidef
