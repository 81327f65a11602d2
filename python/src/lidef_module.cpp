// The Python module `lidef` (its compiled part, lidef._lidef; python/lidef/__init__.py re-exports it):
// numpy arrays in and out (float64 points, int faces), the same library calls as the `lidef` CLI
// (app/cmd_deform.cpp, app/cmd_certify.cpp), the GIL released while they compute and Ctrl-C honoured
// between units of work (python_interrupt.h). docs/tutorial.md describes the API.
#include <omp.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lidef/analysis/certificate_report.h"
#include "lidef/analysis/deform_outputs.h"
#include "lidef/analysis/vtk_export.h"
#include "lidef/blas_kernel.h"
#include "lidef/cage/auto_cage.h"
#include "lidef/deform.h"
#include "lidef/deform_params.h"
#include "lidef/errors.h"
#include "lidef/explorer/random_search.h"
#include "lidef/green_coordinates.h"
#include "lidef/model_check.h"
#include "lidef/normalization.h"
#include "lidef/opencl/opencl_backend.h"
#include "lidef/precompute_cache.h"
#include "lidef/scenario.h"
#include "lidef/staged_outputs.h"
#include "lidef/subspace.h"
#include "python_arrays.h"
#include "python_interrupt.h"

namespace py = pybind11;

namespace lidef::python {
namespace {

using ModelPtr = std::shared_ptr<Model>;

// --- Parameters: **params by the table's names (deform_params.h), each value through set_param as a JSON
// value, so that a keyword means exactly what the same key means in a scenario file.
nlohmann::json to_json_value(const std::string& name, const py::handle& v) {
  if (py::isinstance<py::bool_>(v)) return v.cast<bool>();
  if (py::isinstance<py::int_>(v)) return v.cast<long long>();
  if (py::isinstance<py::float_>(v)) return v.cast<double>();
  if (py::isinstance<py::str>(v)) return v.cast<std::string>();
  // numpy scalars and other numbers: integers as integers (an int parameter refuses 60.0)
  try {
    if (py::hasattr(v, "__index__")) return v.attr("__index__")().cast<long long>();
    if (py::hasattr(v, "__float__")) return v.attr("__float__")().cast<double>();
  } catch (const py::error_already_set&) {
  } catch (const py::cast_error&) {
  }
  throw InputError(name, "must be a number, a bool or a string (got " +
                             py::str(py::type::of(v).attr("__name__")).cast<std::string>() + ")");
}

DeformParams params_from_kwargs(const py::kwargs& kwargs, std::vector<std::string>* given = nullptr) {
  DeformParams params;
  for (const auto& [key, value] : kwargs) {
    const std::string name = key.cast<std::string>();
    set_param(params, name, to_json_value(name, value), name);
    if (given) given->push_back(name);
  }
  validate_params(params, "parameters");
  if (params.threads > 0) omp_set_num_threads(params.threads);
  return params;
}

std::shared_ptr<const ComputeBackend> backend_for(const DeformParams& params) {
  std::string message;
  return select_backend(params, default_cache_dir(), &message);
}

// --- Model.
ModelPtr load_model_py(const std::string& path) {
  py::gil_scoped_release release;
  // A mesh file as the model: its automatic cage, made once and cached (lidef/cage/auto_cage.h).
  return std::make_shared<Model>(load_model(resolve_model_path(path)));
}

py::tuple evaluate(const Model& model, const py::object& Y, const py::object& P) {
  const MatX3d y = coefficients_arg(Y, "Y", model.cage);
  const MatX3d p = points_arg(P, "P");
  std::vector<MapJet> jets(p.rows());
  {
    py::gil_scoped_release release;
    const HarmonicBasis basis(model.cage);
#pragma omp parallel for schedule(dynamic, 64)
    for (Eigen::Index i = 0; i < p.rows(); ++i) jets[i] = basis.map_jet(y, p.row(i).transpose(), 1);
  }
  const py::ssize_t n = p.rows();
  py::array_t<double> f({n, py::ssize_t(3)}), J({n, py::ssize_t(3), py::ssize_t(3)});
  auto fm = f.mutable_unchecked<2>();
  auto Jm = J.mutable_unchecked<3>();
  for (py::ssize_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      fm(i, a) = jets[i].f(a);
      for (int b = 0; b < 3; ++b) Jm(i, a, b) = jets[i].J(a, b);  // ∂f_a/∂p_b
    }
  return py::make_tuple(f, J);
}

// --- Certificate: the verdict, the leaves as arrays, and the CLI's certificate files.
struct PyCertificate {
  ModelPtr model;
  Certificate cert;
  MatX3d y;
  std::shared_ptr<const VoxelSampling> sampling;
  SamplingParams sampling_params;
  CertifyParams certify_params;
  std::string coefficients_name;  // how certificate.json names the map
  // The global injectivity verdict, computed on first use (certificate_report.h).
  mutable std::shared_ptr<const GlobalInjectivity> global_verdict;

