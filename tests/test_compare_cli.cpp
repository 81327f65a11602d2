// `lidef compare` end to end on the project's beam (small lidef problem): every output file, the table's
// columns and rows, and per-method sanity (handles reached, no inverted tet, lidef certified, volume ratios
// near 1). Bad input: a tet mesh that misses the mesh vertices, an empty tet mesh and a TetGen failure on a
// self-intersecting cage each fail only their method; an unknown method is an error before anything runs.
// CompareSlow.* runs the shared bar_bend scenario with every method (ctest label "slow").
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "lidef/compare/compare.h"
#include "lidef/procedural_models.h"
#include "lidef/scenario.h"
#include "test_support.h"

namespace fs = std::filesystem;
using lidef::test::TempDir;

namespace {

const char* const kSmall = "--samples 4000 --reduced-dof 60 --cache-dir ''";

int run_lidef(const std::string& args, std::string* out) {
  return lidef::test::run_command("'" + lidef::test::cli() + "' " + args, out);
}

// table.csv as rows of (column → text); quoted fields may hold commas.
std::vector<std::map<std::string, std::string>> read_table(const std::string& path,
                                                           std::vector<std::string>* header) {
  std::ifstream in(path);
  std::string line;
  std::vector<std::map<std::string, std::string>> rows;
  auto split = [](const std::string& l) {
    std::vector<std::string> f;
    std::string cur;
    bool q = false;
    for (size_t i = 0; i < l.size(); ++i) {
      const char c = l[i];
      if (c == '"') {
        if (q && i + 1 < l.size() && l[i + 1] == '"') {
          cur += '"';
          ++i;
        } else {
          q = !q;
        }
      } else if (c == ',' && !q) {
        f.push_back(cur);
        cur.clear();
      } else {
        cur += c;
      }
    }
    f.push_back(cur);
    return f;
  };
  if (!std::getline(in, line)) return rows;
  *header = split(line);
  while (std::getline(in, line)) {
    const auto f = split(line);
    std::map<std::string, std::string> r;
    for (size_t k = 0; k < header->size() && k < f.size(); ++k) r[(*header)[k]] = f[k];
    EXPECT_EQ(f.size(), header->size()) << line;
    rows.push_back(r);
  }
  return rows;
}

std::map<std::string, std::string> row_of(const std::vector<std::map<std::string, std::string>>& rows,
                                          const std::string& method) {
  for (const auto& r : rows)
    if (r.at("method") == method) return r;
  ADD_FAILURE() << "no row for " << method;
  return {};
}

double num(const std::map<std::string, std::string>& r, const std::string& c) {
  return r.count(c) && !r.at(c).empty() ? std::stod(r.at(c)) : std::nan("");
}

// A copy of the project's beam in `dir`/beam with extra files, and beam_bend pointing at it.
std::string beam_copy(const TempDir& dir, const std::map<std::string, std::string>& extra) {
  const fs::path m = fs::path(dir.str()) / "beam";
  fs::create_directories(m);
  for (const char* f : {"cage.obj", "mesh.obj", "model.json"})
    fs::copy_file(fs::path(lidef::test::project_data()) / "models/beam" / f, m / f);
  for (const auto& [name, text] : extra) lidef::test::write_text((m / name).string(), text);
  std::ifstream in(lidef::test::project_data() + "/scenarios/beam_bend.json");
  nlohmann::json j = nlohmann::json::parse(in);
  j["model"] = m.string();
  const std::string sc = dir / "scenario.json";
  lidef::test::write_text(sc, j.dump(2));
  return sc;
}

}  // namespace

