// lidef's OpenCL kernels (OpenCL C 1.2, double precision: cl_khr_fp64 is required).
//
// Each kernel is the device twin of a CPU function in deform/ (named beside it); tests/test_opencl.cpp
// compares them on random inputs. Everything that decides a certificate is double. Stored basis derivatives
// are float (as on the CPU, whose rounding allowance covers that storage), always multiplied into double sums.
//
// Layouts (R = 3n rows of the reduced gradient matrix G, s = reduced size):
//   Gt      float, s by R column-major of G: Gt[k*R + r] = G(r, k)        (adjacent work-items read adjacent words)
//   y       double, s by 3 column-major (Eigen MatS3): y[a*s + k]
//   J       double, per sample the 9 entries of JT rows 3i..3i+2: J[9i + 3b + a] = J_i(a, b) = ∂f_a/∂p_b
//   GHt     float, certificate: GHt[(row*m + k)*N + i], rows 0..2 = ∂/∂x,y,z, rows 3..8 = xx,xy,xz,yy,yz,zz
//   Ft      float, certificate edge factors transposed: Ft[e*N + i] (rounded up on the host)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

#define M_PI_D 3.14159265358979323846
#define INV_4PI (1.0 / (4.0 * M_PI_D))
#define INV_2PI (1.0 / (2.0 * M_PI_D))

// ---------------------------------------------------------------- 3x3 helpers (row-major m[3a+b] = M(a,b))

inline double det3(const double* m) {
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
         m[2] * (m[3] * m[7] - m[4] * m[6]);
}

// One-sided (Hestenes) Jacobi SVD of J (row-major): A = J V with orthogonal columns, V a product of plane
// rotations. Column norms of A are the singular values with high relative accuracy (the property that makes
// σ3 near 0 trustworthy). Returns the columns sorted by decreasing norm; V is made a rotation, U = A/σ with
// u3 = u1 × u2, so that σ3 = a3·u3 carries the sign of det J (signed SVD, signed_svd.h).
inline void signed_svd3(const double* J, double* U, double* S, double* V) {
  double A[9], W[9];
  for (int q = 0; q < 9; ++q) {
    A[q] = J[q];
    W[q] = (q % 4 == 0) ? 1.0 : 0.0;
  }
  for (int sweep = 0; sweep < 40; ++sweep) {
    int rotated = 0;
    for (int pair = 0; pair < 3; ++pair) {
      const int p = pair == 2 ? 1 : 0, q = pair == 0 ? 1 : 2;
      double al = 0, be = 0, ga = 0;
      for (int i = 0; i < 3; ++i) {
        al += A[3 * i + p] * A[3 * i + p];
        be += A[3 * i + q] * A[3 * i + q];
        ga += A[3 * i + p] * A[3 * i + q];
      }
      if (fabs(ga) <= 1e-15 * sqrt(al * be)) continue;
      rotated = 1;
      const double zeta = (be - al) / (2.0 * ga);
      const double t = (zeta >= 0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
      const double c = 1.0 / sqrt(1.0 + t * t), s = c * t;
      for (int i = 0; i < 3; ++i) {
        const double ap = A[3 * i + p], aq = A[3 * i + q];
        A[3 * i + p] = c * ap - s * aq;
        A[3 * i + q] = s * ap + c * aq;
        const double vp = W[3 * i + p], vq = W[3 * i + q];
        W[3 * i + p] = c * vp - s * vq;
        W[3 * i + q] = s * vp + c * vq;
      }
    }
    if (!rotated) break;
  }
  double nrm[3];
  for (int j = 0; j < 3; ++j) nrm[j] = sqrt(A[j] * A[j] + A[3 + j] * A[3 + j] + A[6 + j] * A[6 + j]);
  int o[3] = {0, 1, 2};
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2 - a; ++b)
      if (nrm[o[b]] < nrm[o[b + 1]]) {
        const int tmp = o[b];
        o[b] = o[b + 1];
        o[b + 1] = tmp;
      }
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) V[3 * i + j] = W[3 * i + o[j]];
  double Ac[9];
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) Ac[3 * i + j] = A[3 * i + o[j]];
  if (det3(V) < 0)
    for (int i = 0; i < 3; ++i) {
      V[3 * i + 2] = -V[3 * i + 2];
      Ac[3 * i + 2] = -Ac[3 * i + 2];
    }
  S[0] = nrm[o[0]];
  S[1] = nrm[o[1]];
  for (int i = 0; i < 3; ++i) {
    U[3 * i] = S[0] > 0 ? Ac[3 * i] / S[0] : (i == 0 ? 1.0 : 0.0);
    U[3 * i + 1] = S[1] > 0 ? Ac[3 * i + 1] / S[1] : (i == 1 ? 1.0 : 0.0);
  }
  U[2] = U[3] * U[7] - U[6] * U[4];
  U[5] = U[6] * U[1] - U[0] * U[7];
  U[8] = U[0] * U[4] - U[3] * U[1];
  S[2] = Ac[2] * U[2] + Ac[5] * U[5] + Ac[8] * U[8];
}

