// The deformation parameter table (deform_params.h) and handle scenarios (scenario.h): defaults from the
// paper, type/range/name checking with suggestions, the shared scenarios, every refusal naming the file and
// the problem, write/read round trip, and model-folder resolution.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/scenario.h"
#include "test_support.h"

namespace {

using namespace lidef;
using lidef::test::TempDir;
using nlohmann::json;
namespace fs = std::filesystem;

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

template <class F>
std::string input_error(F&& f) {
  return lidef::test::input_error_message(std::forward<F>(f));
}

// --- Parameter table

TEST(DeformParams, TableListsEveryFieldOnce) {
  // Counted by hand in deform_params.h: 6 sampling + 2 energy + 15 newton (3 of them continuation) +
  // 12 certificate + 9 weighting + 5 execution + 3 testing. A new field must be added here and to the table.
  const int kFields = 52;
  const auto& table = deform_param_table();
  EXPECT_EQ(static_cast<int>(table.size()), kFields);
  std::set<std::string> names;
  for (const ParamInfo& p : table) {
    EXPECT_TRUE(names.insert(p.name).second) << "duplicate name " << p.name;
    EXPECT_NE(std::string(p.help), "") << p.name;
    EXPECT_EQ(find_param(p.name), &p);
  }
  // Every member pointer distinct: each field is reachable through exactly one row.
  for (size_t i = 0; i < table.size(); ++i)
    for (size_t j = i + 1; j < table.size(); ++j)
      EXPECT_FALSE(table[i].member == table[j].member) << table[i].name;
  // Each field by name (a row pointing at the wrong member would show here).
  const std::vector<std::string> expected = {"reduced_dof",
                                             "samples",
                                             "voxel_side",
                                             "safety",
                                             "hessian_fraction",
                                             "domain",  // sampling
                                             "lambda_p2p",
                                             "lambda_smooth",  // energy
                                             "max_iterations",
                                             "step_tolerance",
                                             "energy_tolerance",
                                             "armijo",
                                             "max_halvings",
                                             "diagonal_shift",
                                             "drag_hessian_reuse",
                                             "newton_cg_steps",
                                             "kept_factor_cg_steps",
                                             "kept_factor_tolerance",
                                             "hessian_precision",
                                             "handle_tolerance",
                                             "continuation",
                                             "continuation_angle",
                                             "continuation_stage_iterations",  // newton
                                             "max_depth",
                                             "bound",
                                             "refinement",
                                             "max_refined",
                                             "line_search_max_refined",
                                             "line_search_spectral_fallback",
                                             "bound_tolerance",
                                             "max_distortion",
                                             "max_sigma1",
                                             "min_sigma3",
                                             "injectivity",
                                             "global_cache_mb",  // certificate
                                             "dynamic_weighting",
                                             "e0",
                                             "kappa1",
                                             "kappa2",
                                             "epsilon",
                                             "max_smooth_factor",
                                             "min_p2p_factor",
                                             "direction_retries",
                                             "max_weight_resets",  // weighting
                                             "threads",
                                             "backend",
                                             "opencl_device",
                                             "opencl_gpu_layout",
                                             "trace_line_search",  // execution
                                             "test_interrupt_after",
                                             "test_break_kernels",
                                             "test_opencl_max_alloc"};  // testing
  ASSERT_EQ(expected.size(), table.size());
  for (size_t i = 0; i < expected.size(); ++i) EXPECT_EQ(table[i].name, expected[i]);
  EXPECT_TRUE(std::get<int DeformParams::*>(find_param("max_depth")->member) == &DeformParams::max_depth);
  EXPECT_TRUE(std::get<double DeformParams::*>(find_param("lambda_p2p")->member) ==
              &DeformParams::lambda_p2p);
  EXPECT_TRUE(std::get<long DeformParams::*>(find_param("max_refined")->member) ==
              &DeformParams::max_refined);
  EXPECT_TRUE(std::get<LipschitzBound DeformParams::*>(find_param("bound")->member) == &DeformParams::bound);
  EXPECT_TRUE(std::get<DomainKind DeformParams::*>(find_param("domain")->member) == &DeformParams::domain);
  EXPECT_EQ(find_param("lamda_p2p"), nullptr);
}

TEST(DeformParams, DefaultsFollowThePaper) {
  const DeformParams p;
  EXPECT_EQ(p.lambda_p2p, 1e5);
  EXPECT_EQ(p.lambda_smooth, 0.1);
  EXPECT_EQ(p.max_depth, 6);
  EXPECT_EQ(p.samples, 30000);
  EXPECT_EQ(p.hessian_fraction, 0.05);
  EXPECT_EQ(p.reduced_dof, 300);
  EXPECT_NO_THROW(validate_params(p, "defaults"));
  const auto j = params_to_json(p);
  EXPECT_EQ(j.size(), deform_param_table().size());
  EXPECT_EQ(j.begin().key(), "reduced_dof");  // table order, not sorted
  EXPECT_EQ(j["lambda_p2p"].get<double>(), 1e5);
  EXPECT_EQ(j["bound"].get<std::string>(), "third");
  EXPECT_EQ(param_value_string(p, *find_param("lambda_smooth")), "0.1");
  EXPECT_EQ(param_value_string(p, *find_param("max_depth")), "6");
  EXPECT_EQ(param_value_string(p, *find_param("dynamic_weighting")), "true");
  EXPECT_EQ(param_value_string(p, *find_param("bound")), "third");
  EXPECT_EQ(param_flag(*find_param("lambda_p2p")), "--lambda-p2p");
  EXPECT_EQ(param_flag(*find_param("max_weight_resets")), "--max-weight-resets");
  // The ordered JSON converts to a plain one with the same content.
  const json plain = j;
  EXPECT_EQ(plain["samples"].get<int>(), 30000);
}

TEST(DeformParams, SetParamAcceptsEachType) {
  DeformParams p;
  set_param(p, "max_depth", json(4), "f");
  set_param(p, "samples", json(2.0e4), "f");   // integral double for an int
  set_param(p, "lambda_p2p", json(250), "f");  // integer for a double
  set_param(p, "max_refined", json(123456789), "f");
  set_param(p, "dynamic_weighting", json(false), "f");
  set_param(p, "bound", json("first"), "f");
  set_param(p, "safety", json(1.25), "f");
  EXPECT_EQ(p.max_depth, 4);
  EXPECT_EQ(p.samples, 20000);
  EXPECT_EQ(p.lambda_p2p, 250.0);
  EXPECT_EQ(p.max_refined, 123456789L);
  EXPECT_FALSE(p.dynamic_weighting);
  EXPECT_EQ(p.bound, LipschitzBound::kFirstOrder);
  EXPECT_EQ(p.safety, 1.25);
  // Range ends are inclusive.
  set_param(p, "max_depth", json(20), "f");
  set_param(p, "hessian_fraction", json(1), "f");
  set_param(p, "kappa2", json(1), "f");
  EXPECT_NO_THROW(validate_params(p, "f"));
}

TEST(DeformParams, SetParamRefusesWrongTypes) {
  DeformParams p;
  const DeformParams before = p;
  std::string m = input_error([&] { set_param(p, "max_depth", json(3.5), "scen.json"); });
  EXPECT_NE(m.find("scen.json: "), std::string::npos) << m;
  EXPECT_NE(m.find("'max_depth'"), std::string::npos) << m;
  EXPECT_NE(m.find("integer"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "lambda_p2p", json("1e5"), "f"); });
  EXPECT_NE(m.find("expected a number"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "dynamic_weighting", json(1), "f"); });
  EXPECT_NE(m.find("true or false"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "bound", json(3), "f"); });
  EXPECT_NE(m.find("expected a string"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "bound", json("second"), "f"); });
  EXPECT_NE(m.find("\"first\", \"third\", \"combined\" or \"spectral\""), std::string::npos) << m;
  m = input_error([&] { set_param(p, "lambda_smooth", json(nullptr), "f"); });
  EXPECT_NE(m.find("null"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "lambda_p2p", json(std::numeric_limits<double>::infinity()), "f"); });
  EXPECT_NE(m.find("not a finite number"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "lambda_p2p", json(std::nan("")), "f"); });
  EXPECT_NE(m.find("not a finite number"), std::string::npos) << m;
  m = input_error([&] { apply_params(p, json::array({1, 2}), "f"); });
  EXPECT_NE(m.find("object"), std::string::npos) << m;
  // Nothing was changed by the refused values.
  EXPECT_EQ(params_to_json(p), params_to_json(before));
}

