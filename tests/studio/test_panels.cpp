// The studio's ParamsPanel (parameter editor over the one parameter table) and PlotsPanel (solver history and
// certificate verification plots). Needs a QApplication (the studio test main creates one) and a display:
// rendering is checked on real pixels, which the offscreen platform does not give.
#include <gtest/gtest.h>

#include <QColor>
#include <QImage>
#include <QObject>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/deform_params.h"
#include "lidef/projected_newton.h"
#include "params_panel.h"
#include "plots_panel.h"

using lidef::DeformParams;
using lidef::studio::ParamsPanel;
using lidef::studio::PlotsPanel;

namespace {

// Records every params_applied emission.
struct AppliedSpy {
  explicit AppliedSpy(ParamsPanel& panel) {
    QObject::connect(&panel, &ParamsPanel::params_applied, [this](const DeformParams& p, bool rebuild) {
      params.push_back(p);
      rebuilds.push_back(rebuild);
    });
  }
  std::vector<DeformParams> params;
  std::vector<bool> rebuilds;
};

TEST(ParamsPanel, EveryTableRowHasAnEditor) {
  ParamsPanel panel;
  const DeformParams defaults;
  for (const lidef::ParamInfo& p : lidef::deform_param_table()) {
    if (lidef::is_test_hook(p)) continue;  // test hooks are not settings: the panel leaves them out
    EXPECT_EQ(panel.text(p.name), lidef::param_value_string(defaults, p)) << p.name;
    EXPECT_TRUE(panel.set_text(p.name, lidef::param_value_string(defaults, p))) << p.name;
  }
  EXPECT_FALSE(panel.set_text("no_such_parameter", "1"));
  EXPECT_EQ(panel.text("no_such_parameter"), "");
}

TEST(ParamsPanel, SetParamsRoundTrip) {
  ParamsPanel panel;
  AppliedSpy spy(panel);
  DeformParams p;
  p.reduced_dof = 123;
  p.lambda_smooth = 0.25;
  p.max_refined = 1234567;
  p.dynamic_weighting = false;
  p.bound = lidef::LipschitzBound::kFirstOrder;
  p.backend = lidef::BackendKind::kAuto;
  panel.set_params(p);
  EXPECT_TRUE(spy.params.empty()) << "set_params must not emit";
  const DeformParams q = panel.params();
  EXPECT_EQ(q.reduced_dof, 123);
  EXPECT_EQ(q.lambda_smooth, 0.25);
  EXPECT_EQ(q.max_refined, 1234567);
  EXPECT_FALSE(q.dynamic_weighting);
  EXPECT_EQ(q.bound, lidef::LipschitzBound::kFirstOrder);
  EXPECT_EQ(q.backend, lidef::BackendKind::kAuto);
  EXPECT_EQ(panel.text("reduced_dof"), "123");
  EXPECT_EQ(panel.text("dynamic_weighting"), "false");
  EXPECT_EQ(panel.text("bound"), "first");
  // Applying without edits changes nothing and needs no rebuild.
  ASSERT_TRUE(panel.apply());
  ASSERT_EQ(spy.params.size(), 1u);
  EXPECT_FALSE(spy.rebuilds[0]);
  EXPECT_EQ(spy.params[0].lambda_smooth, 0.25);
  EXPECT_EQ(spy.params[0].bound, lidef::LipschitzBound::kFirstOrder);
}

TEST(ParamsPanel, ApplyEmitsWithRebuildFlag) {
  ParamsPanel panel;
  AppliedSpy spy(panel);
  // A weight: no rebuild. "1e3" is JSON, as on the command line.
  ASSERT_TRUE(panel.set_text("lambda_p2p", "1e3"));
  ASSERT_TRUE(panel.apply()) << panel.error_text().toStdString();
  ASSERT_EQ(spy.params.size(), 1u);
  EXPECT_EQ(spy.params[0].lambda_p2p, 1e3);
  EXPECT_FALSE(spy.rebuilds[0]);
  EXPECT_EQ(panel.params().lambda_p2p, 1e3);
  EXPECT_TRUE(panel.error_text().isEmpty());

  // The subspace size: rebuild; the earlier change is kept.
  ASSERT_TRUE(panel.set_text("reduced_dof", "150"));
  ASSERT_TRUE(panel.apply());
  ASSERT_EQ(spy.params.size(), 2u);
  EXPECT_EQ(spy.params[1].reduced_dof, 150);
  EXPECT_EQ(spy.params[1].lambda_p2p, 1e3);
  EXPECT_TRUE(spy.rebuilds[1]);

  // Choice and check boxes: backend rebuilds, bound does not.
  ASSERT_TRUE(panel.set_text("backend", "opencl"));
  ASSERT_TRUE(panel.apply());
  EXPECT_EQ(spy.params.back().backend, lidef::BackendKind::kOpenCL);
  EXPECT_TRUE(spy.rebuilds.back());
  ASSERT_TRUE(panel.set_text("bound", "first"));
  ASSERT_TRUE(panel.set_text("dynamic_weighting", "false"));
  ASSERT_TRUE(panel.apply());
  EXPECT_EQ(spy.params.back().bound, lidef::LipschitzBound::kFirstOrder);
  EXPECT_FALSE(spy.params.back().dynamic_weighting);
  EXPECT_FALSE(spy.rebuilds.back());
  EXPECT_FALSE(panel.set_text("bound", "second")) << "a choice box offers only valid choices";

  // Each of the precomputation parameters alone triggers a rebuild.
  for (const auto& [name, text] :
       std::vector<std::pair<std::string, std::string>>{{"samples", "20000"},
                                                        {"voxel_side", "0.05"},
                                                        {"safety", "2"},
                                                        {"hessian_fraction", "0.1"},
                                                        {"threads", "1"}}) {
    ASSERT_TRUE(panel.set_text(name, text));
    ASSERT_TRUE(panel.apply()) << name;
    EXPECT_TRUE(spy.rebuilds.back()) << name;
  }
  EXPECT_EQ(panel.params().voxel_side, 0.05);
  EXPECT_EQ(panel.params().threads, 1);
}

TEST(ParamsPanel, InvalidValuesFailWithoutEmitting) {
  ParamsPanel panel;
  AppliedSpy spy(panel);
  const DeformParams before = panel.params();

  ASSERT_TRUE(panel.set_text("lambda_p2p", "-1"));  // out of range
  EXPECT_FALSE(panel.apply());
  EXPECT_TRUE(spy.params.empty());
  EXPECT_NE(panel.error_text().toStdString().find("lambda_p2p"), std::string::npos)
      << panel.error_text().toStdString();
  EXPECT_TRUE(panel.is_marked("lambda_p2p"));
  EXPECT_FALSE(panel.is_marked("lambda_smooth"));
  EXPECT_EQ(panel.params().lambda_p2p, before.lambda_p2p);

  ASSERT_TRUE(panel.set_text("lambda_p2p", "1e4"));
  ASSERT_TRUE(panel.set_text("reduced_dof", "abc"));  // not a number
  EXPECT_FALSE(panel.apply());
  EXPECT_TRUE(spy.params.empty());
  EXPECT_NE(panel.error_text().toStdString().find("reduced_dof"), std::string::npos)
      << panel.error_text().toStdString();
  EXPECT_TRUE(panel.is_marked("reduced_dof"));
  EXPECT_FALSE(panel.is_marked("lambda_p2p"));

  ASSERT_TRUE(panel.set_text("reduced_dof", "12.5"));  // not an integer
  EXPECT_FALSE(panel.apply());
  EXPECT_NE(panel.error_text().toStdString().find("reduced_dof"), std::string::npos);

  // Fixed, the whole edit applies and the error is gone.
  ASSERT_TRUE(panel.set_text("reduced_dof", "64"));
  ASSERT_TRUE(panel.apply());
  ASSERT_EQ(spy.params.size(), 1u);
  EXPECT_EQ(spy.params[0].reduced_dof, 64);
  EXPECT_EQ(spy.params[0].lambda_p2p, 1e4);
  EXPECT_TRUE(panel.error_text().isEmpty());
  EXPECT_FALSE(panel.is_marked("reduced_dof"));
}

TEST(ParamsPanel, DefaultsAndPresetAreNotAppliedUntilApply) {
  ParamsPanel panel;
  AppliedSpy spy(panel);
  DeformParams p;
  p.lambda_p2p = 7;
  p.reduced_dof = 50;
  panel.set_params(p);

  panel.load_interactive_preset();
  EXPECT_EQ(panel.text("reduced_dof"), "100");
  EXPECT_EQ(panel.text("samples"), "10000");
  EXPECT_EQ(panel.params().reduced_dof, 50);
  EXPECT_TRUE(spy.params.empty());
  ASSERT_TRUE(panel.apply());
  EXPECT_EQ(panel.params().reduced_dof, 100);
  EXPECT_EQ(panel.params().samples, 10000);
  EXPECT_EQ(panel.params().lambda_p2p, 7);
  EXPECT_TRUE(spy.rebuilds.back());

  panel.load_defaults();
  EXPECT_EQ(panel.params().lambda_p2p, 7);
  ASSERT_TRUE(panel.apply());
  EXPECT_EQ(panel.params().lambda_p2p, DeformParams{}.lambda_p2p);
  EXPECT_EQ(panel.params().reduced_dof, DeformParams{}.reduced_dof);
  EXPECT_EQ(spy.params.size(), 2u);
}

// Pixels of the plot colours (saturated), as opposed to the white page and the grey/black axes and text.
int coloured_pixels(const QImage& image, int y0, int y1) {
  int count = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = 0; x < image.width(); ++x) {
      const QColor c = image.pixelColor(x, y);
      const int hi = std::max({c.red(), c.green(), c.blue()}), lo = std::min({c.red(), c.green(), c.blue()});
      if (hi - lo > 60) ++count;
    }
  return count;
}

