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
#include "lidef/deform_params.h"
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

// The test and benchmark programs' device filter, $LIDEF_OPENCL_DEVICE ("" when unset), so that one build can
// be pointed at a GPU host's device. lidef and the studio take the parameter opencl_device instead.
std::string opencl_device_filter_from_env();

// How a backend is made: the execution parameters of the table (deform_params.h) and its OpenCL test hooks.
struct OpenCLOptions {
  std::string device;                // opencl_device: case-insensitive substring of "<platform> <device>"
  bool gpu_layout = false;           // opencl_gpu_layout: a CPU device takes the GPU code paths
  bool break_kernels = false;        // test_break_kernels
  unsigned long long max_alloc = 0;  // test_opencl_max_alloc (0 = the device's limit)
};
OpenCLOptions opencl_options(const DeformParams& params);

// A backend on the first device with fp64 whose "<platform> <device>" contains `options.device` (GPUs first).
// Compiled kernels are cached under `cache_dir`/opencl (keyed by source, device, driver), so a second start
// skips the compiler. Throws OpenCLError.
std::shared_ptr<const ComputeBackend> make_opencl_backend(const OpenCLOptions& options,
                                                          const std::string& cache_dir);

// params.backend: cpu, opencl (throws OpenCLError when unusable) or auto (OpenCL when a device with fp64
// works, else the CPU). `message` says which backend was chosen and, for auto's fallback, why.
std::shared_ptr<const ComputeBackend> select_backend(const DeformParams& params, const std::string& cache_dir,
                                                     std::string* message);
// select_backend as a BackendFactory (compute_backend.h) with kernels cached under `cache_dir`.
BackendFactory opencl_backend_factory(const std::string& cache_dir);

}  // namespace lidef
