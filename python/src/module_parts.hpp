// The parts of the module, each compiled in its own file.
#pragma once

#include <pybind11/pybind11.h>

namespace kdspace::python {

void bind_points_float(pybind11::module_& m);   // PointIndex32 (bind_points_float.cpp)
void bind_points_double(pybind11::module_& m);  // PointIndex64 (bind_points_double.cpp)
void bind_forest(pybind11::module_& m);         // ForestIndex32/64, ForestParams, TuneParams (bind_forest.cpp)
void bind_boxes(pybind11::module_& m);          // BoxIndex, overlapping_pairs (bind_boxes.cpp)
void bind_io(pybind11::module_& m);             // the file readers and writers (bind_io.cpp)

}  // namespace kdspace::python
