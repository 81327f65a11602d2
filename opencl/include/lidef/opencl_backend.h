// The OpenCL compute backend (docs/opencl.md): the per-sample stages of the solver and the certificate as
// OpenCL kernels (opencl/kernels/lidef.cl), CLBlast for the dense Hessian product. Runs on any OpenCL 1.2
// device with double precision (cl_khr_fp64): PoCL's CPU device here, a GPU's driver elsewhere.
//
// Failures (no platform, no fp64, a kernel that does not build, out of device memory, a CLBlast error) throw
// OpenCLError naming the device and the stage; nothing here calls exit() or aborts.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "lidef/compute_backend.h"
#include "lidef/errors.h"

namespace lidef {

class OpenCLError : public Error {
 public:
  using Error::Error;
};

struct OpenCLDeviceInfo {
  std::string platform, name, version, driver, type;  // type: "GPU", "CPU", "accelerator", "other"
  bool fp64 = false;
  unsigned long long global_mem = 0, max_alloc = 0;
  unsigned compute_units = 0;
};

// Every device of every platform. Never throws: an empty list when there is no OpenCL platform (the reason,
// if any, in *why).
std::vector<OpenCLDeviceInfo> opencl_devices(std::string* why = nullptr);

// The device filter from $LIDEF_OPENCL_DEVICE ("" when unset): a case-insensitive substring of
// "<platform> <device>".
std::string opencl_device_filter_from_env();

// A backend on the first device with fp64 whose "<platform> <device>" contains `filter` (GPUs first).
// Compiled kernels are cached under `cache_dir`/opencl (keyed by source, device, driver), so a second start
// skips the compiler. Throws OpenCLError.
std::shared_ptr<const ComputeBackend> make_opencl_backend(const std::string& filter,
                                                          const std::string& cache_dir);

// "cpu", "opencl" (throws OpenCLError when unusable) or "auto" (OpenCL when a device with fp64 works, else
// the CPU). `message` says which backend was chosen and, for auto's fallback, why.
std::shared_ptr<const ComputeBackend> select_backend(const std::string& which, const std::string& cache_dir,
                                                     std::string* message);
// select_backend as a BackendFactory (compute_backend.h) with kernels cached under `cache_dir`.
BackendFactory opencl_backend_factory(const std::string& cache_dir);

}  // namespace lidef
