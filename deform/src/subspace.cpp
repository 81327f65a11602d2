#include "lidef/subspace.h"

#include <Spectra/SymEigsSolver.h>
#include <unistd.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <vector>

#include "lidef/atomic_file.h"
#include "lidef/errors.h"
#include "lidef/hash.h"
#include "lidef/internal/stopwatch.h"
#include "lidef/smoothness.h"

extern "C" {
// LAPACK (OpenBLAS): eigenvalues and eigenvectors of a symmetric matrix, divide and conquer.
void dsyevd_(const char* jobz, const char* uplo, const int* n, double* a, const int* lda, double* w,
             double* work, const int* lwork, int* iwork, const int* liwork, int* info);
}

namespace lidef {

namespace {

using SpMat = Eigen::SparseMatrix<double>;

// Orthonormalises the columns of X in place, in order, against Q's columns first (modified Gram–Schmidt,
// applied twice: "twice is enough" for full working accuracy). Throws if a column becomes dependent.
void orthonormalize_against(MatXd& X, const MatXd& Q, const char* what) {
  for (int j = 0; j < X.cols(); ++j) {
    for (int pass = 0; pass < 2; ++pass) {
      for (int i = 0; i < Q.cols(); ++i) X.col(j) -= Q.col(i).dot(X.col(j)) * Q.col(i);
      for (int i = 0; i < j; ++i) X.col(j) -= X.col(i).dot(X.col(j)) * X.col(i);
    }
    const double nrm = X.col(j).norm();
    if (!(nrm > 1e-8))
      throw NumericalError(std::string(what) + ": column " + std::to_string(j) + " is dependent");
    X.col(j) /= nrm;
  }
}

// Makes the columns of X (nearly orthonormal, as eigen-solvers return them) exactly orthogonal to Q's and
// orthonormal among themselves, by block projection and Cholesky QR, each done twice. On an X whose Gram
// matrix is ≈ I this is as accurate as Gram–Schmidt, keeps each column ≈ where it was (the factor is ≈ I),
// and runs as matrix products instead of O(n s²) vector operations.
void block_orthonormalize_against(MatXd& X, const MatXd& Q) {
  for (int pass = 0; pass < 2; ++pass) {
    X.noalias() -= Q * (Q.transpose() * X);
    const MatXd G = X.transpose() * X;
    Eigen::LLT<MatXd> llt(G);
    if (llt.info() != Eigen::Success)
      throw NumericalError("spectral subspace: eigenvectors are numerically dependent (Cholesky QR failed)");
    llt.matrixU().solveInPlace<Eigen::OnTheRight>(X);
  }
}

// Orthonormal basis (#V+#F by 4) of the per-column affine space, the exact null space of K.
MatXd affine_null_basis(const Cage& cage) {
  const int nv = cage.num_vertices(), n = cage.num_coeffs();
  MatXd Q = MatXd::Zero(n, 4);
  for (int a = 0; a < 3; ++a) {
    Q.col(a).head(nv) = cage.V.col(a);
    Q.col(a).tail(cage.num_faces()) = cage.N.col(a);
  }
  Q.col(3).head(nv).setOnes();
  // Translation first: it is the best-conditioned direction, and the order fixes the basis.
  MatXd X(n, 4);
  X << Q.col(3), Q.leftCols(3);
  orthonormalize_against(X, MatXd(n, 0), "affine null basis");
  return X;
}

// Flips each column so that its largest-magnitude entry (first one on near-ties) is positive.
void fix_signs(MatXd& X) {
  for (int j = 0; j < X.cols(); ++j) {
    const double mx = X.col(j).cwiseAbs().maxCoeff();
    for (int i = 0; i < X.rows(); ++i)
      if (std::abs(X(i, j)) >= (1.0 - 1e-8) * mx) {
        if (X(i, j) < 0) X.col(j) = -X.col(j);
        break;
      }
  }
}

// All eigenpairs of the symmetric D (ascending) by LAPACK's divide and conquer (OpenBLAS's dsyevd).
bool lapack_symmetric_eigen(MatXd D, MatXd& vecs, VecXd& vals) {
  const int n = static_cast<int>(D.rows());
  VecXd w(n);
  int lwork = -1, liwork = -1, info = 0, iwork_query = 0;
  double work_query = 0;
  dsyevd_("V", "L", &n, D.data(), &n, w.data(), &work_query, &lwork, &iwork_query, &liwork, &info);
  if (info != 0) return false;
  lwork = static_cast<int>(work_query);
  liwork = iwork_query;
  std::vector<double> work(static_cast<size_t>(std::max(1, lwork)));
  std::vector<int> iwork(static_cast<size_t>(std::max(1, liwork)));
  dsyevd_("V", "L", &n, D.data(), &n, w.data(), work.data(), &lwork, iwork.data(), &liwork, &info);
  if (info != 0) return false;
  vecs = std::move(D);
  vals = std::move(w);
  return true;
}

// Smallest `m` eigenpairs of M = KᵀK on Q's orthogonal complement, dense: the Q directions are lifted above
// the whole spectrum (M + μ QQᵀ, μ > λ_max) so that the lowest m eigenvectors are those of the complement.
// Eigen's tridiagonal QR iteration can stop at its iteration limit without converging: measured on the
// project's ball cage in its normalized frame with -march=native code on an AMD EPYC (never on the Xeon the
// project was first measured on). LAPACK's dsyevd then computes the same eigenpairs; returns whether it was
// needed.
bool complement_dense(const SpMat& M, const MatXd& Q, int m, MatXd& vecs, VecXd& vals) {
  MatXd D = MatXd(M);
  const double mu = 2.0 * D.trace() + 1.0;  // trace >= λ_max for a PSD matrix
  D.noalias() += mu * Q * Q.transpose();
  Eigen::SelfAdjointEigenSolver<MatXd> es(D);
  if (es.info() == Eigen::Success) {
    vecs = es.eigenvectors().leftCols(m);
    vals = es.eigenvalues().head(m);
    return false;
  }
  MatXd all_vecs;
  VecXd all_vals;
  if (!lapack_symmetric_eigen(std::move(D), all_vecs, all_vals))
    throw NumericalError("spectral subspace: the dense eigen-solvers (Eigen's, then LAPACK dsyevd) failed");
  vecs = all_vecs.leftCols(m);
  vals = all_vals.head(m);
  return true;
}

// y = P (M − σI)^{-1} P x with P = I − QQᵀ: the largest eigenvalues ν of this operator are 1/(λ − σ) for
// the smallest complement eigenvalues λ; the Q directions map to 0 and can never be selected.
class DeflatedShiftInvert {
 public:
  using Scalar = double;
  DeflatedShiftInvert(const Eigen::SimplicialLDLT<SpMat>& ldlt, const MatXd& Q) : ldlt_(ldlt), Q_(Q) {}
  Eigen::Index rows() const { return Q_.rows(); }
  Eigen::Index cols() const { return Q_.rows(); }
  void perform_op(const double* x_in, double* y_out) const {
    Eigen::Map<const VecXd> x(x_in, rows());
    Eigen::Map<VecXd> y(y_out, rows());
    VecXd px = x - Q_ * (Q_.transpose() * x);
    y = ldlt_.solve(px);
    y -= Q_ * (Q_.transpose() * y);
  }

