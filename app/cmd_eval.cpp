// lidef eval: f, J, signed singular values and det J of a cage map at given points.
#include <cmath>
#include <iostream>

#include "commands.h"
#include "lidef/atomic_file.h"
#include "lidef/coefficients.h"
#include "lidef/errors.h"
#include "lidef/green_coordinates.h"
#include "lidef/mesh_io.h"
#include "lidef/model_check.h"
#include "lidef/number_format.h"
#include "lidef/signed_svd.h"

namespace lidef::cli {

void add_eval_command(CLI::App& app, Action& action) {
  struct Opts {
    std::string model, coeffs, points, out;
  };
  auto opts = std::make_shared<Opts>();
  auto* sub = app.add_subcommand("eval", "Evaluate a cage map f = Σ y_v φ_v + Σ y_t ψ_t at points");
  sub->add_option("MODEL_DIR", opts->model, "Model folder (cage.obj|off, mesh.obj|off)")->required();
  sub->add_option("--coeffs", opts->coeffs,
                  "Coefficient file: #V+#F rows 'x y z', vertex rows first; or the word 'identity'")
      ->required();
  sub->add_option("--points", opts->points, "Points, one 'x y z' per line (.xyz)")->required();
  sub->add_option("--out", opts->out, "Output CSV: x,y,z,fx,fy,fz,J00..J22,s1,s2,s3,detJ")->required();
  sub->footer(
      "J[a][b] = dF_a/dp_b. s1 >= s2 >= |s3| are the signed singular values: s3 < 0 iff detJ < 0.\n"
      "Points outside the cage are evaluated but reported: there f is not the deformation.");
  sub->callback([opts, &action] {
    action = [opts] {
      const Model model = load_model(opts->model);
      const MatX3d y = read_coefficients(opts->coeffs, model.cage);
      const MatX3d P = read_points_xyz(opts->points);
      const HarmonicBasis basis(model.cage);
      const Eigen::Index n = P.rows();
      std::vector<MapJet> jets(n);
      std::vector<double> wind(n);
#pragma omp parallel for schedule(dynamic, 64)
      for (Eigen::Index i = 0; i < n; ++i) {
        jets[i] = basis.map_jet(y, P.row(i).transpose(), 1);
        wind[i] = model.cage.winding_number(P.row(i).transpose());
      }
      long outside = 0, first_outside = -1;
      for (Eigen::Index i = 0; i < n; ++i)
        if (std::abs(wind[i] - 1.0) > 1e-6 && outside++ == 0) first_outside = i;
      if (outside > 0)
        std::cerr << "lidef eval: warning: " << opts->points << ": " << outside
                  << " point(s) not inside the cage (first: point " << first_outside + 1
                  << "); their values are not the deformation\n";
      write_file_atomic(opts->out, [&](std::ostream& out) {
        out << "x,y,z,fx,fy,fz,J00,J01,J02,J10,J11,J12,J20,J21,J22,s1,s2,s3,detJ\n";
        for (Eigen::Index i = 0; i < n; ++i) {
          const MapJet& j = jets[i];
          const Vec3 s = signed_singular_values(j.J);
          std::string row;
          auto put = [&](double v) {
            if (!row.empty()) row += ',';
            row += format_double(v);
          };
          for (int k = 0; k < 3; ++k) put(P(i, k));
          for (int k = 0; k < 3; ++k) put(j.f(k));
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) put(j.J(a, b));
          for (int k = 0; k < 3; ++k) put(s(k));
          put(j.J.determinant());
          out << row << '\n';
        }
      });
      std::cout << "lidef eval: " << n << " points -> " << opts->out << "\n";
      return kOk;
    };
  });
}

}  // namespace lidef::cli
