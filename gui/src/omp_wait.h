// The studio's solver thread and its UI thread share two cores with Mesa's software renderer. With OpenMP's
// default (active, spinning) wait policy a parallel region stalls whenever the UI thread holds one of the
// cores: dragging on the bar ran 14 Newton steps/s instead of 26 (docs/benchmarks.md, "Studio"). libgomp
// reads OMP_WAIT_POLICY when it is loaded, before main(), so the process re-executes itself once with it set
// (unless the user set it).
#pragma once
#include <unistd.h>

#include <cstdlib>

namespace lidef::studio {

inline void ensure_passive_omp_wait(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY")) return;
  setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
  execv("/proc/self/exe", argv);  // returns only on failure: then run on with the default policy
}

}  // namespace lidef::studio
