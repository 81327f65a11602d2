#include "commands.h"
#include "lidef/errors.h"

namespace lidef::cli {
void add_make_model_command(CLI::App& app, Action& action) {
  auto* sub = app.add_subcommand("make-model", "(under construction)");
  sub->callback([&action] { action = [] { throw Error("'make_model' is not implemented yet"); return 0; }; });
}
}  // namespace lidef::cli