QImage render(PlotsPanel& panel) {
  panel.resize(400, 400);
  QImage image(400, 400, QImage::Format_ARGB32);
  image.fill(Qt::black);  // anything the panel leaves unpainted would show
  panel.render(&image);
  return image;
}

std::vector<lidef::IterationRecord> sample_history() {
  std::vector<lidef::IterationRecord> h;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const double energy[] = {1e4, 3e2, inf, 20, 5, 0, nan, 4.5};
  const double bound[] = {0.5, 0.3, 0.3, -0.1, 0.2, 0.25, nan, 0.26};
  for (int i = 0; i < 8; ++i) {
    lidef::IterationRecord r;
    r.iteration = i + 1;
    r.terms.total = energy[i];
    r.min_lower_bound = bound[i];
    r.accepted = i != 2 && i != 6;
    h.push_back(r);
  }
  return h;
}

lidef::VerificationResult sample_verification(int leaves, long violations) {
  lidef::VerificationResult v;
  for (int i = 0; i < leaves; ++i) {
    lidef::VoxelVerification x{};
    x.leaf = i;
    x.L = 10.0 + (i * 37) % 101;  // unsorted on purpose
    x.max_quotient = i % 7 == 0 ? 0.0 : x.L * 0.3 * (1 + i % 3);
    x.violations = i < violations ? 1 : 0;
    v.voxels.push_back(x);
  }
  v.voxels.back().L = std::numeric_limits<double>::quiet_NaN();
  v.violations = violations;
  return v;
}

