// lidef explore: the σ3 counterexample explorer (paper Fig. 2, App. D; docs/explorer.md).
//   explore search     random harmonic polynomial maps, interior minima of σ3, the best candidates verified
//   explore show       one map file: minima, certificate, boundary embedding, fields, image, slice PNG
//   explore construct  the twist counterexample family as a map file
//   explore laplacian  Δσ1 and Δσ3 at random points of random maps
// One function per sub-command (run_show, run_search, run_construct, run_laplacian), made of named steps;
// add_explore_command only wires them to their options.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "commands.h"
#include "gnuplot.h"
#include "lidef/analysis/explorer_export.h"
#include "lidef/analysis/mesh_export.h"
#include "lidef/atomic_file.h"
#include "lidef/errors.h"
#include "lidef/explorer/ball_certificate.h"
#include "lidef/explorer/ball_fields.h"
#include "lidef/explorer/boundary_injectivity.h"
#include "lidef/explorer/counterexample.h"
#include "lidef/explorer/explorer_example.h"
#include "lidef/explorer/laplacian_experiment.h"
#include "lidef/explorer/random_search.h"
#include "lidef/explorer/sigma_minima.h"
#include "lidef/mesh_io.h"
#include "lidef/number_format.h"
#include "lidef/procedural_models.h"
#include "lidef/signed_svd.h"
#include "lidef/staged_outputs.h"

