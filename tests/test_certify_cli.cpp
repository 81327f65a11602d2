// End-to-end tests of `lidef certify` and `lidef verify` (the real binary) and of the certificate files.
// Truth: the identity map (σ3 = 1 everywhere, L = 0 up to rounding: must certify at depth 0); a map with
// folds (σ3 < 0 at voxel centers: must not certify); dense sampling (verify) of a certified non-affine map; a
// certificate whose L was understated on purpose (verify must catch it).
#include <gtest/gtest.h>
#include <unistd.h>
#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkDataArray.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLImageDataReader.h>
#include <vtkXMLUnstructuredGridReader.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "lidef/analysis/certificate_report.h"
#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "test_support.h"

using namespace lidef;
namespace fs = std::filesystem;
using lidef::test::TempDir;

namespace {

const char* const kVoxelsHeader =
    "cx,cy,cz,side,depth,sigma3,L,margin,certified,sigma3_error,sigma1,sigma1_upper,distortion_upper";
const char* const kVerifyHeader =
    "cx,cy,cz,side,depth,L,sigma3_center,min_sigma3,max_quotient,tightness,violations,certified,max_sigma1,"
    "max_distortion,distortion_violations";

using lidef::test::read_text;
using lidef::test::write_text;

std::string quote(const std::string& s) {
  return "'" + s + "'";
}

std::string ball() {
  return lidef::test::project_data() + "/models/ball";
}

int run_lidef(const std::string& args, std::string* output) {
  return lidef::test::run_command(quote(lidef::test::cli()) + " " + args, output);
}

// `lidef certify MODEL --coeffs C --out OUT EXTRA`, with --samples 2000 and --grid 16 unless EXTRA sets them.
int certify(const std::string& model, const std::string& coeffs, const std::string& out, std::string* output,
            const std::string& extra = "") {
  std::string opts = extra;
  if (extra.find("--samples ") == std::string::npos) opts += " --samples 2000";
  if (extra.find("--grid ") == std::string::npos) opts += " --grid 16";
  return run_lidef(
      "certify " + quote(model) + " --coeffs " + quote(coeffs) + " --out " + quote(out) + " " + opts, output);
}

nlohmann::json read_json(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot open " << path;
  return nlohmann::json::parse(in);
}

// Strict CSV: header, then rows of `columns` numeric fields.
std::vector<std::vector<double>> read_csv(const std::string& path, const std::string& header,
                                          size_t columns) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot open " << path;
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, header) << path;
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::istringstream ss(line);
    std::string field;
    while (std::getline(ss, field, ',')) {
      char* end = nullptr;
      row.push_back(std::strtod(field.c_str(), &end));
      EXPECT_TRUE(!field.empty() && *end == '\0') << "not a number: '" << field << "' in " << path;
    }
    EXPECT_EQ(row.size(), columns) << line;
    rows.push_back(row);
  }
  return rows;
}

// Identity coefficients of `model` plus amp · (cage diagonal) · N(0,1) on every entry.
MatX3d perturbed(const std::string& model, double amp, unsigned seed) {
  const Cage cage(read_mesh(model + "/cage.obj"));
  const double size = (cage.bbox_max - cage.bbox_min).norm();
  MatX3d y = cage.identity_coefficients();
  std::mt19937 rng(seed);
  std::normal_distribution<double> N01;
  for (Eigen::Index i = 0; i < y.rows(); ++i)
    for (int k = 0; k < 3; ++k) y(i, k) += amp * size * N01(rng);
  return y;
}

void write_coeffs(const std::string& path, const MatX3d& y) {
  std::ofstream out(path);
  write_coefficients(out, y);
}

bool have_gnuplot() {
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path ? path : "");
  for (std::string d; std::getline(dirs, d, ':');)
    if (!d.empty() && ::access((fs::path(d) / "gnuplot").c_str(), X_OK) == 0) return true;
  return false;
}

// Entries of `dir` (names), to check that nothing (no staging folder, no temporary) was left behind.
std::vector<std::string> entries(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// ctest runs each test in its own process, several at once: seed std::rand (TempDir, run_command) per
// process.
class CertifyCli : public ::testing::Test {
 protected:
  void SetUp() override { std::srand(static_cast<unsigned>(::getpid()) * 2654435761u); }
};
using VerifyCli = CertifyCli;
using CertificateFiles = CertifyCli;

}  // namespace