TEST(DeformParams, SetParamRefusesOutOfRange) {
  DeformParams p;
  std::string m = input_error([&] { set_param(p, "max_depth", json(21), "f"); });
  EXPECT_NE(m.find("'max_depth' = 21 is out of range [0, 20]"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "safety", json(1), "f"); });  // must be > 1
  EXPECT_NE(m.find("out of range"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "hessian_fraction", json(0), "f"); });
  EXPECT_NE(m.find("out of range"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "reduced_dof", json(3), "f"); });
  EXPECT_NE(m.find("out of range [4, 100000]"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "threads", json(-1), "f"); });
  EXPECT_NE(m.find("out of range"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "samples", json(1e30), "f"); });  // no int overflow on the way
  EXPECT_NE(m.find("out of range"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "kappa2", json(0.5), "f"); });
  EXPECT_NE(m.find("out of range"), std::string::npos) << m;
  // validate_params catches what was set directly in code.
  p.lambda_smooth = -1;
  m = input_error([&] { validate_params(p, "here"); });
  EXPECT_NE(m.find("here: parameter 'lambda_smooth'"), std::string::npos) << m;
  p = DeformParams();
  p.bound = static_cast<LipschitzBound>(7);  // an enum without a name, as only code can set it
  EXPECT_THROW(validate_params(p, "here"), InputError);
  p = DeformParams();
  p.armijo = std::nan("");
  EXPECT_THROW(validate_params(p, "here"), InputError);
}