namespace lidef::cli {
namespace {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

// Options shared by `show` and the verification part of `search`.
struct ShowOptions {
  int starts = 24;
  unsigned long long seed = 1;
  int grid = 64;
  int sphere_subdivisions = 5;
  int max_depth = 8;
  int net_subdivisions = 6;
  int slice_resolution = 201;
};

void check_show_options(const ShowOptions& o) {
  if (o.starts < 1 || o.starts > 100000) throw InputError("--starts", "must be in 1..100000");
  if (o.grid < 2 || o.grid > 512)
    throw InputError("--grid", "must be in 2..512 (got " + std::to_string(o.grid) + ")");
  if (o.sphere_subdivisions < 1 || o.sphere_subdivisions > 7)
    throw InputError("--sphere-subdivisions",
                     "must be in 1..7 (got " + std::to_string(o.sphere_subdivisions) + ")");
  if (o.net_subdivisions < 1 || o.net_subdivisions > 8)
    throw InputError("--net-subdivisions",
                     "must be in 1..8 (got " + std::to_string(o.net_subdivisions) + ")");
  if (o.max_depth < 0 || o.max_depth > 12)
    throw InputError("--max-depth", "must be in 0..12 (got " + std::to_string(o.max_depth) + ")");
}

ojson vec_json(const Vec3& v) {
  return ojson::array({v.x(), v.y(), v.z()});
}

ojson certificate_json(const BallCertificate& c) {
  ojson j;
  j["certified"] = c.certified;
  j["reason"] = c.reason;
  j["region"] = c.sphere_only ? "sphere" : "ball";
  j["threshold"] = c.threshold;
  j["cells_evaluated"] = c.cells_evaluated;
  j["leaves"] = c.leaves;
  j["max_depth_used"] = c.max_depth_used;
  j["min_lower_bound"] = std::isfinite(c.min_lower_bound) ? ojson(c.min_lower_bound) : ojson(nullptr);
  j["min_sigma3_center"] = std::isfinite(c.min_sigma3_center) ? ojson(c.min_sigma3_center) : ojson(nullptr);
  return j;
}

void write_minima_csv(const std::string& path, const std::vector<Sigma3Minimum>& minima) {
  write_file_atomic(path, [&](std::ostream& s) {
    s << "x,y,z,sigma3,gradient_norm,hessian_eig1,hessian_eig2,hessian_eig3,sphere_radius,sphere_min_sigma3,"
         "strict,"
         "starts\n";
    for (const Sigma3Minimum& m : minima)
      s << format_double(m.position.x()) << ',' << format_double(m.position.y()) << ','
        << format_double(m.position.z()) << ',' << format_double(m.sigma3) << ','
        << format_double(m.gradient_norm) << ',' << format_double(m.hessian_eigenvalues(0)) << ','
        << format_double(m.hessian_eigenvalues(1)) << ',' << format_double(m.hessian_eigenvalues(2)) << ','
        << format_double(m.sphere_radius) << ',' << format_double(m.sphere_min_sigma3) << ','
        << (m.strict ? 1 : 0) << ',' << m.starts << '\n';
  });
}

// Two slices through the minimum (Fig. 2, right): the planes z = z0 and y = y0, σ3 on a square grid, NaN
// outside the ball; a gnuplot script draws both with the minimum marked. Returns the PNG's status note (empty
// when drawn).
std::string write_slice(StagedOutputs& out, const std::string& prefix, const ExplorerMap& map,
                        const Ball& ball, const Sigma3Minimum* m, int res, const std::string& title) {
  const Vec3 p0 = m ? m->position : ball.center;
  const double step = 2 * ball.radius / (res - 1);
  double lo = INFINITY, hi = -INFINITY;
  // axis_u, axis_v: in-plane axes; the fixed axis goes through p0.
  struct Plane {
    const char* name;
    int u, v, fixed;
  };
  const Plane planes[2] = {{"xy", 0, 1, 2}, {"xz", 0, 2, 1}};
  for (const Plane& pl : planes) {
    std::vector<double> v(static_cast<size_t>(res) * res, NAN);
#pragma omp parallel for schedule(dynamic)
    for (int j = 0; j < res; ++j)
      for (int i = 0; i < res; ++i) {
        Vec3 p = p0;
        p(pl.u) = ball.center(pl.u) - ball.radius + i * step;
        p(pl.v) = ball.center(pl.v) - ball.radius + j * step;
        if (ball.contains(p))
          v[static_cast<size_t>(j) * res + i] = signed_singular_values(map.jacobian(p))(2);
      }
    for (double x : v)
      if (std::isfinite(x)) lo = std::min(lo, x), hi = std::max(hi, x);
    write_file_atomic(out.path(prefix + "slice_" + pl.name + ".dat"), [&](std::ostream& s) {
      s << "# "
        << "xyz"[pl.u] << ' ' << "xyz"[pl.v] << " sigma3 on the plane "
        << "xyz"[pl.fixed] << " = " << format_double(p0(pl.fixed)) << " (NaN outside the ball)\n";
      for (int j = 0; j < res; ++j) {
        for (int i = 0; i < res; ++i) {
          const double x = v[static_cast<size_t>(j) * res + i];
          s << format_double(ball.center(pl.u) - ball.radius + i * step) << ' '
            << format_double(ball.center(pl.v) - ball.radius + j * step) << ' '
            << (std::isfinite(x) ? format_double(x) : "NaN") << '\n';
        }
        s << '\n';
      }
    });
  }
  if (!(hi > lo)) hi = lo + 1;
  write_file_atomic(out.path(prefix + "slice.gp"), [&](std::ostream& s) {
    s << "# sigma3 on two slices through the ball (paper Fig. 2, right).\n"
      << "# Render with: gnuplot " << prefix << "slice.gp   (in this folder)\n"
      << "set terminal pngcairo enhanced size 1400,680 font 'sans,11'\n"
      << "set output '" << prefix << "slice.png'\n"
      << "set multiplot layout 1,2 title \"" << title << "\"\n"
      << "set size ratio -1\n"
      << "set cbrange [" << format_double(lo) << ":" << format_double(hi) << "]\nset cblabel 'sigma_3'\n"
      << "set palette defined (0 '#0d0887', 0.25 '#7e03a8', 0.5 '#cc4778', 0.75 '#f89540', 1 '#f0f921')\n"
      << "set key below\n";
    for (const Plane& pl : planes) {
      const double d = p0(pl.fixed) - ball.center(pl.fixed);
      const double rr = std::sqrt(std::max(0.0, ball.radius * ball.radius - d * d));
      s << "set title 'sigma_3 on the plane "
        << "xyz"[pl.fixed] << " = " << format_g(p0(pl.fixed)) << "'\n"
        << "set xlabel '"
        << "xyz"[pl.u] << "'\nset ylabel '"
        << "xyz"[pl.v] << "'\n"
        << "set xrange [" << format_double(ball.center(pl.u) - ball.radius) << ":"
        << format_double(ball.center(pl.u) + ball.radius) << "]\n"
        << "set yrange [" << format_double(ball.center(pl.v) - ball.radius) << ":"
        << format_double(ball.center(pl.v) + ball.radius) << "]\n"
        << "set object 1 circle at " << format_double(ball.center(pl.u)) << ","
        << format_double(ball.center(pl.v)) << " size " << format_double(rr)
        << " front fillstyle empty border lc rgb 'black' lw 1.5\n"
        << ""
        << "plot '" << prefix << "slice_" << pl.name << ".dat' using 1:2:3 with image notitle";
      if (m)
        s << ", '-' using 1:2 with points pt 7 ps 1.6 lc rgb '#00ff66' title sprintf('interior minimum, "
             "sigma_3 = %.6g', "
          << format_double(m->sigma3) << ")\n"
          << format_double(m->position(pl.u)) << ' ' << format_double(m->position(pl.v)) << "\ne\n";
      else
        s << "\n";
    }
    s << "unset multiplot\n";
  });
  return render_staged_png(out, prefix + "slice", " (install gnuplot-nox or set LIDEF_GNUPLOT)");
}

// The source ball and its image (Fig. 2, left and middle): the boundary sphere (icosphere, `subdivisions`)
// and its image, each triangle coloured by the mean σ3 of its corners, drawn by gnuplot (pm3d, depth-sorted).
// Returns the PNG's status note (empty when drawn).
std::string write_image_png(StagedOutputs& out, const std::string& prefix, const ExplorerMap& map,
                            const Ball& ball, int subdivisions) {
  TriMesh src = icosphere(ball.radius, subdivisions);
  src.V.rowwise() += ball.center.transpose();
  MatX3d img(src.V.rows(), 3);
  VecXd s3(src.V.rows());
  for (int i = 0; i < src.V.rows(); ++i) {
    const PolyJet j = map.jet(src.V.row(i).transpose());
    img.row(i) = j.f.transpose();
    s3(i) = signed_singular_values(j.J)(2);
  }
  for (const char* which : {"sphere", "image"}) {
    const MatX3d& V = std::string(which) == "sphere" ? src.V : img;
    write_file_atomic(out.path(prefix + which + "_tri.dat"), [&](std::ostream& f) {
      f << "# triangles of the " << which << " as degenerate pm3d quads: x y z mean_sigma3\n";
      for (int t = 0; t < src.F.rows(); ++t) {
        const double c = (s3(src.F(t, 0)) + s3(src.F(t, 1)) + s3(src.F(t, 2))) / 3;
        auto pt = [&](int k) {
          const int v = src.F(t, k);
          f << format_double(V(v, 0)) << ' ' << format_double(V(v, 1)) << ' ' << format_double(V(v, 2)) << ' '
            << format_double(c) << '\n';
        };
        pt(0);
        pt(1);
        f << '\n';
        pt(2);
        pt(2);
        f << "\n\n";
      }
    });
  }
  write_file_atomic(out.path(prefix + "image.gp"), [&](std::ostream& f) {
    f << "# The boundary sphere of the ball and its image, coloured by sigma3 (paper Fig. 2, left and "
         "middle).\n"
      << "# Render with: gnuplot " << prefix << "image.gp   (in this folder)\n"
      << "set terminal pngcairo enhanced size 1400,680 font 'sans,11'\n"
      << "set output '" << prefix << "image.png'\n"
      << "set multiplot layout 1,2 title 'the unit ball and its image, coloured by sigma_3 on the boundary'\n"
      << "set view equal xyz\nset view 65, 30\nunset border\nunset tics\nset cbtics\nunset key\n"
      << "set pm3d depthorder border lc rgb '#404040' lw 0.2\n"
      << "set palette defined (0 '#0d0887', 0.25 '#7e03a8', 0.5 '#cc4778', 0.75 '#f89540', 1 '#f0f921')\n"
      << "set cbrange [" << format_double(s3.minCoeff()) << ":"
      << format_double(std::max(s3.maxCoeff(), s3.minCoeff() + 1e-12)) << "]\n"
      << "set cblabel 'sigma_3'\n"
      << "set title 'source: the ball'\nsplot '" << prefix << "sphere_tri.dat' using 1:2:3:4 with pm3d\n"
      << "set title 'image f(ball)'\nsplot '" << prefix << "image_tri.dat' using 1:2:3:4 with pm3d\n"
      << "unset multiplot\n";
  });
  return render_staged_png(out, prefix + "image", "");
}

// --- explore show: one map through the checks of docs/explorer.md ("Why verified ..."), then its files.

struct ShowResult {
  bool verified = false;
  ojson summary;
};

// The checks' results of one map (null/empty: not run).
struct ShowChecks {
  std::vector<Sigma3Minimum> minima;
  int best = -1;  // index of the lowest strict minimum in minima, or -1
  std::pair<double, Vec3> sphere_min;
  std::optional<BallCertificate> local_injectivity, boundary_above_minimum;
  std::optional<BoundaryInjectivity> boundary_injectivity;
  BoundaryEmbedding embedding;

