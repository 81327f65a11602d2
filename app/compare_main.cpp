// lidef-compare: `lidef compare` as its own program, so that TetGen and CHOLMOD (lidef_compare) are linked
// here and not into lidef or the studio. `lidef compare ARGS` execs this program with ARGS.
#include "cli_main.h"
#include "lidef/blas_kernel.h"

int main(int argc, char** argv) {
  lidef::reexec_with_environment(argv, lidef::process_environment());  // blas_kernel.h
  using namespace lidef::cli;
  CLI::App app{"lidef compare: lidef against PWL(Tet), VHM and SR-ARAP on one scenario (docs/compare.md)"};
  app.set_version_flag("--version", "lidef 0.1.0");
  app.name("lidef compare");
  Action action;
  add_compare_options(app, action);
  return run_cli(app, action, argc, argv, "lidef compare");
}
