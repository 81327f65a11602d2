// Tetrahedral meshes of a cage's interior for PWL(Tet) (Smith, De Goes, Kim 2019; paper Sec. 8, Table 1):
// reading TetGen's .node/.ele files, tetrahedralizing a cage with the TetGen library, and locating points in
// the tets (barycentric embedding of the mesh vertices and the handles).
//
// TetGen is confined to tetgen_mesher.cpp (its own object library, compiled with -DTETLIBRARY) and runs in a
// forked child process, because TetGen 1.5 can also fail by a failed assertion (abort) or a segmentation
// fault; all its failures (thrown int codes, a crashed child) become lidef::InputError / NumericalError with
// the input's name.
#pragma once
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <string>
#include <vector>

#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

using MatX4i = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;

struct TetMesh {
  MatX3d V;            // #V by 3 vertex positions
  MatX4i T;            // #T by 4 vertex indices, 0-based, positively oriented (det[v1-v0, v2-v0, v3-v0] > 0)
  std::string source;  // where it came from (file or "tetgen <switches>")
  int num_vertices() const { return static_cast<int>(V.rows()); }
  int num_tets() const { return static_cast<int>(T.rows()); }
};

// Reads TetGen's `.node` (`n 3 attrs markers`, then `i x y z ...`) and `.ele` (`m 4 attrs`, then
// `i a b c d ...`) files; the index base (0 or 1) is taken from the first vertex number of the .node file, as
// TetGen does. Negatively oriented tets are flipped. Throws InputError (file, line) on malformed input, an
// index out of range, a degenerate (zero-volume) tet, or an empty mesh.
TetMesh read_tet_mesh(const std::string& node_path, const std::string& ele_path);

// TetGen switches of the PWL(Tet) tetrahedralization (docs/compare.md).
struct TetgenOptions {
  double min_ratio = 2.0;  // quality: maximal radius-edge ratio (TetGen -q); <= 0 = no quality refinement
  double max_volume = 0;   // > 0: maximal tet volume (TetGen -a), absolute model units³
  bool quiet = true;       // TetGen -Q
};
// The switch string given to TetGen, e.g. "pq2a0.001Q" (p: tetrahedralize a piecewise-linear complex; with
// `refine`, r: refine an existing tet mesh).
std::string tetgen_switches(const TetgenOptions& options, bool refine = false);

// Tetrahedralizes the interior of the closed triangle mesh `cage` (#V by 3, #F by 3). The result keeps the
// cage's vertices first (Steiner points after them). A self-intersecting cage is refused before TetGen runs
// (find_self_intersections, exact: TetGen 1.5 can crash on such input instead of reporting it). Throws
// InputError naming cage.source when the input is refused or TetGen rejects it, NumericalError when TetGen
// fails otherwise or returns no tet.
TetMesh tetrahedralize(const TriMesh& cage, const TetgenOptions& options = {});

// The TetGen mesh of the cage's interior for PWL(Tet) at a given resolution (paper Table 1 states PWL(Tet)'s
// DOF = 3 × tet vertices): the max tet volume (-a, `options.max_volume` is replaced) is searched so that the
// mesh has at least `min_vertices` vertices, and kept as large as the search can: the vertex count grows as
// the volume shrinks but not strictly (TetGen's quality refinement adds points unevenly), so the search
// brackets the target between a volume with too few vertices and one with enough, and halves the bracket in
// log scale until its ends are within 10% (volumes rounded to 3 significant digits, so the switches read
// plainly). Deterministic: the same cage and options try the same volumes and give the same mesh. Throws as
// tetrahedralize, and NumericalError when no volume reaches the target within the search's 40 meshings.
struct TetgenForVertices {
  TetMesh mesh;
  TetgenOptions options;  // the switches that made `mesh` (max_volume: the volume found)
  int meshings = 0;       // TetGen runs of the search
};
TetgenForVertices tetrahedralize_min_vertices(const TriMesh& cage, TetgenOptions options, int min_vertices);

// Refines an existing tet mesh with TetGen (-r) to the quality and volume bounds of `options`, keeping its
// vertices and boundary. Works where the cage itself cannot be tetrahedralized (e.g. the animal's slightly
// self-intersecting cage, whose published tet mesh is valid). Errors as for tetrahedralize.
TetMesh refine_tet_mesh(const TetMesh& mesh, const TetgenOptions& options = {});

// Barycentric location of points in a tet mesh.
struct TetEmbedding {
  VecXi tet;       // #P: containing tet
  MatX4i corners;  // #P by 4: the vertices of that tet
  MatXd bary;      // #P by 4 barycentric coordinates (sum 1, each >= -tolerance)
  // The point positions reproduced: Σ_k bary(i,k) V(T(tet(i),k)) — exactly linear in V, so the map of the
  // points is Eigen's sparse product `weights * X` (#P by #V) of the tet vertices X.
  Eigen::SparseMatrix<double, Eigen::RowMajor> weights() const;
  int num_vertices = 0;
};
// Locates every point (#P by 3) in a tet of `mesh` (a uniform grid of tet bounding boxes; ties and points on
// shared faces go to the tet with the largest minimum barycentric coordinate). A point is inside when its
// smallest barycentric coordinate is >= -tolerance (relative, 1e-9 by default). Throws InputError(where, ...)
// naming the first point outside every tet (and how many are outside).
TetEmbedding embed_points(const TetMesh& mesh, const MatX3d& points, const std::string& where,
                          double tolerance = 1e-9);

}  // namespace lidef
