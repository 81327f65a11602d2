#include "commands.h"
#include "lidef/errors.h"

namespace lidef::cli {
void add_check_command(CLI::App& app, Action& action) {
  auto* sub = app.add_subcommand("check", "(under construction)");
  sub->callback([&action] { action = [] { throw Error("'check' is not implemented yet"); return 0; }; });
}
}  // namespace lidef::cli
