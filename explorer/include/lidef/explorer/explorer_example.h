// Explorer map files (JSON, "format": "lidef-explorer-map"; docs/explorer.md, "Map files"): a harmonic
// polynomial or a cage map, with the ball it is studied on.
#pragma once
#include <memory>
#include <string>

#include "lidef/explorer/explorer_map.h"
#include "lidef/explorer/harmonic_polynomials.h"

namespace lidef {

struct ExplorerExample {
  std::string kind;  // "harmonic_polynomial" or "cage"
  Ball ball;
  std::string note;
  std::shared_ptr<const ExplorerMap> map;
  std::string cage_model, cage_coefficients;  // kind == cage: the resolved paths ("identity" kept as is)
  // The polynomial map (kind == harmonic_polynomial), else null.
  const HarmonicPolynomialMap* polynomial() const;
};

// Throws InputError(path, ...) on any problem (a cage map's ball must lie inside its cage).
ExplorerExample read_explorer_example(const std::string& path);

// The polynomial map as JSON text (format of read_explorer_example), deterministic, numbers in shortest
// round-trip form.
std::string explorer_example_json(const HarmonicPolynomialMap& map, const Ball& ball,
                                  const std::string& note);

}  // namespace lidef
