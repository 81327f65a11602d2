// The command-line face of the one parameter table (deform_params.h): every command that takes solver or
// certificate parameters registers them here, so a parameter has the same name in a scenario's JSON, on every
// command line (--name-with-dashes) and in the studio.
#pragma once
#include <functional>
#include <map>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include "commands.h"
#include "lidef/deform_params.h"

namespace lidef::cli {

// Parameter name → text given on the command line.
using ParamOverrides = std::map<std::string, std::string>;

// One flag per row of the table that `keep` accepts (all rows without it), grouped in --help under
// `group_prefix` + the row's group. `overrides` must outlive the parse.
inline void add_param_flags(CLI::App* sub, ParamOverrides* overrides, const std::string& group_prefix,
                            const std::function<bool(const ParamInfo&)>& keep = {}) {
  const DeformParams defaults;
  for (const ParamInfo& p : deform_param_table()) {
    if (keep && !keep(p)) continue;
    const std::string name = p.name;
    std::string help = std::string(p.help) + " [default " + param_value_string(defaults, p) + "]";
    if (const auto choices = param_choices(p); !choices.empty()) {
      help += " {";
      for (size_t i = 0; i < choices.size(); ++i) help += (i ? "," : "") + choices[i];
      help += "}";
    }
    sub->add_option_function<std::string>(
           param_flag(p), [overrides, name](const std::string& v) { (*overrides)[name] = v; }, help)
        // Test hooks are accepted but not listed (an empty group hides an option in CLI11's --help).
        ->group(is_test_hook(p) ? std::string() : group_prefix + p.group)
        ->type_name(std::visit(
            [](auto m) -> std::string {
              using T = std::remove_reference_t<decltype(DeformParams{}.*m)>;
              if constexpr (std::is_same_v<T, bool>)
                return "BOOL";
              else if constexpr (std::is_same_v<T, std::string> || std::is_enum_v<T>)
                return "TEXT";
              else if constexpr (std::is_floating_point_v<T>)
                return "REAL";
              else
                return "INT";
            },
            p.member));
  }
}

// Sets every overridden parameter (errors name the flag); the names go to *given when it is not null.
inline void apply_param_overrides(DeformParams& params, const ParamOverrides& overrides,
                                  std::vector<std::string>* given = nullptr) {
  for (const auto& [name, text] : overrides) {
    set_param_from_text(params, name, text, param_flag(*find_param(name)));
    if (given) given->push_back(name);
  }
}

}  // namespace lidef::cli
