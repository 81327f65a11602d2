// Fuzz target: lidef's own model-mesh reader (read_mesh, mesh_io.h) on a .obj or .off file, or the automatic
// cage's any-format reader (read_any_mesh, cage/auto_cage.h: CGAL's OBJ/OFF/PLY/STL polygon soup readers,
// lidef's PLY point-cloud and splat reader, plus lidef's checks). Built once per format: LIDEF_FUZZ_EXT is
// the extension the file gets (the readers pick the format by it), LIDEF_FUZZ_ANY selects read_any_mesh. A
// clean InputError is a correct rejection; anything else (a crash, a sanitizer report, another exception, a
// hang, a leak) is a finding.
#include <cstddef>
#include <cstdint>

#include "fuzz_input.h"
#include "lidef/errors.h"
#if LIDEF_FUZZ_ANY
#include "lidef/cage/auto_cage.h"
#else
#include "lidef/mesh_io.h"
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = lidef_fuzz::write_input(data, size, "input." LIDEF_FUZZ_EXT);
  try {
#if LIDEF_FUZZ_ANY
    lidef::MeshReadInfo info;
    const lidef::TriMesh mesh = lidef::read_any_mesh(path, &info);
#else
    lidef::MeshLines lines;
    const lidef::TriMesh mesh = lidef::read_mesh(path, &lines);
#endif
    // What both readers promise and callers rely on without checking again: finite coordinates, indices in
    // range, at least one face — or, for the any-format reader, a point cloud (vertices, no faces).
#if LIDEF_FUZZ_ANY
    if (mesh.V.rows() == 0 || !mesh.V.allFinite()) __builtin_trap();
#else
    if (mesh.F.rows() == 0 || !mesh.V.allFinite()) __builtin_trap();
#endif
    for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
      for (int k = 0; k < 3; ++k)
        if (mesh.F(f, k) < 0 || mesh.F(f, k) >= mesh.V.rows()) __builtin_trap();
    lidef_fuzz::report("accepted");
  } catch (const lidef::InputError& e) {
    lidef_fuzz::report(e.what());
  }
  return 0;
}
