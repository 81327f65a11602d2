#include "lidef/blas_kernel.h"

#include <unistd.h>

#include <cstdlib>

extern "C" char* openblas_get_corename(void);

namespace lidef {

namespace {

// The kernels OpenBLAS 0.3.21 has for what this CPU supports (its own names, as OPENBLAS_CORETYPE takes
// them). Measured on the 2-core Xeon (model 207) on bar_bend, ms per Newton iteration: Prescott 312, Haswell
// 164, SkylakeX 170, Cooperlake 151.
std::string core_for_cpu_features() {
  __builtin_cpu_init();
  const bool avx512 = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
                      __builtin_cpu_supports("avx512cd");
  if (avx512 && __builtin_cpu_supports("avx512bf16")) return "Cooperlake";
  if (avx512) return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
  return "";
}

}  // namespace

BlasKernelInfo blas_kernel_info() {
  BlasKernelInfo info;
  const char* name = openblas_get_corename();
  info.core = name ? name : "";
  info.forced = std::getenv("OPENBLAS_CORETYPE") != nullptr;
  // "Prescott" is what 0.3.21 picks for an Intel model it does not know; on a CPU that really is that old
  // there is nothing better (core_for_cpu_features() is then empty).
  if (info.core == "Prescott") info.recommended = core_for_cpu_features();
  return info;
}

std::vector<std::pair<std::string, std::string>> blas_environment() {
  if (std::getenv("OPENBLAS_CORETYPE")) return {};  // the user's (or our earlier) choice stands
  const BlasKernelInfo info = blas_kernel_info();
  if (info.recommended.empty()) return {};
  return {{"OPENBLAS_CORETYPE", info.recommended}};
}

void reexec_with_environment(char** argv, const std::vector<std::pair<std::string, std::string>>& env) {
  bool changed = false;
  for (const auto& [name, value] : env) {
    if (std::getenv(name.c_str())) continue;
    setenv(name.c_str(), value.c_str(), 1);
    changed = true;
  }
  // Each variable is now set, so the re-executed process finds nothing to change and runs on.
  if (changed) execv("/proc/self/exe", argv);
}

}  // namespace lidef