 private:
  const Eigen::SimplicialLDLT<SpMat>& ldlt_;
  const MatXd& Q_;
};

void complement_sparse(const SpMat& M, const MatXd& Q, int m, MatXd& vecs, VecXd& vals) {
  const int n = static_cast<int>(M.rows());
  // σ < 0 keeps M − σI positive definite (M is singular), so a sparse LDLᵀ without pivoting is safe.
  // Its size relative to the mean diagonal only needs to sit well below λ_5; deflation takes care of λ_1..4.
  const double sigma = -1e-6 * M.diagonal().mean();
  SpMat S = M;
  for (int i = 0; i < n; ++i) S.coeffRef(i, i) -= sigma;
  Eigen::SimplicialLDLT<SpMat> ldlt(S);
  if (ldlt.info() != Eigen::Success) throw NumericalError("spectral subspace: LDLT of KᵀK − σI failed");
  DeflatedShiftInvert op(ldlt, Q);
  const int ncv = std::min(n - 4, std::max(2 * m + 1, m + 40));
  Spectra::SymEigsSolver<DeflatedShiftInvert> eigs(op, m, ncv);
  eigs.init();  // Spectra's fixed-seed start vector: deterministic
  eigs.compute(Spectra::SortRule::LargestAlge, 1000, 1e-10, Spectra::SortRule::LargestAlge);
  if (eigs.info() != Spectra::CompInfo::Successful)
    throw NumericalError("spectral subspace: Spectra did not converge (" + std::to_string(m) + " of " +
                         std::to_string(n) + " eigenpairs, " + std::to_string(eigs.num_iterations()) +
                         " restarts)");
  const VecXd nu = eigs.eigenvalues();  // descending ν  <=>  ascending λ
  vecs = eigs.eigenvectors();
  vals.resize(m);
  for (int i = 0; i < m; ++i) vals(i) = sigma + 1.0 / nu(i);
}

constexpr char kMagic[8] = {'L', 'I', 'D', 'E', 'F', 'S', 'U', 'B'};
constexpr std::uint32_t kVersion = 1;
constexpr std::uint32_t kByteOrder = 0x01020304;

#pragma pack(push, 1)
struct CacheHeader {
  char magic[8];
  std::uint32_t version;
  std::uint32_t byte_order;
  std::int64_t n;
  std::int64_t s;
  std::uint64_t cage_hash;
  std::uint64_t payload_hash;
};
#pragma pack(pop)

int clamp_s(const Cage& cage, int s) {
  if (s < 4)
    throw InputError(cage.source, "spectral subspace: s = " + std::to_string(s) +
                                      " cannot hold the 4-dim affine space (need s >= 4)");
  return std::min(s, cage.num_coeffs());
}

// Reads a cache file; returns false (never throws) when it is missing, truncated, corrupt or for another
// cage.
bool read_cache(const std::string& path, std::int64_t n, std::int64_t s, std::uint64_t cage_hash,
                SpectralSubspace& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::vector<char> buf((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t payload = sizeof(double) * static_cast<size_t>(s + n * s);
  if (buf.size() != sizeof(CacheHeader) + payload) return false;
  CacheHeader h;
  std::memcpy(&h, buf.data(), sizeof h);
  if (std::memcmp(h.magic, kMagic, 8) != 0 || h.version != kVersion || h.byte_order != kByteOrder ||
      h.n != n || h.s != s || h.cage_hash != cage_hash)
    return false;
  const char* p = buf.data() + sizeof h;
  if (fnv1a64(p, payload) != h.payload_hash) return false;
  out.eigenvalues.resize(s);
  out.basis.resize(n, s);
  std::memcpy(out.eigenvalues.data(), p, sizeof(double) * s);
  std::memcpy(out.basis.data(), p + sizeof(double) * s, sizeof(double) * n * s);
  return out.basis.allFinite() && out.eigenvalues.allFinite();
}

void write_cache(const std::string& path, const SpectralSubspace& sub) {
  CacheHeader h;
  std::memcpy(h.magic, kMagic, 8);
  h.version = kVersion;
  h.byte_order = kByteOrder;
  h.n = sub.basis.rows();
  h.s = sub.basis.cols();
  h.cage_hash = sub.cage_hash;
  std::uint64_t ph = fnv1a64(sub.eigenvalues.data(), sizeof(double) * sub.eigenvalues.size());
  h.payload_hash = fnv1a64(sub.basis.data(), sizeof(double) * sub.basis.size(), ph);
  // Atomic (a unique temporary per process and call, renamed): two processes filling the same cache never see
  // each other's half-written file.
  write_file_atomic(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(&h), sizeof h);
    out.write(reinterpret_cast<const char*>(sub.eigenvalues.data()), sizeof(double) * sub.eigenvalues.size());
    out.write(reinterpret_cast<const char*>(sub.basis.data()), sizeof(double) * sub.basis.size());
  });
}

}  // namespace

SpectralSubspace compute_subspace(const Cage& cage, int s, SubspaceSolver solver) {
  const auto t0 = Clock::now();
  s = clamp_s(cage, s);
  const int n = cage.num_coeffs(), m = s - 4;
  const SpMat K = smoothness_matrix(cage);
  const SpMat M = SpMat(K.transpose() * K);
  const MatXd Q = affine_null_basis(cage);

  if (solver == SubspaceSolver::Auto)
    solver = (n <= kDenseSubspaceLimit || 3 * m > n) ? SubspaceSolver::Dense : SubspaceSolver::Sparse;
  // Lanczos on the (n − 4)-dim complement needs room for its Krylov basis.
  if (solver == SubspaceSolver::Sparse && 2 * m + 1 > n - 4) solver = SubspaceSolver::Dense;

  MatXd vecs;
  VecXd vals;
  bool lapack = false;
  if (m > 0) {
    if (solver == SubspaceSolver::Dense)
      lapack = complement_dense(M, Q, m, vecs, vals);
    else
      complement_sparse(M, Q, m, vecs, vals);
    // The solvers return the complement eigenvectors orthogonal to Q only up to rounding; make it exact so
    // that span(basis) ⊇ affine maps holds to machine precision.
    block_orthonormalize_against(vecs, Q);
  } else {
    vecs.resize(n, 0);
    vals.resize(0);
  }

  SpectralSubspace out;
  out.basis.resize(n, s);
  out.basis << Q, vecs;
  fix_signs(out.basis);
  out.eigenvalues.resize(s);
  // The null directions: report the Rayleigh quotient ‖K q‖² (exactly 0 in exact arithmetic).
  for (int j = 0; j < 4; ++j) out.eigenvalues(j) = (K * out.basis.col(j)).squaredNorm();
  out.eigenvalues.tail(m) = vals;
  out.cage_hash = subspace_cage_hash(cage);
  out.solver = solver == SubspaceSolver::Dense ? (lapack ? "dense, LAPACK dsyevd" : "dense") : "sparse";
  out.seconds = seconds_since(t0);
  return out;
}

std::uint64_t subspace_cage_hash(const Cage& cage) {
  const std::int64_t sizes[2] = {cage.num_vertices(), cage.num_faces()};
  std::uint64_t h = fnv1a64(sizes, sizeof sizes);
  h = fnv1a64(cage.V.data(), sizeof(double) * cage.V.size(), h);
  std::vector<std::int32_t> f(cage.F.data(), cage.F.data() + cage.F.size());
  return fnv1a64(f.data(), sizeof(std::int32_t) * f.size(), h);
}

std::string default_cache_dir() {
  if (const char* d = std::getenv("LIDEF_CACHE_DIR"); d && *d) return d;
  if (const char* d = std::getenv("XDG_CACHE_HOME"); d && *d) return std::string(d) + "/lidef";
  if (const char* d = std::getenv("HOME"); d && *d) return std::string(d) + "/.cache/lidef";
  return "";
}

std::string subspace_cache_path(const Cage& cage, int s, const std::string& cache_dir) {
  s = clamp_s(cage, s);
  char name[64];
  std::snprintf(name, sizeof name, "subspace-%016llx-s%d.bin",
                static_cast<unsigned long long>(subspace_cage_hash(cage)), s);
  return (std::filesystem::path(cache_dir) / name).string();
}

SpectralSubspace load_or_compute_subspace(const Cage& cage, int s, const std::string& cache_dir) {
  s = clamp_s(cage, s);
  if (cache_dir.empty()) return compute_subspace(cage, s);
  const auto t0 = Clock::now();
  const std::string path = subspace_cache_path(cage, s, cache_dir);
  SpectralSubspace sub;
  sub.cage_hash = subspace_cage_hash(cage);
  if (read_cache(path, cage.num_coeffs(), s, sub.cage_hash, sub)) {
    sub.solver = "cache";
    sub.seconds = seconds_since(t0);
    return sub;
  }
  sub = compute_subspace(cage, s);
  try {
    std::error_code ec;
    std::filesystem::create_directories(cache_dir, ec);
    write_cache(path, sub);
  } catch (const Error& e) {
    // The cache is an optimisation: a read-only or full disk must not stop a deformation.
    std::cerr << "lidef: warning: subspace not cached: " << e.what() << "\n";
  }
  return sub;
}

}  // namespace lidef