  const Sigma3Minimum* best_minimum() const { return best < 0 ? nullptr : &minima[best]; }
  CounterexampleVerdict verdict() const {
    CounterexampleChecks c;
    c.minimum = best_minimum();
    c.local_injectivity = local_injectivity ? &*local_injectivity : nullptr;
    c.boundary_above_minimum = boundary_above_minimum ? &*boundary_above_minimum : nullptr;
    c.boundary_injectivity = boundary_injectivity ? &*boundary_injectivity : nullptr;
    c.boundary_embedding = &embedding;
    return counterexample_verdict(c);
  }
};

// Step: interior minima of σ3 and the sampled minimum on the boundary sphere; their summary entries.
void find_minima_step(const ExplorerExample& ex, const ShowOptions& o, const std::string& tag, ShowChecks& c,
                      ojson& s) {
  const ExplorerMap& map = *ex.map;
  const Ball& ball = ex.ball;
  std::cerr << tag << ": interior minima of sigma3 (" << o.starts << " starts)...\n";
  MinimaSearchParams mp;
  mp.starts = o.starts;
  mp.seed = o.seed;
  c.minima = find_sigma3_minima(map, ball, mp);
  const Sigma3Minimum* best = lowest_strict_minimum(c.minima);
  c.best = best ? static_cast<int>(best - c.minima.data()) : -1;
  c.sphere_min = sampled_sphere_min_sigma3(map, ball, 4);

  s["map"] = map.description();
  s["note"] = ex.note;
  s["domain"] = {{"center", vec_json(ball.center)}, {"radius", ball.radius}};
  s["minima_found"] = c.minima.size();
  s["strict_minima"] =
      std::count_if(c.minima.begin(), c.minima.end(), [](const Sigma3Minimum& m) { return m.strict; });
  s["sphere_min_sigma3_sampled"] = c.sphere_min.first;
  s["sphere_min_point_sampled"] = vec_json(c.sphere_min.second);
  if (best) {
    s["minimum"] = {{"position", vec_json(best->position)},
                    {"sigma3", best->sigma3},
                    {"gradient_norm", best->gradient_norm},
                    {"hessian_eigenvalues", vec_json(best->hessian_eigenvalues)},
                    {"sphere_radius", best->sphere_radius},
                    {"sphere_min_sigma3", best->sphere_min_sigma3},
                    {"sigma3_gap", best->gap}};
  } else {
    s["minimum"] = nullptr;
  }
}

ojson boundary_injectivity_json(const BoundaryInjectivity& bi) {
  return {
      {"certified", bi.certified},
      {"reason", bi.reason},
      {"sigma3_lower", bi.sigma3_lower},
      {"hessian_bound", bi.hessian_bound},
      {"jacobian_bound", bi.jacobian_bound},
      {"rho", bi.rho},
      {"subdivisions", bi.subdivisions},
      {"triangles", bi.triangles},
      {"pairs_measured", bi.pairs_measured},
      {"max_delta", bi.max_delta},
      {"min_pair_margin", std::isfinite(bi.min_pair_margin) ? ojson(bi.min_pair_margin) : ojson(nullptr)}};
}

// Step (polynomial maps): σ3 > 0 on the ball, injectivity on the sphere, σ3 above the minimum on the sphere.
void certify_polynomial_step(const HarmonicPolynomialMap& poly, const Ball& ball, const ShowOptions& o,
                             const std::string& tag, ShowChecks& c, ojson& s) {
  const Sigma3Minimum* best = c.best_minimum();
  std::cerr << tag << ": certifying sigma3 > 0 on the ball...\n";
  BallCertifyParams cp;
  cp.max_depth = o.max_depth;
  c.local_injectivity = certify_sigma3_on_ball(poly, ball, cp);
  s["local_injectivity"] = certificate_json(*c.local_injectivity);
  if (c.local_injectivity->certified) {
    const double t = boundary_injectivity_threshold(*c.local_injectivity, best);
    std::cerr << tag << ": certifying injectivity on the boundary sphere (net of " << o.net_subdivisions
              << " subdivisions, sigma3 > " << format_g(t) << ")...\n";
    c.boundary_injectivity = certify_boundary_injective(poly, ball, t, o.net_subdivisions, o.max_depth);
    s["boundary_injectivity"] = boundary_injectivity_json(*c.boundary_injectivity);
  } else {
    s["boundary_injectivity"] = nullptr;
  }
  if (best && best->sigma3 > 0) {
    std::cerr << tag << ": certifying sigma3 > " << format_g(best->sigma3) << " on the boundary sphere...\n";
    cp.threshold = best->sigma3;
    cp.sphere_only = true;
    c.boundary_above_minimum = certify_sigma3_on_ball(poly, ball, cp);
    s["boundary_above_minimum"] = certificate_json(*c.boundary_above_minimum);
  } else {
    s["boundary_above_minimum"] = nullptr;
  }
}

// Step (cage maps): the project's certificate on cubes covering the ball; no bound on the sphere (it
// certifies σ3 > 0 only), so a cage map is never a verified counterexample.
void certify_cage_step(const CageExplorerMap& map, const Ball& ball, const ShowOptions& o,
                       const std::string& tag, ShowChecks& c, ojson& s) {
  std::cerr << tag << ": certifying sigma3 > 0 on the ball (lidef certify's bounds)...\n";
  c.local_injectivity = certify_cage_map_on_ball(map, ball, std::min(o.max_depth, 6));
  s["local_injectivity"] = certificate_json(*c.local_injectivity);
  s["boundary_injectivity"] = nullptr;
  s["boundary_above_minimum"] = nullptr;
}

// Step: the triangulated boundary image's self-intersections.
void embedding_step(const ExplorerExample& ex, const ShowOptions& o, const std::string& tag, ShowChecks& c,
                    ojson& s) {
  std::cerr << tag << ": boundary sphere image (" << o.sphere_subdivisions
            << " subdivisions) self-intersections...\n";
  c.embedding = check_boundary_embedding(*ex.map, ex.ball, o.sphere_subdivisions);
  const BoundaryEmbedding& be = c.embedding;
  s["boundary_embedding"] = {{"embedded", be.embedded},
                             {"subdivisions", be.subdivisions},
                             {"triangles", be.image.F.rows()},
                             {"intersecting_pairs", be.intersecting_pairs},
                             {"min_image_edge", be.min_image_edge},
                             {"image_volume", be.signed_volume}};
}

// Step: the files of one map (prefix + map.json, minima.csv, fields.vti, sphere.vtp, image.vtp, slice and
// image pictures, summary.json).
void write_show_files(StagedOutputs& out, const std::string& prefix, const ExplorerExample& ex,
                      const ShowOptions& o, const std::string& tag, const std::string& map_json,
                      const ShowChecks& c, ojson& s) {
  const ExplorerMap& map = *ex.map;
  const Ball& ball = ex.ball;
  const Sigma3Minimum* best = c.best_minimum();
  const BoundaryEmbedding& be = c.embedding;
  write_file_atomic(out.path(prefix + "map.json"), [&](std::ostream& f) { f << map_json; });
  write_minima_csv(out.path(prefix + "minima.csv"), c.minima);
  std::cerr << tag << ": fields on a " << o.grid << "^3 grid...\n";
  write_ball_fields_vti(out.path(prefix + "fields.vti"), compute_ball_fields(map, ball, o.grid));
  VecXd s1(be.source.V.rows()), s3(be.source.V.rows());
  for (int i = 0; i < be.source.V.rows(); ++i) {
    const Vec3 sv = signed_singular_values(map.jacobian(be.source.V.row(i).transpose()));
    s1(i) = sv(0);
    s3(i) = sv(2);
  }
  write_mesh_vtp(out.path(prefix + "sphere.vtp"), be.source.V, be.source.F, {{"sigma3", s3}, {"sigma1", s1}});
  write_mesh_vtp(out.path(prefix + "image.vtp"), be.image.V, be.image.F, {{"sigma3", s3}, {"sigma1", s1}});
  const std::string title = best
                                ? "interior minimum of sigma_3 at (" + format_g(best->position.x()) + ", " +
                                      format_g(best->position.y()) + ", " + format_g(best->position.z()) + ")"
                                : "no strict interior minimum found";
  const std::string note = write_slice(out, prefix, map, ball, best, o.slice_resolution, title);
  if (!note.empty()) std::cerr << tag << ": warning: " << note << "\n";
  s["slice_png"] = note.empty() ? ojson(prefix + "slice.png") : ojson(note);
  const std::string inote = write_image_png(out, prefix, map, ball, std::min(3, o.sphere_subdivisions));
  if (!inote.empty()) std::cerr << tag << ": warning: " << inote << "\n";
  s["image_png"] = inote.empty() ? ojson(prefix + "image.png") : ojson(inote);
  write_file_atomic(out.path(prefix + "summary.json"), [&](std::ostream& f) { f << s.dump(2) << "\n"; });
}

// The `show` pipeline for one map: minima, certificates, embedding, verdict, files.
ShowResult show_map(StagedOutputs& out, const std::string& prefix, const ExplorerExample& ex,
                    const ShowOptions& o, const std::string& tag, const std::string& map_json) {
  ShowChecks c;
  ojson s;
  find_minima_step(ex, o, tag, c, s);
  if (const HarmonicPolynomialMap* poly = ex.polynomial())
    certify_polynomial_step(*poly, ex.ball, o, tag, c, s);
  else
    certify_cage_step(dynamic_cast<const CageExplorerMap&>(*ex.map), ex.ball, o, tag, c, s);
  embedding_step(ex, o, tag, c, s);
  ShowResult r;
  r.verified = c.verdict().verified;
  s["verified_counterexample"] = r.verified;
  write_show_files(out, prefix, ex, o, tag, map_json, c, s);
  r.summary = s;
  return r;
}

void print_show_summary(const ojson& s, const std::string& tag) {
  std::cout << tag << ": " << s["map"].get<std::string>() << "\n";
  if (!s["minimum"].is_null()) {
    const ojson& m = s["minimum"];
    std::cout << "  interior minimum of sigma3 " << format_g(m["sigma3"].get<double>()) << " at ("
              << format_g(m["position"][0].get<double>()) << ", " << format_g(m["position"][1].get<double>())
              << ", " << format_g(m["position"][2].get<double>()) << "), Hessian eigenvalues "
              << format_g(m["hessian_eigenvalues"][0].get<double>()) << ", "
              << format_g(m["hessian_eigenvalues"][1].get<double>()) << ", "
              << format_g(m["hessian_eigenvalues"][2].get<double>()) << "\n";
  } else {
    std::cout << "  no strict interior minimum of sigma3 found\n";
  }
  std::cout << "  min sigma3 on the boundary sphere (sampled) "
            << format_g(s["sphere_min_sigma3_sampled"].get<double>()) << "\n";
  const ojson& li = s["local_injectivity"];
  std::cout << "  local injectivity on the ball: "
            << (li["certified"].get<bool>() ? "certified" : "NOT certified");
  if (li.contains("min_lower_bound") && !li["min_lower_bound"].is_null())
    std::cout << " (sigma3 >= " << format_bound(li["min_lower_bound"].get<double>(), false) << ", "
              << li["leaves"].get<long>() << " cells)";
  if (!li["reason"].get<std::string>().empty()) std::cout << ": " << li["reason"].get<std::string>();
  std::cout << "\n";
  if (!s["boundary_above_minimum"].is_null()) {
    const ojson& b = s["boundary_above_minimum"];
    std::cout << "  sigma3 > interior minimum on the whole sphere: "
              << (b["certified"].get<bool>() ? "certified" : "NOT certified");
    if (!b["min_lower_bound"].is_null())
      std::cout << " (sigma3 >= " << format_bound(b["min_lower_bound"].get<double>(), false) << " there)";
    std::cout << "\n";
  }
  if (!s["boundary_injectivity"].is_null()) {
    const ojson& b = s["boundary_injectivity"];
    std::cout << "  injective on the boundary sphere: "
              << (b["certified"].get<bool>() ? "certified" : "NOT certified");
    if (b["certified"].get<bool>())
      std::cout << " (rho " << format_g(b["rho"].get<double>()) << ", " << b["triangles"].get<long>()
                << " triangles, " << b["pairs_measured"].get<long>() << " pairs measured)";
    else
      std::cout << ": " << b["reason"].get<std::string>();
    std::cout << "\n";
  }
  const ojson& e = s["boundary_embedding"];
  std::cout << "  boundary image: " << (e["embedded"].get<bool>() ? "embedded" : "NOT embedded") << " ("
            << e["triangles"].get<long>() << " triangles, " << e["intersecting_pairs"].get<long>()
            << " intersecting pairs)\n";
  std::cout << "  verdict: "
            << (s["verified_counterexample"].get<bool>()
                    ? "verified counterexample (bijective harmonic map, sigma3 minimum in the interior)"
                    : "not a verified counterexample")
            << "\n";
}

std::string json_for_example(const ExplorerExample& ex) {
  if (const HarmonicPolynomialMap* p = ex.polynomial()) return explorer_example_json(*p, ex.ball, ex.note);
  // Cage maps: the same file with absolute paths, so that it loads from anywhere.
  auto abs = [](const std::string& p) {
    return p == "identity" ? p : fs::absolute(p).lexically_normal().string();
  };
  ojson j;
  j["format"] = "lidef-explorer-map";
  j["type"] = "cage";
  j["note"] = ex.note;
  j["model"] = abs(ex.cage_model);
  j["coefficients"] = abs(ex.cage_coefficients);
  j["domain"] = {{"center", vec_json(ex.ball.center)}, {"radius", ex.ball.radius}};
  return j.dump(2) + "\n";
}

void add_show_options(CLI::App* sub, ShowOptions& o) {
  sub->add_option("--starts", o.starts,
                  "Starts of the local minimization of sigma3 (the center + random points)")
      ->capture_default_str();
  sub->add_option("--grid", o.grid, "Points per axis of fields.vti over the ball's bounding cube")
      ->capture_default_str();
  sub->add_option(
         "--sphere-subdivisions", o.sphere_subdivisions,
         "Icosphere subdivisions of the boundary sphere for the embedding check and image.vtp (1..7)")
      ->capture_default_str();
  sub->add_option("--max-depth", o.max_depth, "Subdivision levels of the ball certificate's cells (0..12)")
      ->capture_default_str();
  sub->add_option("--net-subdivisions", o.net_subdivisions,
                  "Icosphere subdivisions of the net of the boundary-injectivity certificate (1..8)")
      ->capture_default_str();
}

void set_threads(int threads) {
  if (threads < 0) throw InputError("--threads", "must be >= 0");
  if (threads > 0) omp_set_num_threads(threads);
}

// --- explore show FILE --out DIR

struct ShowCommandOptions {
  std::string file, out;
  ShowOptions show;
  int threads = 0;
};

int run_show(const ShowCommandOptions& o) {
  check_show_options(o.show);
  set_threads(o.threads);
  const ExplorerExample example = read_explorer_example(o.file);
  StagedOutputs out(o.out);
  const ShowResult r = show_map(out, "", example, o.show, "lidef explore show", json_for_example(example));
  out.commit();
  print_show_summary(r.summary, "lidef explore show");
  std::cout << "  wrote " << out.final_path("")
            << "{map.json, minima.csv, fields.vti, sphere.vtp, image.vtp, "
            << "slice.png, image.png, summary.json}\n";
  return r.verified ? kOk : kNotCertified;
}

void add_show_subcommand(CLI::App* ex, Action& action) {
  auto o = std::make_shared<ShowCommandOptions>();
  auto* sub =
      ex->add_subcommand("show", "Study one map file: minima of sigma3, certificate, boundary, pictures");
  sub->add_option("EXAMPLE", o->file,
                  "Map file (JSON, docs/explorer.md), e.g. data/explorer/sigma3_interior_min.json")
      ->required();
  sub->add_option("--out", o->out, "Output folder (created if missing)")->required();
  add_show_options(sub, o->show);
  sub->add_option("--seed", o->show.seed, "Seed of the random starts")->capture_default_str();
  sub->add_option("--threads", o->threads, "OpenMP threads (0 = all cores)")->capture_default_str();

  sub->footer(
      "Writes map.json, minima.csv (position, sigma3, Hessian eigenvalues, small-sphere check),\n"
      "fields.vti (sigma1..3, detJ on a grid over the ball), sphere.vtp and image.vtp (the boundary sphere "
      "and\n"
      "its image), slice.png (sigma3 on the planes z = z_min and y = y_min through the minimum; slice.gp,\n"
      "slice_xy.dat, slice_xz.dat), image.png (the ball and its image coloured by sigma3; image.gp, "
      "*_tri.dat)\n"
      "and summary.json. PNGs need gnuplot ($LIDEF_GNUPLOT or PATH; skipped with a warning otherwise).\n"
      "Exit code: 0 verified counterexample (strict interior minimum, sigma3 > 0 certified on the ball,\n"
      "sigma3 > the minimum certified on the sphere, injectivity on the sphere certified, triangulated "
      "boundary\n"
      "image embedded), 1 not verified, 2 error.");
  sub->callback([o, &action] { action = [o] { return run_show(*o); }; });
}

// --- explore search --out DIR

struct SearchCommandOptions {
  std::string out;
  int degree = 4, trials = 200, verify = 3, threads = 0;
  unsigned long long seed = 1;
  double amplitude = 0.6;
  std::string family = "random";
  ShowOptions show;
};

void check_search_options(const SearchCommandOptions& o) {
  check_show_options(o.show);
  if (o.degree < 2 || o.degree > kMaxHarmonicDegree)
    throw InputError("--degree", "must be in 2.." + std::to_string(kMaxHarmonicDegree) + " (got " +
                                     std::to_string(o.degree) + ")");
  if (o.family != "random" && o.family != "twist")
    throw InputError("--family", "must be 'random' or 'twist' (got '" + o.family + "')");
  if (o.family == "twist" && o.degree < 3)
    throw InputError("--degree", "the twist family needs degree 3 or 4");
  if (o.trials < 1 || o.trials > 1000000) throw InputError("--trials", "must be in 1..1000000");
  if (o.verify < 0 || o.verify > 1000) throw InputError("--verify", "must be in 0..1000");
  if (!(o.amplitude >= 0) || !std::isfinite(o.amplitude) || o.amplitude > 10)
    throw InputError("--amplitude", "must be in 0..10");
}

// The note of a search trial's map file.
std::string search_note(const SearchCommandOptions& o, int trial) {
  return "lidef explore search --family " + o.family + " --degree " + std::to_string(o.degree) +
         " --amplitude " + format_double(o.amplitude) + " --seed " + std::to_string(o.seed) + ": trial " +
         std::to_string(trial);
}

std::vector<SearchTrial> run_trials(const SearchCommandOptions& o) {
  SearchParams sp;
  sp.family = o.family == "twist" ? SearchFamily::kTwist : SearchFamily::kRandom;
  sp.degree = o.degree;
  sp.trials = o.trials;
  sp.seed = o.seed;
  sp.max_amplitude = o.amplitude;
  sp.minima.starts = o.show.starts;
  const int every = std::max(1, o.trials / 10);
  return search_sigma3_minima(sp, [&](int done) {
    if (done % every == 0 || done == o.trials)
      std::cerr << "lidef explore search: " << done << "/" << o.trials << " maps\n";
  });
}

struct SearchCounts {
  int with_min = 0, with_strict = 0, positive = 0, candidates = 0;
};

SearchCounts count_trials(const std::vector<SearchTrial>& trials) {
  SearchCounts n;
  for (const SearchTrial& t : trials) {
    n.with_min += !t.minima.empty();
    n.with_strict += t.strict_minima > 0;
    bool pos = false;
    for (const Sigma3Minimum& m : t.minima) pos = pos || (m.strict && m.sigma3 > 0);
    n.positive += pos;
    n.candidates += t.candidate;
  }
  return n;
}

void write_trial_tables(StagedOutputs& out, const std::vector<SearchTrial>& trials) {
  write_file_atomic(out.path("trials.csv"), [&](std::ostream& s) {
    s << "trial,seed,interior_minima,strict_minima,lowest_minimum_sigma3,sphere_min_sigma3_sampled,"
         "candidate,"
         "candidate_gap\n";
    for (const SearchTrial& t : trials)
      s << t.trial << ',' << t.seed << ',' << t.minima.size() << ',' << t.strict_minima << ','
        << (t.minima.empty() ? "NaN" : format_double(t.minima[0].sigma3)) << ','
        << format_double(t.sphere_min_sigma3) << ',' << (t.candidate ? 1 : 0) << ','
        << format_double(t.candidate_gap) << '\n';
  });
  write_file_atomic(out.path("minima.csv"), [&](std::ostream& s) {
    s << "trial,x,y,z,sigma3,hessian_eig1,hessian_eig2,hessian_eig3,sphere_min_sigma3,strict\n";
    for (const SearchTrial& t : trials)
      for (const Sigma3Minimum& m : t.minima)
        s << t.trial << ',' << format_double(m.position.x()) << ',' << format_double(m.position.y()) << ','
          << format_double(m.position.z()) << ',' << format_double(m.sigma3) << ','
          << format_double(m.hessian_eigenvalues(0)) << ',' << format_double(m.hessian_eigenvalues(1)) << ','
          << format_double(m.hessian_eigenvalues(2)) << ',' << format_double(m.sphere_min_sigma3) << ','
          << (m.strict ? 1 : 0) << '\n';
  });
}

// The candidates to verify: the `verify` ones with the largest relative gap between the sphere and the
// interior minimum.
std::vector<int> candidates_to_verify(const std::vector<SearchTrial>& trials, int verify) {
  std::vector<int> order;
  for (const SearchTrial& t : trials)
    if (t.candidate) order.push_back(t.trial);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return trials[a].candidate_gap > trials[b].candidate_gap; });
  if (static_cast<int>(order.size()) > verify) order.resize(verify);
  return order;
}

