// `lidef reproduce` (docs/reproduction.md): every name with --quick, the structure of its outputs
// (summary.json's claims, README.md's claims list, the CSV header, the PNG when gnuplot exists) and the
// claims that must hold whatever the machine: the Lipschitz bounds lie above the sampled ground truth (fig5,
// checked again here from the CSV) and the σ3 counterexample is verified (fig2). Reproduce.* run in the unit
// label (≲ 30 s each on the 2-core machine), ReproduceSlow.* in the slow one.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "test_cli_outputs.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;
using lidef::test::read_text;
using lidef::test::run_lidef_cli;
using lidef::test::shared_data;
using lidef::test::shell_quote;
using lidef::test::TempDir;

nlohmann::json read_json(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  return nlohmann::json::parse(in, nullptr, false);
}

bool have_gnuplot() {
  if (const char* g = std::getenv("LIDEF_GNUPLOT")) return std::string(g) != "none" && fs::exists(g);
  return std::system("command -v gnuplot > /dev/null 2>&1") == 0;
}

std::string first_line(const std::string& path) {
  std::ifstream in(path);
  std::string l;
  std::getline(in, l);
  return l;
}

// Runs `lidef reproduce NAME --quick --out DIR [--models shared]` with a private subspace cache.
int reproduce(const TempDir& tmp, const std::string& name, bool shared, std::string* output,
              const std::string& extra = "") {
  return run_lidef_cli("reproduce " + name + " --quick --threads 2 --out " + shell_quote(tmp / "out") +
                           " --cache-dir " + shell_quote(tmp / "cache") +
                           (shared ? " --models " + shell_quote(shared_data()) : "") + " " + extra,
                       output);
}

// The files every name writes and their structure; returns summary.json.
nlohmann::json check_structure(const std::string& dir, const std::string& name, const std::string& csv,
                               const std::string& csv_header) {
  const nlohmann::json s = read_json(dir + "/summary.json");
  EXPECT_EQ(s["name"], name);
  EXPECT_TRUE(s["quick"].get<bool>());
  EXPECT_TRUE(s["models"].is_string() && !s["models"].get<std::string>().empty());
  EXPECT_TRUE(s["claims"].is_array() && !s["claims"].empty()) << s.dump(2);
  const std::string readme = read_text(dir + "/README.md");
  for (const auto& c : s["claims"]) {
    for (const char* k : {"claim", "paper", "source", "measured", "holds"}) EXPECT_TRUE(c.contains(k)) << k;
    EXPECT_TRUE(c["holds"].is_boolean());
    EXPECT_FALSE(c["measured"].is_null()) << c.dump();
    // README.md lists every claim with its verdict.
    EXPECT_NE(readme.find(c["claim"].get<std::string>()), std::string::npos) << c["claim"];
  }
  EXPECT_TRUE(s["all_claims_measured"].get<bool>());
  EXPECT_TRUE(s.contains("data") && s.contains("timings"));
  EXPECT_NE(s["run"]["command"].get<std::string>().find("lidef reproduce " + name), std::string::npos);
  EXPECT_FALSE(s["run"]["machine"].get<std::string>().empty());
  EXPECT_FALSE(s["run"]["started_utc"].get<std::string>().empty());
  EXPECT_NE(readme.find("## Claims"), std::string::npos);
  EXPECT_NE(readme.find("lidef reproduce " + name), std::string::npos);
  EXPECT_EQ(first_line(dir + "/" + csv), csv_header);
  if (have_gnuplot()) {
    EXPECT_TRUE(s["plot"].is_string()) << s.dump(2);
    if (s["plot"].is_string()) {
      EXPECT_GT(fs::file_size(dir + "/" + s["plot"].get<std::string>()), 1000u);
    }
  }
  // Nothing of the staging area is left behind.
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().rfind(".lidef-staging-", 0), std::string::npos) << e.path();
  return s;
}

const nlohmann::json* claim_containing(const nlohmann::json& s, const std::string& text) {
  for (const auto& c : s["claims"])
    if (c["claim"].get<std::string>().find(text) != std::string::npos) return &c;
  return nullptr;
}

