// End-to-end tests of `lidef eval` (the real binary), and the coefficient file round trip.
// Truth: the identity and affine maps, whose f, J, signed singular values and det J are known in closed form.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/QR>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include "lidef/cage.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "test_cages.h"
#include "test_support.h"

using namespace lidef;
namespace fs = std::filesystem;
using lidef::test::TempDir;

namespace {

const char* const kHeader = "x,y,z,fx,fy,fz,J00,J01,J02,J10,J11,J12,J20,J21,J22,s1,s2,s3,detJ";
constexpr int kColumns = 19;

using lidef::test::read_text;
using lidef::test::write_text;

struct Csv {
  std::string header;
  std::vector<std::array<double, kColumns>> rows;
};

// Parses the eval output strictly: every row has exactly 19 fully numeric fields.
Csv read_csv(const std::string& path) {
  Csv csv;
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << "cannot open " << path;
  std::getline(in, csv.header);
  std::string line;
  while (std::getline(in, line)) {
    std::array<double, kColumns> row{};
    std::istringstream ss(line);
    std::string field;
    int k = 0;
    while (std::getline(ss, field, ',')) {
      EXPECT_LT(k, kColumns) << "too many fields: " << line;
      if (k >= kColumns) break;
      char* end = nullptr;
      row[k] = std::strtod(field.c_str(), &end);
      EXPECT_TRUE(!field.empty() && *end == '\0') << "not a number: '" << field << "' in " << line;
      ++k;
    }
    EXPECT_EQ(k, kColumns) << line;
    csv.rows.push_back(row);
  }
  return csv;
}

// A model folder, its cage, and points strictly inside the cage.
struct EvalModel {
  std::string dir;
  Cage cage;
  MatX3d points;
  double size;  // bounding-box diagonal of the cage
};

// The project's own model (data/models/beam or data/models/ball) when it exists; otherwise a model written
// into `tmp`: a bumpy icosphere cage (radius 0.9..1.1) around a radius-0.5 icosphere mesh.
EvalModel eval_model(const TempDir& tmp, int npoints = 40) {
  std::string dir;
  for (const char* name : {"beam", "ball"}) {
    const std::string d = lidef::test::project_data() + "/models/" + name;
    if (fs::exists(d + "/cage.obj") && fs::exists(d + "/mesh.obj")) {
      dir = d;
      break;
    }
  }
  if (dir.empty()) {
    dir = tmp / "model";
    fs::create_directories(dir);
    const TriMesh cage = lidef::test::icosphere(2, 0.1, 4);
    const TriMesh mesh = lidef::test::icosphere(1);
    std::ofstream c(dir + "/cage.obj"), m(dir + "/mesh.obj");
    write_obj(c, cage.V, cage.F, "test cage");
    write_obj(m, 0.5 * mesh.V, mesh.F, "test mesh");
  }
  Cage cage(read_mesh(dir + "/cage.obj"));
  const double size = (cage.bbox_max - cage.bbox_min).norm();
  MatX3d P = lidef::test::interior_points(cage, npoints, 0.02 * size, 13);
  return {dir, std::move(cage), std::move(P), size};
}

void write_points(const std::string& path, const MatX3d& P) {
  std::ofstream out(path);
  out << "# test points\n";
  for (Eigen::Index i = 0; i < P.rows(); ++i)
    out << format_double(P(i, 0)) << ' ' << format_double(P(i, 1)) << ' ' << format_double(P(i, 2)) << '\n';
}

void write_coeff_file(const std::string& path, const MatX3d& y) {
  std::ofstream out(path);
  write_coefficients(out, y);
}

std::string quote(const std::string& s) {
  return "'" + s + "'";
}

int run_eval(const std::string& model, const std::string& coeffs, const std::string& points,
             const std::string& out, std::string* output) {
  return lidef::test::run_command(quote(lidef::test::cli()) + " eval " + quote(model) + " --coeffs " +
                                      quote(coeffs) + " --points " + quote(points) + " --out " + quote(out),
                                  output);
}

Mat3 jacobian_of(const std::array<double, kColumns>& r) {
  Mat3 J;
  for (int k = 0; k < 9; ++k) J(k / 3, k % 3) = r[6 + k];
  return J;
}

// ctest runs every test in its own process, several at once. TempDir and run_command name their files with
// std::rand(), whose sequence is the same in every process unless seeded: seed it per process so that
// concurrent tests never share a temporary file.
class EvalCli : public ::testing::Test {
 protected:
  void SetUp() override { std::srand(static_cast<unsigned>(::getpid()) * 2654435761u); }
};
using Coefficients = EvalCli;

}  // namespace

