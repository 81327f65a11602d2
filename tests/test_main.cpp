#include <gtest/gtest.h>

#include "lidef/blas_kernel.h"

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::blas_environment());  // OpenBLAS kernels: blas_kernel.h
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