TEST(DeformParams, UnknownNameSuggestsTheClosest) {
  DeformParams p;
  std::string m = input_error([&] { set_param(p, "lamda_p2p", json(1), "s.json"); });
  EXPECT_NE(m.find("s.json: unknown parameter 'lamda_p2p' (did you mean 'lambda_p2p'?)"), std::string::npos)
      << m;
  m = input_error([&] { set_param(p, "max-depth", json(1), "f"); });  // CLI spelling in JSON
  EXPECT_NE(m.find("did you mean 'max_depth'"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "kappa", json(1), "f"); });
  EXPECT_NE(m.find("'kappa1' or 'kappa2'"), std::string::npos) << m;
  m = input_error([&] { set_param(p, "completely_unrelated", json(1), "f"); });
  EXPECT_EQ(m.find("did you mean"), std::string::npos) << m;
  EXPECT_NE(m.find("valid parameters:"), std::string::npos) << m;
  EXPECT_NE(m.find("lambda_p2p"), std::string::npos) << m;
  // apply_params stops at the bad key.
  m = input_error([&] { apply_params(p, json{{"max_depth", 5}, {"lambda_smoth", 1}}, "f"); });
  EXPECT_NE(m.find("did you mean 'lambda_smooth'"), std::string::npos) << m;
}

// --- Scenarios

struct SharedScenario {
  const char* name;
  const char* model;
  int handles;
};

TEST(Scenario, SharedScenariosLoad) {
  LIDEF_REQUIRE_SHARED();
  const SharedScenario all[] = {{"bar_bend", "bar", 8},        {"bar_twist90", "bar", 8},
                                {"bar_twist180", "bar", 8},    {"horse_leg_lift", "horse", 4},
                                {"spot_head_turn", "spot", 5}, {"animal_tail_lift", "animal", 6}};
  for (const auto& c : all) {
    SCOPED_TRACE(c.name);
    const std::string file = lidef::test::shared_data() + "/scenarios/" + c.name + ".json";
    const Scenario s = read_scenario(file);
    EXPECT_EQ(s.path, file);
    EXPECT_EQ(s.name, c.name);
    EXPECT_EQ(s.model, c.model);
    EXPECT_FALSE(s.description.empty());
    EXPECT_EQ(s.num_handles(), c.handles);
    EXPECT_EQ(s.targets.rows(), c.handles);
    EXPECT_TRUE(s.sources.allFinite() && s.targets.allFinite());
    ASSERT_TRUE(fs::is_directory(s.model_dir)) << s.model_dir;
    EXPECT_TRUE(fs::equivalent(s.model_dir, lidef::test::shared_model(c.model))) << s.model_dir;
    EXPECT_TRUE(s.params_given.empty());
    EXPECT_EQ(params_to_json(s.params), params_to_json(DeformParams()));
  }
}