TEST(CompareCli, BeamAllMethodsEndToEnd) {
  TempDir dir;
  const std::string out = dir / "cmp";
  std::string log;
  const int rc =
      run_lidef("compare '" + lidef::test::project_data() + "/scenarios/beam_bend.json' --out '" + out +
                    "' --methods lidef,pwl-tet,pwl-tet-fine,vhm,pwl-tri --fine-volume-factor 4 " + kSmall,
                &log);
  ASSERT_EQ(rc, 0) << log;
  for (const std::string m : {"lidef", "pwl-tet", "pwl-tet-fine", "vhm", "pwl-tri"}) {
    for (const char* ext : {".obj", ".vtp", ".log"}) EXPECT_TRUE(fs::exists(out + "/" + m + ext)) << m << ext;
    EXPECT_NE(log.find("[" + m + "]"), std::string::npos) << "no progress for " << m;
  }
  std::vector<std::string> header;
  const auto rows = read_table(out + "/table.csv", &header);
  EXPECT_EQ(header, lidef::comparison_table_columns());
  ASSERT_EQ(rows.size(), 5u);
  const std::string md = lidef::test::read_text(out + "/table.md");
  for (const char* col : {"DOF", "time (s)", "iterations", "max handle error", "mean E_iso−6", "max E_iso−6",
                          "global volume ratio", "inverted tets", "certified", "min σ3", "time / lidef"})
    EXPECT_NE(md.find(col), std::string::npos) << col;
  for (const auto& r : rows) {
    EXPECT_NE(r.at("status"), "failed") << r.at("method") << ": " << r.at("error");
    EXPECT_GT(num(r, "dof"), 0);
    EXPECT_GT(num(r, "time_s"), 0);
    EXPECT_GE(num(r, "iterations"), 1);
    EXPECT_LT(num(r, "max_handle_error"), 0.05) << r.at("method");
    EXPECT_NEAR(num(r, "global_volume_ratio"), 1.0, 0.25) << r.at("method");
    EXPECT_GT(num(r, "time_ratio_to_lidef"), 0);
  }
  const auto lidef = row_of(rows, "lidef"), tet = row_of(rows, "pwl-tet"),
             fine = row_of(rows, "pwl-tet-fine"), vhm = row_of(rows, "vhm"), tri = row_of(rows, "pwl-tri");
  EXPECT_EQ(lidef.at("certified"), "1");
  EXPECT_GT(num(lidef, "min_sigma3"), 0);
  EXPECT_DOUBLE_EQ(num(lidef, "time_ratio_to_lidef"), 1.0);
  EXPECT_EQ(num(lidef, "dof"), 180);
  EXPECT_EQ(tet.at("inverted_elements"), "0");
  EXPECT_EQ(fine.at("inverted_elements"), "0");
  EXPECT_GT(num(fine, "dof"), 2 * num(tet, "dof"));
  EXPECT_GE(num(tet, "mean_e_iso_minus_6"), 0);
  EXPECT_FALSE(vhm.at("certified").empty());          // judged by lidef's certificate
  EXPECT_TRUE(tri.at("mean_e_iso_minus_6").empty());  // no volumetric distortion for a surface method
  EXPECT_TRUE(tri.at("certified").empty());
  // The solid mean (harmonic methods, on the samples of lidef's certified domain): for lidef it is the
  // distortion term lidef minimized, which `lidef deform` reports from its own (float-stored, reduced) basis
  // gradients — an independent evaluation of the same number (full basis, per point); 1e-5 covers the float
  // storage.
  EXPECT_NE(md.find("mean E_iso−6 (solid)"), std::string::npos);
  EXPECT_TRUE(tet.at("mean_e_iso_minus_6_solid").empty());
  EXPECT_TRUE(tri.at("mean_e_iso_minus_6_solid").empty());
  EXPECT_GT(num(vhm, "mean_e_iso_minus_6_solid"), 0);
  const double solid = num(lidef, "mean_e_iso_minus_6_solid");
  EXPECT_GT(solid, 0);
  std::string dlog;
  ASSERT_EQ(run_lidef("deform '" + lidef::test::project_data() +
                          "/scenarios/beam_bend.json' --quiet --out '" + dir / "deform" + "' " + kSmall,
                      &dlog),
            0)
      << dlog;
  const nlohmann::json summary = nlohmann::json::parse(lidef::test::read_text(dir / "deform/summary.json"));
  const double e_dis = summary.at("energy").at("dis").get<double>();
  EXPECT_NEAR(solid, e_dis, 1e-5 * e_dis) << "compare's solid mean vs deform's distortion term";
}

