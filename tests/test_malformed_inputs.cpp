// Malformed inputs, end to end through the CLI: every case exits with 2, names the
// offending file (and where useful the line or element), and writes nothing: the output folder does not exist
// afterwards, and a certificate's folder keeps exactly what it had.
//
// Cases per input kind here: models 8 (lidef certify), scenarios 9 and saved sessions 2 (lidef deform),
// coefficient files 5 (lidef certify), certificates 7 (lidef verify), PLY/STL/OFF meshes 6 (lidef cage) and
// 2 (a mesh file as a scenario's model). The other suites add their own tables (docs/cli.md, "Bad input and
// interrupted runs").
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/mesh_io.h"
#include "test_cli_outputs.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;
using namespace lidef::test;  // NOLINT: the helpers of test_support.h and test_cli_outputs.h
using json = nlohmann::json;

struct Case {
  std::string kind, name;
  std::string args;                   // "{OUT}" stands for the fresh output folder
  std::vector<std::string> culprits;  // all must appear in the output
  std::string watched;                // a folder that must keep exactly what it had ("" none)
};

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size()))
    s.replace(p, from.size(), to);
  return s;
}

// The cage.obj text with its first "v" line replaced by `line`.
std::string with_first_vertex(const std::string& cage, const std::string& line) {
  const size_t b = cage.find("\nv ") + 1, e = cage.find('\n', b);
  return cage.substr(0, b) + line + cage.substr(e);
}

// A binary STL header (80 bytes + triangle count) announcing `count` triangles, followed by `body` bytes.
std::string binary_stl(uint32_t count, size_t body) {
  std::string s(80, '\0');
  for (int i = 0; i < 4; ++i) s.push_back(static_cast<char>((count >> (8 * i)) & 0xff));
  return s + std::string(body, '\0');
}

const char* const kPlyHeader =
    "ply\nformat ascii 1.0\nelement vertex %V\nproperty float x\nproperty float y\nproperty float z\n"
    "element face %F\nproperty list uchar int vertex_indices\nend_header\n";
std::string ply(const std::string& v, const std::string& f, const std::string& body) {
  return replace_all(replace_all(kPlyHeader, "%V", v), "%F", f) + body;
}

class MalformedInputs : public ::testing::Test {
 protected:
  TempDir tmp;
  std::string data = lidef::test::project_data();
  std::string ball = data + "/models/ball", beam = data + "/models/beam";

  // A model folder named `name` holding the ball's mesh and `cage` as cage.obj.
  std::string model(const std::string& name, const std::string& cage) {
    const std::string dir = tmp / name;
    fs::create_directories(dir);
    fs::copy_file(ball + "/mesh.obj", dir + "/mesh.obj");
    write_text(dir + "/cage.obj", cage);
    return dir;
  }
  std::string file(const std::string& name, const std::string& text) {
    write_text(tmp / name, text);
    return tmp / name;
  }
  // beam_bend.json with its model as an absolute path, then changed by `edit`.
  template <class F>
  std::string scenario(const std::string& name, F&& edit, const std::string& model_path = "") {
    json s = json::parse(read_text(data + "/scenarios/beam_bend.json"));
    s["model"] = model_path.empty() ? beam : model_path;
    edit(s);
    return file(name, s.dump(2));
  }
  // A copy of the certificate folder `cert` named `name`, with `edit(dir)` applied.
  template <class F>
  std::string cert_copy(const std::string& cert, const std::string& name, F&& edit) {
    const std::string dir = tmp / name;
    fs::copy(cert, dir, fs::copy_options::recursive);
    edit(dir);
    return dir;
  }
};

