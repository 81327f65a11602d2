// Render tests: `lidef-studio --scenario beam_bend.json --view V --screenshot` against baseline PNGs.
//
// Tolerance (docs/studio.md): a pixel differs when one of its channels differs by more than kChannelTol; the
// test fails when more than kMaxFraction of the pixels differ or the mean absolute channel difference exceeds
// kMaxMean. The images come from Mesa's llvmpipe under Xvfb, deterministic on one machine; the tolerance
// absorbs anti-aliasing and rounding differences in the solver (thread count), not a changed picture. A
// failing test keeps the new image and a difference image in LIDEF_FAILED_DIR. LIDEF_UPDATE_BASELINES=1
// rewrites the baselines.
#include <gtest/gtest.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPNGReader.h>
#include <vtkPNGWriter.h>
#include <vtkPointData.h>
#include <vtkUnsignedCharArray.h>

#include <cstdlib>
#include <filesystem>
#include <set>

#include "test_support.h"

namespace {
using namespace lidef::test;
namespace fs = std::filesystem;

constexpr int kChannelTol = 24;
constexpr double kMaxFraction = 0.002;
constexpr double kMaxMean = 0.5;

struct Image {
  int w = 0, h = 0;
  std::vector<unsigned char> rgb;  // w*h*3, bottom row first (VTK order)
};

Image read_png(const std::string& path) {
  Image img;
  vtkNew<vtkPNGReader> r;
  if (!r->CanReadFile(path.c_str())) return img;
  r->SetFileName(path.c_str());
  r->Update();
  vtkImageData* d = r->GetOutput();
  int dims[3];
  d->GetDimensions(dims);
  const int nc = d->GetNumberOfScalarComponents();
  auto* a = vtkUnsignedCharArray::SafeDownCast(d->GetPointData()->GetScalars());
  if (!a || nc < 3) return img;
  img.w = dims[0];
  img.h = dims[1];
  img.rgb.resize(static_cast<size_t>(img.w) * img.h * 3);
  for (long i = 0; i < static_cast<long>(img.w) * img.h; ++i)
    for (int c = 0; c < 3; ++c) img.rgb[3 * i + c] = a->GetValue(nc * i + c);
  return img;
}

void write_png(const std::string& path, const Image& img) {
  vtkNew<vtkImageData> d;
  d->SetDimensions(img.w, img.h, 1);
  d->AllocateScalars(VTK_UNSIGNED_CHAR, 3);
  std::copy(img.rgb.begin(), img.rgb.end(), static_cast<unsigned char*>(d->GetScalarPointer()));
  vtkNew<vtkPNGWriter> w;
  w->SetFileName(path.c_str());
  w->SetInputData(d);
  w->Write();
}

struct Comparison {
  double fraction = 1, mean = 255;
  Image diff;
};

Comparison compare(const Image& a, const Image& b) {
  Comparison c;
  if (a.w != b.w || a.h != b.h || a.rgb.empty()) return c;
  c.diff = a;
  long over = 0;
  double sum = 0;
  const long n = static_cast<long>(a.w) * a.h;
  for (long i = 0; i < n; ++i) {
    int m = 0;
    for (int k = 0; k < 3; ++k) {
      const int d = std::abs(int(a.rgb[3 * i + k]) - int(b.rgb[3 * i + k]));
      m = std::max(m, d);
      sum += d;
    }
    if (m > kChannelTol) ++over;
    for (int k = 0; k < 3; ++k) c.diff.rgb[3 * i + k] = m > kChannelTol ? (k == 0 ? 255 : 0) : 255 - m;
  }
  c.fraction = double(over) / n;
  c.mean = sum / (3.0 * n);
  return c;
}

// Counts pixels close to a colour (checks that a view shows what it should, independent of the baseline).
long count_near(const Image& img, int r, int g, int b, int tol) {
  long n = 0;
  for (size_t i = 0; i + 2 < img.rgb.size(); i += 3)
    if (std::abs(img.rgb[i] - r) <= tol && std::abs(img.rgb[i + 1] - g) <= tol &&
        std::abs(img.rgb[i + 2] - b) <= tol)
      ++n;
  return n;
}

std::string studio() {
  return LIDEF_STUDIO;
}

class StudioRender : public ::testing::TestWithParam<std::string> {};

TEST_P(StudioRender, MatchesBaseline) {
  const std::string view = GetParam();
  TempDir dir;
  const std::string out = dir / (view + ".png");
  std::string log;
  const int rc =
      run_command(studio() + " --scenario " + project_data() + "/scenarios/beam_bend.json --view " + view +
                      " --screenshot " + out + " --size 640x480",
                  &log);
  ASSERT_EQ(rc, 0) << log;
  EXPECT_NE(log.find("certified"), std::string::npos) << log;
  const Image img = read_png(out);
  ASSERT_EQ(img.w, 640) << log;
  ASSERT_EQ(img.h, 480);
  // Not a blank or black grab: many distinct colours.
  std::set<int> colours;
  for (size_t i = 0; i + 2 < img.rgb.size(); i += 3 * 7)
    colours.insert((img.rgb[i] << 16) | (img.rgb[i + 1] << 8) | img.rgb[i + 2]);
  EXPECT_GT(colours.size(), 200u);
  if (view == "mesh") {
    EXPECT_GT(count_near(img, 0, 217, 230, 40), 100);  // cyan target spheres
    EXPECT_GT(count_near(img, 200, 60, 60, 50), 50);   // the heat map's red where the beam bends
  }
  const std::string baseline = std::string(LIDEF_BASELINE_DIR) + "/" + view + ".png";
  if (std::getenv("LIDEF_UPDATE_BASELINES")) {
    fs::copy_file(out, baseline, fs::copy_options::overwrite_existing);
    GTEST_SKIP() << "baseline rewritten: " << baseline;
  }
  const Image base = read_png(baseline);
  ASSERT_FALSE(base.rgb.empty()) << "no baseline " << baseline << " (LIDEF_UPDATE_BASELINES=1 writes it)";
  const Comparison c = compare(img, base);
  const bool ok = c.fraction <= kMaxFraction && c.mean <= kMaxMean;
  if (!ok) {
    fs::create_directories(LIDEF_FAILED_DIR);
    const std::string kept = std::string(LIDEF_FAILED_DIR) + "/" + view + ".png";
    fs::copy_file(out, kept, fs::copy_options::overwrite_existing);
    if (!c.diff.rgb.empty()) write_png(std::string(LIDEF_FAILED_DIR) + "/" + view + "_diff.png", c.diff);
    ADD_FAILURE() << view << ": " << 100 * c.fraction << "% of pixels differ by more than " << kChannelTol
                  << " (limit " << 100 * kMaxFraction << "%), mean difference " << c.mean << " (limit "
                  << kMaxMean << "); new image kept: " << kept;
  }
}

INSTANTIATE_TEST_SUITE_P(Views, StudioRender, ::testing::Values("mesh", "sigma3", "lipschitz", "octree"));

// The comparison can fail: two different views are far outside the tolerance, an image matches itself.
TEST(StudioRenderErrors, ComparisonSeparatesViews) {
  const Image a = read_png(std::string(LIDEF_BASELINE_DIR) + "/mesh.png");
  const Image b = read_png(std::string(LIDEF_BASELINE_DIR) + "/sigma3.png");
  ASSERT_FALSE(a.rgb.empty());
  ASSERT_FALSE(b.rgb.empty());
  const Comparison same = compare(a, a), other = compare(a, b);
  EXPECT_EQ(same.fraction, 0.0);
  EXPECT_GT(other.fraction, 10 * kMaxFraction);
  Image shifted = a;  // the mesh drawn 3 pixels to the right
  for (int y = 0; y < a.h; ++y)
    for (int x = a.w - 1; x >= 3; --x)
      for (int k = 0; k < 3; ++k)
        shifted.rgb[3 * (static_cast<size_t>(y) * a.w + x) + k] =
            a.rgb[3 * (static_cast<size_t>(y) * a.w + x - 3) + k];
  const Comparison moved = compare(a, shifted);
  EXPECT_TRUE(moved.fraction > kMaxFraction || moved.mean > kMaxMean) << moved.fraction << " " << moved.mean;
}

TEST(StudioRenderErrors, BadInputExitsTwoAndWritesNothing) {
  TempDir dir;
  const std::string out = dir / "x.png";
  std::string log;
  EXPECT_EQ(run_command(studio() + " --scenario " + project_data() +
                            "/scenarios/beam_bend.json --view bogus --screenshot " + out,
                        &log),
            2);
  EXPECT_NE(log.find("unknown view"), std::string::npos) << log;
  write_text(dir / "broken.json", "{\"model\": \"beam\", \"handles\": [");
  EXPECT_EQ(run_command(studio() + " --scenario " + (dir / "broken.json") + " --screenshot " + out, &log), 2);
  EXPECT_NE(log.find("broken.json"), std::string::npos) << log;
  EXPECT_EQ(run_command(studio() + " --scenario " + project_data() +
                            "/scenarios/beam_bend.json --screenshot " + out + " --size 12by3",
                        &log),
            2);
  EXPECT_NE(log.find("--size"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path), fs::directory_iterator{}),
            1);  // broken.json only
}