TEST_F(CertifyCli, IdentityCertifiesAtDepthZeroAndIsDeterministic) {
  TempDir tmp;
  std::string output;
  ASSERT_EQ(certify(ball(), "identity", tmp / "a", &output), 0) << output;
  EXPECT_NE(output.find("CERTIFIED"), std::string::npos) << output;
  const nlohmann::json j = read_json(tmp / "a/certificate.json");
  EXPECT_EQ(j["certified"], true);
  EXPECT_EQ(j["reason"], "");
  EXPECT_EQ(j["bound"], "third");
  EXPECT_EQ(j["refined"], 0);
  EXPECT_EQ(j["max_depth_used"], 0);
  EXPECT_EQ(j["max_depth"], 6);
  EXPECT_EQ(j["leaves"], j["voxels"]);
  EXPECT_GT(j["voxels"].get<int>(), 1500);
  EXPECT_TRUE(j["failing"].empty());
  EXPECT_NEAR(j["min_sigma3_center"].get<double>(), 1.0, 1e-6);
  EXPECT_GT(j["min_margin"].get<double>(), 0.99);
  EXPECT_GT(j["voxel_side"].get<double>(), 0);
  EXPECT_EQ(j["rounding_allowance"].get<double>(), OctreeCertifier::kRoundingRel);
  const double cov = j["mesh_coverage"].get<double>();
  EXPECT_GE(cov, 0.0);
  EXPECT_LE(cov, 1.0);
  const long nmesh = j["mesh_vertices"].get<long>(), unc = j["mesh_vertices_uncovered"].get<long>();
  EXPECT_EQ(nmesh, 2562);
  EXPECT_NEAR(cov, static_cast<double>(nmesh - unc) / nmesh, 1e-15);
  EXPECT_EQ(j["sampling"]["target_count"], 2000);
  EXPECT_EQ(j["sampling"]["voxels"], j["voxels"]);
  EXPECT_EQ(j["coefficients"], "identity");

  // The default domain is the whole mesh: every vertex covered, every leaf meeting it.
  EXPECT_EQ(j["domain"]["kind"], "mesh");
  EXPECT_EQ(j["mesh_coverage"].get<double>(), 1.0);
  EXPECT_EQ(j["domain"]["leaves_meeting_mesh_domain"], j["leaves"]);
  EXPECT_EQ(j["domain"]["uncleared_voxels"], 0);
  // voxels.csv: exact header, one row per leaf, all certified; no refinement, so each leaf is a sampling leaf
  // of side base side / 2^depth (the mesh domain's levels toward the cage).
  const auto rows = read_csv(tmp / "a/voxels.csv", kVoxelsHeader, 13);
  ASSERT_EQ(static_cast<long>(rows.size()), j["leaves"].get<long>());
  for (const auto& r : rows) {
    EXPECT_EQ(r[3], std::ldexp(j["voxel_side"].get<double>(), -static_cast<int>(r[4])));
    EXPECT_GE(r[4], 0);
    EXPECT_NEAR(r[5], 1.0, 1e-6);
    EXPECT_GT(r[7], 0);
    EXPECT_EQ(r[8], 1);
  }
  // The paper's grid (--domain voxels): base voxels only, and the layer next to the cage uncovered.
  ASSERT_EQ(certify(ball(), "identity", tmp / "grid", &output, "--domain voxels --grid 0"), 0) << output;
  const nlohmann::json g = read_json(tmp / "grid/certificate.json");
  EXPECT_EQ(g["domain"]["kind"], "voxels");
  EXPECT_LT(g["mesh_coverage"].get<double>(), 0.5);
  for (const auto& r : read_csv(tmp / "grid/voxels.csv", kVoxelsHeader, 13)) {
    EXPECT_EQ(r[3], g["voxel_side"].get<double>());
    EXPECT_EQ(r[4], 0);
  }
  EXPECT_EQ(entries(tmp / "a"), (std::vector<std::string>{"certificate.json", "field.vti", "leaves.vtu",
                                                          "timings.json", "voxels.csv"}));
  const nlohmann::json t = read_json(tmp / "a/timings.json");
  EXPECT_GT(t["total_ms"].get<double>(), 0);

  // The same input again, on one thread: byte-identical certificate.json and voxels.csv.
  ASSERT_EQ(certify(ball(), "identity", tmp / "b", &output, "--threads 1"), 0) << output;
  EXPECT_EQ(read_text(tmp / "a/certificate.json"), read_text(tmp / "b/certificate.json"));
  EXPECT_EQ(read_text(tmp / "a/voxels.csv"), read_text(tmp / "b/voxels.csv"));
  // Re-running into an existing folder replaces the files; --grid 0 removes the now stale field.vti.
  ASSERT_EQ(certify(ball(), "identity", tmp / "a", &output, "--grid 0"), 0) << output;
  EXPECT_FALSE(fs::exists(tmp / "a/field.vti"));
  EXPECT_EQ(read_text(tmp / "a/certificate.json"), read_text(tmp / "b/certificate.json"));
}

