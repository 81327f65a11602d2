// The certificate as files: certificate.json (verdict, counts, parameters, the first failing leaves) and
// voxels.csv (one row per octree leaf), plus the reader `lidef verify` uses. No VTK here (see vtk_export.h).
// Every field and column is documented in docs/outputs.md.
//
// Determinism: both files are a pure function of the model, the coefficients and the parameters —
// byte-identical for the same input whatever the thread count. Wall-clock timings are therefore NOT part of
// them; `lidef certify` writes them to a separate timings.json. Doubles use the shortest decimal form that
// reads back to the identical double (format_double), so the files round-trip exactly; non-finite values (the
// NaN σ3 and infinite L of a leaf left unevaluated when the refinement budget ran out) are written as nan /
// inf / -inf in the CSV and as the JSON strings "nan" / "inf" / "-inf".
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/global_injectivity.h"
#include "lidef/hash.h"
#include "lidef/number_format.h"
#include "lidef/octree_certifier.h"
#include "lidef/sampling.h"
#include "lidef/tri_mesh.h"
#include "lidef/types.h"

namespace lidef {

// Everything certificate.json records: the certifier's result plus its provenance.
struct CertificateReport {
  Certificate cert;  // verdict, counts, minima, failing leaves; leaves go to voxels.csv
  // Global injectivity on D (global_injectivity.h): decided only when the local certificate covers the
  // mesh's solid; otherwise not decided, with the reason.
  GlobalInjectivity global;
  std::string model;                    // model folder as given on the command line
  std::string coefficients;             // coefficient file as given, or "identity"
  std::uint64_t cage_hash = 0;          // FNV-1a 64 of the cage (subspace_cage_hash)
  std::uint64_t coefficients_hash = 0;  // coefficients_hash(y)
  int cage_vertices = 0, cage_faces = 0, cage_edges = 0;
  long mesh_vertices = 0;
  double mesh_coverage = 0;  // fraction of mesh vertices inside the union of the base voxels
  long mesh_vertices_uncovered = 0;
  // The certified domain (docs/certificate.md): "mesh" (D = the mesh's triangles and solid, sample_domain)
  // or "voxels" (the paper's grid); the leaves that meet D (exact test, cubes_meeting_mesh_domain) and the
  // voxels the certifier refused as not clear of the cage.
  std::string domain = "voxels";
  // Domain "mesh": what D holds for this mesh (MeshDomain::description / definition: "mesh and its solid",
  // "points and surface, no solid", ...); empty for "voxels".
  std::string domain_statement, domain_definition;
  long leaves_meeting_domain = 0;
  long uncleared_voxels = 0;
  SamplingParams sampling_params;  // as requested (voxel_side 0 = searched from target_count)
  // As obtained (the VoxelSampling fields that the report needs; the centers are not stored).
  double sampling_radius = 0;
  Vec3 sampling_origin = Vec3::Zero();
  bool sampling_target_met = true;
  int sampling_search_iterations = 0;
  int hessian_subset = 0;
  CertifyParams params;                   // bound, max_depth, budgets
  std::string voxels_csv = "voxels.csv";  // leaf table, relative to the certificate's folder
  std::uint64_t voxels_csv_hash = 0;      // FNV-1a 64 of the exact bytes of voxels.csv
};

// FNV-1a 64 of the coefficient doubles (#V+#F by 3, row by row, native byte order) and the row count.
std::uint64_t coefficients_hash(const MatX3d& y);

// The global injectivity verdict of a map whose local certificate is `cert` on the domain named `domain`:
// decided (global_injectivity.h) only when the certificate holds on the mesh's solid, else not decided with
// the reason.
GlobalInjectivity decide_global_injectivity(const Certificate& cert, const std::string& domain,
                                            const Cage& cage, const TriMesh& mesh, const MatX3d& y);
// Why the global verdict cannot be decided whatever the map's shape (the local certificate failed, the voxel
// domain, a point cloud); "" when the surface check can decide it. decide_global_injectivity states these
// reasons; the studio, which holds one GlobalInjectivityChecker per model, asks this first.
std::string global_injectivity_undecidable(const Certificate& cert, const std::string& domain,
                                           const TriMesh& mesh);

// Fills the provenance fields of a report (hashes, sizes, sampling as obtained, mesh coverage) and the global
// injectivity verdict: `known_global` where the caller holds the verdict of this very map (the solver's, in
// global mode), else computed (decide_global_injectivity).
CertificateReport make_certificate_report(const Certificate& cert, const Cage& cage, const TriMesh& mesh,
                                          const MatX3d& y, const std::string& model,
                                          const std::string& coefficients,
                                          const SamplingParams& sampling_params,
                                          const VoxelSampling& sampling, const CertifyParams& params,
                                          const GlobalInjectivity* known_global = nullptr);

// For console summaries when a distortion target is on (empty otherwise): "distortion targets
// (max_sigma1 1.2, min_sigma3 0.8) proven: sigma1 <= 1.19, sigma3 >= 0.81, sigma1/sigma3 <= 1.46" or "... not
// proven: <reason>".
std::string distortion_targets_summary(const Certificate& cert);

// voxels.csv: header `cx,cy,cz,side,depth,sigma3,L,margin,certified,sigma3_error,sigma1,sigma1_upper,
// distortion_upper`, one row per leaf in leaf order (base-voxel order, children depth-first), certified =
// 1/0.
const char* voxels_csv_header();
std::string voxels_csv(const std::vector<CertLeaf>& leaves);
// Parses voxels.csv (strictly: header, 13 fields per row — or 9 / 10 under the headers written before
// sigma3_error / the distortion columns —, numbers). Throws InputError(path, message, line).
std::vector<CertLeaf> read_voxels_csv(const std::string& path);

// certificate.json text (2-space indented, keys in a fixed order, trailing newline). Sets nothing in `r`:
// voxels_csv_hash must already be the hash of the voxels.csv that goes with it.
std::string certificate_json(const CertificateReport& r);

// Writes DIR/certificate.json and DIR/voxels.csv (each atomically; DIR must exist). Fills r.voxels_csv_hash.
void write_certificate_files(const std::string& dir, CertificateReport& r);

// Reads certificate.json and the voxels.csv named in it (relative to the JSON's folder) into a report whose
// cert.leaves holds the leaves. Checks the format tag, the leaf count and the voxels.csv hash, so a stale or
// edited voxels.csv is refused. Throws InputError naming the file.
CertificateReport read_certificate_json(const std::string& path);

}  // namespace lidef
