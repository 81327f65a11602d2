// lidef devices: the OpenCL platforms and devices lidef can use (--backend opencl|auto), with the one `auto`
// would choose, and the OpenBLAS kernels of the CPU backend.
#include <iostream>
#include <memory>

#include "commands.h"
#include "lidef/blas_kernel.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/subspace.h"
#include "param_flags.h"

namespace lidef::cli {

void add_devices_command(CLI::App& app, Action& action) {
  auto* sub =
      app.add_subcommand("devices", "List the OpenCL devices and the backend that --backend auto picks");
  auto overrides = std::make_shared<ParamOverrides>();
  add_param_flags(sub, overrides.get(), "Parameters: ", [](const ParamInfo& p) {
    return std::string(p.name).rfind("opencl_", 0) == 0;
  });
  sub->callback([overrides, &action] {
    action = [overrides] {
      std::string why;
      const auto devs = opencl_devices(&why);
      if (devs.empty()) std::cout << "OpenCL: " << why << "\n";
      for (const auto& d : devs)
        std::cout << d.name << "\n  platform " << d.platform << ", " << d.type << ", " << d.version
                  << ", driver " << d.driver << "\n  " << d.compute_units << " compute units, "
                  << (d.global_mem >> 20) << " MiB memory (" << (d.max_alloc >> 20)
                  << " MiB per buffer), double precision " << (d.fp64 ? "yes" : "NO (not usable by lidef)")
                  << "\n";
      DeformParams params;
      apply_param_overrides(params, *overrides);
      params.backend = BackendKind::kAuto;
      std::string msg;
      select_backend(params, default_cache_dir(), &msg);
      std::cout << "--backend auto -> " << msg.substr(msg.find(':') + 2) << "\n";
      if (!params.opencl_device.empty()) std::cout << "(--opencl-device '" << params.opencl_device << "')\n";
      // The CPU backend's dense products run on OpenBLAS; which kernels it chose decides their speed.
      const BlasKernelInfo blas = blas_kernel_info();
      std::cout << "CPU backend: OpenBLAS kernels " << blas.core
                << (blas.forced ? " (OPENBLAS_CORETYPE)"
                    : blas.replaced.empty()
                        ? " (chosen by OpenBLAS)"
                        : " (chosen by lidef for this CPU; OpenBLAS chose " + blas.replaced + ")")
                << (blas.recommended.empty() ? "" : "; this CPU supports " + blas.recommended) << "\n";
      return kOk;
    };
  });
}

}  // namespace lidef::cli
