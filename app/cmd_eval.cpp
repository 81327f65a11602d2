#include "commands.h"
#include "lidef/errors.h"

namespace lidef::cli {
void add_eval_command(CLI::App& app, Action& action) {
  auto* sub = app.add_subcommand("eval", "(under construction)");
  sub->callback([&action] { action = [] { throw Error("'eval' is not implemented yet"); return 0; }; });
}
}  // namespace lidef::cli
