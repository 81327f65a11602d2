// Tests of the spectral subspace (paper Sec. 6.2) and its disk cache.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <tuple>

#include "lidef/cage.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/normalization.h"
#include "lidef/smoothness.h"
#include "lidef/subspace.h"
#include "test_support.h"

namespace lidef {
namespace {

// Box [0,sx]x[0,sy]x[0,sz] with each side split into n x n quads (2 triangles each), CCW seen from outside.
TriMesh grid_box_mesh(int n, double sx, double sy, double sz) {
  std::vector<Vec3> V;
  std::vector<Eigen::Vector3i> F;
  std::map<std::tuple<int, int, int>, int> id;
  auto vid = [&](int i, int j, int k) {
    auto key = std::make_tuple(i, j, k);
    auto it = id.find(key);
    if (it != id.end()) return it->second;
    V.emplace_back(sx * i / n, sy * j / n, sz * k / n);
    return id[key] = static_cast<int>(V.size()) - 1;
  };
  // For each axis a and side s, the face grid spanned by the other two axes (b, c) with b × c = ±a.
  for (int a = 0; a < 3; ++a)
    for (int side = 0; side < 2; ++side) {
      const int b = (a + 1) % 3, c = (a + 2) % 3;
      for (int u = 0; u < n; ++u)
        for (int v = 0; v < n; ++v) {
          int q[4];
          const int uu[4] = {u, u + 1, u + 1, u}, vv[4] = {v, v, v + 1, v + 1};
          for (int m = 0; m < 4; ++m) {
            int ijk[3];
            ijk[a] = side * n, ijk[b] = uu[m], ijk[c] = vv[m];
            q[m] = vid(ijk[0], ijk[1], ijk[2]);
          }
          // (b, c) counter-clockwise has normal +a: keep it on the far side, flip it on the near side.
          if (side == 1) {
            F.emplace_back(q[0], q[1], q[2]);
            F.emplace_back(q[0], q[2], q[3]);
          } else {
            F.emplace_back(q[0], q[2], q[1]);
            F.emplace_back(q[0], q[3], q[2]);
          }
        }
    }
  TriMesh m;
  m.V.resize(V.size(), 3);
  for (size_t i = 0; i < V.size(); ++i) m.V.row(i) = V[i];
  m.F.resize(F.size(), 3);
  for (size_t i = 0; i < F.size(); ++i) m.F.row(i) = F[i].transpose();
  m.source = "grid box";
  return m;
}

// Residual of projecting the columns of Y (n by k) onto span(B) (orthonormal columns), relative to ‖Y‖.
double projection_residual(const MatXd& B, const MatXd& Y) {
  return (Y - B * (B.transpose() * Y)).norm() / Y.norm();
}

// All affine coefficient columns: 12 maps (A = e_i e_jᵀ, b = 0 and A = 0, b = e_i) give the whole space.
MatXd affine_columns(const Cage& cage) {
  MatXd Y(cage.num_coeffs(), 12 * 3);
  int c = 0;
  for (int k = 0; k < 12; ++k) {
    Mat3 A = Mat3::Zero();
    Vec3 b = Vec3::Zero();
    if (k < 9)
      A(k / 3, k % 3) = 1;
    else
      b(k - 9) = 1;
    const MatX3d y = cage.affine_coefficients(A, b);
    for (int j = 0; j < 3; ++j) Y.col(c++) = y.col(j);
  }
  return Y;
}

void check_subspace(const Cage& cage, const SpectralSubspace& sub, int s) {
  const int n = cage.num_coeffs();
  ASSERT_EQ(sub.basis.rows(), n);
  ASSERT_EQ(sub.basis.cols(), std::min(s, n));
  ASSERT_EQ(sub.eigenvalues.size(), sub.basis.cols());
  // Orthonormal columns.
  EXPECT_LT(
      (sub.basis.transpose() * sub.basis - MatXd::Identity(sub.size(), sub.size())).cwiseAbs().maxCoeff(),
      1e-12);
  // The identity and every affine map lie in the span.
  EXPECT_LT(projection_residual(sub.basis, cage.identity_coefficients()), 1e-10);
  EXPECT_LT(projection_residual(sub.basis, affine_columns(cage)), 1e-10);
  // Ascending, nonnegative eigenvalues; exactly 4 (numerically) zero ones on a connected cage.
  const auto K = smoothness_matrix(cage);
  const Eigen::SparseMatrix<double> M = K.transpose() * K;
  const double scale = M.diagonal().maxCoeff();
  for (int i = 0; i < sub.size(); ++i) {
    EXPECT_GE(sub.eigenvalues(i), -1e-9) << i;
    if (i > 0) {
      EXPECT_GE(sub.eigenvalues(i), sub.eigenvalues(i - 1) - 1e-12 * scale) << i;
    }
    // Each column is an eigenvector of KᵀK for its eigenvalue.
    const VecXd r = M * sub.basis.col(i) - sub.eigenvalues(i) * sub.basis.col(i);
    EXPECT_LT(r.norm(), 1e-8 * scale) << i;
  }
  if (sub.size() > 4) {
    EXPECT_GT(sub.eigenvalues(4), 1e-8 * scale);
  }
  EXPECT_LT(sub.eigenvalues.head(4).maxCoeff(), 1e-20 * scale);
}

TEST(Subspace, DenseMatchesFullSpectrumOnSmallCage) {
  const Cage cage(grid_box_mesh(3, 1.0, 0.8, 1.2));
  const int n = cage.num_coeffs();
  const SpectralSubspace sub = compute_subspace(cage, 40, SubspaceSolver::Dense);
  check_subspace(cage, sub, 40);
  EXPECT_EQ(sub.solver, "dense");
  // Independent truth: the full spectrum of KᵀK by a dense eigen-solver, no deflation.
  const auto K = smoothness_matrix(cage);
  const Eigen::MatrixXd M = Eigen::MatrixXd(K.transpose() * K);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(M);
  const VecXd ev = es.eigenvalues();
  EXPECT_LT((sub.eigenvalues - ev.head(40)).cwiseAbs().maxCoeff(), 1e-10 * ev(n - 1));
  // s is clamped to #V+#F.
  const SpectralSubspace all = compute_subspace(cage, 100000);
  EXPECT_EQ(all.size(), n);
  EXPECT_LT((all.eigenvalues - ev).cwiseAbs().maxCoeff(), 1e-10 * ev(n - 1));
}

TEST(Subspace, SparseAgreesWithDense) {
  const Cage cage(grid_box_mesh(6, 1.0, 0.8, 1.2));
  const int s = 60;
  const SpectralSubspace d = compute_subspace(cage, s, SubspaceSolver::Dense);
  const SpectralSubspace sp = compute_subspace(cage, s, SubspaceSolver::Sparse);
  EXPECT_EQ(sp.solver, "sparse");
  check_subspace(cage, sp, s);
  const double top = d.eigenvalues.maxCoeff();
  EXPECT_LT((d.eigenvalues - sp.eigenvalues).cwiseAbs().maxCoeff(), 1e-9 * top);
  // Same spaces, cluster by cluster (the box's symmetry makes some eigenvalues multiple, so compare the
  // spans of the first k columns where k ends a cluster).
  for (int k = 8; k < s; ++k) {
    if (d.eigenvalues(k) - d.eigenvalues(k - 1) < 1e-6 * top) continue;
    EXPECT_LT(projection_residual(d.basis.leftCols(k), sp.basis.leftCols(k)), 1e-6) << k;
  }
}

// The project's ball cage in its normalized frame: Eigen's dense solver stops at its iteration limit without
// converging on this matrix on an AMD EPYC (-march=native), and LAPACK dsyevd takes over; elsewhere Eigen
// converges. Either way the basis must be an eigenbasis with the sparse (Spectra) solver's eigenvalues.
TEST(Subspace, NormalizedBallCageGetsAnEigenbasisFromEitherDenseSolver) {
  const Model ball = load_model(lidef::test::project_data() + "/models/ball");
  const Cage cage = Frame::of(ball.cage).normalized(ball.cage);
  const int s = 50;
  const SpectralSubspace d = compute_subspace(cage, s, SubspaceSolver::Dense);
  EXPECT_TRUE(d.solver == "dense" || d.solver == "dense, LAPACK dsyevd") << d.solver;
  std::cout << "[ note ] dense solver on the normalized ball cage: " << d.solver << "\n";
  check_subspace(cage, d, s);
  const SpectralSubspace sp = compute_subspace(cage, s, SubspaceSolver::Sparse);
  const double top = d.eigenvalues.maxCoeff();
  EXPECT_LT((d.eigenvalues - sp.eigenvalues).cwiseAbs().maxCoeff(), 1e-9 * top);
  for (int k = 8; k < s; ++k) {
    if (d.eigenvalues(k) - d.eigenvalues(k - 1) < 1e-6 * top) continue;
    EXPECT_LT(projection_residual(d.basis.leftCols(k), sp.basis.leftCols(k)), 1e-6) << k;
  }
}

TEST(Subspace, SharedModelsContainAffineMaps) {
  LIDEF_REQUIRE_SHARED();
  for (const char* name : {"bar", "horse", "spot", "animal"}) {
    const Cage cage(read_mesh(test::shared_model(name) + "/cage.obj"));
    const SpectralSubspace sub = compute_subspace(cage, 300);
    std::printf("[subspace] %-6s n = %4d  s = %3d  solver = %-6s  %.3f s  lambda_5 = %.3e  lambda_s = %.3e\n",
                name, cage.num_coeffs(), sub.size(), sub.solver.c_str(), sub.seconds, sub.eigenvalues(4),
                sub.eigenvalues(sub.size() - 1));
    SCOPED_TRACE(name);
    check_subspace(cage, sub, 300);
  }
}

// Measures both solvers on bar and animal (765 + 1526 coefficients) and checks that they agree. The dense
// solver needs ~40 s on animal, so this runs only with LIDEF_SLOW_TESTS=1 (numbers in
// docs/sampling-and-subspace.md).
TEST(Subspace, AnimalDenseVersusSparse) {
  LIDEF_REQUIRE_SHARED();
  if (!std::getenv("LIDEF_SLOW_TESTS"))
    GTEST_SKIP() << "set LIDEF_SLOW_TESTS=1 to time the dense solver on animal";
  for (const char* name : {"bar", "animal"}) {
    const Cage cage(read_mesh(test::shared_model(name) + "/cage.obj"));
    const SpectralSubspace sp = compute_subspace(cage, 300, SubspaceSolver::Sparse);
    const SpectralSubspace d = compute_subspace(cage, 300, SubspaceSolver::Dense);
    std::printf("[subspace] %-6s n = %4d s = 300: dense %.3f s, sparse (%s) %.3f s\n", name,
                cage.num_coeffs(), d.seconds, sp.solver.c_str(), sp.seconds);
    RecordProperty(std::string(name) + "_dense_seconds", std::to_string(d.seconds));
    RecordProperty(std::string(name) + "_sparse_seconds", std::to_string(sp.seconds));
    const double top = d.eigenvalues.maxCoeff();
    EXPECT_LT((d.eigenvalues - sp.eigenvalues).cwiseAbs().maxCoeff(), 1e-8 * top) << name;
  }
}

TEST(Subspace, DeterministicSigns) {
  const Cage cage(grid_box_mesh(4, 1.0, 0.8, 1.2));
  const SpectralSubspace a = compute_subspace(cage, 30), b = compute_subspace(cage, 30);
  EXPECT_TRUE(a.basis == b.basis);
  // The sign rule: the first entry of largest magnitude (up to a 1e-8 relative tie) is positive. The box
  // is symmetric, so exact ties between entries of opposite sign do occur.
  for (int j = 0; j < a.size(); ++j) {
    const double mx = a.basis.col(j).cwiseAbs().maxCoeff();
    int i = 0;
    while (std::abs(a.basis(i, j)) < (1 - 1e-8) * mx) ++i;
    EXPECT_GT(a.basis(i, j), 0.0) << j;
  }
}

TEST(Subspace, RejectsTooSmallDimension) {
  const Cage cage(grid_box_mesh(1, 1, 1, 1));
  EXPECT_THROW(compute_subspace(cage, 3), InputError);
}

TEST(Subspace, CacheRoundTripIsBitIdentical) {
  test::TempDir dir;
  const Cage cage(grid_box_mesh(4, 1.0, 0.8, 1.2));
  const SpectralSubspace a = load_or_compute_subspace(cage, 30, dir.str());
  const std::string path = subspace_cache_path(cage, 30, dir.str());
  ASSERT_TRUE(std::filesystem::exists(path));
  EXPECT_NE(a.solver, "cache");
  const SpectralSubspace b = load_or_compute_subspace(cage, 30, dir.str());
  EXPECT_EQ(b.solver, "cache");
  EXPECT_TRUE(a.basis == b.basis);
  EXPECT_TRUE(a.eigenvalues == b.eigenvalues);
  EXPECT_EQ(a.cage_hash, b.cage_hash);
  // No temp files left behind.
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path)) files += e.is_regular_file();
  EXPECT_EQ(files, 1);

