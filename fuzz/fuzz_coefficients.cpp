// Fuzz target: the coefficient reader (read_coefficients, coefficients.h) for a fixed cage, a tetrahedron
// (4 vertices + 4 faces = 8 rows). A clean InputError is a correct rejection; anything else is a finding.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.h"
#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const lidef::Cage cage = [] {
    lidef::TriMesh m;
    m.V.resize(4, 3);
    m.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
    m.F.resize(4, 3);
    m.F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;  // outward-oriented
    return lidef::Cage(m);
  }();
  const std::string path = lidef_fuzz::write_input(data, size, "coefficients.txt");
  try {
    const lidef::MatX3d y = lidef::read_coefficients(path, cage);
    if (y.rows() != cage.num_coeffs() || !y.allFinite()) __builtin_trap();  // what read_coefficients promises
    lidef_fuzz::report("accepted");
  } catch (const lidef::InputError& e) {
    lidef_fuzz::report(e.what());
  }
  return 0;
}
