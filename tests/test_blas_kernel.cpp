// The OpenBLAS kernel choice (lidef/blas_kernel.h): lidef_core selects OpenBLAS's kernels again in-process
// when OpenBLAS ran its SSE3 fallback on a CPU it does not know, so no program re-executes itself for it.
#include <gtest/gtest.h>
#include <omp.h>

#include <cstdlib>
#include <random>
#include <string>

#include "lidef/blas_kernel.h"
#include "lidef/errors.h"
#include "test_support.h"

extern "C" int openblas_get_num_threads(void);

namespace {

TEST(BlasKernel, TheTestProcessRunsKernelsItsCpuSupports) {
  // test_main.cpp does not re-execute: were the in-process selection missing on a CPU model OpenBLAS does not
  // know, the core would be the fallback "Prescott" and `recommended` would name a better one.
  const lidef::BlasKernelInfo info = lidef::blas_kernel_info();
  EXPECT_FALSE(info.core.empty());
  EXPECT_TRUE(info.recommended.empty())
      << "OpenBLAS runs " << info.core << " on a CPU that supports " << info.recommended;
  if (!info.replaced.empty()) {
    EXPECT_NE(info.core, info.replaced);
  }
  // Nothing left for a re-executed process to set.
  EXPECT_TRUE(lidef::blas_environment().empty());
}

// The mechanism itself, on any CPU with AVX2/FMA (so also where OpenBLAS knows the CPU and nothing needed
// replacing): selecting Haswell's kernels in-process takes effect at once, the products stay right, the
// environment is left as it was, and the process's own choice comes back.
TEST(BlasKernel, SelectingACoreInProcessSwitchesTheKernels) {
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) GTEST_SKIP() << "no AVX2/FMA";
  const std::string before = lidef::blas_kernel_info().core;
  const char* env = std::getenv("OPENBLAS_CORETYPE");
  const std::string env_before = env ? env : "<unset>";
  const std::string other = before == "Haswell" ? "Sandybridge" : "Haswell";
  ASSERT_TRUE(lidef::select_blas_core(other)) << "OpenBLAS runs " << lidef::blas_kernel_info().core;
  EXPECT_EQ(lidef::blas_kernel_info().core, other);
  env = std::getenv("OPENBLAS_CORETYPE");
  EXPECT_EQ(env ? env : "<unset>", env_before);
  std::mt19937 rng(5);
  std::normal_distribution<double> N01;
  lidef::MatXdR A(64, 70), C;
  lidef::MatXd B(70, 33);
  for (Eigen::Index i = 0; i < A.size(); ++i) A.data()[i] = N01(rng);
  for (Eigen::Index i = 0; i < B.size(); ++i) B.data()[i] = N01(rng);
  lidef::blas_product(A, B, C);
  const lidef::MatXd ref = A * B;
  EXPECT_LT((C - ref).cwiseAbs().maxCoeff(), 1e-12 * (A.cwiseAbs() * B.cwiseAbs()).maxCoeff());
  EXPECT_FALSE(lidef::select_blas_core("NoSuchCore"));
  ASSERT_TRUE(lidef::select_blas_core(before));
  EXPECT_EQ(lidef::blas_kernel_info().core, before);
}

TEST(BlasKernel, TheCliReportsItsKernelsAndKeepsTheUsersChoice) {
  std::string out;
  ASSERT_EQ(lidef::test::run_command("env -u OPENBLAS_CORETYPE " + lidef::test::cli() + " devices", &out), 0)
      << out;
  EXPECT_NE(out.find("CPU backend: OpenBLAS kernels "), std::string::npos) << out;
  EXPECT_EQ(out.find("this CPU supports"), std::string::npos) << out;  // the fallback was replaced
  EXPECT_EQ(out.find("kernels Prescott"), std::string::npos) << out;
  // A user's OPENBLAS_CORETYPE is kept as it is (Haswell's kernels run on every x86-64 CPU with AVX2).
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) GTEST_SKIP() << "no AVX2/FMA";
  ASSERT_EQ(lidef::test::run_command("OPENBLAS_CORETYPE=Haswell " + lidef::test::cli() + " devices", &out), 0)
      << out;
  EXPECT_NE(out.find("CPU backend: OpenBLAS kernels Haswell (OPENBLAS_CORETYPE)"), std::string::npos) << out;
}