  // A different s or a moved vertex is a different key.
  EXPECT_NE(subspace_cache_path(cage, 31, dir.str()), path);
  TriMesh moved = grid_box_mesh(4, 1.0, 0.8, 1.2);
  moved.V(0, 0) = std::nextafter(moved.V(0, 0), 1.0);
  EXPECT_NE(subspace_cache_path(Cage(moved), 30, dir.str()), path);
}

TEST(Subspace, CorruptCacheIsRecomputed) {
  test::TempDir dir;
  const Cage cage(grid_box_mesh(4, 1.0, 0.8, 1.2));
  const SpectralSubspace a = load_or_compute_subspace(cage, 30, dir.str());
  const std::string path = subspace_cache_path(cage, 30, dir.str());
  const auto size = std::filesystem::file_size(path);

  // Flip one byte of the payload: the checksum catches it.
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(size - 100));
    f.put('\x5a');
  }
  SpectralSubspace b = load_or_compute_subspace(cage, 30, dir.str());
  EXPECT_NE(b.solver, "cache");
  EXPECT_TRUE(a.basis == b.basis);
  EXPECT_EQ(load_or_compute_subspace(cage, 30, dir.str()).solver, "cache");  // rewritten

  // Truncated file.
  std::filesystem::resize_file(path, size / 2);
  b = load_or_compute_subspace(cage, 30, dir.str());
  EXPECT_NE(b.solver, "cache");
  EXPECT_TRUE(a.basis == b.basis);

  // A valid file of another cage placed under this name (hash mismatch in the header).
  const Cage other(grid_box_mesh(4, 1.0, 0.8, 1.3));
  load_or_compute_subspace(other, 30, dir.str());
  std::filesystem::copy_file(subspace_cache_path(other, 30, dir.str()), path,
                             std::filesystem::copy_options::overwrite_existing);
  b = load_or_compute_subspace(cage, 30, dir.str());
  EXPECT_NE(b.solver, "cache");
  EXPECT_TRUE(a.basis == b.basis);

  // Garbage.
  { std::ofstream(path, std::ios::binary | std::ios::trunc) << "not a cache file"; }
  b = load_or_compute_subspace(cage, 30, dir.str());
  EXPECT_NE(b.solver, "cache");
  EXPECT_TRUE(a.basis == b.basis);
}

