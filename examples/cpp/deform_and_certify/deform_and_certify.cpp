// deform_and_certify SCENARIO.json [--models DIR]: solves a handle scenario with lidef and says whether the
// result is certified locally injective. Exit status 0 when it is, 1 when not, 2 on bad input.
#include <lidef/cage/auto_cage.h>
#include <lidef/lidef.h>

#include <iostream>
#include <string>

int main(int argc, char** argv) {
  if (argc != 2 && !(argc == 4 && std::string(argv[2]) == "--models")) {
    std::cerr << "usage: deform_and_certify SCENARIO.json [--models DIR]\n";
    return 2;
  }
  try {
    const lidef::Scenario scenario = lidef::read_scenario(argv[1], argc == 4 ? argv[3] : "");
    // A model folder, or a mesh file turned into one (its automatic cage, cached).
    const lidef::Model model = lidef::load_model(lidef::resolve_model_path(scenario.model_dir));

    const lidef::DeformResult result =
        lidef::deform(model, scenario.sources, scenario.targets, scenario.params);

    std::cout << scenario.name << ": " << lidef::to_string(result.solve.reason) << " after "
              << result.iterations << " iterations, max handle error " << result.max_handle_error
              << (result.handles_reached ? " (reached)" : " (not reached)") << "\n";
    if (result.certificate.certified) {
      std::cout << "certified: locally injective, min lower bound of sigma3 "
                << result.certificate.min_lower_bound << " on " << result.certificate.voxels << " voxels\n";
      return 0;
    }
    std::cout << "NOT certified: " << result.certificate.reason << "\n";
    return 1;
  } catch (const lidef::InputError& e) {
    std::cerr << "deform_and_certify: " << e.what() << "\n";
    return 2;
  }
}