TEST(Scenario, ProjectScenarioLoads) {
  const std::string file = lidef::test::project_data() + "/scenarios/beam_bend.json";
  const Scenario s = read_scenario(file);
  EXPECT_EQ(s.name, "beam_bend");
  EXPECT_EQ(s.num_handles(), 10);
  EXPECT_TRUE(fs::equivalent(s.model_dir, lidef::test::project_data() + "/models/beam"));
  EXPECT_EQ(s.targets(5, 0), 0.85);
  EXPECT_EQ(s.targets(5, 1), 0.4);
}

// A scenario folder laid out like data/: <tmp>/scenarios/x.json and <tmp>/models/cube/.
struct ScenarioDir {
  TempDir tmp;
  ScenarioDir() {
    fs::create_directories(tmp.path / "scenarios");
    fs::create_directories(tmp.path / "models" / "cube");
  }
  std::string write(const std::string& name, const std::string& text) const {
    const std::string path = (tmp.path / "scenarios" / name).string();
    write_text(path, text);
    return path;
  }
  std::string models() const { return (tmp.path / "models").string(); }
};

const char* const kGoodHandles = R"("handles": [{"source": [0, 0, 0], "target": [0.1, 0, 0]},
                {"source": [1, 0, 0], "target": [1, 0.5, -0.25]}])";

std::string scenario_text(const std::string& extra = "", const std::string& model = "cube",
                          const std::string& handles = kGoodHandles) {
  return "{\n  \"name\": \"t\",\n  \"model\": \"" + model + "\",\n  " + handles +
         (extra.empty() ? "" : ",\n  " + extra) + "\n}\n";
}

// The message of read_scenario(path) failing; checks that it names the file.
std::string read_error(const std::string& path, const std::string& models_dir = "") {
  const std::string m = input_error([&] { read_scenario(path, models_dir); });
  EXPECT_EQ(m.rfind(path, 0), 0u) << "message does not start with the file: " << m;
  return m;
}

TEST(Scenario, ReadsParametersInFileOrder) {
  ScenarioDir d;
  const std::string f = d.write(
      "p.json",
      scenario_text(
          R"("description": "two handles", "parameters": {"max_depth": 4, "bound": "first", "lambda_p2p": 1e3})"));
  const Scenario s = read_scenario(f);
  EXPECT_EQ(s.name, "t");
  EXPECT_EQ(s.description, "two handles");
  EXPECT_EQ(s.num_handles(), 2);
  EXPECT_EQ(s.targets(1, 2), -0.25);
  EXPECT_EQ(s.params.max_depth, 4);
  EXPECT_EQ(s.params.bound, LipschitzBound::kFirstOrder);
  EXPECT_EQ(s.params.lambda_p2p, 1e3);
  EXPECT_EQ(s.params.lambda_smooth, 0.1);
  EXPECT_EQ(s.params_given, (std::vector<std::string>{"max_depth", "bound", "lambda_p2p"}));
  EXPECT_TRUE(fs::equivalent(s.model_dir, d.tmp.path / "models" / "cube"));
}

TEST(Scenario, NameDefaultsToTheFileStem) {
  ScenarioDir d;
  const std::string f = d.write("my_scene.json", std::string("{\"model\": \"cube\", ") + kGoodHandles + "}");
  EXPECT_EQ(read_scenario(f).name, "my_scene");
}

TEST(Scenario, MissingFile) {
  TempDir t;
  const std::string m = read_error(t / "nope.json");
  EXPECT_NE(m.find("not found"), std::string::npos) << m;
  const std::string md = read_error(t.str());
  EXPECT_NE(md.find("directory"), std::string::npos) << md;
}