TEST_F(CertifyCli, VtkFilesParseWithTheDocumentedArrays) {
  TempDir tmp;
  std::string output;
  ASSERT_EQ(certify(ball(), "identity", tmp / "c", &output), 0) << output;
  const long leaves = read_json(tmp / "c/certificate.json")["leaves"].get<long>();

  vtkNew<vtkXMLUnstructuredGridReader> ur;
  ur->SetFileName((tmp / "c/leaves.vtu").c_str());
  ur->Update();
  vtkUnstructuredGrid* ug = ur->GetOutput();
  ASSERT_NE(ug, nullptr);
  ASSERT_EQ(ug->GetNumberOfCells(), leaves);
  EXPECT_EQ(ug->GetNumberOfPoints(), 8 * leaves);
  EXPECT_EQ(ug->GetCellType(0), VTK_HEXAHEDRON);
  EXPECT_EQ(ug->GetCellType(leaves - 1), VTK_HEXAHEDRON);
  for (const char* name : {"depth", "side", "sigma3", "L", "margin", "status"}) {
    vtkDataArray* a = ug->GetCellData()->GetArray(name);
    ASSERT_NE(a, nullptr) << name;
    EXPECT_EQ(a->GetNumberOfTuples(), leaves) << name;
  }
  vtkDataArray* status = ug->GetCellData()->GetArray("status");
  for (vtkIdType i = 0; i < leaves; ++i) ASSERT_EQ(status->GetTuple1(i), 1.0);
  // Cell 0 is the cube of the first voxels.csv row: its volume is side³ (hexahedron corner order is right).
  double b[6];
  ug->GetCell(0)->GetBounds(b);
  const double side = read_csv(tmp / "c/voxels.csv", kVoxelsHeader, 13).front()[3];  // its own (mesh domain)
  EXPECT_NEAR(b[1] - b[0], side, 1e-12);
  EXPECT_NEAR(b[3] - b[2], side, 1e-12);
  EXPECT_NEAR(b[5] - b[4], side, 1e-12);

  vtkNew<vtkXMLImageDataReader> ir;
  ir->SetFileName((tmp / "c/field.vti").c_str());
  ir->Update();
  vtkImageData* im = ir->GetOutput();
  ASSERT_NE(im, nullptr);
  int dims[3];
  im->GetDimensions(dims);
  EXPECT_EQ(std::max({dims[0], dims[1], dims[2]}), 16);
  const vtkIdType np = static_cast<vtkIdType>(dims[0]) * dims[1] * dims[2];
  ASSERT_EQ(im->GetNumberOfPoints(), np);
  for (const char* name : {"sigma1", "sigma3", "detJ", "E_iso", "inside_cage", "inside_sampled"}) {
    vtkDataArray* a = im->GetPointData()->GetArray(name);
    ASSERT_NE(a, nullptr) << name;
    EXPECT_EQ(a->GetNumberOfTuples(), np) << name;
  }
  // Identity: σ1 = σ3 = det J = 1 and E_iso = 6 wherever the point is inside the cage; NaN outside.
  vtkDataArray *s1 = im->GetPointData()->GetArray("sigma1"), *s3 = im->GetPointData()->GetArray("sigma3"),
               *det = im->GetPointData()->GetArray("detJ"), *e = im->GetPointData()->GetArray("E_iso"),
               *in = im->GetPointData()->GetArray("inside_cage"),
               *ins = im->GetPointData()->GetArray("inside_sampled");
  long inside = 0, sampled = 0;
  for (vtkIdType i = 0; i < np; ++i) {
    if (ins->GetTuple1(i) == 1) {
      ++sampled;
      EXPECT_EQ(in->GetTuple1(i), 1) << "a sampled point outside the cage";
    }
    if (in->GetTuple1(i) != 1) {
      EXPECT_TRUE(std::isnan(s3->GetTuple1(i)));
      continue;
    }
    ++inside;
    EXPECT_NEAR(s1->GetTuple1(i), 1.0, 1e-5);
    EXPECT_NEAR(s3->GetTuple1(i), 1.0, 1e-5);
    EXPECT_NEAR(det->GetTuple1(i), 1.0, 1e-5);
    EXPECT_NEAR(e->GetTuple1(i), 6.0, 1e-4);
  }
  // A ball in its bounding cube: about π/6 of the grid is inside.
  EXPECT_GT(inside, np / 3);
  EXPECT_LT(inside, np * 2 / 3);
  EXPECT_GT(sampled, inside / 3);
}