// det_sign_bounded (signed_svd.cpp), same formula: +1 / −1 when |fl(det J)| exceeds the bound on its rounding
// error 2⁻⁵⁰·Σ_j |J0j|(|J1a J2b| + |J1b J2a|) + 2⁻¹⁰⁷⁰·(Σ_j |J0j| + 2), else 0; *resolved is 1 for ±1 and
// for det J = 0 exactly (every Leibniz product has a zero factor).
inline int det_sign3(const double* m, int* resolved) {
  const double det = det3(m);
  double A[9];
  for (int q = 0; q < 9; ++q) A[q] = fabs(m[q]);
  const double P = A[0] * (A[4] * A[8] + A[5] * A[7]) + A[1] * (A[3] * A[8] + A[5] * A[6]) +
                   A[2] * (A[3] * A[7] + A[4] * A[6]);
  const double bound = 0x1p-50 * P + 0x1p-1070 * (A[0] + A[1] + A[2] + 2.0);
  *resolved = 0;
  if (!isfinite(det) || !isfinite(bound)) return 0;
  if (fabs(det) > bound) {
    *resolved = 1;
    return det > 0 ? 1 : -1;
  }
  const int t0 = m[0] == 0 || ((m[4] == 0 || m[8] == 0) && (m[5] == 0 || m[7] == 0));
  const int t1 = m[1] == 0 || ((m[3] == 0 || m[8] == 0) && (m[5] == 0 || m[6] == 0));
  const int t2 = m[2] == 0 || ((m[3] == 0 || m[7] == 0) && (m[4] == 0 || m[6] == 0));
  *resolved = t0 && t1 && t2;
  return 0;
}

// Signed σ3 as signed_singular_values(J)(2): the smallest singular value, negative when det J < 0, and 0 when
// the sign of det J is not resolved (*resolved = 0) or det J = 0 exactly; *sigma1 = σ1 (signed_singular_values
// (J)(0), the bounded-distortion stage's σ1) from the same decomposition.
inline double signed_sigma3(const double* J, int* resolved, double* sigma1) {
  double U[9], S[3], V[9];
  signed_svd3(J, U, S, V);
  *sigma1 = fabs(S[0]);
  const double s3 = fabs(S[2]);
  const int sg = det_sign3(J, resolved);
  return sg == 0 ? 0.0 : (sg < 0 ? -s3 : s3);
}

// ---------------------------------------------------------------- symmetric Dirichlet (symmetric_dirichlet.cpp)

// E = ‖J‖² + ‖J⁻¹‖², +∞ when det J ≤ 0. Jinv (row-major) is filled when det > 0.
inline double sd_energy(const double* J, double* Jinv) {
  const double det = det3(J);
  if (!(det > 0)) return INFINITY;
  const double id = 1.0 / det;
  Jinv[0] = (J[4] * J[8] - J[5] * J[7]) * id;
  Jinv[1] = (J[2] * J[7] - J[1] * J[8]) * id;
  Jinv[2] = (J[1] * J[5] - J[2] * J[4]) * id;
  Jinv[3] = (J[5] * J[6] - J[3] * J[8]) * id;
  Jinv[4] = (J[0] * J[8] - J[2] * J[6]) * id;
  Jinv[5] = (J[2] * J[3] - J[0] * J[5]) * id;
  Jinv[6] = (J[3] * J[7] - J[4] * J[6]) * id;
  Jinv[7] = (J[1] * J[6] - J[0] * J[7]) * id;
  Jinv[8] = (J[0] * J[4] - J[1] * J[3]) * id;
  double e = 0;
  for (int q = 0; q < 9; ++q) e += J[q] * J[q] + Jinv[q] * Jinv[q];
  return isfinite(e) ? e : INFINITY;
}

// J (row-major) of sample i from the JT layout, optionally J + t dJ.
inline void load_J(__global const double* Jc, __global const double* dJ, double t, long i, double* J) {
  for (int b = 0; b < 3; ++b)
    for (int a = 0; a < 3; ++a) {
      double v = Jc[9 * i + 3 * b + a];
      if (dJ) v += t * dJ[9 * i + 3 * b + a];
      J[3 * a + b] = v;
    }
}

// ---------------------------------------------------------------- energy kernels (deformation_energy.cpp)

