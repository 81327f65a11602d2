// The only translation unit that includes TetGen (compiled with -DTETLIBRARY, see deform/CMakeLists.txt).
#include <tetgen.h>

#include <cstdio>
#include <sstream>

#include "lidef/errors.h"
#include "lidef/self_intersections.h"
#include "lidef/tet_mesh.h"

namespace lidef {

std::string tetgen_switches(const TetgenOptions& o, bool refine) {
  std::ostringstream s;
  s.precision(9);
  s << (refine ? "r" : "p");
  if (o.min_ratio > 0) s << "q" << o.min_ratio;
  if (o.max_volume > 0) s << "a" << o.max_volume;
  if (o.quiet) s << "Q";
  return s.str();
}

namespace {
// TetGen's exit codes in library mode (tetgen.h, terminatetetgen).
std::string tetgen_error_text(int code) {
  switch (code) {
    case 1: return "out of memory";
    case 2: return "internal error (TetGen bug or degenerate input)";
    case 3: return "the input surface self-intersects";
    case 4: return "a very small input feature size was detected (nearly degenerate input)";
    case 5: return "two very close input facets were detected";
    case 10: return "the input has no valid facets or is otherwise invalid";
    default: return "TetGen failed with code " + std::to_string(code);
  }
}
}  // namespace

namespace {
// Runs TetGen and converts its result; `in` is set up by the caller.
TetMesh run_tetgen(tetgenio& in, std::string sw, const std::string& where) {
  tetgenio out;
  try {
    ::tetrahedralize(sw.data(), &in, &out);
  } catch (int code) {
    if (code == 3 || code == 4 || code == 5 || code == 10)
      throw InputError(where, "TetGen (" + sw + ") rejected the input: " + tetgen_error_text(code));
    throw NumericalError(where + ": TetGen (" + sw + ") failed: " + tetgen_error_text(code));
  }
  if (out.numberoftetrahedra <= 0 || out.numberofcorners < 4)
    throw NumericalError(where + ": TetGen (" + sw + ") produced no tetrahedra");
  TetMesh m;
  m.source = "tetgen " + sw + " of " + where;
  m.V.resize(out.numberofpoints, 3);
  for (int i = 0; i < out.numberofpoints; ++i)
    for (int k = 0; k < 3; ++k) m.V(i, k) = out.pointlist[3 * i + k];
  m.T.resize(out.numberoftetrahedra, 4);
  const int base = out.firstnumber;
  for (int t = 0; t < out.numberoftetrahedra; ++t)
    for (int k = 0; k < 4; ++k) m.T(t, k) = out.tetrahedronlist[t * out.numberofcorners + k] - base;
  // Orient every tet explicitly (det[v1-v0, v2-v0, v3-v0] > 0) rather than rely on TetGen's convention.
  for (int t = 0; t < m.num_tets(); ++t) {
    const Vec3 a = m.V.row(m.T(t, 0)), b = m.V.row(m.T(t, 1)), c = m.V.row(m.T(t, 2)), d = m.V.row(m.T(t, 3));
    if ((b - a).cross(c - a).dot(d - a) < 0) std::swap(m.T(t, 2), m.T(t, 3));
  }
  return m;
}
}  // namespace

TetMesh refine_tet_mesh(const TetMesh& mesh, const TetgenOptions& options) {
  const std::string where = mesh.source.empty() ? "tet mesh" : mesh.source;
  if (mesh.num_tets() == 0) throw InputError(where, "refine: the tet mesh is empty");
  tetgenio in;
  in.firstnumber = 0;
  in.numberofpoints = mesh.num_vertices();
  in.pointlist = new REAL[3 * in.numberofpoints];
  for (int i = 0; i < in.numberofpoints; ++i)
    for (int k = 0; k < 3; ++k) in.pointlist[3 * i + k] = mesh.V(i, k);
  in.numberoftetrahedra = mesh.num_tets();
  in.numberofcorners = 4;
  in.tetrahedronlist = new int[4 * in.numberoftetrahedra];
  for (int t = 0; t < in.numberoftetrahedra; ++t)
    for (int k = 0; k < 4; ++k) in.tetrahedronlist[4 * t + k] = mesh.T(t, k);
  return run_tetgen(in, tetgen_switches(options, true), where);
}

TetMesh tetrahedralize(const TriMesh& cage, const TetgenOptions& options) {
  const std::string where = cage.source.empty() ? "cage" : cage.source;
  if (cage.V.rows() < 4 || cage.F.rows() < 4) throw InputError(where, "tetrahedralize: the cage has too few faces");
  // TetGen 1.5 crashes (segmentation fault) on some self-intersecting surfaces instead of reporting them: check
  // with exact predicates first.
  const auto crossing = find_self_intersections(cage.V, cage.F);
  if (!crossing.empty())
    throw InputError(where, "TetGen is not run on a self-intersecting cage: faces " +
                                std::to_string(crossing[0].first + 1) + " and " + std::to_string(crossing[0].second + 1) +
                                " intersect (" + std::to_string(crossing.size()) + " pair(s); 1-based `f` order)");
  tetgenio in;
  in.firstnumber = 0;
  in.numberofpoints = static_cast<int>(cage.V.rows());
  in.pointlist = new REAL[3 * in.numberofpoints];
  for (int i = 0; i < in.numberofpoints; ++i)
    for (int k = 0; k < 3; ++k) in.pointlist[3 * i + k] = cage.V(i, k);
  in.numberoffacets = static_cast<int>(cage.F.rows());
  in.facetlist = new tetgenio::facet[in.numberoffacets];
  in.facetmarkerlist = new int[in.numberoffacets];
  for (int f = 0; f < in.numberoffacets; ++f) {
    tetgenio::facet& fa = in.facetlist[f];
    tetgenio::init(&fa);
    fa.numberofpolygons = 1;
    fa.polygonlist = new tetgenio::polygon[1];
    tetgenio::init(&fa.polygonlist[0]);
    fa.polygonlist[0].numberofvertices = 3;
    fa.polygonlist[0].vertexlist = new int[3];
    for (int k = 0; k < 3; ++k) fa.polygonlist[0].vertexlist[k] = cage.F(f, k);
    in.facetmarkerlist[f] = 1;
  }
  return run_tetgen(in, tetgen_switches(options, false), where);
}

}  // namespace lidef