TEST_F(EvalCli, IdentityCoefficientsGiveIdentityMap) {
  TempDir tmp;
  const EvalModel m = eval_model(tmp);
  write_points(tmp / "p.xyz", m.points);
  std::string output;
  ASSERT_EQ(run_eval(m.dir, "identity", tmp / "p.xyz", tmp / "out.csv", &output), 0) << output;
  const Csv csv = read_csv(tmp / "out.csv");
  EXPECT_EQ(csv.header, kHeader);
  ASSERT_EQ(static_cast<Eigen::Index>(csv.rows.size()), m.points.rows());
  const double ftol = 1e-10 * std::max(1.0, m.size);
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    const auto& r = csv.rows[i];
    const Vec3 p = m.points.row(i).transpose();
    // The input point is echoed exactly (shortest round-trip formatting on both sides).
    EXPECT_EQ(r[0], p(0));
    EXPECT_EQ(r[1], p(1));
    EXPECT_EQ(r[2], p(2));
    EXPECT_LT((Vec3(r[3], r[4], r[5]) - p).norm(), ftol) << "row " << i;
    EXPECT_LT((jacobian_of(r) - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-10) << "row " << i;
    for (int k = 15; k < 18; ++k) EXPECT_NEAR(r[k], 1.0, 1e-10) << "row " << i << " column " << k;
    EXPECT_NEAR(r[18], 1.0, 1e-10) << "row " << i;
  }
  EXPECT_EQ(output.find("warning"), std::string::npos) << output;

  // The same coefficients through a file give byte-identical output (the file round trip is exact).
  write_coeff_file(tmp / "id.txt", m.cage.identity_coefficients());
  ASSERT_EQ(run_eval(m.dir, tmp / "id.txt", tmp / "p.xyz", tmp / "out2.csv", &output), 0) << output;
  EXPECT_EQ(read_text(tmp / "out.csv"), read_text(tmp / "out2.csv"));
}

TEST_F(EvalCli, AffineCoefficientsWithReflection) {
  TempDir tmp;
  const EvalModel m = eval_model(tmp);
  // A = R1 diag(σ) R2ᵀ with a negative σ3: an orientation-reversing map with known signed singular values.
  std::mt19937 rng(3);
  std::normal_distribution<double> N01;
  auto rotation = [&] {
    Mat3 G;
    for (int k = 0; k < 9; ++k) G(k / 3, k % 3) = N01(rng);
    Mat3 Q = Eigen::HouseholderQR<Mat3>(G).householderQ();
    if (Q.determinant() < 0) Q.col(0) *= -1;
    return Q;
  };
  const Vec3 sigma(1.3, 0.8, -0.6);
  const Mat3 A = rotation() * sigma.asDiagonal() * rotation().transpose();
  const Vec3 b(0.3, -0.2, 0.1);
  ASSERT_LT(A.determinant(), 0);
  write_coeff_file(tmp / "affine.txt", m.cage.affine_coefficients(A, b));
  write_points(tmp / "p.xyz", m.points);
  std::string output;
  ASSERT_EQ(run_eval(m.dir, tmp / "affine.txt", tmp / "p.xyz", tmp / "out.csv", &output), 0) << output;
  const Csv csv = read_csv(tmp / "out.csv");
  EXPECT_EQ(csv.header, kHeader);
  ASSERT_EQ(static_cast<Eigen::Index>(csv.rows.size()), m.points.rows());
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    const auto& r = csv.rows[i];
    const Vec3 p = m.points.row(i).transpose();
    EXPECT_LT((Vec3(r[3], r[4], r[5]) - (A * p + b)).norm(), 1e-10 * std::max(1.0, m.size)) << "row " << i;
    EXPECT_LT((jacobian_of(r) - A).cwiseAbs().maxCoeff(), 1e-10) << "row " << i;
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(r[15 + k], sigma(k), 1e-10) << "row " << i;
    EXPECT_LT(r[17], 0.0);
    EXPECT_NEAR(r[18], sigma.prod(), 1e-10) << "row " << i;
  }
}