// J = G y: one work-item per row r of G (JT row r = 3i + b).
__kernel void jacobians(__global const float* Gt, long R, int s, __global const double* y,
                        __global double* Jout) {
  const long r = get_global_id(0);
  if (r >= R) return;
  double a0 = 0, a1 = 0, a2 = 0;
  for (int k = 0; k < s; ++k) {
    const double g = Gt[(long)k * R + r];
    a0 += g * y[k];
    a1 += g * y[s + k];
    a2 += g * y[2 * s + k];
  }
  Jout[3 * r] = a0;
  Jout[3 * r + 1] = a1;
  Jout[3 * r + 2] = a2;
}

// The same dot products for CPU devices (PoCL). A CPU OpenCL compiler vectorizes across work-items only when
// the kernel body has no inner loop, so the layouts above leave the k loop scalar there. These kernels read one
// contiguous row per work-item (the host's layout) in explicit 4-wide vectors instead: fixed summation order
// (deterministic), no fast-math needed.
inline void dot3_rows4(__global const float* g, int m, __global const double* Y, double* o) {
  double4 a0 = (double4)(0.0), a1 = (double4)(0.0), a2 = (double4)(0.0);
  int k = 0;
  for (; k + 4 <= m; k += 4) {
    const double4 gk = convert_double4(vload4(0, g + k));
    a0 += gk * vload4(0, Y + k);
    a1 += gk * vload4(0, Y + m + k);
    a2 += gk * vload4(0, Y + 2 * m + k);
  }
  double s0 = (a0.s0 + a0.s1) + (a0.s2 + a0.s3), s1 = (a1.s0 + a1.s1) + (a1.s2 + a1.s3),
         s2 = (a2.s0 + a2.s1) + (a2.s2 + a2.s3);
  for (; k < m; ++k) {
    const double gk = g[k];
    s0 += gk * Y[k];
    s1 += gk * Y[m + k];
    s2 += gk * Y[2 * m + k];
  }
  o[0] = s0;
  o[1] = s1;
  o[2] = s2;
}

// J = G y with G row-major (R by s).
__kernel void jacobians_rows(__global const float* G, long R, int s, __global const double* y,
                             __global double* Jout) {
  const long r = get_global_id(0);
  if (r >= R) return;
  double o[3];
  dot3_rows4(G + r * s, s, y, o);
  Jout[3 * r] = o[0];
  Jout[3 * r + 1] = o[1];
  Jout[3 * r + 2] = o[2];
}

// partial[group] = the work-group's sum of e, by a fixed tree (deterministic). Every work-item calls it.
inline void group_tree_sum(double e, __local double* scratch, __global double* partial) {
  const int lid = get_local_id(0), ls = get_local_size(0);
  scratch[lid] = e;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (int h = ls / 2; h > 0; h /= 2) {
    if (lid < h) scratch[lid] += scratch[lid + h];
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid == 0) partial[get_group_id(0)] = scratch[0];
}

// Work-group sums of w_i (E_iso(J_i + t dJ_i) − 6) (fixed tree order: deterministic); partial[group]. w: the
// per-sample volume weights (all 1 when the sampling is uniform: the products are then exact).
__kernel void sd_sum(__global const double* Jc, __global const double* dJ, double t, int use_dJ, long n,
                     __global const double* w, __global double* partial, __local double* scratch) {
  const long i = get_global_id(0);
  double e = 0;
  if (i < n) {
    double J[9], Jinv[9];
    load_J(Jc, use_dJ ? dJ : 0, t, i, J);
    e = w[i] * (sd_energy(J, Jinv) - 6.0);
  }
  group_tree_sum(e, scratch, partial);
}

// P_i = w_i ∂E_iso/∂J_i = w_i (2J − 2 J⁻ᵀ J⁻¹ J⁻ᵀ), stored in the JT layout. NaN where det J ≤ 0 (as the CPU).
__kernel void sd_gradient(__global const double* Jc, long n, __global const double* w, __global double* P) {
  const long i = get_global_id(0);
  if (i >= n) return;
  double J[9], Ji[9];
  load_J(Jc, 0, 0.0, i, J);
  if (!(det3(J) > 0)) {
    for (int q = 0; q < 9; ++q) P[9 * i + q] = NAN;
    return;
  }
  sd_energy(J, Ji);
  // M = J⁻ᵀ J⁻¹ J⁻ᵀ: (J⁻ᵀ)(a,c) = Ji(c,a).
  double T1[9], M[9];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      double v = 0;
      for (int c = 0; c < 3; ++c) v += Ji[3 * c + a] * Ji[3 * c + b];  // (J⁻ᵀ J⁻¹)(a,b)
      T1[3 * a + b] = v;
    }
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      double v = 0;
      for (int c = 0; c < 3; ++c) v += T1[3 * a + c] * Ji[3 * b + c];  // (T1 J⁻ᵀ)(a,b)
      M[3 * a + b] = v;
    }
  const double wi = w[i];
  for (int b = 0; b < 3; ++b)
    for (int a = 0; a < 3; ++a) P[9 * i + 3 * b + a] = wi * (2.0 * J[3 * a + b] - 2.0 * M[3 * a + b]);
}

