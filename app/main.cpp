// lidef: headless command line front end. All work is done by the library; this file only maps
// exceptions to messages and exit codes (cli_main.h).
#include "cli_main.h"
#include "compare_forward.h"
#include "lidef/blas_kernel.h"

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  using namespace lidef::cli;
  // `lidef compare ...` runs lidef-compare (the only program linking TetGen and CHOLMOD); see
  // compare_forward.h.
  if (argc >= 2 && std::string(argv[1]) == "compare") return forward_to_compare(argc, argv);
  CLI::App app{"lidef: certified locally injective volumetric deformation (Liao et al. 2021)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "lidef 0.1.0");
  Action action;
  add_cage_command(app, action);
  add_certify_command(app, action);
  add_check_command(app, action);
  add_compare_placeholder(app);
  add_deform_command(app, action);
  add_devices_command(app, action);
  add_eval_command(app, action);
  add_explore_command(app, action);
  add_make_model_command(app, action);
  add_reproduce_command(app, action);
  add_verify_command(app, action);
  return run_cli(app, action, argc, argv, "lidef");
}
