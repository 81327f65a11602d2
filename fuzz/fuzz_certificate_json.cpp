// Fuzz target: the certificate reader (read_certificate_json, certificate_report.h). The input is
// certificate.json; the voxels.csv it names is a fixed two-leaf file written beside it, and the seed corpus
// carries that file's fnv1a64, so inputs with the right name and hash reach the leaf checks.
// A clean InputError is a correct rejection; anything else is a finding.
#include <cstddef>
#include <cstdint>
#include <fstream>

#include "fuzz_input.h"
#include "lidef/analysis/certificate_report.h"
#include "lidef/errors.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const bool csv_written = [] {
    std::ofstream out(lidef_fuzz::scratch_dir() / "voxels.csv", std::ios::binary);
    out << "cx,cy,cz,side,depth,sigma3,L,margin,certified\n"
           "0.25,0.25,0.25,0.5,0,1,0.5,0.75,1\n"
           "0.75,0.25,0.25,0.5,0,0.9,0.5,0.65,1\n";
    return static_cast<bool>(out);
  }();
  if (!csv_written) __builtin_trap();
  const std::string path = lidef_fuzz::write_input(data, size, "certificate.json");
  try {
    const lidef::CertificateReport r = lidef::read_certificate_json(path);
    if (static_cast<long>(r.cert.leaves.size()) != r.cert.num_leaves)
      __builtin_trap();  // checked by the reader
    lidef_fuzz::report("accepted");
  } catch (const lidef::InputError& e) {
    lidef_fuzz::report(e.what());
  }
  return 0;
}