// C = A B for row-major 3x3 matrices.
inline void mul33(const double* A, const double* B, double* C) {
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) C[3 * a + b] = A[3 * a] * B[b] + A[3 * a + 1] * B[3 + b] + A[3 * a + 2] * B[6 + b];
}

// The exact SD Hessian at J applied to D (sd_hessian_times in symmetric_dirichlet.cpp, the same products in the
// same order), row-major; Ji = J⁻¹. With B = J⁻ᵀ, X = Dᵀ: 2D + 2(B X B Bᵀ B + B Bᵀ D Bᵀ B + B Bᵀ B X B).
inline void sd_hessian_times3(const double* Ji, const double* D, double* out) {
  double B[9], Bt[9], X[9];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      B[3 * a + b] = Ji[3 * b + a];
      Bt[3 * a + b] = Ji[3 * a + b];
      X[3 * a + b] = D[3 * b + a];
    }
  double BBt[9], BtB[9], XB[9], T[9], U[9], t1[9], t2[9], t3[9];
  mul33(B, Bt, BBt);
  mul33(Bt, B, BtB);
  mul33(X, B, XB);
  mul33(B, XB, T);  // ((B XB) Bᵀ) B
  mul33(T, Bt, U);
  mul33(U, B, t1);
  mul33(BBt, D, T);  // (B Bᵀ D) BᵀB
  mul33(T, BtB, t2);
  mul33(BBt, B, T);  // (B Bᵀ B) XB
  mul33(T, XB, t3);
  for (int q = 0; q < 9; ++q) out[q] = 2.0 * D[q] + 2.0 * ((t1[q] + t2[q]) + t3[q]);
}

// P_i = w_i H(J_i)[dJ_i] (the exact Hessian along the direction's Jacobians), stored in the JT layout for
// gradient_reduce / gradient_rows_partial; NaN where det J ≤ 0 (as the CPU).
__kernel void sd_hessian_times(__global const double* Jc, __global const double* dJ, long n,
                               __global const double* w, __global double* P) {
  const long i = get_global_id(0);
  if (i >= n) return;
  double J[9], Ji[9], D[9], M[9];
  load_J(Jc, 0, 0.0, i, J);
  if (!(det3(J) > 0)) {
    for (int q = 0; q < 9; ++q) P[9 * i + q] = NAN;
    return;
  }
  sd_energy(J, Ji);
  load_J(dJ, 0, 0.0, i, D);
  sd_hessian_times3(Ji, D, M);
  const double wi = w[i];
  for (int b = 0; b < 3; ++b)
    for (int a = 0; a < 3; ++a) P[9 * i + 3 * b + a] = wi * M[3 * a + b];
}

// Work-group sums of w_i dJ_i : H(J_i)[dJ_i] (the curvature along the direction; fixed tree order, as sd_sum).
__kernel void sd_curvature(__global const double* Jc, __global const double* dJ, long n,
                           __global const double* w, __global double* partial, __local double* scratch) {
  const long i = get_global_id(0);
  double e = 0;
  if (i < n) {
    double J[9], Ji[9], D[9], M[9];
    load_J(Jc, 0, 0.0, i, J);
    if (!(det3(J) > 0)) {
      e = NAN;
    } else {
      sd_energy(J, Ji);
      load_J(dJ, 0, 0.0, i, D);
      sd_hessian_times3(Ji, D, M);
      double c = 0;
      for (int q = 0; q < 9; ++q) c += D[q] * M[q];
      e = w[i] * c;
    }
  }
  group_tree_sum(e, scratch, partial);
}

// out(k, a) = Σ_r G(r, k) P(r, a): one work-group per k, fixed-order tree reduction (deterministic).
__kernel void gradient_reduce(__global const float* Gt, long R, int s, __global const double* P,
                              __global double* out, __local double* scratch) {
  const int k = get_group_id(0);
  const int lid = get_local_id(0), ls = get_local_size(0);
  double a0 = 0, a1 = 0, a2 = 0;
  for (long r = lid; r < R; r += ls) {
    const double g = Gt[(long)k * R + r];
    a0 += g * P[3 * r];
    a1 += g * P[3 * r + 1];
    a2 += g * P[3 * r + 2];
  }
  scratch[3 * lid] = a0;
  scratch[3 * lid + 1] = a1;
  scratch[3 * lid + 2] = a2;
  barrier(CLK_LOCAL_MEM_FENCE);
  for (int h = ls / 2; h > 0; h /= 2) {
    if (lid < h)
      for (int c = 0; c < 3; ++c) scratch[3 * lid + c] += scratch[3 * (lid + h) + c];
    barrier(CLK_LOCAL_MEM_FENCE);
  }
  if (lid == 0)
    for (int c = 0; c < 3; ++c) out[c * s + k] = scratch[c];
}