TEST(Reproduce, HelpListsEveryNameAndItsClaim) {
  std::string out;
  ASSERT_EQ(run_lidef_cli("reproduce --help", &out), 0) << out;
  for (const char* n : {"table1", "fig2", "fig5", "fig6", "fig7", "fig8", "fig9", "fig12", "fig13"})
    EXPECT_NE(out.find(std::string("  ") + n + " "), std::string::npos) << n << "\n" << out;
  EXPECT_NE(out.find("claim: >= 10x fewer samples"), std::string::npos) << out;
  EXPECT_NE(out.find("--quick"), std::string::npos);
}

TEST(Reproduce, UnknownNameIsAnErrorAndWritesNothing) {
  TempDir tmp;
  std::string out;
  EXPECT_EQ(reproduce(tmp, "fig99", false, &out), 2) << out;
  EXPECT_NE(out.find("fig99"), std::string::npos) << out;
  EXPECT_NE(out.find("known: table1"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(tmp / "out"));
}

TEST(Reproduce, ModelsFolderWithoutScenariosIsAnError) {
  TempDir tmp;
  fs::create_directories(tmp / "empty");
  std::string out;
  EXPECT_EQ(run_lidef_cli("reproduce fig5 --out " + shell_quote(tmp / "out") + " --models " +
                              shell_quote(tmp / "empty"),
                          &out),
            2)
      << out;
  EXPECT_NE(out.find("scenarios/"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(tmp / "out"));
}

// fig2 needs no model: the explorer's twist map, verified by `lidef explore show`.
TEST(Reproduce, Fig2CounterexampleIsVerified) {
  TempDir tmp;
  std::string out;
  ASSERT_EQ(reproduce(tmp, "fig2", false, &out), 0) << out;
  const std::string dir = tmp / "out/fig2";
  const nlohmann::json s = check_structure(
      dir, "fig2", "fig2.csv", "sigma,twist,cubic,verified,min_sigma3,min_distance_from_center,ball_radius");
  const nlohmann::json* c = claim_containing(s, "interior local minimum");
  ASSERT_NE(c, nullptr);
  EXPECT_EQ((*c)["measured"], true);
  EXPECT_EQ((*c)["holds"], true);
  // The explorer's own summary agrees (it is copied, not rewritten).
  EXPECT_EQ(read_json(dir + "/explore_summary.json")["verified_counterexample"], true);
  const nlohmann::json* inside = claim_containing(s, "inside the ball");
  ASSERT_NE(inside, nullptr);
  EXPECT_LT((*inside)["measured"].get<double>(), 1e-6);  // the closed form puts it at the center
}

// Both Lipschitz bounds must lie above the sampled ground truth in every voxel: checked from the CSV, not
// only from the claim.
TEST(Reproduce, Fig5BoundsAboveGroundTruthOnSharedBar) {
  LIDEF_REQUIRE_SHARED();
  TempDir tmp;
  std::string out;
  ASSERT_EQ(reproduce(tmp, "fig5", true, &out), 0) << out;
  const std::string dir = tmp / "out/fig5";
  const nlohmann::json s =
      check_structure(dir, "fig5", "fig5.csv",
                      "case,lambda_smooth,rank,voxel,cx,cy,cz,ground_truth,L_first_order,L_third_order");
  std::ifstream in(dir + "/fig5.csv");
  std::string line;
  std::getline(in, line);
  long rows = 0, positive_truth = 0;
  while (std::getline(in, line)) {
    std::stringstream ls(line);
    std::vector<std::string> cells;
    for (std::string c; std::getline(ls, c, ',');) cells.push_back(c);
    ASSERT_EQ(cells.size(), 10u) << line;
    const double truth = std::stod(cells[7]), l1 = std::stod(cells[8]), l3 = std::stod(cells[9]);
    EXPECT_GE(l1, truth) << line;
    EXPECT_GE(l3, truth) << line;
    positive_truth += truth > 0;
    ++rows;
  }
  EXPECT_EQ(rows, 400);                 // 200 voxels per case in the quick run
  EXPECT_GT(positive_truth, rows / 2);  // a ground truth of zeros would make the check empty
  for (const auto& c : s["claims"])
    if (c["claim"].get<std::string>().find(">= ground truth") != std::string::npos) {
      EXPECT_EQ(c["measured"], 0) << c.dump();
      EXPECT_TRUE(c["holds"].get<bool>()) << c.dump();
    }
}

TEST(Reproduce, Fig13StageSplitOnSharedModels) {
  LIDEF_REQUIRE_SHARED();
  TempDir tmp;
  std::string out;
  ASSERT_EQ(reproduce(tmp, "fig13", true, &out), 0) << out;
  const nlohmann::json s = check_structure(tmp / "out/fig13", "fig13", "fig13.csv",
                                           "scenario,dof,iterations,ms_gradient,ms_hessian,ms_solve,ms_line_"
                                           "search,ms_line_search_certificate,ms_total");
  EXPECT_EQ(s["claims"].size(), 2u);
  for (const char* sc : {"bar_bend", "spot_head_turn"}) {
    EXPECT_GT(s["data"][sc]["iterations"].get<int>(), 0) << sc;
    EXPECT_GT(s["timings"][sc]["ms_total"].get<double>(), 0) << sc;
  }
}

// The project's own models (no --models): the beam.
TEST(Reproduce, Fig13OnOwnModels) {
  TempDir tmp;
  std::string out;
  ASSERT_EQ(reproduce(tmp, "fig13", false, &out), 0) << out;
  const nlohmann::json s = read_json(tmp / "out/fig13/summary.json");
  EXPECT_NE(s["models"].get<std::string>().find("project's own"), std::string::npos);
  EXPECT_TRUE(s["data"].contains("beam_bend"));
  EXPECT_NE(read_text(tmp / "out/fig13/README.md").find("project's own"), std::string::npos);
}

TEST(ReproduceSlow, Table1QuickOnSharedBar) {
  LIDEF_REQUIRE_SHARED();
  TempDir tmp;
  std::string out;
  ASSERT_EQ(reproduce(tmp, "table1", true, &out), 0) << out;
  const nlohmann::json s =
      check_structure(tmp / "out/table1", "table1", "table1.csv",
                      "scenario,method,status,dof,iterations,converged,certified,inverted_mesh_vertices,max_"
                      "handle_error,paper_dof,paper_iterations,time_s,time_ratio_to_lidef,paper_time_s,"
                      "tet_mesh,time_runs,time_s_min,time_s_max,pwl_blas_threads");
  const nlohmann::json* c = claim_containing(s, "lidef's result is certified");
  ASSERT_NE(c, nullptr);
  EXPECT_EQ((*c)["measured"], true);  // lidef never returns an uncertified map
  const nlohmann::json* it = claim_containing(s, "no more iterations");
  ASSERT_NE(it, nullptr);
  EXPECT_EQ((*it)["paper"]["lidef"], 14);  // Table 1, bar
  for (const char* m : {"lidef", "pwl-tet", "pwl-tet-model-mesh", "pwl-tet-fine", "vhm", "pwl-tri"})
    EXPECT_TRUE(s["data"]["bar_bend"].contains(m)) << m;
  // PWL(Tet) at the paper's resolution (Table 1, bar: 3,312 DOF): the bar's own tet mesh has only the cage's
  // 106 vertices, so `pwl-tet` runs on a TetGen mesh with at least the paper's DOF and the model's mesh stays
  // as the extra row `pwl-tet-model-mesh`.
  const auto& fair = s["data"]["bar_bend"]["pwl-tet"];
  const auto& coarse = s["data"]["bar_bend"]["pwl-tet-model-mesh"];
  EXPECT_EQ(fair["paper_dof"], 3312);
  EXPECT_GE(fair["dof"].get<double>(), 3312) << fair.dump();
  EXPECT_NE(fair["tet_mesh"].get<std::string>().find("TetGen"), std::string::npos) << fair.dump();
  EXPECT_EQ(coarse["dof"].get<double>(), 318) << coarse.dump();
  EXPECT_NE(fair["status"], "failed");
  EXPECT_EQ((*it)["paper"]["pwl-tet"], 23);
  EXPECT_EQ((*it)["measured"]["pwl-tet"], fair["iterations"]);  // the claims use the paper-resolution row
  EXPECT_FALSE((*it)["measured"].contains("pwl-tet-model-mesh"));
  const nlohmann::json* fastest = claim_containing(s, "shortest solve time");
  ASSERT_NE(fastest, nullptr);
  EXPECT_TRUE((*fastest)["measured"].contains("pwl-tet"));
  EXPECT_FALSE((*fastest)["measured"].contains("pwl-tet-model-mesh"));
  // table1.csv: both rows, with the DOF next to the paper's.
  std::ifstream csv(tmp / "out/table1/table1.csv");
  std::string line;
  int fair_rows = 0, coarse_rows = 0;
  while (std::getline(csv, line)) {
    fair_rows += line.rfind("bar_bend,pwl-tet,", 0) == 0 && line.find(",3312,") != std::string::npos;
    coarse_rows += line.rfind("bar_bend,pwl-tet-model-mesh,", 0) == 0 &&
                   line.find(",318,") != std::string::npos &&
                   line.find("model tet mesh (coarser than the paper's") != std::string::npos;
  }
  EXPECT_EQ(fair_rows, 1);
  EXPECT_EQ(coarse_rows, 1);
  EXPECT_TRUE(fs::exists(tmp / "out/table1/compare_bar_bend_timed.log"));
  // The compared times: lidef and PWL(Tet) each run twice (quick), interleaved; the time is the median of the
  // runs, between the fastest and the slowest, and every run ended at the same map.
  // table1.csv's cells hold no commas (tet_mesh is written without them).
  std::vector<std::map<std::string, std::string>> rows;
  {
    std::ifstream in(tmp / "out/table1/table1.csv");
    auto split = [](const std::string& l) {
      std::vector<std::string> v;
      std::stringstream ss(l);
      for (std::string c; std::getline(ss, c, ',');) v.push_back(c);
      if (!l.empty() && l.back() == ',') v.push_back("");
      return v;
    };
    std::string l;
    std::getline(in, l);
    const auto head = split(l);
    while (std::getline(in, l)) {
      const auto cells = split(l);
      ASSERT_EQ(cells.size(), head.size()) << l;
      std::map<std::string, std::string> row;
      for (size_t k = 0; k < head.size(); ++k) row[head[k]] = cells[k];
      rows.push_back(row);
    }
  }
  int timed = 0;
  for (const auto& r : rows) {
    if (r.at("scenario") != "bar_bend") continue;
    const bool pair = r.at("method") == "lidef" || r.at("method") == "pwl-tet";
    EXPECT_EQ(r.at("time_runs"), pair ? "2" : "1") << r.at("method");
    const double t = std::stod(r.at("time_s")), lo = std::stod(r.at("time_s_min")),
                 hi = std::stod(r.at("time_s_max"));
    EXPECT_LE(lo, t) << r.at("method");
    EXPECT_LE(t, hi) << r.at("method");
    timed += pair;
  }
  EXPECT_EQ(timed, 2);
  // PWL(Tet)'s row is the faster of its two timed series, BLAS on the run's 2 threads or in the calling
  // thread.
  for (const auto& r : rows) {
    if (r.at("method") == "pwl-tet") {
      EXPECT_TRUE(r.at("pwl_blas_threads") == "1" || r.at("pwl_blas_threads") == "2")
          << r.at("pwl_blas_threads");
    } else {
      EXPECT_EQ(r.at("pwl_blas_threads"), "") << r.at("method");
    }
  }
  // ... the one with the smaller median: each log's table prints PWL(Tet)'s median to 3 digits.
  auto logged_time = [&](const std::string& log) -> double {
    const std::string text = read_text(tmp / ("out/table1/" + log));
    const std::string key = "\n| pwl-tet | ";
    const size_t at = text.rfind(key);
    EXPECT_NE(at, std::string::npos) << log;
    if (at == std::string::npos) return NAN;
    std::stringstream cells(text.substr(at + key.size()));
    std::string dof, time;
    std::getline(cells, dof, '|');
    std::getline(cells, time, '|');
    return std::stod(time);
  };
  const double t_run = logged_time("compare_bar_bend_timed.log"),
               t_one = logged_time("compare_bar_bend_timed_blas1.log");
  for (const auto& r : rows) {
    if (r.at("scenario") != "bar_bend" || r.at("method") != "pwl-tet") continue;
    const double faster = std::min(t_run, t_one);
    EXPECT_LE(std::abs(std::stod(r.at("time_s")) - faster), 0.01 * faster) << t_run << " " << t_one;
    if (std::abs(t_run - t_one) > 0.02 * faster) {
      EXPECT_EQ(r.at("pwl_blas_threads"), t_one < t_run ? "1" : "2") << t_run << " " << t_one;
    }
  }
  EXPECT_TRUE(fs::exists(tmp / "out/table1/compare_bar_bend_timed_blas1.log"));
  EXPECT_NE(read_text(tmp / "out/table1/compare_bar_bend_timed_blas1.log").find("CHOLMOD's BLAS threads: 1"),
            std::string::npos);
  EXPECT_NE(read_text(tmp / "out/table1/README.md").find("BLAS threads of the series taken: bar_bend "),
            std::string::npos);
  EXPECT_NE(read_text(tmp / "out/table1/README.md").find("Every run of each ended at the same map"),
            std::string::npos);
}

TEST(ReproduceSlow, Fig12QuickOnSharedBar) {
  LIDEF_REQUIRE_SHARED();
  TempDir tmp;
  std::string out;
  ASSERT_EQ(reproduce(tmp, "fig12", true, &out), 0) << out;
  const nlohmann::json s =
      check_structure(tmp / "out/fig12", "fig12", "fig12.csv",
                      "method,status,global_volume_ratio,local_volume_ratio_min,local_"
                      "volume_ratio_max,local_volume_change_mean,inverted_mesh_vertices");
  const double g = s["data"]["lidef"]["global_volume_ratio"].get<double>();
  EXPECT_GT(g, 0.5);
  EXPECT_LT(g, 1.5);
  // PWL(Tri) has no det J; the volumetric methods have a local range around 1.
  EXPECT_TRUE(s["data"]["pwl-tri"]["local_volume_ratio_min"].is_null());
  EXPECT_LE(s["data"]["lidef"]["local_volume_ratio_min"].get<double>(), 1.0);
  EXPECT_GE(s["data"]["lidef"]["local_volume_ratio_max"].get<double>(), 1.0);
}

TEST(ReproduceSlow, Fig6Fig7Fig8Fig9QuickOnSharedData) {
  LIDEF_REQUIRE_SHARED();
  const std::vector<std::pair<std::string, std::string>> names = {
      {"fig6",
       "run,lambda_smooth,samples_target,samples,iterations,stop,certified,max_handle_error,reached,"
       "solve_s"},
      {"fig7",
       "dof_per_coordinate,dof,full,energy,relative_to_full,iterations,stop,certified,max_handle_error,"
       "solve_s,ms_per_iteration"},
      {"fig8",
       "hessian_fraction,energy,relative_to_full_hessian,iterations,stop,certified,max_handle_error,"
       "solve_s"},
      {"fig9",
       "run,iteration,energy,max_handle_error,min_sigma3_lower_bound,certified,lambda_p2p,lambda_smooth,"
       "ms"}};
  for (const auto& [name, header] : names) {
    TempDir tmp;
    std::string out;
    const int rc = reproduce(tmp, name, true, &out);
    // fig6 cannot measure its claim when even the smoothed case never reaches the targets: exit 1, reported.
    ASSERT_TRUE(rc == 0 || (name == "fig6" && rc == 1)) << name << "\n" << out;
    if (rc != 0) continue;
    const nlohmann::json s = check_structure(tmp / ("out/" + name), name, name + ".csv", header);
    if (name == "fig9") {
      // Fixed vs dynamic weights in one Newton solve each: the continuation must not have run.
      EXPECT_EQ(s["data"]["continuation"], false);
      EXPECT_NE(s["models"].get<std::string>().find("continuation off"), std::string::npos);
      for (const char* run : {"fixed", "dynamic"}) EXPECT_TRUE(s["data"].contains(run)) << run;
    }
  }
}

// Same input and thread count → the same CSV and summary, times apart.
TEST(ReproduceSlow, Fig5IsDeterministic) {
  LIDEF_REQUIRE_SHARED();
  TempDir a, b;
  std::string out;
  ASSERT_EQ(reproduce(a, "fig5", true, &out), 0) << out;
  ASSERT_EQ(reproduce(b, "fig5", true, &out), 0) << out;
  EXPECT_EQ(read_text(a / "out/fig5/fig5.csv"), read_text(b / "out/fig5/fig5.csv"));
  nlohmann::json sa = read_json(a / "out/fig5/summary.json"), sb = read_json(b / "out/fig5/summary.json");
  for (auto* s : {&sa, &sb}) {
    s->erase("timings");
    s->erase("run");
  }
  EXPECT_EQ(sa, sb);
}

}  // namespace
