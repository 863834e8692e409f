// PointForest: its neighbour graph, built from the trees (neighbor_graph_build.cpp), and the search
// of it: the query goes down the first tree to a leaf, whose points (near the query, and one run of
// rows) are the entry points of the best-first search of the graph (graph_search.hpp).
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <vector>

#include "forest_scratch.hpp"
#include "graph_search.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/point_forest.hpp"
#include "neighbor_graph_build.hpp"

namespace kdspace {

template <class T>
void PointForest<T>::build_graph() {
  const auto start = std::chrono::steady_clock::now();
  detail::GraphBuildParams graph_params;
  graph_params.degree = params_.graph_degree;
  graph_params.build_ef = params_.graph_build_ef;
  graph_params.alpha = params_.graph_alpha;
  graph_params.threads = params_.threads;
  // The copy of the points follows the first tree's leaf order: that tree's order is the rows'.
  std::vector<const std::uint32_t*> orders{nullptr};
  for (std::size_t t = 1; t < trees_.size(); ++t) orders.push_back(trees_[t].order.data());
  // params() (and a saved index) report the pool the build used, also when it was chosen from the data.
  graph_ = compact() ? detail::build_neighbor_graph<T>(bytes_.data(), size(), dim_, orders, graph_params,
                                                       &params_.graph_build_ef)
                     : detail::build_neighbor_graph<T>(points_.data(), size(), dim_, orders, graph_params,
                                                       &params_.graph_build_ef);
  graph_build_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

template <class T>
template <class U>
void PointForest<T>::search_graph(const U* points, const T* q, std::size_t k, std::size_t ef, Scratch& s,
                                  QueryStats& stats, Neighbor<T>* out) const {
  const std::size_t pool_size = std::max(ef, k);
  // The entry points: the leaf of the first tree the query falls in, one run of rows. (Starting from
  // the trees' best-bin-first search instead, with 16 or 32 checks, helped queries far outside the
  // data but cost 29% more instructions a query on 20k music frames, for the same recall.)
  const Node* const nodes = trees_[0].nodes.data();
  s.start(size(), projected_dims_);
  std::uint32_t id = 0;
  while (!nodes[id].is_leaf()) {
    const Node& node = nodes[id];
    const double x = s.projected(q, node.axis(), mean_, projection_, params_.pca);
    id = x - node.left_max <= node.right_min - x ? id + 1 : node.link;
  }
  std::vector<std::uint32_t>& entries = s.arriving;  // free outside the trees' search
  entries.resize(nodes[id].count());
  for (std::uint32_t i = 0; i < nodes[id].count(); ++i) entries[i] = nodes[id].link + i;
  stats.nodes_visited += 1;
  detail::GraphEntries<T> start;
  start.rows = entries.data();
  start.row_count = entries.size();
  detail::graph_search(graph_, size(), detail::RowScorer<T, U>(points, dim_, q), start, pool_size, s.graph, stats);
  const detail::GraphPool<T>& pool = s.graph.pool;
  if (pool.size() < k) {
    // The graph led to fewer than k points (a graph in pieces, on tiny or degenerate data): the
    // trees answer instead, exactly.
    search_rows(points, q, k, ForestSearchParams{unlimited_checks, 0, 0}, s, stats, out);
    return;
  }
  stats.queries += 1;
  // The pool is in (distance, row) order; the answer is in (distance, original index) order, so
  // every point tied with the k-th is sorted again by its index.
  std::size_t ties_end = k;
  while (ties_end < pool.size() && pool.dist(ties_end) == pool.dist(k - 1)) ++ties_end;
  std::vector<detail::Candidate<T>>& found = s.results;
  found.resize(ties_end);
  for (std::size_t i = 0; i < ties_end; ++i) found[i] = detail::Candidate<T>{pool.dist(i), ids_[pool.row(i)]};
  std::sort(found.begin(), found.end(), detail::comes_before);
  for (std::size_t i = 0; i < k; ++i) out[i] = Neighbor<T>{found[i].index, L2::to_distance(found[i].dist)};
}

template void PointForest<float>::build_graph();
template void PointForest<double>::build_graph();
template void PointForest<float>::search_graph(const float*, const float*, std::size_t, std::size_t, Scratch&,
                                               QueryStats&, Neighbor<float>*) const;
template void PointForest<float>::search_graph(const std::uint8_t*, const float*, std::size_t, std::size_t, Scratch&,
                                               QueryStats&, Neighbor<float>*) const;
template void PointForest<double>::search_graph(const double*, const double*, std::size_t, std::size_t, Scratch&,
                                                QueryStats&, Neighbor<double>*) const;
template void PointForest<double>::search_graph(const std::uint8_t*, const double*, std::size_t, std::size_t,
                                                Scratch&, QueryStats&, Neighbor<double>*) const;

}  // namespace kdspace
