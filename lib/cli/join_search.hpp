// The batch searches of `kdspace knn` and `kdspace radius` that go through the dual-tree joins
// (kdspace/joins/joins.hpp): --self (each base point's k nearest other points), --boxsize (periodic
// boundaries), and, for exact k-NN, large query sets in few dimensions, where a join of a tree built
// over the queries with the base's tree is faster than one query after the other. Same answers.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <vector>

#include "kdspace/io/matrix.hpp"
#include "kdspace/joins/joins.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace::cli {

/// Exact k-NN of at least this many queries, in at most join_max_dim dimensions, go to the join.
/// Measured (README, "Joins"): below ~join_min_queries the tree over the queries does not pay for
/// itself; above ~8 dimensions cells overlap so much that pairs of cells prune little.
inline constexpr std::size_t join_min_queries = 5000;
inline constexpr std::size_t join_max_dim = 8;

inline bool join_is_faster(std::size_t queries, std::size_t dim) {
  return queries >= join_min_queries && dim <= join_max_dim;
}

struct JoinRequest {
  bool knn = true;        ///< k-NN, else radius
  std::size_t k = 0;
  double radius = 0;
  std::size_t max_results = 0;  ///< radius: keep only the nearest this many (0: all)
  bool self = false;      ///< each base point's k nearest other points; no queries
  std::vector<double> boxsize;
  unsigned threads = 0;
};

/// Each row cut to its first `most` entries.
template <class T>
NeighborLists<T> first_of_each_row(const NeighborLists<T>& lists, std::size_t most) {
  NeighborLists<T> out;
  for (std::size_t q = 0; q < lists.rows(); ++q) {
    const auto row = lists.row(q);
    out.neighbors.insert(out.neighbors.end(), row.begin(), row.begin() + std::min(most, row.size()));
    out.offsets.push_back(out.neighbors.size());
  }
  return out;
}

/// The answers, rows in query order (base order with self); the join's work is added to `stats`
/// (nodes visited: node pairs; points visited: distances).
template <class T, int Dim, class Metric>
NeighborLists<T> search_by_join(const PointTree<T, Dim, Metric>& tree, const io::Matrix<T>& queries,
                                const JoinRequest& request, QueryStats& stats) {
  JoinParams params;
  params.threads = request.threads;
  params.boxsize = request.boxsize;
  JoinStats join;
  NeighborLists<T> found;
  if (request.self) {
    found = self_knn_join(tree, request.k, params, &join);
  } else {
    BuildParams build;
    build.threads = request.threads;
    const PointTree<T, Dim, Metric> query_tree(queries.data.data(), queries.rows, queries.cols, build);
    if (request.knn) {
      found = knn_join(query_tree, tree, request.k, params, &join);
    } else {
      const T r = request.radius > static_cast<double>(std::numeric_limits<T>::max())
                      ? std::numeric_limits<T>::infinity()
                      : static_cast<T>(request.radius);
      found = radius_join(query_tree, tree, r, params, &join);
      if (request.max_results > 0) found = first_of_each_row(found, request.max_results);
    }
  }
  stats.queries += found.rows();
  stats.nodes_visited += join.node_pairs;
  stats.points_visited += join.distances;
  return found;
}

}  // namespace kdspace::cli