// --repeat: every method's solve three times, interleaved; the time is the median of the runs (between their
// min and max, the three columns from the same runs), every run ends at the first run's map, and the
// results (iterations, handle error) are those of a single run.
TEST(CompareCli, RepeatTimesTheMedianOfInterleavedRuns) {
  TempDir dir;
  const std::string sc = lidef::test::project_data() + "/scenarios/beam_bend.json";
  std::string log;
  ASSERT_EQ(
      run_lidef("compare '" + sc + "' --out '" + dir / "once" + "' --methods lidef,pwl-tet " + kSmall, &log),
      0)
      << log;
  ASSERT_EQ(run_lidef("compare '" + sc + "' --out '" + dir / "rep" + "' --methods lidef,pwl-tet --repeat 3 " +
                          kSmall,
                      &log),
            0)
      << log;
  // Interleaved: the second run of lidef starts after PWL(Tet)'s first.
  const size_t tet_first = log.find("[pwl-tet] starting"), lidef_second = log.find("[lidef] run 2 of 3");
  ASSERT_NE(lidef_second, std::string::npos) << log;
  EXPECT_LT(tet_first, lidef_second) << log;
  std::vector<std::string> header;
  const auto once = read_table(dir / "once/table.csv", &header);
  const auto rep = read_table(dir / "rep/table.csv", &header);
  EXPECT_EQ(header, lidef::comparison_table_columns());
  for (const char* m : {"lidef", "pwl-tet"}) {
    const auto a = row_of(once, m), b = row_of(rep, m);
    EXPECT_EQ(a.at("repeats"), "1") << m;
    EXPECT_EQ(a.at("repeats_identical"), "") << m;
    EXPECT_EQ(b.at("repeats"), "3") << m;
    EXPECT_EQ(b.at("repeats_identical"), "1") << m;
    EXPECT_LE(num(b, "time_s_min"), num(b, "time_s")) << m;
    EXPECT_LE(num(b, "time_s"), num(b, "time_s_max")) << m;
    EXPECT_LT(num(b, "time_s_min"), num(b, "time_s_max")) << m;  // three timings, not one copied
    EXPECT_EQ(a.at("iterations"), b.at("iterations")) << m;
    EXPECT_EQ(a.at("max_handle_error"), b.at("max_handle_error")) << m;
  }
  EXPECT_DOUBLE_EQ(num(row_of(rep, "lidef"), "time_ratio_to_lidef"), 1.0);
  EXPECT_NE(lidef::test::read_text(dir / "rep/table.md").find("the median of 3 runs"), std::string::npos);
  EXPECT_NE(run_lidef("compare '" + sc + "' --out '" + dir / "bad" + "' --repeat 0 " + kSmall, &log), 0);
  EXPECT_FALSE(fs::exists(dir / "bad/table.csv"));
}

TEST(CompareCli, FailingMethodIsReportedAndOthersRun) {
  // A tet mesh of one small tet: the mesh vertices lie outside every tet.
  {
    TempDir dir;
    const std::string sc =
        beam_copy(dir, {{"tet.node", "4 3 0 0\n1 0 0 0\n2 0.1 0 0\n3 0 0.1 0\n4 0 0 0.1\n"},
                        {"tet.ele", "1 4 0\n1 1 2 3 4\n"}});
    std::string log;
    const int rc =
        run_lidef("compare '" + sc + "' --out '" + dir / "cmp" + "' --methods pwl-tet,pwl-tri", &log);
    EXPECT_EQ(rc, 1) << log;
    std::vector<std::string> header;
    const auto rows = read_table(dir / "cmp/table.csv", &header);
    ASSERT_EQ(rows.size(), 2u) << log;
    EXPECT_EQ(row_of(rows, "pwl-tet").at("status"), "failed");
    EXPECT_NE(row_of(rows, "pwl-tet").at("error").find("outside every tetrahedron"), std::string::npos);
    EXPECT_NE(row_of(rows, "pwl-tri").at("status"), "failed");
    EXPECT_FALSE(fs::exists(dir / "cmp/pwl-tet.obj"));
    EXPECT_TRUE(fs::exists(dir / "cmp/pwl-tet.log"));
    EXPECT_TRUE(fs::exists(dir / "cmp/pwl-tri.obj"));
  }
  // An empty tet mesh.
  {
    TempDir dir;
    const std::string sc = beam_copy(
        dir, {{"tet.node", "4 3 0 0\n1 0 0 0\n2 0.1 0 0\n3 0 0.1 0\n4 0 0 0.1\n"}, {"tet.ele", "0 4 0\n"}});
    std::string log;
    EXPECT_EQ(run_lidef("compare '" + sc + "' --out '" + dir / "cmp" + "' --methods pwl-tet,pwl-tri", &log),
              1)
        << log;
    std::vector<std::string> header;
    const auto rows = read_table(dir / "cmp/table.csv", &header);
    EXPECT_NE(row_of(rows, "pwl-tet").at("error").find("no tetrahedra"), std::string::npos);
    EXPECT_NE(row_of(rows, "pwl-tri").at("status"), "failed");
  }
}

