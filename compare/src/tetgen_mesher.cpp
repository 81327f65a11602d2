// The only translation unit that includes TetGen (compiled with -DTETLIBRARY, see deform/CMakeLists.txt).
// TetGen runs in a forked child process (run_tetgen): it can abort or crash instead of throwing.
#include <sys/wait.h>
#include <tetgen.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <vector>

#include "lidef/errors.h"
#include "lidef/self_intersections.h"
#include "lidef/compare/tet_mesh.h"

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
    case 1:
      return "out of memory";
    case 2:
      return "internal error (TetGen bug or degenerate input)";
    case 3:
      return "the input surface self-intersects";
    case 4:
      return "a very small input feature size was detected (nearly degenerate input)";
    case 5:
      return "two very close input facets were detected";
    case 10:
      return "the input has no valid facets or is otherwise invalid";
    default:
      return "TetGen failed with code " + std::to_string(code);
  }
}
}  // namespace

namespace {
// Writes/reads all of a buffer through a file descriptor (pipes deliver in pieces).
bool write_all(int fd, const void* data, size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t k = ::write(fd, p, n);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) return false;
    p += k;
    n -= static_cast<size_t>(k);
  }
  return true;
}

// Runs TetGen in a child process. TetGen 1.5 can end the process instead of throwing: a failed assertion
// (abort) on some refinements, a segmentation fault on some self-intersecting input; in a child that only
// costs the child, and the parent turns it into an error. The child sends: int32 status (0 ok, else TetGen's
// code), then int32 #points, int32 #tets, #points*3 doubles, #tets*4 int32 (0-based).
TetMesh run_tetgen(tetgenio& in, std::string sw, const std::string& where) {
  int fds[2];
  if (::pipe(fds) != 0) throw NumericalError(where + ": cannot create a pipe for TetGen");
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw NumericalError(where + ": cannot fork for TetGen");
  }
  if (pid == 0) {  // child: TetGen only, then _exit (never return into the caller)
    ::close(fds[0]);
    int32_t status = 0;
    try {
      tetgenio out;
      ::tetrahedralize(sw.data(), &in, &out);
      const int32_t np = out.numberofpoints, nt = out.numberofcorners >= 4 ? out.numberoftetrahedra : 0;
      std::vector<int32_t> tets(4 * static_cast<size_t>(std::max(nt, 0)));
      for (int32_t t = 0; t < nt; ++t)
        for (int k = 0; k < 4; ++k)
          tets[4 * t + k] = out.tetrahedronlist[t * out.numberofcorners + k] - out.firstnumber;
      const bool ok = write_all(fds[1], &status, 4) && write_all(fds[1], &np, 4) &&
                      write_all(fds[1], &nt, 4) &&
                      write_all(fds[1], out.pointlist, sizeof(double) * 3 * static_cast<size_t>(np)) &&
                      write_all(fds[1], tets.data(), 4 * tets.size());
      ::_exit(ok ? 0 : 1);
    } catch (int code) {
      status = code > 0 ? code : 2;
    } catch (...) {
      status = 1;  // out of memory
    }
    write_all(fds[1], &status, 4);
    ::_exit(0);
  }
  ::close(fds[1]);
  std::vector<char> buf;
  char chunk[1 << 16];
  for (;;) {
    const ssize_t k = ::read(fds[0], chunk, sizeof chunk);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) break;
    buf.insert(buf.end(), chunk, chunk + k);
  }
  ::close(fds[0]);
  int wstatus = 0;
  while (::waitpid(pid, &wstatus, 0) < 0 && errno == EINTR) {
  }
  const std::string what = "TetGen (" + sw + ")";
  if (WIFSIGNALED(wstatus))
    throw NumericalError(where + ": " + what + " crashed (signal " + std::to_string(WTERMSIG(wstatus)) +
                         (WTERMSIG(wstatus) == SIGABRT ? ", a failed internal assertion" : "") + ")");
  int32_t head[3] = {0, 0, 0};
  if (buf.size() < 4) throw NumericalError(where + ": " + what + " ended without a result");
  std::memcpy(head, buf.data(), std::min(buf.size(), sizeof head));
  if (head[0] != 0) {
    if (head[0] == 3 || head[0] == 4 || head[0] == 5 || head[0] == 10)
      throw InputError(where, what + " rejected the input: " + tetgen_error_text(head[0]));
    throw NumericalError(where + ": " + what + " failed: " + tetgen_error_text(head[0]));
  }
  const size_t np = static_cast<size_t>(std::max(head[1], 0)), nt = static_cast<size_t>(std::max(head[2], 0));
  if (buf.size() != 12 + 24 * np + 16 * nt)
    throw NumericalError(where + ": " + what + " returned a truncated result");
  if (nt == 0) throw NumericalError(where + ": " + what + " produced no tetrahedra");
  TetMesh m;
  m.source = "tetgen " + sw + " of " + where;
  m.V.resize(static_cast<Eigen::Index>(np), 3);
  std::vector<double> pts(3 * np);
  std::memcpy(pts.data(), buf.data() + 12, 24 * np);
  for (size_t i = 0; i < np; ++i)
    for (int k = 0; k < 3; ++k) m.V(static_cast<Eigen::Index>(i), k) = pts[3 * i + k];
  std::vector<int32_t> tets(4 * nt);
  std::memcpy(tets.data(), buf.data() + 12 + 24 * np, 16 * nt);
  m.T.resize(static_cast<Eigen::Index>(nt), 4);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 4; ++k) {
      if (tets[4 * t + k] < 0 || static_cast<size_t>(tets[4 * t + k]) >= np)
        throw NumericalError(where + ": " + what + " returned a bad vertex index");
      m.T(static_cast<Eigen::Index>(t), k) = tets[4 * t + k];
    }
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
  if (cage.V.rows() < 4 || cage.F.rows() < 4)
    throw InputError(where, "tetrahedralize: the cage has too few faces");
  // TetGen 1.5 crashes (segmentation fault) on some self-intersecting surfaces instead of reporting them:
  // check with exact predicates first, for a message that names the faces (run_tetgen would also survive the
  // crash).
  const auto crossing = find_self_intersections(cage.V, cage.F);
  if (!crossing.empty())
    throw InputError(where, "TetGen is not run on a self-intersecting cage: faces " +
                                std::to_string(crossing[0].first + 1) + " and " +
                                std::to_string(crossing[0].second + 1) + " intersect (" +
                                std::to_string(crossing.size()) + " pair(s); 1-based `f` order)");
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