  const GlobalInjectivity& global() const {
    if (!global_verdict) {
      py::gil_scoped_release release;
      global_verdict = std::make_shared<const GlobalInjectivity>(
          decide_global_injectivity(cert, sampling->domain, model->cage, model->mesh, y));
    }
    return *global_verdict;
  }

  py::dict leaves() const {
    const auto& L = cert.leaves;
    const py::ssize_t n = static_cast<py::ssize_t>(L.size());
    py::array_t<double> center({n, py::ssize_t(3)}), side(n), sigma3(n), lipschitz(n), lower(n);
    py::array_t<int> depth(n);
    py::array_t<bool> certified(n);
    auto c = center.mutable_unchecked<2>();
    for (py::ssize_t i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) c(i, k) = L[i].center(k);
      side.mutable_at(i) = L[i].side;
      sigma3.mutable_at(i) = L[i].sigma3;
      lipschitz.mutable_at(i) = L[i].L;
      lower.mutable_at(i) = L[i].margin;  // σ3 − r L − τ: the leaf's lower bound of σ3
      depth.mutable_at(i) = L[i].depth;
      certified.mutable_at(i) = L[i].certified;
    }
    py::dict d;
    d["center"] = center;
    d["side"] = side;
    d["sigma3"] = sigma3;
    d["lipschitz"] = lipschitz;
    d["lower_bound"] = lower;
    d["depth"] = depth;
    d["certified"] = certified;
    return d;
  }

  // certificate.json, voxels.csv and leaves.vtu, as `lidef certify` writes them (all or none).
  void write(const std::string& dir) const {
    py::gil_scoped_release release;
    CertificateReport report =
        make_certificate_report(cert, model->cage, model->mesh, y, model->dir, coefficients_name,
                                sampling_params, *sampling, certify_params, global_verdict.get());
    StagedOutputs out(dir);
    out.path("voxels.csv");
    out.path("certificate.json");
    write_certificate_files(out.staging_dir(), report);
    write_leaves_vtu(out.path("leaves.vtu"), cert.leaves);
    out.commit();
  }
};

PyCertificate certify_py(const ModelPtr& model, const py::object& Y, const py::kwargs& kwargs) {
  const DeformParams dp = params_from_kwargs(kwargs);
  const MatX3d y = coefficients_arg(Y, "Y", model->cage);
  const auto backend = backend_for(dp);
  PyCertificate out;
  out.model = model;
  out.y = y;
  out.coefficients_name = "python array";
  out.sampling_params = sampling_params_of(dp);
  out.certify_params = certify_params_of(dp, false, true);
  {
    py::gil_scoped_release release;
    // The same stages as `lidef certify` (app/cmd_certify.cpp): the sampling through the cache, then the
    // certificate in the model's normalized frame.
    const PrecomputeCache cache(default_cache_dir());
    auto sampling = std::make_shared<VoxelSampling>(cached_sample_for_domain(
        to_string(dp.domain), model->cage, model->mesh.V, model->mesh.F, out.sampling_params, cache));
    if (sampling->size() == 0)
      throw InputError(model->dir, "no voxel fits inside the cage at these sampling parameters");
    NormalizedCertifier certifier(model->cage, *sampling);
    certifier.set_backend(*backend);
    out.cert = certifier.certify(y, out.certify_params);
    out.sampling = std::move(sampling);
  }
  return out;
}

// --- Deformation results.
struct PyDeformResult {
  ModelPtr model;
  std::shared_ptr<const DeformResult> result;
  Scenario scenario;  // what write() records in scenario.json

