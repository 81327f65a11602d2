// Fuzz target: the scenario reader (read_scenario, scenario.h), which also reads the studio's saved sessions
// (a scenario with a "studio" object). A model folder "bar" exists in the scratch folder's models/, so inputs
// naming it get past model resolution into the handle and parameter checks. A clean InputError is a correct
// rejection; anything else is a finding.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>

#include "fuzz_input.h"
#include "lidef/errors.h"
#include "lidef/scenario.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string models = [] {
    const auto dir = lidef_fuzz::scratch_dir() / "models";
    std::filesystem::create_directories(dir / "bar");
    return dir.string();
  }();
  const std::string path = lidef_fuzz::write_input(data, size, "scenario.json");
  try {
    const lidef::Scenario s = lidef::read_scenario(path, models);
    // Promised by read_scenario: at least one handle, sources and targets of one shape, finite coordinates.
    if (s.num_handles() < 1 || s.targets.rows() != s.sources.rows() || !s.sources.allFinite() ||
        !s.targets.allFinite())
      __builtin_trap();
    lidef_fuzz::report("accepted");
  } catch (const lidef::InputError& e) {
    lidef_fuzz::report(e.what());
  }
  return 0;
}