// Verifies one candidate (the checks of `show` but the pictures, each run only while the previous ones
// hold); returns its entry of summary.json's "verified" list.
ojson verify_candidate(const SearchTrial& tr, const ShowOptions& o) {
  const Ball ball;
  const PolynomialExplorerMap m(tr.map);
  // A candidate has a strict interior minimum with σ3 > 0 (SearchTrial::candidate): the lowest one is x*.
  const Sigma3Minimum* x_star = lowest_strict_minimum(tr.minima);
  BallCertifyParams cp;
  cp.max_depth = o.max_depth;
  std::cerr << "lidef explore search: verifying trial " << tr.trial << "...\n";
  const BallCertificate c = certify_sigma3_on_ball(tr.map, ball, cp);
  cp.threshold = x_star->sigma3;
  cp.sphere_only = true;
  std::optional<BallCertificate> sc;
  std::optional<BoundaryEmbedding> be;
  std::optional<BoundaryInjectivity> bi;
  if (c.certified) sc = certify_sigma3_on_ball(tr.map, ball, cp);
  if (sc && sc->certified) be = check_boundary_embedding(m, ball, o.sphere_subdivisions);
  if (be && be->embedded)
    bi = certify_boundary_injective(tr.map, ball, boundary_injectivity_threshold(c, x_star),
                                    o.net_subdivisions, o.max_depth);
  CounterexampleChecks checks;
  checks.minimum = x_star;
  checks.local_injectivity = &c;
  checks.boundary_above_minimum = sc ? &*sc : nullptr;
  checks.boundary_embedding = be ? &*be : nullptr;
  checks.boundary_injectivity = bi ? &*bi : nullptr;
  return {{"trial", tr.trial},
          {"local_injectivity_certified", c.certified},
          {"boundary_above_minimum_certified", sc && sc->certified},
          {"boundary_injectivity_certified", bi && bi->certified},
          {"boundary_embedded", be && be->embedded},
          {"verified", counterexample_verdict(checks).verified}};
}