// The side-by-side picture of a `lidef compare` run: every method's mesh, labelled.
TEST(StudioRenderCompare, SideBySidePictureOfACompareRun) {
  TempDir dir;
  std::string log;
  ASSERT_EQ(
      run_command(cli() + " compare " + project_data() + "/scenarios/beam_bend.json --out " + (dir / "cmp") +
                      " --methods lidef,pwl-tri --samples 4000 --reduced-dof 60 --cache-dir '' --quiet",
                  &log),
      0)
      << log;
  const std::string out = dir / "cmp.png";
  ASSERT_EQ(run_command(studio() + " --compare " + (dir / "cmp") + " --screenshot " + out + " --size 900x300",
                        &log),
            0)
      << log;
  EXPECT_NE(log.find("2 methods"), std::string::npos) << log;
  EXPECT_NE(log.find("lidef pwl-tri"), std::string::npos) << log;
  const Image img = read_png(out);
  ASSERT_EQ(img.w, 900);
  ASSERT_EQ(img.h, 300);
  // lidef's mesh in the heat map (reddish) on the left half, PWL(Tri)'s uncoloured surface (grey-blue) on the
  // right.
  Image left = img, right = img;
  for (int y = 0; y < img.h; ++y)
    for (int x = 0; x < img.w; ++x)
      for (int k = 0; k < 3; ++k)
        (x < img.w / 2 ? right : left).rgb[3 * (static_cast<size_t>(y) * img.w + x) + k] = 0;
  EXPECT_GT(count_near(left, 215, 120, 120, 60), 20);
  EXPECT_GT(count_near(right, 191, 199, 217, 20), 500);
  // Not a compare folder: exit 2, the reason on stderr, nothing written.
  fs::create_directories(dir / "empty");
  write_text(dir / "empty/readme.txt", "");
  EXPECT_EQ(
      run_command(studio() + " --compare " + (dir / "empty") + " --screenshot " + (dir / "x.png"), &log), 2);
  EXPECT_NE(log.find("table.csv"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(dir / "x.png"));
}

}  // namespace