TEST(Scenario, MissingModelFolderListsThePathsTried) {
  ScenarioDir d;
  const std::string f = d.write("m.json", scenario_text("", "elephant"));
  const std::string m = read_error(f);
  EXPECT_NE(m.find("model folder \"elephant\" not found"), std::string::npos) << m;
  EXPECT_NE(m.find((d.tmp.path / "scenarios" / "elephant").string()), std::string::npos) << m;
  EXPECT_NE(m.find((d.tmp.path / "models" / "elephant").string()), std::string::npos) << m;
  const std::string no_model = read_error(d.write("n.json", std::string("{") + kGoodHandles + "}"));
  EXPECT_NE(no_model.find("missing \"model\""), std::string::npos) << no_model;
  const std::string not_string =
      read_error(d.write("s.json", std::string("{\"model\": 3, ") + kGoodHandles + "}"));
  EXPECT_NE(not_string.find("\"model\" must be a string"), std::string::npos) << not_string;
}

TEST(Scenario, RefusesMissingOrEmptyHandles) {
  ScenarioDir d;
  std::string m = read_error(d.write("e.json", scenario_text("", "cube", "\"handles\": []")));
  EXPECT_NE(m.find("no handles: a scenario needs at least one handle"), std::string::npos) << m;
  m = read_error(d.write("n.json", "{\"model\": \"cube\"}"));
  EXPECT_NE(m.find("missing \"handles\""), std::string::npos) << m;
  m = read_error(d.write("o.json", scenario_text("", "cube", "\"handles\": {}")));
  EXPECT_NE(m.find("\"handles\" must be an array"), std::string::npos) << m;
}

TEST(Scenario, RefusesNonFiniteOrMalformedCoordinates) {
  ScenarioDir d;
  auto with_second = [&](const std::string& handle) {
    return scenario_text("", "cube",
                         "\"handles\": [{\"source\": [0, 0, 0], \"target\": [0, 0, 0]}, " + handle + "]");
  };
  std::string m =
      read_error(d.write("null.json", with_second(R"({"source": [1, 0, 0], "target": [1, null, 0]})")));
  EXPECT_NE(m.find("handle 2 of 2: target[1] (y) is not a finite number (got null)"), std::string::npos) << m;
  m = read_error(d.write("nan.json", with_second(R"({"source": [1, 0, "nan"], "target": [1, 0, 0]})")));
  EXPECT_NE(m.find("source[2] (z) is not a finite number (got string \"nan\")"), std::string::npos) << m;
  m = read_error(d.write("NaN.json", with_second(R"({"source": [NaN, 0, 0], "target": [1, 0, 0]})")));
  EXPECT_NE(m.find("JSON syntax error"), std::string::npos) << m;  // bare NaN is not JSON
  m = read_error(d.write("inf.json", with_second(R"({"source": [1e400, 0, 0], "target": [1, 0, 0]})")));
  EXPECT_NE(m.find("1e400"), std::string::npos) << m;
  EXPECT_NE(m.find(":4:"), std::string::npos) << m;  // the line of the number
  m = read_error(d.write("two.json", with_second(R"({"source": [1, 0], "target": [1, 0, 0]})")));
  EXPECT_NE(m.find("\"source\" must be an array of 3 numbers"), std::string::npos) << m;
  m = read_error(d.write("miss.json", with_second(R"({"source": [1, 0, 0]})")));
  EXPECT_NE(m.find("handle 2 of 2: missing \"target\""), std::string::npos) << m;
  m = read_error(
      d.write("key.json", with_second(R"({"source": [1, 0, 0], "target": [1, 0, 0], "weight": 2})")));
  EXPECT_NE(m.find("handle 2 of 2: unknown key \"weight\""), std::string::npos) << m;
  m = read_error(d.write("arr.json", with_second("[1, 2, 3]")));
  EXPECT_NE(m.find("handle 2 of 2 must be an object"), std::string::npos) << m;
}