// The trial shown with `show`'s files: the first verified one, else the best candidate, else the first with a
// strict interior minimum, else trial 0 (so that the pictures and fields always exist).
int shown_trial(int first_verified, const std::vector<int>& order, const std::vector<SearchTrial>& trials) {
  int best_trial = first_verified;
  if (best_trial < 0 && !order.empty()) best_trial = order[0];
  for (const SearchTrial& t : trials)
    if (best_trial < 0 && t.strict_minima > 0) best_trial = t.trial;
  if (best_trial < 0) best_trial = 0;
  return best_trial;
}

ojson search_summary_json(const SearchCommandOptions& o, const SearchCounts& n, const ojson& verified,
                          int best_trial) {
  ojson s;
  s["family"] = o.family;
  s["degree"] = o.degree;
  s["trials"] = o.trials;
  s["seed"] = o.seed;
  s["amplitude"] = o.amplitude;
  s["starts"] = o.show.starts;
  s["maps_with_interior_critical_minimum"] = n.with_min;
  s["maps_with_strict_interior_minimum"] = n.with_strict;
  s["maps_with_strict_interior_minimum_sigma3_positive"] = n.positive;
  s["candidates"] = n.candidates;
  s["candidate_fraction"] = static_cast<double>(n.candidates) / o.trials;
  s["verified"] = verified;
  s["best_trial"] = best_trial;
  return s;
}

