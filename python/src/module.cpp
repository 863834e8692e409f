// The compiled core of the Python package kdspace (kdspace._core). The Python layer (kdspace/*.py)
// gives it SciPy's interface; errors of the library (kdspace::Error) arrive in Python as ValueError
// with the library's message.
#include <pybind11/pybind11.h>

#include "kdspace/error.hpp"
#include "kdspace/version.hpp"
#include "module_parts.hpp"

PYBIND11_MODULE(_core, m) {
  m.doc() = "kdspace's compiled core; use the package kdspace";
  m.attr("__version__") = kdspace::version;
  pybind11::register_exception_translator([](std::exception_ptr error) {
    try {
      if (error) std::rethrow_exception(error);
    } catch (const kdspace::Error& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
  kdspace::python::bind_points_float(m);
  kdspace::python::bind_points_double(m);
  kdspace::python::bind_forest(m);
  kdspace::python::bind_boxes(m);
  kdspace::python::bind_io(m);
}
