// PointIndex over float32 data: kdspace.KDTree keeps float32 input as it is.
#include "module_parts.hpp"
#include "point_index.hpp"

namespace kdspace::python {

void bind_points_float(pybind11::module_& m) {
  bind_point_index<float>(m, "PointIndex32");
}

}  // namespace kdspace::python