// The gradient product for CPU devices: work-item c accumulates rows [c rpc, (c+1) rpc) of Gᵀ P into its own
// slice of `partial` (3s doubles, layout a s + k) with 4-wide vectors; sum_partials adds the slices in order.
__kernel void gradient_rows_partial(__global const float* G, long R, int s, __global const double* P, int rpc,
                                    __global double* partial) {
  const long c = get_global_id(0);
  const long r0 = c * rpc;
  if (r0 >= R) return;
  const long r1 = min(R, r0 + rpc);
  __global double* out = partial + c * 3L * s;
  for (int q = 0; q < 3 * s; ++q) out[q] = 0;
  for (long r = r0; r < r1; ++r) {
    const double p0 = P[3 * r], p1 = P[3 * r + 1], p2 = P[3 * r + 2];
    __global const float* g = G + r * s;
    int k = 0;
    for (; k + 4 <= s; k += 4) {
      const double4 gk = convert_double4(vload4(0, g + k));
      vstore4(vload4(0, out + k) + gk * p0, 0, out + k);
      vstore4(vload4(0, out + s + k) + gk * p1, 0, out + s + k);
      vstore4(vload4(0, out + 2 * s + k) + gk * p2, 0, out + 2 * s + k);
    }
    for (; k < s; ++k) {
      const double gk = g[k];
      out[k] += gk * p0;
      out[s + k] += gk * p1;
      out[2 * s + k] += gk * p2;
    }
  }
}

__kernel void sum_partials(__global const double* partial, int chunks, int len, __global double* out) {
  const int j = get_global_id(0);
  if (j >= len) return;
  double acc = 0;
  for (int c = 0; c < chunks; ++c) acc += partial[(long)c * len + j];
  out[j] = acc;
}

// S ← α dJ (start) or S + α dJ: the conjugate-gradient direction's Jacobians, combined on the device.
__kernel void scale_add_J(__global double* S, __global const double* dJ, double alpha, int start, long len) {
  const long q = get_global_id(0);
  if (q < len) S[q] = start ? alpha * dJ[q] : S[q] + alpha * dJ[q];
}

// Jc ← Jc + t dJ.
__kernel void axpy_J(__global double* Jc, __global const double* dJ, double t, long len) {
  const long q = get_global_id(0);
  if (q < len) Jc[q] = Jc[q] + t * dJ[q];
}

// PSD-projected 9x9 SD Hessian of subset sample k, times its block weight (sd_hessian_psd;
// DeformationEnergy::subset_block_weights), column-major vec(J) index a + 3b, stored as blocks[81k + 9 row + col].
__kernel void psd_blocks(__global const double* Jc, __global const int* subset, int m,
                         __global const double* block_weight, __global double* blocks) {
  const int k = get_global_id(0);
  if (k >= m) return;
  const double weight = block_weight[k];
  double J[9];
  load_J(Jc, 0, 0.0, subset[k], J);
  __global double* H = blocks + 81L * k;
  if (!(det3(J) > 0)) {
    for (int q = 0; q < 81; ++q) H[q] = NAN;
    return;
  }
  double U[9], S[3], V[9];
  signed_svd3(J, U, S, V);
  double Hl[81];
  for (int q = 0; q < 81; ++q) Hl[q] = 0;
  double qv[9];
  // Scaling modes: λ = 2 + 6σ⁻⁴, q = vec(u_i v_iᵀ).
  for (int i = 0; i < 3; ++i) {
    const double s2 = S[i] * S[i];
    const double lambda = max(2.0 + 6.0 / (s2 * s2), 0.0);
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a) qv[a + 3 * b] = U[3 * a + i] * V[3 * b + i];
    for (int r = 0; r < 9; ++r)
      for (int c = 0; c < 9; ++c) Hl[9 * r + c] += lambda * qv[r] * qv[c];
  }
  const int pi[3] = {0, 1, 0}, pj[3] = {1, 2, 2};
  const double rs = sqrt(0.5);
  for (int p = 0; p < 3; ++p) {
    const int i = pi[p], j = pj[p];
    const double a = S[i], b = S[j];
    const double c = a * a * a * b * b * b;
    const double twist = max(2.0 - 2.0 * (a * a - a * b + b * b) / c, 0.0);
    const double flip = max(2.0 + 2.0 * (a * a + a * b + b * b) / c, 0.0);
    for (int mode = 0; mode < 2; ++mode) {
      const double sg = mode == 0 ? -1.0 : 1.0, lambda = mode == 0 ? twist : flip;
      for (int bb = 0; bb < 3; ++bb)
        for (int aa = 0; aa < 3; ++aa)
          qv[aa + 3 * bb] = (U[3 * aa + i] * V[3 * bb + j] + sg * U[3 * aa + j] * V[3 * bb + i]) * rs;
      for (int r = 0; r < 9; ++r)
        for (int cc = 0; cc < 9; ++cc) Hl[9 * r + cc] += lambda * qv[r] * qv[cc];
    }
  }
  for (int r = 0; r < 9; ++r)
    for (int cc = 0; cc < 9; ++cc) H[9 * r + cc] = weight * 0.5 * (Hl[9 * r + cc] + Hl[9 * cc + r]);
}