TEST(Scenario, RefusesBadParameters) {
  ScenarioDir d;
  std::string m = read_error(d.write("u.json", scenario_text(R"("parameters": {"lamda_p2p": 1})")));
  EXPECT_NE(m.find("unknown parameter 'lamda_p2p' (did you mean 'lambda_p2p'?)"), std::string::npos) << m;
  m = read_error(d.write("r.json", scenario_text(R"("parameters": {"max_depth": 99})")));
  EXPECT_NE(m.find("'max_depth' = 99 is out of range [0, 20]"), std::string::npos) << m;
  m = read_error(d.write("t.json", scenario_text(R"("parameters": {"max_depth": 2.5})")));
  EXPECT_NE(m.find("expected an integer"), std::string::npos) << m;
  m = read_error(d.write("a.json", scenario_text(R"("parameters": [1])")));
  EXPECT_NE(m.find("\"parameters\" must be a JSON object"), std::string::npos) << m;
}

TEST(Scenario, RefusesUnknownTopLevelKeysAndDuplicates) {
  ScenarioDir d;
  std::string m = read_error(
      d.write("k.json", std::string("{\"model\": \"cube\", \"handels\": [], ") + kGoodHandles + "}"));
  EXPECT_NE(m.find("unknown key \"handels\""), std::string::npos) << m;
  m = read_error(d.write("dup.json", scenario_text(R"("handles": [])")));
  EXPECT_NE(m.find("duplicate key \"handles\""), std::string::npos) << m;
  m = read_error(d.write("arr.json", "[1, 2]"));
  EXPECT_NE(m.find("must be a JSON object"), std::string::npos) << m;
}

TEST(Scenario, SyntaxErrorGivesTheLine) {
  ScenarioDir d;
  const std::string f = d.write(
      "syn.json", "{\n  \"model\": \"cube\",\n  \"handles\": [\n    {\"source\": [0, 0 0]}\n  ]\n}\n");
  const std::string m = read_error(f);
  EXPECT_NE(m.find(f + ":4: JSON syntax error at line 4"), std::string::npos) << m;
  EXPECT_NE(m.find("byte"), std::string::npos) << m;
  const std::string empty = read_error(d.write("empty.json", "\n"));
  EXPECT_NE(empty.find("the file is empty"), std::string::npos) << empty;
  const std::string first = read_error(d.write("first.json", "x"));
  EXPECT_NE(first.find("JSON syntax error at line 1, column 1 (byte 1)"), std::string::npos) << first;
}

TEST(Scenario, WriteReadRoundTrip) {
  ScenarioDir d;
  Scenario s;
  s.name = "round \"trip\" λ";
  s.model = "cube";
  s.description = "odd numbers\nand a newline";
  s.sources.resize(3, 3);
  s.targets.resize(3, 3);
  s.sources << 0.1, 1.0 / 3.0, -0.0, 1e-300, 5e-324, 123456789.123456789, -2.5, 1e21, 0;
  s.targets << std::nextafter(1.0, 2.0), -1.0 / 7.0, 3, 0.3, 0.7, 2.0 / 3.0, 1e-7, -1e5, 42;
  s.params.lambda_p2p = 1.0 / 3.0;
  s.params.max_depth = 8;
  s.params.bound = LipschitzBound::kFirstOrder;
  s.params.dynamic_weighting = false;
  s.params.max_refined = 1000000000L;
  const std::string f = (d.tmp.path / "scenarios" / "rt.json").string();
  write_scenario(f, s);
  const Scenario r = read_scenario(f);
  EXPECT_EQ(r.name, s.name);
  EXPECT_EQ(r.model, s.model);
  EXPECT_EQ(r.description, s.description);
  ASSERT_EQ(r.num_handles(), 3);
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(r.sources(i, k), s.sources(i, k));
      EXPECT_EQ(std::signbit(r.sources(i, k)), std::signbit(s.sources(i, k)));
      EXPECT_EQ(r.targets(i, k), s.targets(i, k));
    }
  EXPECT_EQ(params_to_json(r.params), params_to_json(s.params));
  // Only the changed parameters are written, in table order.
  EXPECT_EQ(r.params_given, (std::vector<std::string>{"lambda_p2p", "max_depth", "bound", "max_refined",
                                                      "dynamic_weighting"}));
  // Writing again gives the same bytes (deterministic), and no temporary is left behind.
  std::ifstream in1(f);
  std::stringstream b1;
  b1 << in1.rdbuf();
  write_scenario(f, r);
  std::ifstream in2(f);
  std::stringstream b2;
  b2 << in2.rdbuf();
  EXPECT_EQ(b1.str(), b2.str());
  EXPECT_NE(b1.str().find("{\"source\": [0.1, "), std::string::npos) << b1.str();
  int files = 0;
  for (const auto& e : fs::directory_iterator(d.tmp.path / "scenarios")) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 1);
}

