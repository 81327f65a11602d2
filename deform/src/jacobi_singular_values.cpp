#include "lidef/internal/jacobi_singular_values.h"

#include <algorithm>
#include <cmath>

namespace lidef {
namespace {

// W lanes of one-sided Jacobi: the columns of A = J V are made orthogonal by plane rotations (V is not
// formed); their norms are then the singular values. Stopping rule per pair |a_pᵀa_q| ≤ 10⁻¹⁵ ‖a_p‖‖a_q‖: AᵀA
// is then D^½ (I + F) D^½ with |F_pq| ≤ 10⁻¹⁵, whose eigenvalues are those of D to within a relative 2·10⁻¹⁵
// (Ostrowski), so each σ is its column's norm to that relative accuracy plus the rotations' rounding
// (docs/certificate.md, Step 5). Each J is first scaled by a power of two (exact) so that its largest entry
// lies in [½, 1): the squared norms neither overflow nor underflow.
template <int W>
void jacobi_lanes(const Mat3* J, Vec3* out) {
  double A[9][W], scale[W];
  for (int l = 0; l < W; ++l) {
    const double m = J[l].cwiseAbs().maxCoeff();
    int e = 0;
    if (m > 0 && std::isfinite(m)) std::frexp(m, &e);
    scale[l] = std::ldexp(1.0, e);
    const double inv = std::ldexp(1.0, -e);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) A[3 * r + c][l] = J[l](r, c) * inv;
  }
  // At most 40 sweeps (the iteration converges quadratically); a matrix with NaN never rotates.
  for (int sweep = 0; sweep < 40; ++sweep) {
    bool rotated = false;
    for (int pair = 0; pair < 3; ++pair) {
      const int p = pair == 2 ? 1 : 0, q = pair == 0 ? 1 : 2;
      double c[W], s[W];
      bool rot[W];
#pragma omp simd
      for (int l = 0; l < W; ++l) {
        const double al = A[p][l] * A[p][l] + A[3 + p][l] * A[3 + p][l] + A[6 + p][l] * A[6 + p][l];
        const double be = A[q][l] * A[q][l] + A[3 + q][l] * A[3 + q][l] + A[6 + q][l] * A[6 + q][l];
        const double ga = A[p][l] * A[q][l] + A[3 + p][l] * A[3 + q][l] + A[6 + p][l] * A[6 + q][l];
        const bool r = std::abs(ga) > 1e-15 * std::sqrt(al * be);
        // The rotation that zeroes a_pᵀa_q (the smaller of the two angles); a lane that needs none takes
        // t = 0, i.e. c = 1, s = 0: an exact identity.
        const double zeta = (be - al) / (r ? 2.0 * ga : 1.0);
        const double t = r ? (zeta >= 0 ? 1.0 : -1.0) / (std::abs(zeta) + std::sqrt(1.0 + zeta * zeta)) : 0.0;
        c[l] = 1.0 / std::sqrt(1.0 + t * t);
        s[l] = c[l] * t;
        rot[l] = r;
      }
      for (int l = 0; l < W; ++l) rotated = rotated || rot[l];
#pragma omp simd
      for (int l = 0; l < W; ++l)
        for (int i = 0; i < 3; ++i) {
          const double ap = A[3 * i + p][l], aq = A[3 * i + q][l];
          A[3 * i + p][l] = c[l] * ap - s[l] * aq;
          A[3 * i + q][l] = s[l] * ap + c[l] * aq;
        }
    }
    if (!rotated) break;
  }
  for (int l = 0; l < W; ++l) {
    double n[3];
    for (int j = 0; j < 3; ++j)
      n[j] = std::sqrt(A[j][l] * A[j][l] + A[3 + j][l] * A[3 + j][l] + A[6 + j][l] * A[6 + j][l]);
    if (n[0] < n[1]) std::swap(n[0], n[1]);
    if (n[1] < n[2]) std::swap(n[1], n[2]);
    if (n[0] < n[1]) std::swap(n[0], n[1]);
    out[l] = Vec3(n[0], n[1], n[2]) * scale[l];
  }
}

}  // namespace

void jacobi_singular_values(const Mat3* J, int n, Vec3* out) {
  if (n <= 0) return;
  if (n == 1) return jacobi_lanes<1>(J, out);
  Mat3 Jl[kSvdLanes];
  Vec3 o[kSvdLanes];
  for (int l = 0; l < kSvdLanes; ++l) Jl[l] = l < n ? J[l] : Mat3::Zero();
  jacobi_lanes<kSvdLanes>(Jl, o);
  std::copy(o, o + std::min(n, kSvdLanes), out);
}

}  // namespace lidef