  PyCertificate certificate() const {
    PyCertificate c;
    c.model = model;
    c.cert = result->certificate;
    c.y = result->coefficients;
    c.sampling = std::shared_ptr<const VoxelSampling>(result, &result->sampling);
    c.sampling_params = result->sampling_params;
    c.certify_params = result->certify_params;
    c.coefficients_name = "coefficients.txt";
    if (result->global) c.global_verdict = std::make_shared<const GlobalInjectivity>(*result->global);
    return c;
  }
  void write(const std::string& dir) const {
    py::gil_scoped_release release;
    write_deform_outputs(dir, *model, scenario, *result);
  }
};

Scenario scenario_of(const ModelPtr& model, const MatX3d& sources, const MatX3d& targets,
                     const DeformParams& params, const std::vector<std::string>& given) {
  Scenario sc;
  sc.name = "python";
  sc.model = model->dir;
  sc.model_dir = model->dir;
  sc.sources = sources;
  sc.targets = targets;
  sc.params = params;
  sc.params_given = given;
  return sc;
}

PyDeformResult deform_py(const ModelPtr& model, const py::object& S, const py::object& T,
                         const py::kwargs& kwargs) {
  std::vector<std::string> given;
  const DeformParams params = params_from_kwargs(kwargs, &given);
  const MatX3d sources = points_arg(S, "sources");
  const MatX3d targets = points_arg(T, "targets");
  if (targets.rows() != sources.rows())
    throw InputError("targets", "has " + std::to_string(targets.rows()) + " rows but sources has " +
                                    std::to_string(sources.rows()));
  DeformOptions options;
  options.backend = backend_for(params);
  Interrupt interrupt;
  interrupt.attach(options);
  std::shared_ptr<DeformResult> result;
  interrupt.run(
      [&] { result = std::make_shared<DeformResult>(deform(*model, sources, targets, params, options)); });
  return {model, result, scenario_of(model, sources, targets, params, given)};
}

// --- Session: a solver kept between calls, each solve starting from the last certified map (the studio's
// drag, for notebooks).
class PySession {
 public:
  PySession(ModelPtr model, const py::kwargs& kwargs) : model_(std::move(model)) {
    params_ = params_from_kwargs(kwargs, &given_);
    const auto backend = backend_for(params_);
    PrecomputeSetup setup;
    setup.mesh = &model_->mesh;
    Interrupt interrupt;
    interrupt.attach(setup);
    interrupt.run(
        [&] { solver_ = std::make_unique<DeformationSolver>(model_->cage, params_, setup, backend); });
  }
  // New handles at `sources` (#h by 3); they stay where the current map takes them until solve() moves them.
  void set_handles(const py::object& S) {
    const MatX3d sources = points_arg(S, "sources");
    py::gil_scoped_release release;
    const MatX3d here = sources.rows() > 0 ? map_points(sources) : sources;
    solver_->set_handles(sources, here, "sources");
  }
  PyDeformResult solve(const py::object& T) {
    if (solver_->handle_sources().rows() == 0)
      throw InputError("targets", "no handles: call set_handles first");
    const MatX3d targets = points_arg(T, "targets");
    if (targets.rows() != solver_->handle_sources().rows())
      throw InputError("targets", "has " + std::to_string(targets.rows()) + " rows but the session has " +
                                      std::to_string(solver_->handle_sources().rows()) + " handles");
    DeformOptions options;
    Interrupt interrupt;
    interrupt.attach(options);
    std::shared_ptr<DeformResult> result;
    interrupt.run([&] {
      solver_->set_targets(targets, "targets");
      PathSolveReport path;
      const SolveResult res =
          solve_to_targets(*solver_, {}, targets, {}, options.on_iteration, options.stop, {}, &path);
      result = std::make_shared<DeformResult>(deform_result(*solver_, model_->mesh, res, path));
    });
    return {model_, result, scenario_of(model_, solver_->handle_sources(), targets, params_, given_)};
  }
  py::array_t<double> coefficients() const { return rows_to_numpy(solver_->coefficients()); }