TEST_F(CertifyCli, FoldedMapIsNotCertified) {
  TempDir tmp;
  // A large random perturbation of every coefficient folds the map: σ3 < 0 at voxel centers.
  write_coeffs(tmp / "folded.txt", perturbed(ball(), 0.5, 7));
  std::string output;
  ASSERT_EQ(certify(ball(), tmp / "folded.txt", tmp / "out", &output, "--max-depth 0"), 1) << output;
  EXPECT_NE(output.find("NOT CERTIFIED"), std::string::npos) << output;
  const nlohmann::json j = read_json(tmp / "out/certificate.json");
  EXPECT_EQ(j["certified"], false);
  EXPECT_FALSE(j["reason"].get<std::string>().empty());
  ASSERT_FALSE(j["failing"].empty());
  const nlohmann::json& f = j["failing"][0];
  EXPECT_EQ(f["center"].size(), 3u);
  EXPECT_LE(f["margin"].get<double>(), 0);
  EXPECT_LT(j["min_sigma3_center"].get<double>(), 0);
  const auto rows = read_csv(tmp / "out/voxels.csv", kVoxelsHeader, 13);
  ASSERT_EQ(static_cast<long>(rows.size()), j["leaves"].get<long>());
  long failing = 0;
  for (const auto& r : rows) failing += r[8] == 0;
  EXPECT_GT(failing, 0);
  // The failing leaves are flagged in the .vtu too.
  vtkNew<vtkXMLUnstructuredGridReader> ur;
  ur->SetFileName((tmp / "out/leaves.vtu").c_str());
  ur->Update();
  vtkDataArray* status = ur->GetOutput()->GetCellData()->GetArray("status");
  ASSERT_NE(status, nullptr);
  long zeros = 0;
  for (vtkIdType i = 0; i < status->GetNumberOfTuples(); ++i) zeros += status->GetTuple1(i) == 0;
  EXPECT_EQ(zeros, failing);
}

// --bound-tolerance (a row of the parameter table): the certificate is refined until its lower bound of σ3 is
// within the tolerance of the smallest sampled σ3, and certificate.json says so; the spectral bound needs
// fewer refined voxels for it than the third-order bound; without the flag the fields say "off".
TEST_F(CertifyCli, BoundToleranceTightensTheLowerBoundAndIsRecorded) {
  TempDir tmp;
  write_coeffs(tmp / "y.txt", perturbed(ball(), 0.004, 3));
  std::string output;
  ASSERT_EQ(certify(ball(), tmp / "y.txt", tmp / "plain", &output), 0) << output;
  const nlohmann::json p = read_json(tmp / "plain/certificate.json");
  EXPECT_EQ(p["bound_tolerance"].get<double>(), 0.0);
  EXPECT_TRUE(p["bound_tolerance_met"].is_null());
  long refined[2] = {0, 0};
  int k = 0;
  for (const char* b : {"third", "spectral"}) {
    const std::string out = tmp / ("t_" + std::string(b));
    ASSERT_EQ(certify(ball(), tmp / "y.txt", out, &output, std::string("--bound-tolerance 0.3 --bound ") + b),
              0)
        << output;
    const nlohmann::json j = read_json(out + "/certificate.json");
    EXPECT_EQ(j["bound_tolerance"].get<double>(), 0.3);
    EXPECT_EQ(j["bound_tolerance_met"], true) << b;
    EXPECT_GE(j["min_lower_bound"].get<double>(), 0.7 * j["min_sigma3_center"].get<double>()) << b;
    EXPECT_GT(j["min_lower_bound"].get<double>(), p["min_lower_bound"].get<double>()) << b;
    refined[k++] = j["refined"].get<long>();
  }
  EXPECT_GT(refined[0], 0) << "the tolerance should need refinement with the third-order bound";
  EXPECT_LE(refined[1], refined[0]) << "spectral is the tighter bound";
  // The fields survive the reader (lidef verify reads certificate.json).
  const CertificateReport back = read_certificate_json(tmp / "t_spectral/certificate.json");
  EXPECT_EQ(back.cert.bound_tolerance, 0.3);
  EXPECT_TRUE(back.cert.bound_tolerance_met);
}