TEST(PlotsPanel, EmptyPanelPaintsNoDataText) {
  PlotsPanel panel;
  EXPECT_EQ(panel.num_iterations(), 0);
  EXPECT_FALSE(panel.has_verification());
  EXPECT_GE(panel.minimumSize().width(), 320);
  EXPECT_GE(panel.minimumSize().height(), 360);
  const QImage image = render(panel);
  EXPECT_EQ(coloured_pixels(image, 0, 400), 0);
  EXPECT_EQ(image.pixelColor(5, 395), QColor(Qt::white));  // the page is painted
  EXPECT_EQ(image.pixelColor(395, 5), QColor(Qt::white));
}

TEST(PlotsPanel, PaintsHistoryAndVerification) {
  PlotsPanel panel;
  panel.set_history(sample_history());
  EXPECT_EQ(panel.num_iterations(), 8);
  const QImage history_only = render(panel);
  EXPECT_GT(coloured_pixels(history_only, 0, 180), 200);
  EXPECT_EQ(coloured_pixels(history_only, 240, 400), 0);

  panel.set_verification(sample_verification(500, 0));
  EXPECT_TRUE(panel.has_verification());
  const QImage both = render(panel);
  EXPECT_GT(coloured_pixels(both, 0, 180), 200);
  EXPECT_GT(coloured_pixels(both, 240, 400), 200);

  // Violations: red in the lower half.
  panel.set_verification(sample_verification(500, 3));
  const QImage violated = render(panel);
  int red = 0;
  for (int y = 220; y < 400; ++y)
    for (int x = 0; x < 400; ++x) {
      const QColor c = violated.pixelColor(x, y);
      if (c.red() > 180 && c.green() < 90 && c.blue() < 90) ++red;
    }
  EXPECT_GT(red, 10);

  panel.clear_verification();
  EXPECT_FALSE(panel.has_verification());
  EXPECT_EQ(coloured_pixels(render(panel), 240, 400), 0);
}

TEST(PlotsPanel, DegenerateDataPaintsWithoutCrash) {
  PlotsPanel panel;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  lidef::IterationRecord r;
  r.iteration = 1;
  r.terms.total = nan;
  r.min_lower_bound = nan;
  panel.set_history({r});  // nothing plottable
  lidef::VerificationResult v;
  panel.set_verification(v);  // no leaves
  render(panel);
  r.terms.total = 1;  // a single point: axes must not collapse
  r.min_lower_bound = 0;
  panel.set_history({r});
  v.voxels.push_back(lidef::VoxelVerification{0, 1, 1, 0, 0, 0, 0});  // only non-positive values
  panel.set_verification(v);
  const QImage image = render(panel);
  EXPECT_GT(coloured_pixels(image, 0, 200), 0);
  panel.resize(100, 80);  // below the minimum size: still paints
  QImage tiny(100, 80, QImage::Format_ARGB32);
  panel.render(&tiny);
}

}  // namespace
