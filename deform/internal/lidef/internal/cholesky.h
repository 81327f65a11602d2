// Dense Cholesky factorization and solves for the reduced Newton system (3s by 3s, s the subspace size).
//
// The factor is computed blocked and right-looking over OpenMP's threads, each block operation a
// single-threaded OpenBLAS call (use_blas_in_calling_thread: OpenBLAS's own pthread workers spin after each
// call and would take cores from the OpenMP stages that follow). Why not LAPACK's dpotrf: in the calling
// thread it leaves every other core idle during what is, on a GPU host, the largest part of a Newton
// iteration (the 900 x 900 factor took 12-18 ms there while the device's stages took ~5 ms).
//
// The blocks and their order do not depend on the thread count, so the factor is bit-identical for any number
// of threads (each block is one BLAS call of the same shape whichever thread runs it).
#pragma once
#include "lidef/types.h"

namespace lidef {

// H (n by n, symmetric positive definite; only its lower triangle is read) is overwritten by its lower
// Cholesky factor L (H = L Lᵀ) in the lower triangle; the strict upper triangle is left as it was. false when
// H is not positive definite (to working precision): H then holds a partial factorization.
bool cholesky_factor(MatXd& H);

// b <- L⁻ᵀ L⁻¹ b for a factor from cholesky_factor (n by n; b of length n), in the calling thread. false when
// the sizes differ or the result is not finite (a zero pivot).
bool cholesky_solve_factored(const MatXd& L, VecXd& b);

// Both: H is overwritten by its factor and b by the solution of H x = b. false when H is not positive
// definite.
bool cholesky_solve(MatXd& H, VecXd& b);

}  // namespace lidef