 private:
  MatX3d map_points(const MatX3d& P) const {
    const MatX3d y = solver_->coefficients();
    const HarmonicBasis& basis = solver_->basis();
    MatX3d out(P.rows(), 3);
    for (Eigen::Index i = 0; i < P.rows(); ++i)
      out.row(i) = basis.map_jet(y, P.row(i).transpose(), 0).f.transpose();
    return out;
  }
  ModelPtr model_;
  DeformParams params_;
  std::vector<std::string> given_;
  std::unique_ptr<DeformationSolver> solver_;  // refers to model_->cage, which model_ keeps alive
};

// --- Scenarios and the parameter table.
struct PyScenario {
  Scenario sc;
  py::dict parameters() const {
    py::dict d;
    const nlohmann::ordered_json all = params_to_json(sc.params);
    for (const std::string& name : sc.params_given)
      d[py::str(name)] = py::module_::import("json").attr("loads")(all[name].dump());
    return d;
  }
};

py::list parameter_table() {
  const DeformParams defaults;
  const nlohmann::ordered_json values = params_to_json(defaults);
  py::object loads = py::module_::import("json").attr("loads");
  py::list rows;
  for (const ParamInfo& p : deform_param_table()) {
    if (is_test_hook(p)) continue;
    py::dict row;
    row["name"] = p.name;
    row["group"] = p.group;
    row["default"] = loads(values[p.name].dump());
    const auto choices = param_choices(p);
    const bool numeric = std::visit(
        [](auto m) {
          using T = std::remove_reference_t<decltype(DeformParams{}.*m)>;
          return std::is_arithmetic_v<T> && !std::is_same_v<T, bool>;
        },
        p.member);
    if (numeric)
      row["range"] = py::make_tuple(p.min, p.max);
    else if (!choices.empty())
      row["range"] = py::cast(choices);
    else
      row["range"] = py::none();
    row["help"] = p.help;
    rows.append(row);
  }
  return rows;
}

// --- The σ3 explorer's random search (docs/explorer.md, "How often it happens"): the function behind
// `lidef explore search`, its trials as dicts.
py::list search_sigma3_minima_py(const std::string& family, int degree, int trials, std::uint64_t seed,
                                 double amplitude, int starts) {
  SearchParams sp;
  if (family == "random")
    sp.family = SearchFamily::kRandom;
  else if (family == "twist")
    sp.family = SearchFamily::kTwist;
  else
    throw InputError("family", "must be 'random' or 'twist' (got '" + family + "')");
  if (degree < 2 || degree > 4 || (sp.family == SearchFamily::kTwist && degree < 3))
    throw InputError("degree", "must be in 2..4 (3..4 for the twist family)");
  if (trials < 1 || trials > 1000000) throw InputError("trials", "must be in 1..1000000");
  if (!(amplitude >= 0) || !std::isfinite(amplitude))
    throw InputError("amplitude", "must be a finite number >= 0");
  if (starts < 1 || starts > 10000) throw InputError("starts", "must be in 1..10000");
  sp.degree = degree;
  sp.trials = trials;
  sp.seed = seed;
  sp.max_amplitude = amplitude;
  sp.minima.starts = starts;
  std::vector<SearchTrial> found;
  {
    py::gil_scoped_release release;
    found = search_sigma3_minima(sp);
  }
  py::list out;
  for (const SearchTrial& t : found) {
    py::array_t<double> minima({static_cast<py::ssize_t>(t.minima.size()), py::ssize_t(4)});
    auto mm = minima.mutable_unchecked<2>();
    for (size_t i = 0; i < t.minima.size(); ++i) {
      for (int k = 0; k < 3; ++k) mm(i, k) = t.minima[i].position(k);
      mm(i, 3) = t.minima[i].sigma3;
    }
    py::dict d;
    d["trial"] = t.trial;
    d["seed"] = t.seed;
    d["minima"] = minima;  // rows x, y, z, sigma3 of the interior minima, by sigma3
    d["strict_minima"] = t.strict_minima;
    d["sphere_min_sigma3"] = t.sphere_min_sigma3;
    d["candidate"] = t.candidate;
    d["candidate_gap"] = t.candidate_gap;
    out.append(d);
  }
  return out;
}

}  // namespace

