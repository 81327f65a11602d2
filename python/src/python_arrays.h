// numpy ⇄ Eigen for the Python module: arguments are checked and copied (any numeric dtype and layout is
// accepted, read as float64), results are fresh C-ordered arrays the caller owns.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <string>

#include "lidef/cage.h"
#include "lidef/errors.h"
#include "lidef/types.h"

namespace lidef::python {

namespace py = pybind11;

// An n by 3 array of finite numbers (n ≥ 0); InputError naming `name` otherwise.
inline MatX3d points_arg(const py::object& obj, const std::string& name) {
  using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
  Array a;
  try {
    a = Array::ensure(obj);
  } catch (const py::error_already_set&) {
    a = Array();
  }
  if (!a) throw InputError(name, "must be an n by 3 array of numbers");
  if (a.ndim() != 2 || a.shape(1) != 3) {
    std::string shape;
    for (py::ssize_t k = 0; k < a.ndim(); ++k) shape += (k ? ", " : "") + std::to_string(a.shape(k));
    throw InputError(name, "must be an n by 3 array (got shape (" + shape + "))");
  }
  MatX3d m(a.shape(0), 3);
  const auto r = a.unchecked<2>();
  for (py::ssize_t i = 0; i < a.shape(0); ++i)
    for (int k = 0; k < 3; ++k) {
      const double v = r(i, k);
      if (!std::isfinite(v))
        throw InputError(name, "row " + std::to_string(i) + " holds a non-finite number");
      m(i, k) = v;
    }
  return m;
}

// Coefficients of a map of `cage`: (#V+#F) by 3.
inline MatX3d coefficients_arg(const py::object& obj, const std::string& name, const Cage& cage) {
  MatX3d y = points_arg(obj, name);
  const long rows = cage.num_vertices() + cage.num_faces();
  if (y.rows() != rows)
    throw InputError(name, "has " + std::to_string(y.rows()) + " rows; a map of this cage has #V+#F = " +
                               std::to_string(rows) + " (" + std::to_string(cage.num_vertices()) +
                               " vertices, " + std::to_string(cage.num_faces()) + " faces)");
  return y;
}

// Rows of 3 as an n by 3 array (float64 for points, int32 for faces).
template <class Scalar>
py::array_t<Scalar> rows_to_numpy(const Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor>& m) {
  py::array_t<Scalar> a({static_cast<py::ssize_t>(m.rows()), py::ssize_t(3)});
  std::copy(m.data(), m.data() + m.size(), a.mutable_data());
  return a;
}

}  // namespace lidef::python
