// Which PointTree the command builds for a dimension known only once the base file is read: a
// compile-time-dimension tree (PointTree<T, D, Metric>, its loops unrolled for D) for 2 and 3, the
// run-time-dimension tree otherwise. Both give the same answers bit for bit (the distances are summed
// in one fixed order whatever D is; tests/test_point_tree_exact.cpp checks it), so the choice changes
// only the speed.
//
// Measured (valgrind instruction counts of a build and a 1-NN and a 10-NN batch on two real 3-D sets,
// CGAL's building.ply and bunny00.off, a tenth held out as queries, and their 2-D projections): the
// run-time tree takes 5-6% more instructions under L2 (it already scans L2 leaves of 2..8 dimensions
// with the dimension as a constant) and 19-23% more under L1 and Linf. The L2 trees of 2 and 3
// are compiled once in the library (lib/points/instances_*.cpp), the L1 and Linf ones in the command.
#pragma once

#include <cstddef>
#include <type_traits>

#include "kdspace/points/point_tree.hpp"

namespace kdspace::cli {

/// Calls f(std::integral_constant<int, D>{}) with D = dim when dim is 2 or 3, else D = Dynamic.
template <class F>
decltype(auto) with_tree_dimension(std::size_t dim, F&& f) {
  if (dim == 2) return f(std::integral_constant<int, 2>{});
  if (dim == 3) return f(std::integral_constant<int, 3>{});
  return f(std::integral_constant<int, Dynamic>{});
}

}  // namespace kdspace::cli
