// Fuzz target: the certificate's leaf table reader (read_voxels_csv, certificate_report.h). A clean
// InputError is a correct rejection; anything else is a finding.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.h"
#include "lidef/analysis/certificate_report.h"
#include "lidef/errors.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = lidef_fuzz::write_input(data, size, "voxels.csv");
  try {
    for (const lidef::CertLeaf& l : lidef::read_voxels_csv(path))
      if (!(l.side > 0) || l.depth < 0 || !l.center.allFinite()) __builtin_trap();  // what the reader checks
    lidef_fuzz::report("accepted");
  } catch (const lidef::InputError& e) {
    lidef_fuzz::report(e.what());
  }
  return 0;
}