void bind(py::module_& m) {
  // Bad input: a ValueError whose message names the file or argument. Other library failures: lidef.Error.
  static py::exception<InputError> input_error(m, "InputError", PyExc_ValueError);
  static py::exception<Error> error(m, "Error", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const InputError& e) {
      PyErr_SetString(input_error.ptr(), e.what());
    } catch (const Error& e) {
      PyErr_SetString(error.ptr(), e.what());
    }
  });

  py::class_<Model, ModelPtr>(m, "Model", "A cage and the mesh it deforms (model units).")
      .def_property_readonly("cage_vertices", [](const Model& mo) { return rows_to_numpy(mo.cage.V); })
      .def_property_readonly("cage_faces", [](const Model& mo) { return rows_to_numpy(mo.cage.F); })
      .def_property_readonly("mesh_vertices", [](const Model& mo) { return rows_to_numpy(mo.mesh.V); })
      .def_property_readonly("mesh_faces", [](const Model& mo) { return rows_to_numpy(mo.mesh.F); })
      .def_property_readonly("path", [](const Model& mo) { return mo.dir; })
      .def_property_readonly("warnings",
                             [](const Model& mo) {
                               std::vector<std::string> w;
                               for (const Issue& i : mo.report.warnings) w.push_back(i.str());
                               return w;
                             })
      .def(
          "identity", [](const Model& mo) { return rows_to_numpy(mo.cage.identity_coefficients()); },
          "Coefficients (#V+#F by 3) of the identity map.")
      .def("evaluate", &evaluate, py::arg("Y"), py::arg("P"),
           "(f, J) of the map with coefficients Y at the points P (n by 3): f n by 3, J n by 3 by 3 with "
           "J[i, a, b] = d f_a / d p_b.")
      .def("__repr__", [](const Model& mo) {
        return "<lidef.Model " + mo.dir + ": cage " + std::to_string(mo.cage.num_vertices()) +
               " vertices, mesh " + std::to_string(mo.mesh.V.rows()) + " vertices>";
      });

  m.def("load_model", &load_model_py, py::arg("path"),
        "A model from a model folder (cage.obj, mesh.obj) or a mesh file (an automatic cage, made once and "
        "cached).");

  py::class_<PyCertificate>(m, "Certificate", "A local-injectivity certificate of a map.")
      .def_property_readonly("certified", [](const PyCertificate& c) { return c.cert.certified; })
      .def_property_readonly("min_lower_bound", [](const PyCertificate& c) { return c.cert.min_lower_bound; })
      .def_property_readonly("reason", [](const PyCertificate& c) { return c.cert.reason; })
      .def_property_readonly("globally_injective",
                             [](const PyCertificate& c) -> py::object {
                               const GlobalInjectivity& g = c.global();
                               if (g.verdict == GlobalInjectivity::Verdict::kInjective)
                                 return py::bool_(true);
                               if (g.verdict == GlobalInjectivity::Verdict::kOverlap) return py::bool_(false);
                               return py::none();
                             })
      .def_property_readonly("global_reason", [](const PyCertificate& c) { return c.global().reason; })
      .def_property_readonly("overlap_point",
                             [](const PyCertificate& c) -> py::object {
                               const GlobalInjectivity& g = c.global();
                               if (g.verdict != GlobalInjectivity::Verdict::kOverlap) return py::none();
                               return py::make_tuple(g.overlap_point.x(), g.overlap_point.y(),
                                                     g.overlap_point.z());
                             })
      .def_property_readonly(
          "max_sigma1_upper_bound", [](const PyCertificate& c) { return c.cert.max_sigma1_upper_bound; },
          "An upper bound of the largest singular value of J on the certified domain (inf: none proven).")
      .def_property_readonly(
          "max_distortion_upper_bound",
          [](const PyCertificate& c) { return c.cert.max_distortion_upper_bound; },
          "An upper bound of sigma1/sigma3 on the certified domain (inf: none proven).")
      .def_property_readonly(
          "distortion_met",
          [](const PyCertificate& c) -> py::object {
            if (!c.cert.targets().any()) return py::none();
            return py::bool_(c.cert.distortion_met);
          },
          "Whether every distortion bound asked for (max_distortion, max_sigma1, min_sigma3) was proven on "
          "every leaf; None when none was asked for.")
      .def_property_readonly("voxels", [](const PyCertificate& c) { return c.cert.voxels; })
      .def_property_readonly("leaves", &PyCertificate::leaves)
      .def("write", &PyCertificate::write, py::arg("dir"),
           "Writes certificate.json, voxels.csv and leaves.vtu into dir (all or none).")
      .def("__repr__", [](const PyCertificate& c) {
        return std::string("<lidef.Certificate ") + (c.cert.certified ? "certified" : "NOT certified") +
               ", min lower bound of sigma3 " + std::to_string(c.cert.min_lower_bound) + ">";
      });

  m.def(
      "certify", &certify_py, py::arg("model"), py::arg("Y"),
      "The certificate of the map with coefficients Y ((#V+#F) by 3); **params: rows of lidef.parameters().");

  py::class_<PyDeformResult>(m, "DeformResult", "The last certified map of a deformation.")
      .def_property_readonly("coefficients",
                             [](const PyDeformResult& r) { return rows_to_numpy(r.result->coefficients); })
      .def_property_readonly("certified",
                             [](const PyDeformResult& r) { return r.result->certificate.certified; })
      .def_property_readonly("certificate", &PyDeformResult::certificate)
      .def_property_readonly(
          "deformed_vertices",
          [](const PyDeformResult& r) { return rows_to_numpy(r.result->deformed_vertices); })
      .def_property_readonly("max_handle_error",
                             [](const PyDeformResult& r) { return r.result->max_handle_error; })
      .def_property_readonly("handles_reached",
                             [](const PyDeformResult& r) { return r.result->handles_reached; })
      .def_property_readonly("iterations", [](const PyDeformResult& r) { return r.result->iterations; })
      .def_property_readonly(
          "stop_reason",
          [](const PyDeformResult& r) { return std::string(to_string(r.result->solve.reason)); })
      .def_property_readonly("message", [](const PyDeformResult& r) { return r.result->solve.message; })
      .def("write", &PyDeformResult::write, py::arg("dir"),
           "Writes the files of `lidef deform --out dir` (all or none).")
      .def("__repr__", [](const PyDeformResult& r) {
        return std::string("<lidef.DeformResult ") + to_string(r.result->solve.reason) + ", " +
               std::to_string(r.result->iterations) + " iterations, max handle error " +
               std::to_string(r.result->max_handle_error) + ">";
      });

  m.def("deform", &deform_py, py::arg("model"), py::arg("sources"), py::arg("targets"),
        "Deforms the model so that the handles at sources (h by 3) move to targets (h by 3); every accepted "
        "step is certified. **params: rows of lidef.parameters().");

  py::class_<PySession>(m, "Session",
                        "A solver kept between calls: each solve starts from the last certified map.")
      .def(py::init<ModelPtr, const py::kwargs&>(), py::arg("model"))
      .def("set_handles", &PySession::set_handles, py::arg("sources"))
      .def("solve", &PySession::solve, py::arg("targets"))
      .def_property_readonly("coefficients", &PySession::coefficients);

  py::class_<PyScenario>(m, "Scenario", "A handle scenario file.")
      .def_property_readonly("name", [](const PyScenario& s) { return s.sc.name; })
      .def_property_readonly("model", [](const PyScenario& s) { return s.sc.model_dir; })
      .def_property_readonly("sources", [](const PyScenario& s) { return rows_to_numpy(s.sc.sources); })
      .def_property_readonly("targets", [](const PyScenario& s) { return rows_to_numpy(s.sc.targets); })
      .def_property_readonly("parameters", &PyScenario::parameters);
  m.def(
      "read_scenario",
      [](const std::string& path, const std::string& models) {
        return PyScenario{read_scenario(path, models)};
      },
      py::arg("path"), py::arg("models") = "",
      "Reads a scenario JSON; `model` is the resolved model folder, `parameters` the ones the file sets.");

  m.def("parameters", &parameter_table,
        "The parameter table: one dict per row (name, group, default, range, help).");
  m.def("search_sigma3_minima", &search_sigma3_minima_py, py::arg("family") = "random", py::arg("degree") = 4,
        py::arg("trials") = 200, py::arg("seed") = 1, py::arg("amplitude") = 0.6, py::arg("starts") = 24,
        "The sigma3 explorer's random search on the unit ball (`lidef explore search`): one dict per random "
        "harmonic polynomial map with its interior minima of sigma3 and whether it is a candidate "
        "counterexample (docs/explorer.md).");
  m.def("_blas_kernel", [] {
    const BlasKernelInfo info = blas_kernel_info();
    return py::make_tuple(info.core, info.recommended, info.replaced);
  });
}

}  // namespace lidef::python

PYBIND11_MODULE(_lidef, m) {
  m.doc() = "lidef: certified locally injective volumetric deformation (compiled part)";
  lidef::python::bind(m);
}