TEST_F(VerifyCli, CertifiedMapPassesDenseSampling) {
  TempDir tmp;
  // A non-affine map that certifies with some refinement.
  write_coeffs(tmp / "y.txt", perturbed(ball(), 0.003, 3));
  std::string output;
  ASSERT_EQ(certify(ball(), tmp / "y.txt", tmp / "cert", &output, "--grid 0"), 0) << output;
  const nlohmann::json j = read_json(tmp / "cert/certificate.json");
  ASSERT_EQ(j["certified"], true);
  EXPECT_GT(j["refined"].get<long>(), 0) << "the map should need refinement, or the test proves little";
  const long leaves = j["leaves"].get<long>();

  ASSERT_EQ(run_lidef("verify " + quote(ball()) + " --coeffs " + quote(tmp / "y.txt") + " --certificate " +
                          quote(tmp / "cert/certificate.json") + " --samples-per-voxel 8",
                      &output),
            0)
      << output;
  EXPECT_NE(output.find("bound violations 0, samples with sigma3 <= 0 in certified leaves 0"),
            std::string::npos)
      << output;
  const auto rows = read_csv(tmp / "cert/verify.csv", kVerifyHeader, 15);
  ASSERT_EQ(static_cast<long>(rows.size()), leaves);
  const auto cert_rows = read_csv(tmp / "cert/voxels.csv", kVoxelsHeader, 13);
  double max_tight = 0;
  for (size_t i = 0; i < rows.size(); ++i) {
    EXPECT_EQ(rows[i][0], cert_rows[i][0]);    // same leaf order, exact centers
    EXPECT_EQ(rows[i][5], cert_rows[i][6]);    // the certificate's L
    EXPECT_EQ(rows[i][10], 0);                 // no violation
    EXPECT_EQ(rows[i][14], 0);                 // no sample above the leaf's σ1 or σ1/σ3 bound
    EXPECT_LE(rows[i][12], cert_rows[i][11]);  // sampled max σ1 ≤ sigma1_upper
    EXPECT_LE(rows[i][13], cert_rows[i][12]);  // sampled max σ1/σ3 ≤ distortion_upper
    EXPECT_GT(rows[i][7], 0);                  // min sampled σ3 > 0 in a certified leaf
    EXPECT_LE(rows[i][9], 1.0);                // sampled Lipschitz estimate ≤ L
    max_tight = std::max(max_tight, rows[i][9]);
  }
  EXPECT_GT(max_tight, 1e-3) << "the map is not affine: the sampled Lipschitz estimate cannot be ~0";
  EXPECT_EQ(read_text(tmp / "cert/violations.csv"), "leaf,px,py,pz,sigma3,bound\n");
  EXPECT_TRUE(fs::exists(tmp / "cert/verify_plot.gp"));
  EXPECT_TRUE(fs::exists(tmp / "cert/verify_plot.dat"));
  if (have_gnuplot()) {
    ASSERT_TRUE(fs::exists(tmp / "cert/verify_plot.png")) << output;
    EXPECT_EQ(read_text(tmp / "cert/verify_plot.png").substr(1, 3), "PNG");
  } else {
    std::cout << "gnuplot not installed: PNG not checked\n";
  }

  // Without gnuplot: a warning, the script and data still written, no (stale) PNG; --out elsewhere.
  ASSERT_EQ(lidef::test::run_command("LIDEF_GNUPLOT=none " + quote(lidef::test::cli()) + " verify " +
                                         quote(ball()) + " --coeffs " + quote(tmp / "y.txt") +
                                         " --certificate " + quote(tmp / "cert/certificate.json") +
                                         " --samples-per-voxel 2 --out " + quote(tmp / "v2"),
                                     &output),
            0)
      << output;
  EXPECT_NE(output.find("warning"), std::string::npos) << output;
  EXPECT_NE(output.find("gnuplot"), std::string::npos) << output;
  EXPECT_EQ(entries(tmp / "v2"),
            (std::vector<std::string>{"verify.csv", "verify_plot.dat", "verify_plot.gp", "violations.csv"}));
}