// W (3m by 6s, row-major): W[3k+b][q s + j] = Σ_b' H̃_k^{q}(b, b') GH[3k+b'][j], H̃^{q}(b,b') = H_k(a+3b, a'+3b')
// for the pair q = (a, a') in {00, 01, 02, 11, 12, 22}. GH: 3m by s row-major. REAL is float or double.
#define PAIR_A(q) ((q) < 3 ? 0 : ((q) < 5 ? 1 : 2))
#define PAIR_B(q) ((q) == 0 ? 0 : ((q) == 1 || (q) == 3) ? 1 : 2)
#define DEFINE_FILL_W(REAL, NAME)                                                                     \
  __kernel void NAME(__global const double* blocks, __global const REAL* GH, int m, int s,          \
                     __global REAL* W) {                                                             \
    const long row = get_global_id(0);                                                               \
    const int col = get_global_id(1);                                                                \
    if (row >= 3L * m || col >= 6 * s) return;                                                       \
    const long k = row / 3;                                                                          \
    const int b = row % 3, q = col / s, j = col % s;                                                 \
    const int a = PAIR_A(q), a2 = PAIR_B(q);                                                         \
    __global const double* H = blocks + 81 * k;                                                      \
    REAL v = 0;                                                                                      \
    for (int b2 = 0; b2 < 3; ++b2) v += (REAL)H[9 * (a + 3 * b) + (a2 + 3 * b2)] * GH[(3 * k + b2) * s + j]; \
    W[row * 6 * s + col] = v;                                                                        \
  }
DEFINE_FILL_W(float, fill_w_float)
DEFINE_FILL_W(double, fill_w_double)

// ---------------------------------------------------------------- certificate (octree_certifier.cpp)

// Base stage, part 1 (streaming, kept simple so that CPU OpenCL compilers vectorize it across work-items):
// row `row` of voxel i's stored derivatives times Y (m by 3, column-major) → JH[(3 row + a) N + i].
__kernel void certify_rows(__global const float* GHt, long N, int m, __global const double* Y, int rows,
                           __global double* JH) {
  const long i = get_global_id(0);
  if (i >= N) return;
  for (int row = 0; row < rows; ++row) {
    __global const float* g = GHt + (long)row * m * N + i;
    double a0 = 0, a1 = 0, a2 = 0;
    for (int k = 0; k < m; ++k) {
      const double gk = g[(long)k * N];
      a0 += gk * Y[k];
      a1 += gk * Y[m + k];
      a2 += gk * Y[2 * m + k];
    }
    JH[(3L * row) * N + i] = a0;
    JH[(3L * row + 1) * N + i] = a1;
    JH[(3L * row + 2) * N + i] = a2;
  }
}

// Base stage, part 1 for CPU devices: voxel i's block of 9 contiguous rows of m floats (GH[(9 i + row) m + k]).
__kernel void certify_rows_blocks(__global const float* GH, long N, int m, __global const double* Y, int rows,
                                  __global double* JH) {
  const long i = get_global_id(0);
  if (i >= N) return;
  for (int row = 0; row < rows; ++row) {
    double o[3];
    dot3_rows4(GH + (9 * i + row) * (long)m, m, Y, o);
    JH[(3L * row) * N + i] = o[0];
    JH[(3L * row + 1) * N + i] = o[1];
    JH[(3L * row + 2) * N + i] = o[2];
  }
}

