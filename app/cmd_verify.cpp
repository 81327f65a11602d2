// lidef verify: checks a certificate written by `lidef certify` by dense sampling inside every leaf (paper
// Fig. 5).
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>

#include "commands.h"
#include "gnuplot.h"
#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/certificate_verification.h"
#include "lidef/analysis/interval_verification.h"
#include "lidef/analysis/leaf_coverage.h"
#include "lidef/atomic_file.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/staged_outputs.h"
#include "lidef/subspace.h"

namespace lidef::cli {
namespace {

namespace fs = std::filesystem;

constexpr int kPlotLeaves = 500;    // as in the paper's Fig. 5
constexpr int kListedUnproven = 5;  // leaves named on the console when some is not proven

// A leaf whose certified σ1 or σ1/σ3 bound the intervals did not confirm (interval_verification.h).
bool distortion_unproven(const IntervalLeaf& r, const CertLeaf& l) {
  return (std::isfinite(l.sigma1_upper) && !(r.sigma1_hi <= l.sigma1_upper)) ||
         (std::isfinite(l.distortion_upper) && !(r.distortion_hi <= l.distortion_upper));
}

// `lidef verify --interval`: the rigorous re-proof of every certified leaf (interval_verification.h).
// Writes interval.csv (deterministic) and interval.json (with the wall time), prints one summary line.
// PROVEN needs three things: the certificate says certified, its leaves cover what it claims
// (leaf_coverage.h), and every certified leaf is re-proved on its ball widened to hold its exact grid cell.
ExitCode run_interval_verify(const CertificateReport& rep, const Model& model, const MatX3d& y,
                             const std::string& out_dir) {
  const std::vector<CertLeaf>& leaves = rep.cert.leaves;
  const LeafCoverage coverage = prove_leaf_coverage(rep, model.mesh);
  const IntervalVerification v =
      verify_certificate_intervals(model.cage, y, leaves, rep.cert.bound, coverage.radius_slack);
  StagedOutputs out(out_dir);
  write_file_atomic(out.path("interval.csv"), [&](std::ostream& s) {
    s << "leaf,proven,sigma3_lo,L_hi,margin_lo,certificate_margin,sigma1_hi,distortion_hi,"
         "certificate_distortion\n";
    for (size_t q = 0; q < v.results.size(); ++q) {
      const IntervalLeaf& r = v.results[q];
      s << v.leaf_index[q] << ',' << (r.proven ? 1 : 0) << ',' << format_double(r.sigma3_lo) << ','
        << format_double(r.L_hi) << ',' << format_double(r.margin_lo) << ','
        << format_double(leaves[v.leaf_index[q]].margin) << ',' << format_double(r.sigma1_hi) << ','
        << format_double(r.distortion_hi) << ',' << format_double(leaves[v.leaf_index[q]].distortion_upper)
        << '\n';
    }
  });
  const long checked = static_cast<long>(v.results.size());
  // A certified map meets its distortion targets on every leaf: the intervals must prove that too (σ1 ≤
  // max_sigma1 by sigma1_hi, σ3 ≥ min_sigma3 by margin_lo, σ1/σ3 ≤ max_distortion by distortion_hi).
  const DistortionTargets targets = rep.cert.targets();
  long targets_not_proven = 0;
  if (targets.any())
    for (const IntervalLeaf& r : v.results)
      targets_not_proven +=
          targets.unproven(r.sigma1_hi, r.margin_lo, r.distortion_hi) != DistortionTarget::kNone;
  const double leaves_per_s = v.seconds > 0 ? checked / v.seconds : 0.0;
  write_file_atomic(out.path("interval.json"), [&](std::ostream& s) {
    auto num = [](double x) { return std::isfinite(x) ? format_double(x) : "\"" + format_double(x) + "\""; };
    s << "{\n"
      << "  \"format\": \"lidef-interval-verification\",\n"
      << "  \"certificate_certified\": " << (rep.cert.certified ? "true" : "false") << ",\n"
      << "  \"coverage_proven\": " << (coverage.proven ? "true" : "false") << ",\n"
      << "  \"coverage\": " << nlohmann::json(coverage.reason).dump() << ",\n"
      << "  \"coverage_cells_checked\": " << coverage.cells_checked << ",\n"
      << "  \"radius_slack\": " << num(coverage.radius_slack) << ",\n"
      << "  \"bound\": \"" << to_string(rep.cert.bound) << "\",\n"
      << "  \"leaves\": " << leaves.size() << ",\n"
      << "  \"certified_leaves\": " << checked << ",\n"
      << "  \"proven\": " << v.proven << ",\n"
      << "  \"not_proven\": " << v.not_proven << ",\n"
      << "  \"worst_slack\": " << num(v.worst_slack) << ",\n"
      << "  \"distortion_proven\": " << v.distortion_proven << ",\n"
      << "  \"distortion_not_proven\": " << v.distortion_not_proven << ",\n"
      << "  \"max_sigma1_hi\": " << num(v.max_sigma1_hi) << ",\n"
      << "  \"max_distortion_hi\": " << num(v.max_distortion_hi) << ",\n"
      << "  \"distortion_targets\": " << nlohmann::json(targets.describe()).dump() << ",\n"
      << "  \"distortion_targets_not_proven\": " << targets_not_proven << ",\n"
      << "  \"transcendental_ulps\": " << kTranscendentalUlps << ",\n"
      << "  \"time_s\": " << num(v.seconds) << ",\n"
      << "  \"leaves_per_s\": " << num(leaves_per_s) << "\n"
      << "}\n";
  });
  out.commit();
  const bool leaves_ok = v.not_proven == 0 && v.distortion_not_proven == 0 && targets_not_proven == 0;
  const bool ok = leaves_ok && coverage.proven && rep.cert.certified;
  std::cout << "lidef verify --interval: " << (ok ? "PROVEN" : "NOT PROVEN") << ": " << v.proven << " of "
            << checked << " certified leaves proven in interval arithmetic (" << leaves.size()
            << " leaves in all), worst slack " << format_g(v.worst_slack) << ", " << format_g(v.seconds, 3)
            << " s (" << format_g(leaves_per_s, 3) << " leaves/s); wrote " << out.final_path("")
            << "{interval.csv, interval.json}\n";
  std::cout << "  coverage: " << coverage.reason << "\n";
  std::cout << "  distortion: " << v.distortion_proven << " of " << checked
            << " certified leaves' sigma1 and sigma1/sigma3 bounds re-proven (max sigma1 <= "
            << format_bound(v.max_sigma1_hi, true)
            << ", max sigma1/sigma3 <= " << format_bound(v.max_distortion_hi, true) << ")\n";
  if (targets.any())
    std::cout << "  distortion targets (" << targets.describe() << "): " << checked - targets_not_proven
              << " of " << checked << " certified leaves re-proven within them\n";
  if (!rep.cert.certified)
    std::cout << "  the certificate itself says 'not certified' (" << rep.cert.reason
              << "): only its certified leaves were re-proved, which certifies nothing about the others\n";
  if (!leaves_ok) {
    int listed = 0;
    for (size_t q = 0; q < v.results.size() && listed < kListedUnproven; ++q) {
      const IntervalLeaf& r = v.results[q];
      if (r.proven && !distortion_unproven(r, leaves[v.leaf_index[q]]) &&
          targets.unproven(r.sigma1_hi, r.margin_lo, r.distortion_hi) == DistortionTarget::kNone)
        continue;
      ++listed;
      const CertLeaf& l = leaves[v.leaf_index[q]];
      std::cout << "  not proven: leaf " << v.leaf_index[q] << " (row " << v.leaf_index[q] + 2
                << " of voxels.csv), center (" << format_g(l.center.x()) << ", " << format_g(l.center.y())
                << ", " << format_g(l.center.z()) << "), side " << format_g(l.side)
                << ": sigma3 >= " << format_bound(r.sigma3_lo, false)
                << ", L <= " << format_bound(r.L_hi, true)
                << ", margin >= " << format_bound(r.margin_lo, false)
                << ", sigma1 <= " << format_bound(r.sigma1_hi, true)
                << ", sigma1/sigma3 <= " << format_bound(r.distortion_hi, true)
                << " (certificate: " << format_bound(l.sigma1_upper, true) << ", "
                << format_bound(l.distortion_upper, true) << ")\n";
    }
  }
  return ok ? kOk : kNotCertified;
}

}  // namespace

void add_verify_command(CLI::App& app, Action& action) {
  struct Opts {
    std::string model, coeffs, certificate, out;
    int samples = 64;
    unsigned seed = 1;
    bool interval = false;
  };
  auto opts = std::make_shared<Opts>();
  auto* sub =
      app.add_subcommand("verify", "Check a certificate by dense sampling of sigma3 inside every leaf voxel");
  sub->add_option("MODEL_DIR", opts->model, "Model folder the certificate was computed for")->required();
  sub->add_option("--coeffs", opts->coeffs,
                  "Coefficient file the certificate was computed for, or 'identity'")
      ->required();
  sub->add_option("--certificate", opts->certificate,
                  "certificate.json written by 'lidef certify' (voxels.csv beside it)")
      ->required();
  sub->add_option("--samples-per-voxel", opts->samples,
                  "Uniform random samples per leaf, in addition to its center and 8 corners")
      ->capture_default_str();
  sub->add_option("--seed", opts->seed, "Random seed (results do not depend on the thread count)")
      ->capture_default_str();
  sub->add_option("--out", opts->out, "Output folder (default: the certificate's folder)");
  sub->add_flag(
      "--interval", opts->interval,
      "Re-prove every certified leaf in interval arithmetic (outward rounding) instead of sampling");
  sub->footer(
      "Writes verify.csv (one row per leaf), violations.csv (the first sampled points where sigma3 drops "
      "below\n"
      "the certificate's bound sigma3(c) - |p-c| L), verify_plot.png (leaves with the largest L, sorted by "
      "the\n"
      "sampled Lipschitz estimate, log scale; paper Fig. 5) and the gnuplot script/data that draw it\n"
      "(verify_plot.gp, verify_plot.dat). Without gnuplot ($LIDEF_GNUPLOT or PATH) the PNG is skipped with "
      "a\n"
      "warning. The distortion bounds are checked too: no sample's sigma1 or sigma1/sigma3 above its leaf's\n"
      "sigma1_upper / distortion_upper (voxels.csv; verify.csv: max_sigma1, max_distortion,\n"
      "distortion_violations). Exit code: 0 no violation and no sigma3 <= 0 in certified leaves, 1 "
      "otherwise,\n"
      "2 error.\n"
      "\n"
      "--interval: a rigorous re-proof instead of sampling (docs/certificate.md, 'Interval re-proof'). For\n"
      "every certified leaf, J and the Hessian at its center (closed-form Green-coordinate derivatives), a\n"
      "lower bound of sigma3, the certificate's Lipschitz constant L (first order, third order or combined, "
      "as certified) "
      "and\n"
      "the margin sigma3 - r L are enclosed in intervals with outward rounding (log/atan widened by 4 "
      "ulps);\n"
      "the leaf is proven when the lower end of the margin is > 0 (no rounding allowance). Writes "
      "interval.csv\n"
      "(leaf,proven,sigma3_lo,L_hi,margin_lo,certificate_margin; leaf = 0-based row of voxels.csv) and\n"
      "interval.json (leaves, proven, not_proven, worst_slack = min margin_lo, coverage, time). The\n"
      "distortion bounds are re-proved too: per leaf sigma1_hi = an upper bound of sigma1 on the ball and\n"
      "distortion_hi of sigma1/sigma3, each at most voxels.csv's sigma1_upper / distortion_upper\n"
      "(interval.csv: sigma1_hi, distortion_hi, certificate_distortion; interval.json: distortion_proven,\n"
      "distortion_not_proven). It also proves that the leaves cover the domain the certificate claims "
      "(every\n"
      "leaf a cell of the certificate's grid, every grid cell meeting the mesh's triangles or solid covered\n"
      "by certified leaves; 'voxels' domain: every base voxel tiled), and widens each ball to hold its "
      "exact\n"
      "cell. Exit code: 0 the certificate says certified, the coverage is proven and every certified leaf\n"
      "and its distortion bounds are proven; 1 otherwise (the first unproven leaves or the coverage gap are\n"
      "listed); 2 error.");
  sub->callback([opts, &action] {
    action = [opts] {
      const Opts& o = *opts;
      if (o.samples < 0 || o.samples > 100000)
        throw InputError("--samples-per-voxel",
                         "must be in 0..100000 (got " + std::to_string(o.samples) + ")");
      const CertificateReport rep = read_certificate_json(o.certificate);
      const Model model = load_model(o.model);
      if (subspace_cage_hash(model.cage) != rep.cage_hash)
        throw InputError(o.certificate, "was computed for a different cage than " + o.model + " (model '" +
                                            rep.model + "')");
      const MatX3d y = read_coefficients(o.coeffs, model.cage);
      if (coefficients_hash(y) != rep.coefficients_hash)
        throw InputError(o.certificate, "was computed for other coefficients than " + o.coeffs +
                                            " (coefficients '" + rep.coefficients + "')");
      const std::vector<CertLeaf>& leaves = rep.cert.leaves;
      std::string out_dir = o.out;
      if (out_dir.empty()) {
        out_dir = fs::path(o.certificate).parent_path().string();
        if (out_dir.empty()) out_dir = ".";
      }
      if (o.interval) return run_interval_verify(rep, model, y, out_dir);
      const HarmonicBasis basis(model.cage);
      const VerificationResult v = verify_certificate(basis, y, leaves, o.samples, o.seed);

      // --- verify.csv and violations.csv.
      StagedOutputs out(out_dir);
      write_file_atomic(out.path("verify.csv"), [&](std::ostream& s) {
        s << "cx,cy,cz,side,depth,L,sigma3_center,min_sigma3,max_quotient,tightness,violations,certified,"
             "max_sigma1,max_distortion,distortion_violations\n";
        for (size_t i = 0; i < leaves.size(); ++i) {
          const CertLeaf& l = leaves[i];
          const VoxelVerification& vv = v.voxels[i];
          s << format_double(l.center.x()) << ',' << format_double(l.center.y()) << ','
            << format_double(l.center.z()) << ',' << format_double(l.side) << ',' << l.depth << ','
            << format_double(l.L) << ',' << format_double(vv.sigma3_center) << ','
            << format_double(vv.min_sigma3) << ',' << format_double(vv.max_quotient) << ','
            << format_double(vv.tightness) << ',' << vv.violations << ',' << (l.certified ? 1 : 0) << ','
            << format_double(vv.max_sigma1) << ',' << format_double(vv.max_distortion) << ','
            << vv.distortion_violations << '\n';
        }
      });
      write_file_atomic(out.path("violations.csv"), [&](std::ostream& s) {
        s << "leaf,px,py,pz,sigma3,bound\n";
        for (const BoundViolation& b : v.violation_list)
          s << b.leaf << ',' << format_double(b.p.x()) << ',' << format_double(b.p.y()) << ','
            << format_double(b.p.z()) << ',' << format_double(b.sigma3) << ',' << format_double(b.bound)
            << '\n';
      });

      // --- The Fig. 5 plot: the kPlotLeaves leaves with the largest finite L, sorted by the sampled
      // estimate.
      std::vector<long> idx;
      for (size_t i = 0; i < leaves.size(); ++i)
        if (std::isfinite(leaves[i].L)) idx.push_back(static_cast<long>(i));
      std::stable_sort(idx.begin(), idx.end(), [&](long a, long b) { return leaves[a].L > leaves[b].L; });
      if (idx.size() > static_cast<size_t>(kPlotLeaves)) idx.resize(kPlotLeaves);
      std::stable_sort(idx.begin(), idx.end(),
                       [&](long a, long b) { return v.voxels[a].max_quotient < v.voxels[b].max_quotient; });
      double max_l = 0;
      for (long i : idx) max_l = std::max(max_l, leaves[i].L);
      write_file_atomic(out.path("verify_plot.dat"), [&](std::ostream& s) {
        s << "# rank  sampled_lipschitz  certificate_L  leaf (0-based row of verify.csv)\n";
        for (size_t r = 0; r < idx.size(); ++r)
          s << r + 1 << ' ' << format_double(v.voxels[idx[r]].max_quotient) << ' '
            << format_double(leaves[idx[r]].L) << ' ' << idx[r] << '\n';
      });
      const bool log_y = max_l > 0;
      write_file_atomic(out.path("verify_plot.gp"), [&](std::ostream& s) {
        s << "# Paper Fig. 5: the certificate's Lipschitz constant L of sigma3 against the sampled ground "
             "truth.\n"
             "# Render with: gnuplot verify_plot.gp   (in this folder)\n"
             "set terminal pngcairo enhanced size 1000,600 font 'sans,11'\n"
             "set output 'verify_plot.png'\n"
          << "set title \"Lipschitz constant of sigma3: " << idx.size()
          << " leaves with the largest L, sorted by the sampled estimate\"\n"
          << "set xlabel 'leaf (sorted by sampled ground truth)'\n"
             "set ylabel 'Lipschitz constant'\n"
          << (log_y ? "set logscale y\nset format y '10^{%L}'\n"
                    : "# all L are 0 (affine map): linear axis\n")
          << "set key below\nset grid\n"
             "plot 'verify_plot.dat' using 1:3 with points pt 7 ps 0.5 lc rgb '#d62728' title 'certificate "
             "L', \\\n"
             "     '' using 1:2 with lines lw 2 lc rgb '#1f77b4' "
             "title 'sampled ground truth: max |sigma3(p) - sigma3(c)| / |p - c| over the leaf'\n";
      });
      std::string plot_note;
      if (idx.empty()) {
        plot_note = "no leaf with a finite L: no plot";
      } else {
        plot_note = render_staged_png(out, "verify_plot",
                                      " (install gnuplot-nox or set LIDEF_GNUPLOT); render it later with "
                                      "'gnuplot verify_plot.gp' in " +
                                          out_dir);
        if (!plot_note.empty()) std::cerr << "lidef verify: warning: " << plot_note << "\n";
      }
      const bool have_png = fs::exists(fs::path(out.staging_dir()) / "verify_plot.png");
      out.commit(have_png ? std::vector<std::string>{} : std::vector<std::string>{"verify_plot.png"});

      // --- Summary.
      long certified_leaves = 0;
      double max_tight = 0;
      for (size_t i = 0; i < leaves.size(); ++i) {
        certified_leaves += leaves[i].certified;
        if (std::isfinite(v.voxels[i].tightness)) max_tight = std::max(max_tight, v.voxels[i].tightness);
      }
      // The distortion targets a certificate claims to meet (max_distortion, max_sigma1, min_sigma3), against
      // the samples of its certified leaves, beyond the SVD's rounding (relative 1e-10).
      const DistortionTargets targets = rep.cert.targets();
      const bool targets_claimed = targets.any() && rep.cert.distortion_met;
      const bool targets_sampled_ok =
          !targets_claimed ||
          ((!(targets.max_distortion > 0) || v.max_distortion <= targets.max_distortion * (1 + 1e-10)) &&
           (!(targets.max_sigma1 > 0) || v.max_sigma1 <= targets.max_sigma1 * (1 + 1e-10)) &&
           (!(targets.min_sigma3 > 0) || v.min_sigma3 >= targets.min_sigma3 * (1 - 1e-10)));
      const bool ok = v.violations == 0 && v.nonpositive_in_certified == 0 && v.distortion_violations == 0 &&
                      targets_sampled_ok;
      std::cout << "lidef verify: " << (ok ? "OK" : "FAILED") << ": " << v.points << " points in "
                << leaves.size() << " leaves (" << certified_leaves << " certified; certificate says "
                << (rep.cert.certified ? "certified" : "not certified") << ")\n";
      std::cout << "  min sigma3 sampled in certified leaves " << format_g(v.min_sigma3) << "\n";
      std::cout << "  bound violations " << v.violations << ", samples with sigma3 <= 0 in certified leaves "
                << v.nonpositive_in_certified << "\n";
      std::cout << "  max tightness (sampled Lipschitz / L) " << format_g(max_tight) << "\n";
      std::cout << "  distortion: sampled max sigma1 " << format_g(v.max_sigma1) << " (certified bound "
                << format_bound(rep.cert.max_sigma1_upper_bound, true) << "), sampled max sigma1/sigma3 "
                << format_g(v.max_distortion) << " (certified bound "
                << format_bound(rep.cert.max_distortion_upper_bound, true)
                << "), samples above their leaf's bounds " << v.distortion_violations << "\n";
      if (targets.any())
        std::cout << "  distortion targets (" << targets.describe() << "): "
                  << (rep.cert.distortion_met ? "proven by the certificate" : "not proven by the certificate")
                  << (targets_claimed ? (targets_sampled_ok ? "; every sample within them"
                                                            : "; a sample beyond them: the claim is WRONG")
                                      : "")
                  << "\n";
      std::cout << "  wrote " << out.final_path("")
                << "{verify.csv, violations.csv, verify_plot.gp, verify_plot.dat"
                << (have_png ? ", verify_plot.png" : "") << "}\n";
      return ok ? kOk : kNotCertified;
    };
  });
}

}  // namespace lidef::cli
