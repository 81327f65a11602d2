// The studio's solver thread and its UI thread share two cores with Mesa's software renderer. With OpenMP's
// default (active, spinning) wait policy a parallel region stalls whenever the UI thread holds one of the
// cores: dragging on the bar ran 14 Newton steps/s instead of 26 (CHANGELOG.md, 2026-11-22). libgomp
// reads OMP_WAIT_POLICY when it is loaded, before main(), so the process re-executes itself once with it set
// (unless the user set it) — together with the OpenBLAS kernel choice and malloc's huge pages
// (process_environment, lidef/blas_kernel.h), one exec for all.
#pragma once
#include "lidef/blas_kernel.h"

namespace lidef::studio {

inline void ensure_studio_environment(char** argv) {
  auto env = process_environment();
  env.emplace_back("OMP_WAIT_POLICY", "PASSIVE");
  reexec_with_environment(argv, env);
}

}  // namespace lidef::studio