TEST_F(EvalCli, PointsOutsideTheCageAreReported) {
  TempDir tmp;
  const EvalModel m = eval_model(tmp, 3);
  MatX3d P(4, 3);
  P.topRows(3) = m.points;
  P.row(3) = (m.cage.bbox_max + Vec3::Constant(m.size)).transpose();  // far outside
  write_points(tmp / "p.xyz", P);
  std::string output;
  ASSERT_EQ(run_eval(m.dir, "identity", tmp / "p.xyz", tmp / "out.csv", &output), 0) << output;
  EXPECT_NE(output.find("warning"), std::string::npos) << output;
  EXPECT_NE(output.find(tmp / "p.xyz"), std::string::npos) << output;
  EXPECT_NE(output.find("point 4"), std::string::npos) << output;
  EXPECT_EQ(read_csv(tmp / "out.csv").rows.size(), 4u);
}

TEST_F(EvalCli, BadInputsFailWithoutWritingOutput) {
  TempDir tmp;
  const EvalModel m = eval_model(tmp, 5);
  const std::string good_points = tmp / "p.xyz", good_coeffs = tmp / "id.txt";
  write_points(good_points, m.points);
  write_coeff_file(good_coeffs, m.cage.identity_coefficients());
  std::ostringstream id_text;
  write_coefficients(id_text, m.cage.identity_coefficients());
  const std::string rows = id_text.str();

  struct Case {
    std::string name, model, coeffs, points, culprit;
  };
  std::vector<Case> cases;
  auto add_coeffs = [&](const std::string& name, const std::string& text) {
    const std::string path = tmp / (name + ".txt");
    write_text(path, text);
    cases.push_back({name, m.dir, path, good_points, path});
  };
  add_coeffs("wrong_row_count", rows.substr(0, rows.rfind('\n', rows.size() - 2) + 1));  // last row dropped
  add_coeffs("nan_coefficient", "nan 0 0\n" + rows.substr(rows.find('\n') + 1));
  add_coeffs("non_numeric", "1 2 3abc\n" + rows.substr(rows.find('\n') + 1));
  cases.push_back(
      {"missing_coeffs", m.dir, tmp / "no_such_coeffs.txt", good_points, tmp / "no_such_coeffs.txt"});
  cases.push_back(
      {"missing_points", m.dir, good_coeffs, tmp / "no_such_points.xyz", tmp / "no_such_points.xyz"});
  write_text(tmp / "two_columns.xyz", "0.1 0.2\n0.0 0.1\n");
  cases.push_back(
      {"two_column_points", m.dir, good_coeffs, tmp / "two_columns.xyz", tmp / "two_columns.xyz"});
  cases.push_back({"missing_model", tmp / "no_such_model", good_coeffs, good_points, tmp / "no_such_model"});

  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string out = tmp / ("out_" + c.name + ".csv");
    std::string output;
    EXPECT_EQ(run_eval(c.model, c.coeffs, c.points, out, &output), 2) << output;
    EXPECT_NE(output.find(c.culprit), std::string::npos) << "message does not name " << c.culprit << ":\n"
                                                         << output;
    EXPECT_NE(output.find("error"), std::string::npos) << output;
    EXPECT_FALSE(fs::exists(out)) << out;
  }
  // Nothing at all was written: no output and no temporary file beside it.
  for (const auto& e : fs::directory_iterator(tmp.path))
    EXPECT_NE(e.path().filename().string().rfind("out_", 0), 0u) << "left behind: " << e.path();

  // An existing output file is left untouched by a failing run.
  write_text(tmp / "keep.csv", "previous contents\n");
  std::string output;
  EXPECT_EQ(run_eval(m.dir, tmp / "wrong_row_count.txt", good_points, tmp / "keep.csv", &output), 2)
      << output;
  EXPECT_EQ(read_text(tmp / "keep.csv"), "previous contents\n");
}

