// Two plots drawn with QPainter (QtCharts is not a dependency):
//  top    — the solver history, as in Fig. 9 of Liao et al. 2021: energy E per iteration, log axis (left);
//           on a linear axis (right) the certified lower bound of sigma3 over the voxels (min over leaves of
//           sigma3 - r L - tau) beside the smallest sampled sigma3 (voxel and node centers): their gap shows
//           how tight the bound is (with bound_tolerance the certifier refines until the gap is within that
//           fraction); the title gives the last iteration's numbers and refined voxels; hollow markers for
//           iterations whose step was not accepted;
//  bottom — a certificate against its ground truth, as in Fig. 5: per leaf voxel, sorted by the certificate's
//           Lipschitz bound L, L as a line and the sampled max |sigma3(p) - sigma3(c)| / |p - c| as points
//           (log axis); the title gives the number of leaves and of bound violations (red unless 0).
// Non-finite values, and non-positive ones on log axes, are skipped (E is +inf at a non-injective trial).
#pragma once
#include <QWidget>
#include <vector>

#include "lidef/analysis/certificate_verification.h"
#include "lidef/projected_newton.h"

class QPainter;

namespace lidef::studio {

class PlotsPanel : public QWidget {
  Q_OBJECT

 public:
  explicit PlotsPanel(QWidget* parent = nullptr);

  // Replaces the history shown in the top plot and repaints.
  void set_history(const std::vector<lidef::IterationRecord>& history);
  // The certifier's bound_tolerance the history was computed with (0: the bound is only proven > 0).
  void set_bound_tolerance(double t);
  // The model the plots describe (first words of both titles).
  void set_model_name(const QString& name);
  // The title of the history plot (what it says about the last iteration).
  QString history_title() const;
  // Shows `v` in the bottom plot and repaints.
  void set_verification(const lidef::VerificationResult& v);
  // Empties the bottom plot ("no data yet").
  void clear_verification();

  int num_iterations() const { return static_cast<int>(iterations_.size()); }
  bool has_verification() const { return has_verification_; }

  QSize sizeHint() const override { return {480, 560}; }

 protected:
  void paintEvent(QPaintEvent* event) override;

 private:
  struct IterationPoint {
    int iteration;
    double energy, lower_bound, sampled;
    long refined;
    bool accepted;
  };
  struct LeafPoint {
    double L, quotient;
    bool violated;
  };
  void paint_history(QPainter& painter, const QRect& area) const;
  void paint_verification(QPainter& painter, const QRect& area) const;

  std::vector<IterationPoint> iterations_;
  std::vector<LeafPoint> leaves_;  // sorted by L (precomputed: a paint must stay cheap with 1e5 leaves)
  long violations_ = 0;
  double bound_tolerance_ = 0;
  QString model_name_;
  bool has_verification_ = false;
};

}  // namespace lidef::studio
