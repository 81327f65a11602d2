// lidef: headless command line front end. All work is done by the library; this file only maps
// exceptions to messages and exit codes.
#include <iostream>

#include "commands.h"
#include "lidef/errors.h"

int main(int argc, char** argv) {
  using namespace lidef::cli;
  CLI::App app{"lidef: certified locally injective volumetric deformation (Liao et al. 2021)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "lidef 0.1.0");
  Action action;
  add_certify_command(app, action);
  add_check_command(app, action);
  add_compare_command(app, action);
  add_deform_command(app, action);
  add_devices_command(app, action);
  add_eval_command(app, action);
  add_explore_command(app, action);
  add_make_model_command(app, action);
  add_verify_command(app, action);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? kOk : kError;
  }
  try {
    return action ? action() : kError;
  } catch (const lidef::InputError& e) {
    std::cerr << "lidef: error: " << e.what() << "\n";
  } catch (const lidef::Error& e) {
    std::cerr << "lidef: error: " << e.what() << "\n";
  } catch (const std::exception& e) {
    std::cerr << "lidef: internal error: " << e.what() << "\n";
  }
  return kError;
}
