// PointIndex over float64 data (and everything converted to it, as SciPy does).
#include "module_parts.hpp"
#include "point_index.hpp"

namespace kdspace::python {

void bind_points_double(pybind11::module_& m) {
  bind_point_index<double>(m, "PointIndex64");
}

}  // namespace kdspace::python
