// The parts of the module, each compiled in its own file.
#pragma once

#include <pybind11/pybind11.h>

namespace kdspace::python {

void bind_points_float(pybind11::module_& m);   // PointIndex32 (bind_points_float.cpp)
void bind_points_double(pybind11::module_& m);  // PointIndex64 (bind_points_double.cpp)

}  // namespace kdspace::python