// Base stage, part 2 per voxel: ‖H‖ (full 27-entry norm; 0 when only the gradient rows were formed), signed
// σ3 and σ1, and T = Σ_e δ_e F(i, e) (skipping δ_e = 0, whose factor may be +∞).
__kernel void certify_finish(__global const double* JH, long N, int third, __global const float* Ft, int E,
                             __global const double* delta, __global double* sigma3, __global double* hnorm,
                             __global double* T, __global double* unresolved, __global double* sigma1) {
  const long i = get_global_id(0);
  if (i >= N) return;
  double J[9];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) J[3 * a + b] = JH[(3L * b + a) * N + i];
  double hs = 0;
  if (third)
    for (int a = 0; a < 3; ++a) {
      const double h0 = JH[(9L + a) * N + i], h1 = JH[(12L + a) * N + i], h2 = JH[(15L + a) * N + i];
      const double h3 = JH[(18L + a) * N + i], h4 = JH[(21L + a) * N + i], h5 = JH[(24L + a) * N + i];
      hs += h0 * h0 + h3 * h3 + h5 * h5 + 2 * (h1 * h1 + h2 * h2 + h4 * h4);
    }
  hnorm[i] = sqrt(hs);
  int resolved = 1;
  double s1 = 0;
  sigma3[i] = signed_sigma3(J, &resolved, &s1);
  sigma1[i] = s1;
  unresolved[i] = resolved ? 0.0 : 1.0;
  double t = 0;
  for (int e = 0; e < E; ++e) {
    const double d = delta[e];
    if (d != 0) t += d * (double)Ft[(long)e * N + i];
  }
  T[i] = t;
}

// lipschitz_bound.cpp
inline double len3(double x, double y, double z) { return sqrt(x * x + y * y + z * z); }

inline double edge_sum_lower_bound(const double* u, const double* w, const double* p, double r) {
  const double ex = w[0] - u[0], ey = w[1] - u[1], ez = w[2] - u[2];
  const double d = len3(ex, ey, ez);
  const double a = len3(u[0] - p[0], u[1] - p[1], u[2] - p[2]) - r;
  const double b = len3(w[0] - p[0], w[1] - p[1], w[2] - p[2]) - r;
  const double px = p[0] - u[0], py = p[1] - u[1], pz = p[2] - u[2];
  const double line_dist = len3(py * ez - pz * ey, pz * ex - px * ez, px * ey - py * ex) / d;
  const double rho = max(0.0, line_dist - r);
  return max(max(a, 0.0) + max(b, 0.0), 2.0 * sqrt(rho * rho + 0.25 * d * d));
}

inline double edge_factor(const double* u, const double* w, const double* p, double r, int third) {
  const double d = len3(w[0] - u[0], w[1] - u[1], w[2] - u[2]);
  const double h = edge_sum_lower_bound(u, w, p, r);
  const double nu = len3(u[0] - p[0], u[1] - p[1], u[2] - p[2]);
  const double nw = len3(w[0] - p[0], w[1] - p[1], w[2] - p[2]);
  const double a = nu - r, b = nw - r;  // lower bounds of |l_u|, |l_w| on the ball
  if (!third) {
    if (!(h > d) || nu <= r || nw <= r) return INFINITY;
    return sqrt(h * h + 4 * d * d) / (2 * M_PI_D * (h * h - d * d));
  }
  if (!(h > d) || !(a > 0) || !(b > 0)) return INFINITY;
  const double md2 = (h * h - d * d) * (h * h - d * d);
  const double nn = (a * b) * (a * b);
  const double b66 = (1.0 + h * h * d * d / nn) / (M_PI_D * M_PI_D * md2);
  const double b67 = 3.0 * h * h * d * d / (2.0 * M_PI_D * M_PI_D * md2 * nn);
  return sqrt(b66 + b67);
}

