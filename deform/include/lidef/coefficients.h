// Coefficient files: (#V+#F) rows of 3 numbers, vertex rows first in file order, then face rows.
#pragma once
#include <ostream>
#include <string>

#include "lidef/cage.h"
#include "lidef/types.h"

namespace lidef {

// Reads a coefficient file for `cage`; the word "identity" instead of a path gives the identity map.
// Throws InputError (file, line) for a missing file, a row without exactly 3 finite numbers, or a row
// count other than #V+#F.
MatX3d read_coefficients(const std::string& path_or_identity, const Cage& cage);

// Writes y (#V+#F by 3), one row per line, in shortest round-trip form (deterministic, exact).
void write_coefficients(std::ostream& out, const MatX3d& y);

}  // namespace lidef
