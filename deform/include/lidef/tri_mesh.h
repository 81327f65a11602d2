// A plain triangle mesh as read from disk, before any validation.
#pragma once
#include <string>

#include "lidef/types.h"

namespace lidef {

struct TriMesh {
  MatX3d V;            // #V by 3 vertex positions
  MatX3i F;            // #F by 3 vertex indices, 0-based, counter-clockwise seen from outside
  std::string source;  // file the mesh came from (for error messages); may be empty
};

}  // namespace lidef