TEST_F(VerifyCli, UnderstatedLipschitzConstantsAreCaught) {
  TempDir tmp;
  write_coeffs(tmp / "y.txt", perturbed(ball(), 0.003, 3));
  std::string output;
  // (Verified or not, a certificate's bounds must hold: verify does not need a certified map.)
  const int rc =
      certify(ball(), tmp / "y.txt", tmp / "cert", &output, "--grid 0 --max-depth 0 --samples 600");
  ASSERT_TRUE(rc == 0 || rc == 1) << output;
  // Forge the certificate: L / 1000 on every leaf, with a matching hash so that verify accepts the files.
  const std::string csv_path = tmp / "cert/voxels.csv";
  std::istringstream in(read_text(csv_path));
  std::string line, forged;
  std::getline(in, line);
  forged = line + "\n";
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::istringstream ss(line);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    ASSERT_EQ(f.size(), 13u);
    f[6] = format_double(std::strtod(f[6].c_str(), nullptr) / 1000);
    for (size_t k = 0; k < f.size(); ++k) forged += (k ? "," : "") + f[k];
    forged += "\n";
  }
  write_text(csv_path, forged);
  // Verify refuses the edited file as long as the recorded hash does not match ...
  EXPECT_EQ(run_lidef("verify " + quote(ball()) + " --coeffs " + quote(tmp / "y.txt") + " --certificate " +
                          quote(tmp / "cert/certificate.json"),
                      &output),
            2)
      << output;
  EXPECT_NE(output.find(csv_path), std::string::npos) << output;
  // ... and finds the violations once the hash is forged too.
  nlohmann::ordered_json j = nlohmann::ordered_json::parse(read_text(tmp / "cert/certificate.json"));
  char hex[20];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(fnv1a64(forged)));
  j["voxels_csv_fnv1a64"] = hex;
  write_text(tmp / "cert/certificate.json", j.dump(2) + "\n");
  EXPECT_EQ(run_lidef("verify " + quote(ball()) + " --coeffs " + quote(tmp / "y.txt") + " --certificate " +
                          quote(tmp / "cert/certificate.json") + " --samples-per-voxel 8",
                      &output),
            1)
      << output;
  EXPECT_NE(output.find("FAILED"), std::string::npos) << output;
  const auto viol = read_csv(tmp / "cert/violations.csv", "leaf,px,py,pz,sigma3,bound", 6);
  ASSERT_FALSE(viol.empty());
  for (const auto& v : viol) EXPECT_LT(v[4], v[5]);  // σ3(p) below the forged bound
}

