// lidef devices: the OpenCL platforms and devices lidef can use (--backend opencl|auto), with the one `auto`
// would choose.
#include <iostream>

#include "commands.h"
#include "lidef/opencl_backend.h"
#include "lidef/subspace.h"

namespace lidef::cli {

void add_devices_command(CLI::App& app, Action& action) {
  auto* sub = app.add_subcommand("devices", "List the OpenCL devices and the backend that --backend auto picks");
  sub->callback([&action] {
    action = [] {
      std::string why;
      const auto devs = opencl_devices(&why);
      if (devs.empty()) std::cout << "OpenCL: " << why << "\n";
      for (const auto& d : devs)
        std::cout << d.name << "\n  platform " << d.platform << ", " << d.type << ", " << d.version << ", driver "
                  << d.driver << "\n  " << d.compute_units << " compute units, " << (d.global_mem >> 20)
                  << " MiB memory (" << (d.max_alloc >> 20) << " MiB per buffer), double precision "
                  << (d.fp64 ? "yes" : "NO (not usable by lidef)") << "\n";
      std::string msg;
      select_backend("auto", default_cache_dir(), &msg);
      std::cout << "--backend auto -> " << msg.substr(msg.find(':') + 2) << "\n";
      const std::string filter = opencl_device_filter_from_env();
      if (!filter.empty()) std::cout << "(LIDEF_OPENCL_DEVICE='" << filter << "')\n";
      return kOk;
    };
  });
}

}  // namespace lidef::cli