TEST_F(MalformedInputs, EachExitsWith2NamingTheFileAndWritesNothing) {
  std::vector<Case> cases;
  const std::string cage = read_text(ball + "/cage.obj");
  const std::string q = " --grid 0 --samples 300";

  // ---- models (cage/mesh files), through lidef certify
  auto add_model = [&](const std::string& name, const std::string& text, std::vector<std::string> culprits) {
    const std::string dir = model("model_" + name, text);
    culprits.insert(culprits.begin(), dir + "/cage.obj");
    cases.push_back(
        {"model", name, "certify " + shell_quote(dir) + " --coeffs identity --out {OUT}" + q, culprits, ""});
  };
  add_model("truncated_obj", cage.substr(0, cage.size() / 2), {"needs 3 coordinates"});
  add_model("vertex_with_two_coordinates", with_first_vertex(cage, "v 1 2"),
            {"cage.obj:3", "vertex 1 needs 3 coordinates"});
  add_model("coordinate_1e400", with_first_vertex(cage, "v 1e400 0 0"), {"cage.obj:3", "1e400"});
  add_model("non_number_token", with_first_vertex(cage, "v 0 abc 0"),
            {"cage.obj:3", "'abc' is not a number"});
  add_model("nan_coordinate", with_first_vertex(cage, "v 0 nan 0"), {"vertex 1", "NaN"});
  {
    const size_t b = cage.find("\nf ") + 1, e = cage.find('\n', b) + 1;  // the first face dropped
    add_model("cage_with_hole", cage.substr(0, b) + cage.substr(e), {"the cage is not closed"});
  }
  add_model("face_index_zero", cage + "f 0 1 2\n", {"vertex index 0 is invalid"});
  add_model("face_index_past_end", cage + "f 1 2 999\n", {"vertex index 999 is out of range"});

  // ---- scenarios and saved sessions, through lidef deform
  const std::string cache = tmp / "cache";
  auto add_deform = [&](const std::string& kind, const std::string& name, const std::string& path,
                        std::vector<std::string> culprits, const std::string& named = "") {
    culprits.insert(culprits.begin(), named.empty() ? path : named);
    cases.push_back({kind, name,
                     "deform " + shell_quote(path) + " --out {OUT} --cache-dir " + shell_quote(cache) +
                         " --samples 4000 --reduced-dof 60 --quiet",
                     culprits, ""});
  };
  add_deform("scenario", "handle_as_string", scenario("h.json", [](json& s) { s["handles"][0] = "h"; }),
             {"handle 1 of 10 must be an object"});
  add_deform("scenario", "handles_missing", scenario("nh.json", [](json& s) { s.erase("handles"); }),
             {"missing \"handles\""});
  add_deform("scenario", "unknown_parameter",
             scenario("up.json",
                      [](json& s) {
                        s["parameters"] = {{"no_such_parameter", 1}};
                      }),
             {"unknown parameter 'no_such_parameter'"});
  {
    const std::string good = read_text(scenario("good.json", [](json&) {}));
    add_deform("scenario", "duplicate_key",
               file("dup.json", good.substr(0, good.rfind('}')) + ", \"model\": \"beam\"}"),
               {"duplicate key \"model\""});
    add_deform("scenario", "truncated_json", file("trunc.json", good.substr(0, good.size() / 2)),
               {"JSON syntax error at line"});
  }
  add_deform("scenario", "top_level_array", file("array.json", "[1, 2, 3]\n"), {"must be a JSON object"});
  add_deform("scenario", "missing_model",
             scenario(
                 "mm.json", [](json&) {}, tmp / "no_such_model"),
             {"no_such_model", "not found"});
  add_deform("scenario", "target_at_1e300",
             scenario("far.json",
                      [](json& s) {
                        s["handles"][5]["target"] = {1e300, 0, 0};
                      }),
             {"handle 6", "cage diagonals"});
  add_deform("scenario", "one_source_two_targets",
             scenario("two.json",
                      [](json& s) {
                        json h = s["handles"][0];
                        h["target"] = {0, 0, 0};
                        s["handles"].push_back(h);
                      }),
             {"handles 1 and 11", "same source but different targets"});
  add_deform("session", "studio_not_an_object", scenario("s1.json", [](json& s) { s["studio"] = 3; }),
             {"\"studio\" must be a JSON object"});
  add_deform("session", "studio_array",
             scenario("s2.json",
                      [](json& s) {
                        s["studio"] = json::array({1, 2});
                      }),
             {"\"studio\" must be a JSON object"});

  // ---- coefficient files, through lidef certify
  std::ostringstream id_text;
  lidef::write_coefficients(id_text,
                            lidef::Cage(lidef::read_mesh(ball + "/cage.obj")).identity_coefficients());
  const std::string rows = id_text.str(), rest = rows.substr(rows.find('\n') + 1);
  auto add_coeffs = [&](const std::string& name, const std::string& text, std::vector<std::string> culprits) {
    const std::string path = file("coeffs_" + name + ".txt", text);
    culprits.insert(culprits.begin(), path);
    cases.push_back({"coefficients", name,
                     "certify " + shell_quote(ball) + " --coeffs " + shell_quote(path) + " --out {OUT}" + q,
                     culprits, ""});
  };
  add_coeffs("extra_row", rows + "0 0 0\n", {});
  add_coeffs("non_number_token", "0 0 x\n" + rest, {"x"});
  add_coeffs("four_columns", "0 0 0 0\n" + rest, {});
  add_coeffs("empty_file", "", {});
  add_coeffs("coefficient_1e400", "1e400 0 0\n" + rest, {"1e400"});

  // ---- certificates, through lidef verify (one good certificate, then copies edited)
  std::string output;
  const std::string cert = tmp / "cert";
  ASSERT_EQ(
      run_lidef_cli("certify " + shell_quote(ball) + " --coeffs identity --out " + shell_quote(cert) + q,
                    &output),
      0)
      << output;
  auto add_cert = [&](const std::string& name, const std::string& dir, std::vector<std::string> culprits,
                      const std::string& model_dir = "") {
    culprits.insert(culprits.begin(), dir);
    cases.push_back({"certificate", name,
                     "verify " + shell_quote(model_dir.empty() ? ball : model_dir) +
                         " --coeffs identity --certificate " + shell_quote(dir + "/certificate.json") +
                         " --samples-per-voxel 2 --out {OUT}",
                     culprits, dir});
  };
  add_cert("voxels_hash_mismatch",
           cert_copy(cert, "c_hash",
                     [](const std::string& d) {
                       const std::string t = read_text(d + "/certificate.json");
                       const size_t p = t.find('"', t.find(':', t.find("\"voxels_csv_fnv1a64\""))) + 1;
                       write_text(d + "/certificate.json",
                                  t.substr(0, p) + "0000000000000000" + t.substr(p + 16));
                     }),
           {"voxels.csv", "hash differs"});
  add_cert("voxels_csv_edited",
           cert_copy(cert, "c_flip",
                     [](const std::string& d) {
                       std::string t = read_text(d + "/voxels.csv");
                       char& c = t[t.size() / 2];
                       c = c == '7' ? '8' : '7';
                       write_text(d + "/voxels.csv", t);
                     }),
           {"voxels.csv", "hash differs"});
  add_cert("voxels_csv_missing",
           cert_copy(cert, "c_nocsv", [](const std::string& d) { fs::remove(d + "/voxels.csv"); }),
           {"voxels.csv", "not found"});
  add_cert("truncated_json",
           cert_copy(cert, "c_trunc",
                     [](const std::string& d) {
                       write_text(d + "/certificate.json", read_text(d + "/certificate.json").substr(0, 500));
                     }),
           {"certificate.json", "not valid JSON"});
  add_cert("wrong_format",
           cert_copy(cert, "c_fmt",
                     [](const std::string& d) {
                       write_text(d + "/certificate.json", replace_all(read_text(d + "/certificate.json"),
                                                                       "\"lidef-certificate\"", "\"other\""));
                     }),
           {"certificate.json", "not a lidef certificate"});
  add_cert(
      "top_level_array",
      cert_copy(cert, "c_array", [](const std::string& d) { write_text(d + "/certificate.json", "[]\n"); }),
      {"certificate.json", "not a lidef certificate"});
  add_cert("for_another_cage", cert_copy(cert, "c_other", [](const std::string&) {}),
           {"certificate.json", "different cage"}, beam);

  // ---- PLY/STL/OFF meshes, through lidef cage and as a scenario's model
  auto add_cage = [&](const std::string& name, const std::string& path, std::vector<std::string> culprits) {
    culprits.insert(culprits.begin(), path);
    cases.push_back({"mesh", name, "cage " + shell_quote(path) + " --out {OUT} --quiet", culprits, ""});
  };
  const std::string ply_lies = file("lies.ply", ply("8", "12", "0 0 0\n1 0 0\n0 1 0\n"));
  const std::string stl_short = file("short.stl", binary_stl(100, 150));
  add_cage("ply_header_lies_about_counts", ply_lies,
           {"element 'vertex' entry 4 of 8: the file ends inside this entry"});
  add_cage("binary_stl_truncated", stl_short, {"cannot read the file as stl"});
  add_cage("empty_stl", file("empty.stl", ""), {"file is empty"});
  add_cage("ascii_stl_vertex_with_two_coordinates",
           file("two.stl",
                "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\nvertex 0 1 0\n"
                "endloop\nendfacet\nendsolid x\n"),
           {"cannot read the file as stl"});
  add_cage("ply_index_out_of_range", file("index.ply", ply("3", "1", "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")),
           {"face 1: vertex index 7 is out of range"});
  add_cage("off_truncated", file("short.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n"), {});
  add_deform("mesh", "scenario_model_ply_header_lies",
             scenario(
                 "mply.json", [](json&) {}, ply_lies),
             {"element 'vertex' entry 4 of 8: the file ends inside this entry"}, ply_lies);
  add_deform("mesh", "scenario_model_stl_truncated",
             scenario(
                 "mstl.json", [](json&) {}, stl_short),
             {"cannot read the file as stl"}, stl_short);

  EXPECT_GE(cases.size(), 39u);
  for (const Case& c : cases) {
    SCOPED_TRACE(c.kind + "/" + c.name);
    const std::string out = tmp / ("out_" + c.kind + "_" + c.name);
    const std::vector<std::string> before =
        c.watched.empty() ? std::vector<std::string>{} : dir_entries(c.watched);
    EXPECT_EQ(run_lidef_cli(replace_all(c.args, "{OUT}", shell_quote(out)), &output), 2) << output;
    EXPECT_NE(output.find("error"), std::string::npos) << output;
    for (const std::string& s : c.culprits)
      EXPECT_NE(output.find(s), std::string::npos) << "message does not name '" << s << "':\n" << output;
    EXPECT_FALSE(fs::exists(out)) << out;
    if (!c.watched.empty()) {
      EXPECT_EQ(dir_entries(c.watched), before) << c.watched;
    }
  }
}

}  // namespace