TEST(Subspace, UnwritableCacheDirStillComputes) {
  test::TempDir dir;
  const std::string file = dir / "plain_file";
  { std::ofstream(file) << "x"; }
  const Cage cage(grid_box_mesh(2, 1, 1, 1));
  // The "directory" is a regular file: nothing can be cached, the result is still returned.
  const SpectralSubspace sub = load_or_compute_subspace(cage, 10, file + "/sub");
  EXPECT_EQ(sub.size(), 10);
  EXPECT_LT(projection_residual(sub.basis, cage.identity_coefficients()), 1e-10);
}

TEST(Subspace, DefaultCacheDirFollowsEnvironment) {
  const char* old = std::getenv("LIDEF_CACHE_DIR");
  const std::string saved = old ? old : "";
  ::setenv("LIDEF_CACHE_DIR", "/tmp/lidef-cache-test", 1);
  EXPECT_EQ(default_cache_dir(), "/tmp/lidef-cache-test");
  ::unsetenv("LIDEF_CACHE_DIR");
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  if (xdg && *xdg) {
    EXPECT_EQ(default_cache_dir(), std::string(xdg) + "/lidef");
  }
  if (old) ::setenv("LIDEF_CACHE_DIR", saved.c_str(), 1);
}

}  // namespace
}  // namespace lidef
