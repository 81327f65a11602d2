// The symmetric Dirichlet energy's per-sample quantities (symmetric_dirichlet.h) for four samples at a time,
// one per SIMD lane: the energy passes over every sample (value, gradient, curvature along a direction) read
// their Jacobians from the JT layout (3|I| by 3, column-major: J_i(a, b) = JT(3i + b, a)) and spend more time
// on the 3x3 algebra than on the reads. The formulas are the closed forms of symmetric_dirichlet.h through
// the inverse A = J⁻¹ = cof(J)ᵀ / det J; they agree with sd_energy, sd_gradient and sd_hessian_times to
// rounding (tests/test_symmetric_dirichlet.cpp). Every lane's value depends on its own sample only.
#pragma once

#include <cmath>
#include <limits>

#include "lidef/internal/float_rows.h"

namespace lidef::sd_lanes {

using Lanes = V4d;                                       // one double per sample
using LaneMask = long __attribute__((vector_size(32)));  // all ones where a comparison holds
using Mat3Lanes = Lanes[3][3];                           // m[a][b]: entry (a, b) of four 3x3 matrices

inline Lanes splat(double v) {
  return Lanes{v, v, v, v};
}

// Samples first, first + 1, …, first + 3 of a JT-layout matrix with leading dimension ld; a sample index past
// last is read as last (the caller ignores those lanes).
inline void load(const double* JT, long ld, long first, long last, Mat3Lanes m) {
  long idx[4];
  for (int k = 0; k < 4; ++k) idx[k] = 3 * (first + k <= last ? first + k : last);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      const double* c = JT + a * ld + b;
      m[a][b] = Lanes{c[idx[0]], c[idx[1]], c[idx[2]], c[idx[3]]};
    }
}

// det J and A = J⁻¹ (A(a, b) = cof(J)(b, a) / det J).
inline Lanes inverse(const Mat3Lanes J, Mat3Lanes A) {
  const Lanes c00 = J[1][1] * J[2][2] - J[1][2] * J[2][1];
  const Lanes c01 = J[1][2] * J[2][0] - J[1][0] * J[2][2];
  const Lanes c02 = J[1][0] * J[2][1] - J[1][1] * J[2][0];
  const Lanes det = J[0][0] * c00 + J[0][1] * c01 + J[0][2] * c02;
  const Lanes r = splat(1.0) / det;
  A[0][0] = c00 * r;
  A[1][0] = c01 * r;
  A[2][0] = c02 * r;
  A[0][1] = (J[0][2] * J[2][1] - J[0][1] * J[2][2]) * r;
  A[1][1] = (J[0][0] * J[2][2] - J[0][2] * J[2][0]) * r;
  A[2][1] = (J[0][1] * J[2][0] - J[0][0] * J[2][1]) * r;
  A[0][2] = (J[0][1] * J[1][2] - J[0][2] * J[1][1]) * r;
  A[1][2] = (J[0][2] * J[1][0] - J[0][0] * J[1][2]) * r;
  A[2][2] = (J[0][0] * J[1][1] - J[0][1] * J[1][0]) * r;
  return det;
}

// P = X Y (tx: X transposed, ty: Y transposed).
template <bool tx = false, bool ty = false>
inline void product(const Mat3Lanes X, const Mat3Lanes Y, Mat3Lanes P) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const auto x = [&](int k) { return tx ? X[k][i] : X[i][k]; };
      const auto y = [&](int k) { return ty ? Y[j][k] : Y[k][j]; };
      P[i][j] = x(0) * y(0) + x(1) * y(1) + x(2) * y(2);
    }
}

inline Lanes squared_norm(const Mat3Lanes X) {
  Lanes s = splat(0.0);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) s += X[a][b] * X[a][b];
  return s;
}

inline Lanes dot(const Mat3Lanes X, const Mat3Lanes Y) {
  Lanes s = splat(0.0);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) s += X[a][b] * Y[a][b];
  return s;
}

inline Lanes select(LaneMask m, Lanes yes, Lanes no) {
  return m ? yes : no;
}

// E_iso(J) = ‖J‖² + ‖J⁻¹‖², +∞ where det J ≤ 0 or the value is not finite (sd_energy).
inline Lanes energy(const Mat3Lanes J) {
  Mat3Lanes A;
  const Lanes det = inverse(J, A);
  const Lanes e = squared_norm(J) + squared_norm(A);
  const Lanes inf = splat(std::numeric_limits<double>::infinity());
  const LaneMask finite = (e == e) & (e < inf);
  return select((det > 0) & finite, e, inf);
}

// ∂E_iso/∂J = 2J − 2 Aᵀ A Aᵀ (sd_gradient); quiet NaN where det J ≤ 0.
inline void gradient(const Mat3Lanes J, Mat3Lanes g) {
  Mat3Lanes A, S, T;
  const Lanes det = inverse(J, A);
  product<false, true>(A, A, S);  // A Aᵀ
  product<true, false>(A, S, T);  // Aᵀ A Aᵀ
  const LaneMask ok = det > 0;
  const Lanes nan = splat(std::numeric_limits<double>::quiet_NaN());
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) g[a][b] = select(ok, 2.0 * J[a][b] - 2.0 * T[a][b], nan);
}

// The curvature D : ∇²E_iso(J)[D] (sd_hessian_times) = 2‖D‖² + 2‖A D A‖² + 4 ⟨A, A D A D A⟩: the second
// derivative of ‖J + tD‖² + ‖(J + tD)⁻¹‖² at t = 0, from (J + tD)⁻¹ = A − t ADA + t² ADADA + O(t³). Quiet NaN
// where det J ≤ 0.
inline Lanes curvature(const Mat3Lanes J, const Mat3Lanes D) {
  Mat3Lanes A, M, N, P;
  const Lanes det = inverse(J, A);
  product(A, D, M);  // A D
  product(M, A, N);  // A D A
  product(M, N, P);  // A D A D A
  const Lanes c = 2.0 * squared_norm(D) + 2.0 * squared_norm(N) + 4.0 * dot(A, P);
  return select(det > 0, c, splat(std::numeric_limits<double>::quiet_NaN()));
}

}  // namespace lidef::sd_lanes