TEST(BlasKernel, ProductOfRowMajorAndColumnMajorMatchesEigen) {
  // blas_product (the precomputation's basis derivatives times Ξ) against Eigen's product, with shapes that
  // are not multiples of any kernel's block.
  std::mt19937 rng(3);
  std::normal_distribution<double> N01;
  lidef::MatXdR A(37, 53), C;
  lidef::MatXd B(53, 11);
  for (Eigen::Index i = 0; i < A.size(); ++i) A.data()[i] = N01(rng);
  for (Eigen::Index i = 0; i < B.size(); ++i) B.data()[i] = N01(rng);
  lidef::blas_product(A, B, C);
  const lidef::MatXd ref = A * B;
  ASSERT_EQ(C.rows(), 37);
  ASSERT_EQ(C.cols(), 11);
  EXPECT_LT((C - ref).cwiseAbs().maxCoeff(), 1e-12 * (A.cwiseAbs() * B.cwiseAbs()).maxCoeff());
  EXPECT_THROW(lidef::blas_product(A, lidef::MatXd(52, 11), C), lidef::Error);
  EXPECT_NE(lidef::blas_numerics().find('/'), std::string::npos);
  // All column-major (the studio's mesh matrices times ỹ: a tall A, 3 columns).
  const lidef::MatXd Ac = lidef::MatXd(A).replicate(40, 1);  // 1480 by 53
  lidef::MatXd Cc;
  lidef::blas_product(Ac, B.leftCols(3), Cc);
  const lidef::MatXd refc = Ac * B.leftCols(3);
  ASSERT_EQ(Cc.rows(), 1480);
  ASSERT_EQ(Cc.cols(), 3);
  EXPECT_LT((Cc - refc).cwiseAbs().maxCoeff(), 1e-12 * (Ac.cwiseAbs() * B.leftCols(3).cwiseAbs()).maxCoeff());
  EXPECT_THROW(lidef::blas_product(Ac, lidef::MatXd(52, 3), Cc), lidef::Error);
}

// gemm_parallel splits C's columns (or rows, for few columns) over OpenMP's threads, OpenBLAS running in each
// calling thread: every transpose combination, both precisions and both split directions against Eigen, and
// the same result with 1 and 2 threads (each element is still one call's sum over the whole k).
TEST(BlasKernel, ParallelGemmMatchesEigenInEverySplit) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1);
  auto random = [&](int r, int c) {
    lidef::MatXd M(r, c);
    for (Eigen::Index i = 0; i < M.size(); ++i) M.data()[i] = U(rng);
    return M;
  };
  const int k = 77;
  for (const auto& [m, n] : {std::pair{301, 95}, std::pair{1200, 3}, std::pair{5, 5}}) {
    for (const bool ta : {false, true})
      for (const bool tb : {false, true}) {
        const lidef::MatXd A = ta ? random(k, m) : random(m, k), B = tb ? random(n, k) : random(k, n);
        const lidef::MatXd ref =
            (ta ? lidef::MatXd(A.transpose()) : A) * (tb ? lidef::MatXd(B.transpose()) : B);
        const double scale = static_cast<double>(k);  // |entries| ≤ 1
        lidef::MatXd C1(m, n), C2(m, n);
        const int saved = omp_get_max_threads();
        omp_set_num_threads(1);
        lidef::gemm_parallel(ta, tb, m, n, k, A.data(), static_cast<int>(A.rows()), B.data(),
                             static_cast<int>(B.rows()), C1.data(), m);
        omp_set_num_threads(2);
        lidef::gemm_parallel(ta, tb, m, n, k, A.data(), static_cast<int>(A.rows()), B.data(),
                             static_cast<int>(B.rows()), C2.data(), m);
        omp_set_num_threads(saved);
        EXPECT_LT((C1 - ref).cwiseAbs().maxCoeff(), 1e-13 * scale) << m << "x" << n << " " << ta << tb;
        EXPECT_LT((C2 - C1).cwiseAbs().maxCoeff(), 1e-13 * scale) << m << "x" << n << " " << ta << tb;
        const Eigen::MatrixXf Af = A.cast<float>(), Bf = B.cast<float>();
        Eigen::MatrixXf Cf(m, n);
        lidef::gemm_parallel(ta, tb, m, n, k, Af.data(), static_cast<int>(Af.rows()), Bf.data(),
                             static_cast<int>(Bf.rows()), Cf.data(), m);
        EXPECT_LT((Cf.cast<double>() - ref).cwiseAbs().maxCoeff(), 1e-5 * scale) << m << "x" << n;
      }
  }
}

}  // namespace

// lidef's kernels leave OpenBLAS one thread for the whole process; a comparison method that calls BLAS
// through CHOLMOD gets the run's threads back for its scope, and lidef its one thread after it.
TEST(BlasKernel, ScopedBlasThreadsRestoresTheCallingThreadSetting) {
  lidef::use_blas_in_calling_thread();
  ASSERT_EQ(openblas_get_num_threads(), 1);
  {
    const lidef::ScopedBlasThreads blas(2);
    EXPECT_EQ(openblas_get_num_threads(), 2);
  }
  EXPECT_EQ(openblas_get_num_threads(), 1);
  {
    const lidef::ScopedBlasThreads none(0);  // at least one thread
    EXPECT_EQ(openblas_get_num_threads(), 1);
  }
}