// --blas-threads: CHOLMOD's OpenBLAS threads for PWL(Tet) (as OpenBLAS reports them in the run), by default
// the run's; the solve is the same Newton iteration either way.
TEST(CompareCli, BlasThreadsSetPwlTetsCholmodThreads) {
  TempDir dir;
  const std::string sc = lidef::test::project_data() + "/scenarios/beam_bend.json";
  std::string one, dflt, bad;
  ASSERT_EQ(run_lidef("compare '" + sc + "' --out '" + dir / "one" +
                          "' --methods pwl-tet --threads 2 --blas-threads 1 " + kSmall,
                      &one),
            0)
      << one;
  ASSERT_EQ(
      run_lidef("compare '" + sc + "' --out '" + dir / "dflt" + "' --methods pwl-tet --threads 2 " + kSmall,
                &dflt),
      0)
      << dflt;
  EXPECT_NE(one.find("[pwl-tet] CHOLMOD's BLAS threads: 1\n"), std::string::npos) << one;
  if (std::thread::hardware_concurrency() >= 2) {  // OpenBLAS caps its threads at the cores it found
    EXPECT_NE(dflt.find("[pwl-tet] CHOLMOD's BLAS threads: 2\n"), std::string::npos) << dflt;
  }
  std::vector<std::string> header;
  const auto a = row_of(read_table(dir / "one/table.csv", &header), "pwl-tet");
  const auto b = row_of(read_table(dir / "dflt/table.csv", &header), "pwl-tet");
  EXPECT_EQ(a.at("status"), "converged");
  EXPECT_EQ(a.at("iterations"), b.at("iterations"));
  EXPECT_NEAR(num(a, "max_handle_error"), num(b, "max_handle_error"), 1e-9);
  EXPECT_EQ(
      run_lidef("compare '" + sc + "' --out '" + dir / "bad" + "' --methods pwl-tet --blas-threads -1", &bad),
      2);
  EXPECT_NE(bad.find("--blas-threads"), std::string::npos) << bad;
  EXPECT_FALSE(fs::exists(dir / "bad"));
}