// Octree nodes: the differential representation (HarmonicBasis::differential_jet) at each node center plus
// the node's own bound Σ_e δ_e factor_e(center, radius) (skipping δ_e = 0).
// faces: per face x0,x1,x2 (9) and dlen (3); fm: per face A (9, row-major), AD_k (3 x 9), A_abs (1).
#define kNodeOut 7
// out per node (kNodeOut values; the host reads the same layout, opencl_backend.cpp): σ3, ‖H‖ (third only,
// else 0), own bound, scale_J, scale_H, 1 when det J's sign is not resolved (else 0), σ1.
__kernel void eval_nodes(__global const double* centers, __global const double* radii, long count,
                         __global const double* faces, __global const double* fm, int nf, int third,
                         __global const double* edges, __global const double* delta, int E,
                         __global double* out) {
  const long j = get_global_id(0);
  if (j >= count) return;
  const double p[3] = {centers[3 * j], centers[3 * j + 1], centers[3 * j + 2]};
  double J[9], H[27];
  for (int q = 0; q < 9; ++q) J[q] = 0;
  for (int q = 0; q < 27; ++q) H[q] = 0;
  double sJ = 0, sH = 0;
  for (int t = 0; t < nf; ++t) {
    __global const double* fc = faces + 12L * t;
    __global const double* F = fm + 37L * t;
    double l[3][3], L[3];
    for (int k = 0; k < 3; ++k) {
      for (int c = 0; c < 3; ++c) l[k][c] = fc[3 * k + c] - p[c];
      L[k] = len3(l[k][0], l[k][1], l[k][2]);
    }
    // l1 × l2
    const double cx = l[1][1] * l[2][2] - l[1][2] * l[2][1];
    const double cy = l[1][2] * l[2][0] - l[1][0] * l[2][2];
    const double cz = l[1][0] * l[2][1] - l[1][1] * l[2][0];
    const double triple = l[0][0] * cx + l[0][1] * cy + l[0][2] * cz;
    const double d01 = l[0][0] * l[1][0] + l[0][1] * l[1][1] + l[0][2] * l[1][2];
    const double d12 = l[1][0] * l[2][0] + l[1][1] * l[2][1] + l[1][2] * l[2][2];
    const double d20 = l[2][0] * l[0][0] + l[2][1] * l[0][1] + l[2][2] * l[0][2];
    const double den = L[0] * L[1] * L[2] + d01 * L[2] + d12 * L[0] + d20 * L[1];
    const double omega = atan2(triple, den) * (2.0 * INV_4PI);
    double a1 = 0;
    for (int q = 0; q < 9; ++q) a1 += fabs(F[q]);
    a1 = max(a1, F[36]);
    for (int q = 0; q < 9; ++q) J[q] += omega * F[q];
    sJ += fabs(omega) * a1;
    for (int k = 0; k < 3; ++k) {
      const int u = (k + 2) % 3, w = (k + 1) % 3;
      const double m = L[u] + L[w];
      const double luw = l[u][0] * l[w][0] + l[u][1] * l[w][1] + l[u][2] * l[w][2];
      const double md = 2.0 * (L[u] * L[w] + luw);
      const double d = fc[9 + k];
      const double C = INV_4PI * log((m + d) * (m + d) / md);
      __global const double* AD = F + 9 + 9 * k;
      double ad1 = 0;
      for (int q = 0; q < 9; ++q) ad1 += fabs(AD[q]);
      ad1 = max(ad1, 2.0 * F[36]);
      for (int q = 0; q < 9; ++q) J[q] -= C * AD[q];
      sJ += fabs(C) * ad1;
      if (third) {
        const double xx = l[u][1] * l[w][2] - l[u][2] * l[w][1];
        const double xy = l[u][2] * l[w][0] - l[u][0] * l[w][2];
        const double xz = l[u][0] * l[w][1] - l[u][1] * l[w][0];
        const double fa = m * INV_2PI / (md * L[u] * L[w]);
        const double al[3] = {fa * xx, fa * xy, fa * xz};
        const double fb = d * INV_2PI / md;
        const double bt[3] = {fb * (l[u][0] / L[u] + l[w][0] / L[w]), fb * (l[u][1] / L[u] + l[w][1] / L[w]),
                              fb * (l[u][2] / L[u] + l[w][2] / L[w])};
        // H[a](b,c) −= A(a,b) α(c) + AD(a,b) β(c)
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b)
            for (int c = 0; c < 3; ++c) H[9 * a + 3 * b + c] -= F[3 * a + b] * al[c] + AD[3 * a + b] * bt[c];
        sH += a1 * (fabs(al[0]) + fabs(al[1]) + fabs(al[2])) + ad1 * (fabs(bt[0]) + fabs(bt[1]) + fabs(bt[2]));
      }
    }
  }
  double hn = 0;
  if (third) {
    for (int q = 0; q < 27; ++q) hn += H[q] * H[q];
    hn = sqrt(hn);
  }
  const double rad = radii[j];
  double own = 0;
  for (int e = 0; e < E; ++e) {
    const double de = delta[e];
    if (de != 0) {
      const double u[3] = {edges[6 * e], edges[6 * e + 1], edges[6 * e + 2]};
      const double w[3] = {edges[6 * e + 3], edges[6 * e + 4], edges[6 * e + 5]};
      own += de * edge_factor(u, w, p, rad, third);
    }
  }
  int resolved = 1;
  double s1 = 0;
  out[kNodeOut * j] = signed_sigma3(J, &resolved, &s1);
  out[kNodeOut * j + 1] = hn;
  out[kNodeOut * j + 2] = own;
  out[kNodeOut * j + 3] = sJ;
  out[kNodeOut * j + 4] = sH;
  out[kNodeOut * j + 5] = resolved ? 0.0 : 1.0;
  out[kNodeOut * j + 6] = s1;
}