TEST_F(VerifyCli, MismatchedInputsAreRefused) {
  TempDir tmp;
  std::string output;
  ASSERT_EQ(certify(ball(), "identity", tmp / "cert", &output, "--grid 0 --samples 300"), 0) << output;
  write_coeffs(tmp / "other.txt", perturbed(ball(), 0.001, 5));
  const std::string cert = tmp / "cert/certificate.json";
  const std::string beam = lidef::test::project_data() + "/models/beam";
  struct Case {
    std::string name, args, culprit;
  };
  const std::vector<Case> cases = {
      {"other coefficients",
       quote(ball()) + " --coeffs " + quote(tmp / "other.txt") + " --certificate " + quote(cert), cert},
      {"other model", quote(beam) + " --coeffs identity --certificate " + quote(cert), cert},
      {"missing certificate", quote(ball()) + " --coeffs identity --certificate " + quote(tmp / "none.json"),
       tmp / "none.json"},
      {"negative samples",
       quote(ball()) + " --coeffs identity --certificate " + quote(cert) + " --samples-per-voxel -1",
       "--samples-per-voxel"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    EXPECT_EQ(run_lidef("verify " + c.args, &output), 2) << output;
    EXPECT_NE(output.find(c.culprit), std::string::npos) << output;
  }
  // None of them wrote anything.
  EXPECT_EQ(entries(tmp / "cert"),
            (std::vector<std::string>{"certificate.json", "leaves.vtu", "timings.json", "voxels.csv"}));
}

TEST_F(CertifyCli, BadInputsFailWithoutWritingAnything) {
  TempDir tmp;
  const Cage cage(read_mesh(ball() + "/cage.obj"));
  std::ostringstream id_text;
  write_coefficients(id_text, cage.identity_coefficients());
  const std::string rows = id_text.str();
  write_text(tmp / "wrong_rows.txt",
             rows.substr(0, rows.rfind('\n', rows.size() - 2) + 1));  // last row dropped
  write_text(tmp / "nan.txt", "0 nan 0\n" + rows.substr(rows.find('\n') + 1));
  struct Case {
    std::string name, model, coeffs, extra, culprit;
  };
  const std::vector<Case> cases = {
      {"wrong_rows", ball(), tmp / "wrong_rows.txt", "", tmp / "wrong_rows.txt"},
      {"nan", ball(), tmp / "nan.txt", "", tmp / "nan.txt"},
      {"missing_coeffs", ball(), tmp / "none.txt", "", tmp / "none.txt"},
      {"voxel_side", ball(), "identity", "--voxel-side -1", "--voxel-side"},
      {"voxel_side_zero", ball(), "identity", "--voxel-side 0", "--voxel-side"},
      {"max_depth", ball(), "identity", "--max-depth -1", "--max-depth"},
      {"missing_model", tmp / "no_such_model", "identity", "", tmp / "no_such_model"},
      {"bound", ball(), "identity", "--bound second", "--bound"},
      {"safety", ball(), "identity", "--safety 1", "--safety"},
      {"grid", ball(), "identity", "--grid 1", "--grid"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string out = tmp / ("out_" + c.name);
    std::string output;
    EXPECT_EQ(certify(c.model, c.coeffs, out, &output, c.extra), 2) << output;
    EXPECT_NE(output.find(c.culprit), std::string::npos) << "message does not name " << c.culprit << ":\n"
                                                         << output;
    EXPECT_NE(output.find("error"), std::string::npos) << output;
    EXPECT_FALSE(fs::exists(out)) << out;
  }
  // An existing output folder keeps exactly what it had.
  fs::create_directories(tmp / "keep");
  write_text(tmp / "keep/certificate.json", "previous\n");
  std::string output;
  EXPECT_EQ(certify(ball(), tmp / "nan.txt", tmp / "keep", &output), 2) << output;
  EXPECT_EQ(entries(tmp / "keep"), std::vector<std::string>{"certificate.json"});
  EXPECT_EQ(read_text(tmp / "keep/certificate.json"), "previous\n");
  // A file where the folder should be.
  write_text(tmp / "a_file", "x");
  EXPECT_EQ(certify(ball(), "identity", tmp / "a_file", &output, "--samples 300 --grid 0"), 2) << output;
  EXPECT_NE(output.find(tmp / "a_file"), std::string::npos) << output;
  EXPECT_EQ(read_text(tmp / "a_file"), "x");
}

TEST_F(CertifyCli, HelpDescribesTheOutputs) {
  std::string output;
  EXPECT_EQ(run_lidef("certify --help", &output), 0) << output;
  for (const char* s : {"--coeffs", "--voxel-side", "--max-depth", "--bound", "--grid", "certificate.json",
                        "voxels.csv", "leaves.vtu", "field.vti", "Exit code"})
    EXPECT_NE(output.find(s), std::string::npos) << s << "\n" << output;
  EXPECT_EQ(run_lidef("verify --help", &output), 0) << output;
  for (const char* s :
       {"--certificate", "--samples-per-voxel", "--seed", "verify.csv", "violations.csv", "gnuplot"})
    EXPECT_NE(output.find(s), std::string::npos) << s << "\n" << output;
}

TEST_F(CertificateFiles, RoundTripIsExactIncludingNonFiniteValues) {
  TempDir tmp;
  CertificateReport r;
  r.model = "some/model";
  r.coefficients = "y.txt";
  r.cage_hash = 0x0123456789abcdefull;
  r.coefficients_hash = 0xfedcba9876543210ull;
  Certificate& c = r.cert;
  c.certified = false;
  c.reason = "refinement budget exhausted";
  c.bound = LipschitzBound::kFirstOrder;
  c.voxel_side = 0.1;
  c.voxels = 2;
  c.min_sigma3_center = 1.0 / 3.0;
  c.min_margin = -std::numeric_limits<double>::infinity();
  c.min_lower_bound = -0.25;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  c.leaves = {{Vec3(0.1, -0.2, 1.0 / 7.0), 0.1, 0, 0.9, 2.5, 0.1, true, 0},
              {Vec3(1e-300, 2, 3), 0.05, 1, nan, inf, -inf, false, 1}};
  c.num_leaves = 2;
  c.failing = {c.leaves[1]};
  write_certificate_files(tmp.str(), r);
  const CertificateReport back = read_certificate_json(tmp / "certificate.json");
  EXPECT_EQ(back.cert.certified, false);
  EXPECT_EQ(back.cert.reason, c.reason);
  EXPECT_EQ(back.cert.bound, LipschitzBound::kFirstOrder);
  EXPECT_EQ(back.cert.min_sigma3_center, 1.0 / 3.0);
  EXPECT_EQ(back.cert.min_margin, -inf);
  EXPECT_EQ(back.cage_hash, r.cage_hash);
  EXPECT_EQ(back.coefficients_hash, r.coefficients_hash);
  ASSERT_EQ(back.cert.leaves.size(), 2u);
  EXPECT_EQ(back.cert.leaves[0].center, c.leaves[0].center);
  EXPECT_EQ(back.cert.leaves[1].center, c.leaves[1].center);
  EXPECT_TRUE(std::isnan(back.cert.leaves[1].sigma3));
  EXPECT_EQ(back.cert.leaves[1].L, inf);
  EXPECT_EQ(back.cert.leaves[1].margin, -inf);
  EXPECT_EQ(back.cert.leaves[1].depth, 1);
  EXPECT_FALSE(back.cert.leaves[1].certified);
  ASSERT_EQ(back.cert.failing.size(), 1u);
  EXPECT_EQ(back.cert.failing[0].L, inf);
  // Writing what was read gives the same bytes.
  TempDir tmp2;
  CertificateReport again = back;
  write_certificate_files(tmp2.str(), again);
  EXPECT_EQ(read_text(tmp / "certificate.json"), read_text(tmp2 / "certificate.json"));
  EXPECT_EQ(read_text(tmp / "voxels.csv"), read_text(tmp2 / "voxels.csv"));

  // A leaf count that disagrees with voxels.csv, a bad header and a non-number are refused with the file
  // named.
  const std::string json = read_text(tmp / "certificate.json");
  write_text(tmp / "voxels.csv", read_text(tmp / "voxels.csv") + "0,0,0,0.1,0,1,1,1,1\n");
  EXPECT_THROW(read_certificate_json(tmp / "certificate.json"), InputError);  // hash differs
  write_text(tmp / "voxels.csv", "cx,cy\n");
  try {
    read_voxels_csv(tmp / "voxels.csv");
    ADD_FAILURE() << "no exception";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), tmp / "voxels.csv");
    EXPECT_EQ(e.line(), 1);
  }
  write_text(tmp / "voxels.csv", std::string(voxels_csv_header()) + "\n0,0,0,0.1,0,x,1,1,1\n");
  try {
    read_voxels_csv(tmp / "voxels.csv");
    ADD_FAILURE() << "no exception";
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 2);
  }
  write_text(tmp / "bad.json", "{\"format\": \"something else\"}");
  EXPECT_THROW(read_certificate_json(tmp / "bad.json"), InputError);
  write_text(tmp / "bad.json", json.substr(0, json.size() / 2));
  EXPECT_THROW(read_certificate_json(tmp / "bad.json"), InputError);
  // Found by fuzzing (fuzz/regressions/certificate_json/): a number beyond the double range is nlohmann's
  // out_of_range, not its parse_error; it escaped as a JSON library exception instead of an InputError.
  write_text(tmp / "bad.json", "{\"format\": \"lidef-certificate\", \"version\": 1e999}");
  try {
    read_certificate_json(tmp / "bad.json");
    ADD_FAILURE() << "no exception";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), tmp / "bad.json");
    EXPECT_NE(std::string(e.what()).find("1e999"), std::string::npos) << e.what();
  }
}

