// The batch searches of `kdspace knn` and `kdspace radius` that go through the dual-tree joins
// (kdspace/joins/joins.hpp): --self (each base point's k nearest other points), --boxsize (periodic
// boundaries). Same answers as the single tree where both apply.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <vector>

#include "kdspace/io/matrix.hpp"
#include "kdspace/joins/joins.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace::cli {

/// Plain k-NN batches (queries against a base) stay on the single tree: since batches visit their
/// queries in leaf order, one query after the other beats a join of a tree over the queries with the
/// base's tree. Measured with `kdspace knn --stats` (query_s), 1e6 uniform float points, 2e5
/// queries, one thread, on a busy 2-core machine: 3-D k = 1 0.16 s (tree) against 0.22 s (join),
/// k = 10 0.42 s against 0.51 s; 6-D k = 1 0.76 s against 2.66 s, k = 10 2.37 s against 4.10 s.
/// The joins serve --self and --boxsize, which a single tree does not answer.

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