TEST(CompareCli, UnknownMethodIsAnErrorAndWritesNothing) {
  TempDir dir;
  std::string log;
  EXPECT_EQ(run_lidef("compare '" + lidef::test::project_data() + "/scenarios/beam_bend.json' --out '" +
                          dir / "cmp" + "' --methods lidef,pwl-quad",
                      &log),
            2);
  EXPECT_NE(log.find("pwl-quad"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(dir / "cmp"));
}

TEST(CompareCli, TetMinDofWithMaxVolumeIsAnErrorAndWritesNothing) {
  // --tet-min-dof searches the max volume: a given one would be silently ignored.
  TempDir dir;
  std::string log;
  EXPECT_EQ(run_lidef("compare '" + lidef::test::project_data() + "/scenarios/beam_bend.json' --out '" +
                          dir / "cmp" + "' --methods pwl-tet --tet-min-dof 3000 --tet-max-volume 0.001",
                      &log),
            2);
  EXPECT_NE(log.find("--tet-min-dof"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(dir / "cmp"));
}

TEST(Compare, TetgenFailureFailsOnlyPwlTet) {
  // Two crossing boxes (closed, manifold, self-intersecting) as the cage; the mesh is the first box shrunk.
  using namespace lidef;
  const TriMesh a = box_surface(Vec3(0, 0, 0), Vec3(1, 1, 1), Eigen::Vector3i(2, 2, 2));
  const TriMesh b = box_surface(Vec3(0.5, 0.5, 0.5), Vec3(1.5, 1.5, 1.5), Eigen::Vector3i(2, 2, 2));
  TriMesh cage;
  cage.V.resize(a.V.rows() + b.V.rows(), 3);
  cage.V << a.V, b.V;
  cage.F.resize(a.F.rows() + b.F.rows(), 3);
  cage.F << a.F, (b.F.array() + static_cast<int>(a.V.rows())).matrix();
  cage.source = "crossing/cage.obj";
  Model model{
      Cage(cage), box_surface(Vec3(0.1, 0.1, 0.1), Vec3(0.4, 0.4, 0.4), Eigen::Vector3i(4, 4, 4)), "", {}};
  Scenario sc;
  sc.name = "crossing";
  sc.sources = model.mesh.V.topRows(2);
  sc.targets = sc.sources;
  sc.targets(1, 0) += 0.05;
  CompareOptions opt;
  opt.methods = {"pwl-tet", "pwl-tri"};
  opt.use_model_tets = false;
  const auto rows = run_comparison(sc, model, opt);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_FALSE(rows[0].ok);
  EXPECT_NE(rows[0].error.find("TetGen"), std::string::npos) << rows[0].error;
  EXPECT_NE(rows[0].error.find("crossing/cage.obj"), std::string::npos) << rows[0].error;
  EXPECT_TRUE(rows[1].ok) << rows[1].error;
  EXPECT_NE(comparison_table_md(rows, sc).find("FAILED"), std::string::npos);
}

TEST(Compare, TetMinDofGivesPwlTetAtLeastThoseDof) {
  // A box cage without a tet mesh of its own: --tet-min-dof makes TetGen's mesh fine enough, and the row says
  // how it was made.
  using namespace lidef;
  const TriMesh box = box_surface(Vec3(0, 0, 0), Vec3(1, 1, 1), Eigen::Vector3i(2, 2, 2));
  Model model{
      Cage(box), box_surface(Vec3(0.1, 0.1, 0.1), Vec3(0.9, 0.9, 0.9), Eigen::Vector3i(3, 3, 3)), "", {}};
  Scenario sc;
  sc.name = "box";
  sc.sources = model.mesh.V.topRows(2);
  sc.targets = sc.sources;
  sc.targets(1, 0) += 0.05;
  CompareOptions opt;
  opt.methods = {"pwl-tet"};
  opt.coarse_min_dof = 900;
  const auto rows = run_comparison(sc, model, opt);
  ASSERT_EQ(rows.size(), 1u);
  ASSERT_TRUE(rows[0].ok) << rows[0].error;
  EXPECT_GE(rows[0].dof, 900);
  EXPECT_NE(rows[0].detail.find("searched"), std::string::npos) << rows[0].detail;
  opt.coarse_min_dof = 0;  // TetGen's default mesh of the box is far coarser
  const auto plain = run_comparison(sc, model, opt);
  ASSERT_TRUE(plain[0].ok) << plain[0].error;
  EXPECT_LT(plain[0].dof, 900);
}

TEST(CompareSlow, SharedBarBendAllMethods) {
  LIDEF_REQUIRE_SHARED();
  TempDir dir;
  std::string log;
  const int rc = run_lidef("compare '" + lidef::test::shared_data() + "/scenarios/bar_bend.json' --out '" +
                               dir / "cmp" + "' --methods lidef,pwl-tet,vhm,pwl-tri --quiet",
                           &log);
  ASSERT_EQ(rc, 0) << log;
  std::vector<std::string> header;
  const auto rows = read_table(dir / "cmp/table.csv", &header);
  ASSERT_EQ(rows.size(), 4u);
  for (const auto& r : rows) EXPECT_LT(num(r, "max_handle_error"), 0.02) << r.at("method");
  EXPECT_EQ(row_of(rows, "lidef").at("certified"), "1");
  EXPECT_EQ(num(row_of(rows, "pwl-tet"), "dof"), 3 * 106);  // the shared tet.node: Table 1's DOF
  EXPECT_EQ(row_of(rows, "pwl-tet").at("inverted_elements"), "0");
}
