// Spectral subspace reduction of Liao et al. 2021, Sec. 6.2: y = Ξ_s ỹ with Ξ_s the s eigenvectors of KᵀK
// (K = smoothness_matrix) with the smallest eigenvalues. The smoothest directions come first; the null space
// of KᵀK is exactly the per-column affine space, so the identity and every affine map lie in span Ξ_s.
//
// Construction (both solvers): the 4 null directions are built exactly — an orthonormalised basis Q of
// {[v_x; n_x], [v_y; n_y], [v_z; n_z], [1; 0]} — and the remaining s − 4 columns are the smallest
// eigenvectors of KᵀK restricted to Q's orthogonal complement. Columns are ordered by ascending eigenvalue,
// each column's sign is fixed (largest-magnitude entry positive), so the basis is reproducible.
#pragma once
#include <cstdint>
#include <string>

#include "lidef/cage.h"
#include "lidef/types.h"

namespace lidef {

enum class SubspaceSolver {
  Auto,    // Dense when #V+#F <= kDenseSubspaceLimit or s is a large fraction of #V+#F, otherwise Sparse
  Dense,   // Eigen::SelfAdjointEigenSolver on the dense #V+#F square matrix (O(n³), exact full spectrum);
           // LAPACK dsyevd where Eigen's QR iteration does not converge
  Sparse,  // Spectra Lanczos, shift-invert (sparse LDLᵀ of KᵀK − σI, σ < 0) on the deflated complement
};

// Above this many coefficients Auto uses the sparse solver (see docs/sampling-and-subspace.md for timings).
constexpr int kDenseSubspaceLimit = 1000;

struct SpectralSubspace {
  MatXd basis;                  // #V+#F by s, orthonormal columns, ascending eigenvalue
  VecXd eigenvalues;            // s, ascending, >= 0 (the first 4 are the affine null space, ~1e-25)
  std::uint64_t cage_hash = 0;  // subspace_cage_hash(cage) of the cage it was computed for
  std::string solver;  // "dense", "dense, LAPACK dsyevd" (Eigen did not converge), "sparse", or "cache"
  double seconds = 0;           // wall time of the computation (or of the load)
  int size() const { return static_cast<int>(basis.cols()); }
};

// Computes the subspace. s is clamped to #V+#F; s < 4 (cannot hold the affine maps) throws InputError.
// Throws NumericalError if the eigen-solver does not converge.
SpectralSubspace compute_subspace(const Cage& cage, int s = 300,
                                  SubspaceSolver solver = SubspaceSolver::Auto);

// FNV-1a 64 of the cage's exact vertex bytes (#V by 3 doubles, row-major) and face bytes (#F by 3 int32).
std::uint64_t subspace_cage_hash(const Cage& cage);

// $LIDEF_CACHE_DIR, else $XDG_CACHE_HOME/lidef, else $HOME/.cache/lidef; "" when none of them is set.
std::string default_cache_dir();

// Path of the cache file for (cage, s) in cache_dir: <cache_dir>/subspace-<hash16hex>-s<s>.bin
// (s after clamping to #V+#F).
std::string subspace_cache_path(const Cage& cage, int s, const std::string& cache_dir);

// Returns the cached subspace for (cage, s) if cache_dir holds a valid file for it, otherwise computes it
// (SubspaceSolver::Auto) and writes the file atomically (temp file + rename). A corrupt, truncated or
// mismatching file is ignored and overwritten; a cache directory that cannot be written only costs the
// cache. cache_dir == "" disables caching.
//
// File format (native little-endian):
//   char[8] "LIDEFSUB" | u32 version (1) | u32 0x01020304 (byte-order check) | i64 n = #V+#F | i64 s |
//   u64 cage hash | u64 FNV-1a 64 of the payload | payload: s doubles eigenvalues, n*s doubles basis
//   (column-major).
SpectralSubspace load_or_compute_subspace(const Cage& cage, int s, const std::string& cache_dir);

}  // namespace lidef