TEST(Scenario, WriteWithDefaultParametersOmitsThem) {
  ScenarioDir d;
  Scenario s;
  s.model = "cube";
  s.sources = MatX3d::Zero(1, 3);
  s.targets = MatX3d::Ones(1, 3);
  const std::string f = (d.tmp.path / "scenarios" / "plain.json").string();
  write_scenario(f, s);
  std::ifstream in(f);
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str().find("parameters"), std::string::npos) << text.str();
  EXPECT_EQ(read_scenario(f).num_handles(), 1);
}

TEST(Scenario, WriteRefusesWhatCannotBeReadBack) {
  TempDir t;
  Scenario s;
  s.model = "cube";
  const std::string f = t / "w.json";
  EXPECT_THROW(write_scenario(f, s), InputError);  // no handles
  s.sources = MatX3d::Zero(1, 3);
  s.targets = MatX3d::Zero(1, 3);
  s.targets(0, 1) = std::nan("");
  EXPECT_THROW(write_scenario(f, s), InputError);
  s.targets(0, 1) = 0;
  s.params.max_depth = 50;
  EXPECT_THROW(write_scenario(f, s), InputError);
  s.params.max_depth = 6;
  const std::string m = input_error([&] { write_scenario(t / "no/such/dir/w.json", s); });
  EXPECT_NE(m.find("no/such/dir/w.json"), std::string::npos) << m;
  EXPECT_TRUE(fs::is_empty(t.path));
}

TEST(Scenario, ModelsDirResolution) {
  ScenarioDir d;
  // A second models folder: --models wins over the scenario's neighbourhood.
  TempDir other;
  fs::create_directories(other.path / "cube");
  fs::create_directories(other.path / "only_here");
  const std::string f = d.write("c.json", scenario_text());
  EXPECT_TRUE(fs::equivalent(read_scenario(f).model_dir, d.tmp.path / "models" / "cube"));
  EXPECT_TRUE(fs::equivalent(read_scenario(f, other.str()).model_dir, other.path / "cube"));
  // A model found only through the models directory.
  const std::string g = d.write("o.json", scenario_text("", "only_here"));
  EXPECT_THROW(read_scenario(g), InputError);
  EXPECT_TRUE(fs::equivalent(read_scenario(g, other.str()).model_dir, other.path / "only_here"));
  // A models directory without the model falls back to the scenario's neighbourhood.
  EXPECT_TRUE(fs::equivalent(read_scenario(f, d.tmp.str()).model_dir, d.tmp.path / "models" / "cube"));
  const std::string m = read_error(d.write("x.json", scenario_text("", "nowhere")), other.str());
  EXPECT_NE(m.find((other.path / "nowhere").string()), std::string::npos) << m;
  // An absolute model path, and a folder beside the scenario.
  const std::string abs_model = (other.path / "only_here").string();
  EXPECT_TRUE(
      fs::equivalent(read_scenario(d.write("a.json", scenario_text("", abs_model))).model_dir, abs_model));
  fs::create_directories(d.tmp.path / "scenarios" / "beside");
  EXPECT_TRUE(fs::equivalent(read_scenario(d.write("b.json", scenario_text("", "beside"))).model_dir,
                             d.tmp.path / "scenarios" / "beside"));
}

TEST(Scenario, SharedScenarioWithModelsDir) {
  LIDEF_REQUIRE_SHARED();
  // A copy of a shared scenario elsewhere finds its model only through the models directory.
  TempDir t;
  const std::string copy = t / "bar_bend.json";
  fs::copy_file(lidef::test::shared_data() + "/scenarios/bar_bend.json", copy);
  EXPECT_THROW(read_scenario(copy), InputError);
  const Scenario s = read_scenario(copy, lidef::test::shared_data() + "/models");
  EXPECT_EQ(s.num_handles(), 8);
  EXPECT_TRUE(fs::equivalent(s.model_dir, lidef::test::shared_model("bar")));
}

}  // namespace