void print_search_summary(const SearchCommandOptions& o, const SearchCounts& n, const ojson& s,
                          size_t verified_candidates, const StagedOutputs& out) {
  std::cout << "lidef explore search: " << o.trials << " " << o.family << " degree-" << o.degree
            << " maps (seed " << o.seed << "): " << n.with_strict
            << " with a strict interior minimum of sigma3, " << n.positive
            << " of them with sigma3 > 0 there, " << n.candidates
            << " candidates (minimum below every sampled boundary value)\n";
  std::cout << "  verified counterexamples among the " << verified_candidates << " best candidates: ";
  int nv = 0;
  for (const auto& v : s["verified"]) nv += v["verified"].get<bool>();
  std::cout << nv << "\n";
  const int best_trial = s["best_trial"].get<int>();
  if (best_trial >= 0) print_show_summary(s["best"], "  best (trial " + std::to_string(best_trial) + ")");
  std::cout << "  wrote " << out.final_path("") << "{trials.csv, minima.csv, summary.json, best_*}\n";
}

int run_search(const SearchCommandOptions& o) {
  check_search_options(o);
  set_threads(o.threads);
  StagedOutputs out(o.out);
  const std::vector<SearchTrial> trials = run_trials(o);
  const SearchCounts counts = count_trials(trials);
  write_trial_tables(out, trials);

  const std::vector<int> order = candidates_to_verify(trials, o.verify);
  ojson verified = ojson::array();
  int first_verified = -1;
  for (int t : order) {
    verified.push_back(verify_candidate(trials[t], o.show));
    if (verified.back()["verified"].get<bool>()) {
      write_file_atomic(out.path("candidate_" + std::to_string(t) + ".json"), [&](std::ostream& s) {
        s << explorer_example_json(trials[t].map, Ball(), search_note(o, t));
      });
      if (first_verified < 0) first_verified = t;
    }
  }
  const int best_trial = shown_trial(first_verified, order, trials);
  ojson s = search_summary_json(o, counts, verified, best_trial);

  ExplorerExample ex;
  ex.kind = "harmonic_polynomial";
  ex.note = search_note(o, best_trial);
  ex.map = std::make_shared<PolynomialExplorerMap>(trials[best_trial].map);
  const ShowResult r = show_map(out, "best_", ex, o.show, "lidef explore search",
                                explorer_example_json(trials[best_trial].map, ex.ball, ex.note));
  s["best"] = r.summary;
  write_file_atomic(out.path("summary.json"), [&](std::ostream& f) { f << s.dump(2) << "\n"; });
  out.commit();
  print_search_summary(o, counts, s, order.size(), out);
  return r.verified ? kOk : kNotCertified;
}

