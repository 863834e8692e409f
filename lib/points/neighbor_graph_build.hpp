// The build of PointForest's neighbour graph from the forest's trees (see neighbor_graph_build.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/points/detail/neighbor_graph.hpp"

namespace kdspace::detail {

struct GraphBuildParams {
  std::size_t degree = 32;    ///< R: the most neighbours a point keeps
  std::size_t build_ef = 0;   ///< pool of the search that finds each point's neighbours; 0: from the data
  double alpha = 1.2;         ///< slack of the pruning rule (1 = the relative neighbourhood rule)
  unsigned threads = 1;
};

/// The graph over n rows (of U: T, or bytes) of `dim` values. `tree_orders` holds each tree's leaf
/// order of the rows (nullptr: the rows themselves are in that tree's leaf order). The graph is the
/// same for any number of threads. With `pool_used`, it receives the pool of the per-point searches
/// (params.build_ef, or the one chosen from the data when that is 0).
template <class T, class U>
NeighborGraph build_neighbor_graph(const U* rows, std::size_t n, std::size_t dim,
                                   const std::vector<const std::uint32_t*>& tree_orders,
                                   const GraphBuildParams& params, std::size_t* pool_used = nullptr);

}  // namespace kdspace::detail