// The published models: the identity certifies on each (animal has cage self-intersections: a warning, and
// the sampling keeps its voxels out of the pockets, so it must still certify).
class SharedModelCertify : public ::testing::TestWithParam<const char*> {
 protected:
  void SetUp() override { std::srand(static_cast<unsigned>(::getpid()) * 2654435761u); }
};

TEST_P(SharedModelCertify, IdentityIsCertified) {
  LIDEF_REQUIRE_SHARED();
  TempDir tmp;
  std::string output;
  const std::string model = lidef::test::shared_model(GetParam());
  ASSERT_EQ(run_lidef("certify " + quote(model) + " --coeffs identity --out " + quote(tmp / "out") +
                          " --samples 3000 --grid 0",
                      &output),
            0)
      << output;
  const nlohmann::json j = read_json(tmp / "out/certificate.json");
  EXPECT_EQ(j["certified"], true);
  EXPECT_EQ(j["refined"], 0);
  EXPECT_EQ(j["leaves"], j["voxels"]);
  EXPECT_EQ(j["mesh_coverage"].get<double>(), 1.0);  // the whole mesh
  std::cout << GetParam() << ": " << j["voxels"] << " voxels, mesh coverage " << j["mesh_coverage"] << "\n"
            << output;
}

INSTANTIATE_TEST_SUITE_P(CertifyCli, SharedModelCertify, ::testing::Values("bar", "horse", "spot", "animal"));