void add_search_subcommand(CLI::App* ex, Action& action) {
  auto o = std::make_shared<SearchCommandOptions>();
  auto* sub = ex->add_subcommand("search",
                                 "Random harmonic polynomial maps: how often sigma3 has an interior minimum");
  sub->add_option(
         "--family", o->family,
         "'random' (random linear part + random harmonic terms) or 'twist' (random perturbations of the "
         "constructed twist family; degree 3..4)")
      ->capture_default_str();
  sub->add_option("--degree", o->degree, "Polynomial degree D of the random maps (2..4)")
      ->capture_default_str();
  sub->add_option("--trials", o->trials, "Number of random maps")->capture_default_str();
  sub->add_option("--seed", o->seed, "Seed (results do not depend on the thread count)")
      ->capture_default_str();
  sub->add_option("--amplitude", o->amplitude, "Largest amplitude of the non-affine part (docs/explorer.md)")
      ->capture_default_str();
  sub->add_option("--verify", o->verify, "Candidates (best first) to certify and check for embedding")
      ->capture_default_str();
  add_show_options(sub, o->show);
  sub->add_option("--threads", o->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  sub->add_option("--out", o->out, "Output folder (created if missing)")->required();
  sub->footer(
      "Writes trials.csv (one row per map), minima.csv (every interior minimum found), summary.json\n"
      "(counts and frequencies), candidate_<trial>.json for each verified candidate, and the files of\n"
      "'lidef explore show' prefixed best_ for the best candidate (else the first map with a strict "
      "interior\n"
      "minimum, else map 0). Exit code: 0 a verified counterexample was found, 1 none, 2 error.");
  sub->callback([o, &action] { action = [o] { return run_search(*o); }; });
}

// --- explore construct --out FILE

struct ConstructCommandOptions {
  std::string out;
  std::vector<double> sigma{1.6, 1.3, 0.5};
  double twist = 0.5, cubic = 0.05;
};

int run_construct(const ConstructCommandOptions& o) {
  const std::vector<double>& s = o.sigma;
  for (double v : s)
    if (!std::isfinite(v)) throw InputError("--sigma", "must be finite numbers");
  if (!(s[0] > s[1] && s[1] > s[2] && s[2] > 0)) throw InputError("--sigma", "needs s1 > s2 > s3 > 0");
  if (!std::isfinite(o.twist) || !std::isfinite(o.cubic))
    throw InputError("--twist/--cubic", "must be finite");
  const HarmonicPolynomialMap m = twist_example(Vec3(s[0], s[1], s[2]), o.twist, o.cubic, 4);
  const std::string note =
      "twist example: sigma = (" + format_double(s[0]) + ", " + format_double(s[1]) + ", " +
      format_double(s[2]) + "), twist c = " + format_double(o.twist) +
      ", cubic d = " + format_double(o.cubic) +
      "; f = (s1 x + c x z, s2 y - c y z, s3 z + (c/2)(y^2 - x^2) + d (z^3 - 1.5 z (x^2 + y^2)))";
  write_file_atomic(o.out, [&](std::ostream& f) { f << explorer_example_json(m, Ball(), note); });
  std::cout << "lidef explore construct: wrote " << o.out << "\n";
  return kOk;
}

void add_construct_subcommand(CLI::App* ex, Action& action) {
  auto o = std::make_shared<ConstructCommandOptions>();
  auto* sub =
      ex->add_subcommand("construct", "Write the constructed twist counterexample family as a map file");
  sub->add_option("--sigma", o->sigma, "Singular values s1 > s2 > s3 > 0 of J at the center")
      ->expected(3)
      ->delimiter(',')
      ->capture_default_str();
  sub->add_option("--twist", o->twist, "Twist c (raises sigma3 in x and y)")->capture_default_str();
  sub->add_option("--cubic", o->cubic, "Cubic weight d (raises sigma3 in z)")->capture_default_str();
  sub->add_option("--out", o->out, "Map file to write (JSON)")->required();
  sub->footer(
      "f(x,y,z) = (s1 x + c x z, s2 y - c y z, s3 z + (c/2)(y^2 - x^2) + d (z^3 - 1.5 z (x^2 + y^2))):\n"
      "grad sigma3 = 0 at the center, Hessian diag(2c^2/(s3+s1) - 3d, 2c^2/(s3+s2) - 3d, 6d) "
      "(docs/explorer.md).\n"
      "Check the result with 'lidef explore show FILE --out DIR'.");
  sub->callback([o, &action] { action = [o] { return run_construct(*o); }; });
}

// --- explore laplacian --out DIR

struct LaplacianCommandOptions {
  std::string out;
  int degree = 4, maps = 100, points = 100, threads = 0;
  unsigned long long seed = 1;
  double amplitude = 0.6;
};

void check_laplacian_options(const LaplacianCommandOptions& o) {
  if (o.degree < 2 || o.degree > kMaxHarmonicDegree)
    throw InputError("--degree", "must be in 2.." + std::to_string(kMaxHarmonicDegree));
  if (o.maps < 1 || o.maps > 100000) throw InputError("--maps", "must be in 1..100000");
  if (o.points < 1 || o.points > 100000) throw InputError("--points", "must be in 1..100000");
  if (!(o.amplitude >= 0) || !std::isfinite(o.amplitude) || o.amplitude > 10)
    throw InputError("--amplitude", "must be in 0..10");
}

// Counts over the points with simple singular values (gap > 1e-3; the formulas need them).
struct LaplacianStats {
  long n = 0, s1neg = 0, s3pos = 0, s3pos_det = 0, det_pos = 0;
  double min_l1 = INFINITY, max_l3 = -INFINITY, max_fd = 0;
};

LaplacianStats laplacian_stats(const std::vector<LaplacianSample>& L) {
  LaplacianStats st;
  for (const LaplacianSample& q : L) {
    if (!(q.gap > 1e-3)) continue;  // the formulas need simple singular values
    ++st.n;
    st.s1neg += q.lap_sigma1 < 0;
    st.s3pos += q.lap_sigma3 > 0;
    st.det_pos += q.sigma(2) > 0;
    st.s3pos_det += q.lap_sigma3 > 0 && q.sigma(2) > 0;
    st.min_l1 = std::min(st.min_l1, q.lap_sigma1);
    st.max_l3 = std::max(st.max_l3, q.lap_sigma3);
    // Finite differences (step 1e-3) are only meaningful well away from repeated singular values.
    if (q.gap > 0.05)
      st.max_fd =
          std::max({st.max_fd, std::abs(q.lap_sigma1 - q.lap_sigma1_fd) / (1 + std::abs(q.lap_sigma1)),
                    std::abs(q.lap_sigma3 - q.lap_sigma3_fd) / (1 + std::abs(q.lap_sigma3))});
  }
  return st;
}

void write_laplacian_csv(const std::string& path, const std::vector<LaplacianSample>& L) {
  write_file_atomic(path, [&](std::ostream& s) {
    s << "map,x,y,z,sigma1,sigma2,sigma3,lap_sigma1,lap_sigma1_fd,lap_sigma3,lap_sigma3_fd,lap_sigma3_"
         "sym,"
         "lap_sigma3_anti,gap\n";
    for (const LaplacianSample& q : L)
      s << q.map << ',' << format_double(q.p.x()) << ',' << format_double(q.p.y()) << ','
        << format_double(q.p.z()) << ',' << format_double(q.sigma(0)) << ',' << format_double(q.sigma(1))
        << ',' << format_double(q.sigma(2)) << ',' << format_double(q.lap_sigma1) << ','
        << format_double(q.lap_sigma1_fd) << ',' << format_double(q.lap_sigma3) << ','
        << format_double(q.lap_sigma3_fd) << ',' << format_double(q.lap_sigma3_sym) << ','
        << format_double(q.lap_sigma3_anti) << ',' << format_double(q.gap) << '\n';
  });
}

ojson laplacian_summary_json(const LaplacianCommandOptions& o, const LaplacianStats& st, size_t samples) {
  ojson s;
  s["degree"] = o.degree;
  s["maps"] = o.maps;
  s["points_per_map"] = o.points;
  s["seed"] = o.seed;
  s["amplitude"] = o.amplitude;
  s["points_used"] = st.n;
  s["points_skipped_small_gap"] = static_cast<long>(samples) - st.n;
  s["lap_sigma1_negative"] = st.s1neg;
  s["lap_sigma1_min"] = st.min_l1;
  s["lap_sigma3_positive"] = st.s3pos;
  s["lap_sigma3_positive_fraction"] = st.n ? static_cast<double>(st.s3pos) / st.n : 0.0;
  s["points_det_positive"] = st.det_pos;
  s["lap_sigma3_positive_det_positive"] = st.s3pos_det;
  s["lap_sigma3_max"] = st.max_l3;
  s["max_rel_difference_exact_vs_fd_gap_above_0.05"] = st.max_fd;
  return s;
}

// Where Δσ3 > 0: the antisymmetric (≥ 0) against the symmetric (≤ 0) part, log-log, with the diagonal
// (laplacian_plot.dat, laplacian.gp, laplacian.png). Returns the PNG's status note (empty when drawn).
std::string write_laplacian_plot(StagedOutputs& out, const std::vector<LaplacianSample>& L) {
  write_file_atomic(out.path("laplacian_plot.dat"), [&](std::ostream& f) {
    f << "# -lap_sigma3_sym lap_sigma3_anti (points with gap > 1e-3 and both parts > 1e-12)\n# "
         "lap_sigma3 <= 0\n";
    for (int pass = 0; pass < 2; ++pass) {
      if (pass == 1) f << "\n\n# lap_sigma3 > 0\n";
      for (const LaplacianSample& q : L)
        if (q.gap > 1e-3 && -q.lap_sigma3_sym > 1e-12 && q.lap_sigma3_anti > 1e-12 &&
            (q.lap_sigma3 > 0) == (pass == 1))
          f << format_double(-q.lap_sigma3_sym) << ' ' << format_double(q.lap_sigma3_anti) << '\n';
    }
  });
  write_file_atomic(out.path("laplacian.gp"), [&](std::ostream& f) {
    f << "# The two parts of the Laplacian of sigma3 at random points of random harmonic maps.\n"
         "# Render with: gnuplot laplacian.gp   (in this folder)\n"
         "set terminal pngcairo enhanced size 800,700 font 'sans,11'\nset output 'laplacian.png'\n"
         "set title 'Laplacian of sigma_3: where it is positive (no superharmonicity)'\n"
         "set logscale xy\nset format x '10^{%L}'\nset format y '10^{%L}'\nset size ratio -1\n"
         "set xlabel '-(symmetric part)  (<= 0 term)'\nset ylabel 'antisymmetric part  (>= 0 term)'\n"
         "set key top left\nset grid\n"
         "plot 'laplacian_plot.dat' index 0 using 1:2 with points pt 7 ps 0.3 lc rgb '#1f77b4' "
         "title 'Laplacian of sigma_3 <= 0', '' index 1 using 1:2 with points pt 7 ps 0.3 lc rgb "
         "'#d62728' "
         "title 'Laplacian of sigma_3 > 0', x with lines lc rgb 'black' dt 2 title 'equal parts'\n";
  });
  return render_staged_png(out, "laplacian", "");
}

void print_laplacian_summary(const LaplacianCommandOptions& o, const LaplacianStats& st,
                             const StagedOutputs& out) {
  std::cout << "lidef explore laplacian: " << st.n << " points (" << o.maps << " maps x " << o.points
            << ", gap > 1e-3)\n"
            << "  lap sigma1 < 0 at " << st.s1neg << " points (min " << format_g(st.min_l1)
            << "): sigma1 subharmonic\n"
            << "  lap sigma3 > 0 at " << st.s3pos << " points ("
            << format_g(100.0 * st.s3pos / std::max(1L, st.n)) << "%; max " << format_g(st.max_l3)
            << "): no superharmonicity, so no minimum principle from it\n"
            << "  exact vs finite-difference Laplacians (gap > 0.05): max relative difference "
            << format_g(st.max_fd) << "\n"
            << "  wrote " << out.final_path("") << "{laplacian.csv, summary.json, laplacian.png}\n";
}

int run_laplacian(const LaplacianCommandOptions& o) {
  check_laplacian_options(o);
  set_threads(o.threads);
  StagedOutputs out(o.out);
  const std::vector<LaplacianSample> L =
      laplacian_experiment(o.degree, o.maps, o.points, o.seed, o.amplitude);
  write_laplacian_csv(out.path("laplacian.csv"), L);
  const LaplacianStats st = laplacian_stats(L);
  const ojson s = laplacian_summary_json(o, st, L.size());
  const std::string plot_note = write_laplacian_plot(out, L);
  if (!plot_note.empty()) std::cerr << "lidef explore laplacian: warning: " << plot_note << "\n";
  write_file_atomic(out.path("summary.json"), [&](std::ostream& f) { f << s.dump(2) << "\n"; });
  out.commit();
  print_laplacian_summary(o, st, out);
  return kOk;
}

void add_laplacian_subcommand(CLI::App* ex, Action& action) {
  auto o = std::make_shared<LaplacianCommandOptions>();
  auto* sub = ex->add_subcommand("laplacian",
                                 "Laplacians of sigma1 and sigma3 at random points of random maps (App. D)");
  sub->add_option("--degree", o->degree, "Polynomial degree of the random maps (2..4)")
      ->capture_default_str();
  sub->add_option("--maps", o->maps, "Number of random maps")->capture_default_str();
  sub->add_option("--points", o->points, "Random points per map (uniform in the unit ball)")
      ->capture_default_str();
  sub->add_option("--seed", o->seed, "Seed")->capture_default_str();
  sub->add_option("--amplitude", o->amplitude, "Largest amplitude of the non-affine part")
      ->capture_default_str();
  sub->add_option("--threads", o->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  sub->add_option("--out", o->out, "Output folder (created if missing)")->required();
  sub->footer(
      "Writes laplacian.csv (per point: sigma's, exact and finite-difference Laplacians of sigma1 and "
      "sigma3) and\n"
      "summary.json. Subharmonicity of sigma1 (paper App. D) means lap_sigma1 >= 0 everywhere; a minimum\n"
      "principle for sigma3 would follow from lap_sigma3 <= 0, which fails where lap_sigma3 > 0.");
  sub->callback([o, &action] { action = [o] { return run_laplacian(*o); }; });
}

}  // namespace

void add_explore_command(CLI::App& app, Action& action) {
  auto* ex = app.add_subcommand("explore",
                                "sigma3 counterexample explorer: interior minima of sigma3 (paper Fig. 2)");
  ex->require_subcommand(1);
  ex->footer(
      "See 'lidef explore search --help', 'lidef explore show --help', 'lidef explore laplacian --help' and\n"
      "docs/explorer.md.");
  add_show_subcommand(ex, action);
  add_search_subcommand(ex, action);
  add_construct_subcommand(ex, action);
  add_laplacian_subcommand(ex, action);
}

}  // namespace lidef::cli