TEST_F(Coefficients, WriteReadRoundTripIsBitExact) {
  TempDir tmp;
  const Cage cage(lidef::test::icosphere(0));  // 12 + 20 = 32 rows
  MatX3d y(cage.num_coeffs(), 3);
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> mant(-1.0, 1.0);
  std::uniform_int_distribution<int> expo(-300, 300);
  for (Eigen::Index i = 0; i < y.rows(); ++i)
    for (int k = 0; k < 3; ++k) y(i, k) = std::ldexp(mant(rng), expo(rng));
  const double specials[] = {0.0,
                             -0.0,
                             0.1,
                             1.0 / 3.0,
                             M_PI,
                             -2.5e-7,
                             std::numeric_limits<double>::max(),
                             std::numeric_limits<double>::lowest(),
                             std::numeric_limits<double>::min(),
                             std::numeric_limits<double>::denorm_min(),
                             -std::numeric_limits<double>::denorm_min(),
                             std::nextafter(1.0, 2.0)};
  int s = 0;
  for (const double v : specials) {
    y(s / 3, s % 3) = v;
    ++s;
  }

  std::ostringstream text;
  write_coefficients(text, y);
  write_text(tmp / "y.txt", text.str());
  const MatX3d back = read_coefficients(tmp / "y.txt", cage);
  ASSERT_EQ(back.rows(), y.rows());
  EXPECT_EQ(std::memcmp(back.data(), y.data(), sizeof(double) * y.size()), 0);  // bit-exact, signed zero too
  std::ostringstream again;
  write_coefficients(again, back);
  EXPECT_EQ(again.str(), text.str());  // deterministic

  // The keyword gives the identity coefficients; comments, commas and blank lines are accepted.
  const MatX3d id = read_coefficients("identity", cage);
  EXPECT_EQ(std::memcmp(id.data(), cage.identity_coefficients().data(), sizeof(double) * id.size()), 0);
  std::string with_comments = "# header comment\n\n";
  std::istringstream lines(text.str());
  std::string line;
  while (std::getline(lines, line)) {
    std::replace(line.begin(), line.end(), ' ', ',');
    with_comments += line + "  # row\n";
  }
  write_text(tmp / "y2.txt", with_comments);
  const MatX3d back2 = read_coefficients(tmp / "y2.txt", cage);
  EXPECT_EQ(std::memcmp(back2.data(), y.data(), sizeof(double) * y.size()), 0);
}

TEST_F(Coefficients, ErrorsNameFileAndLine) {
  TempDir tmp;
  const Cage cage(lidef::test::icosphere(0));
  std::ostringstream text;
  write_coefficients(text, cage.identity_coefficients());
  std::string rows = text.str();
  // Corrupt the 5th row: a non-numeric token, then a NaN, then a missing column.
  auto nth_row_start = [&](int n) {
    size_t pos = 0;
    for (int i = 1; i < n; ++i) pos = rows.find('\n', pos) + 1;
    return pos;
  };
  for (const std::string bad : {"1 x 3", "1 nan 3", "1 2", "1 2 3 4", "1 inf 3"}) {
    SCOPED_TRACE(bad);
    std::string t = rows;
    const size_t a = nth_row_start(5), e = t.find('\n', a);
    t.replace(a, e - a, bad);
    write_text(tmp / "bad.txt", t);
    try {
      read_coefficients(tmp / "bad.txt", cage);
      ADD_FAILURE() << "no exception";
    } catch (const InputError& err) {
      EXPECT_EQ(err.file(), tmp / "bad.txt");
      EXPECT_EQ(err.line(), 5);
    }
  }
  write_text(tmp / "short.txt", rows.substr(0, nth_row_start(cage.num_coeffs())));
  try {
    read_coefficients(tmp / "short.txt", cage);
    ADD_FAILURE() << "no exception";
  } catch (const InputError& err) {
    EXPECT_EQ(err.file(), tmp / "short.txt");
    EXPECT_NE(err.message().find(std::to_string(cage.num_coeffs())), std::string::npos) << err.what();
  }
  EXPECT_THROW(read_coefficients(tmp / "missing.txt", cage), InputError);
}
