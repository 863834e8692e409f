// Running a rule over two BoundedTrees on several threads, and putting its results in order.
//
// The query tree is cut into subtrees (task_roots); each is traversed against the whole reference
// tree on whichever thread takes it, with results kept per subtree and joined in subtree order. A
// k-NN join writes only the heaps of its own subtree's points. So every answer, and every float sum,
// is the same on any number of threads.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/index_pair.hpp"
#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/count_rule.hpp"
#include "kdspace/joins/first_index_buckets.hpp"
#include "kdspace/joins/join_stats.hpp"
#include "kdspace/joins/knn_rule.hpp"
#include "kdspace/joins/range_rule.hpp"
#include "kdspace/joins/traversal.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace::detail {

/// The largest query subtree one task takes: about 1/256 of the queries, so that threads share the
/// work evenly, and no fewer than 4096 points, so that a task's traversal from the reference root
/// costs little beside its work.
inline std::size_t task_points(std::size_t queries) { return std::max<std::size_t>(4096, queries / 256); }

/// Runs body(task, root, stats, worker) for each query subtree on `threads` threads (worker: the
/// thread's number, below resolve_threads(threads)); sums the stats.
template <class Tree, class Body>
void for_each_task(const Tree& queries, unsigned threads, JoinStats* stats, Body&& body) {
  const std::vector<std::uint32_t> roots = task_roots(queries, task_points(queries.size()));
  std::vector<JoinStats> per_task(roots.size());
  parallel_for(roots.size(), threads, 1, [&](std::size_t begin, std::size_t end, unsigned worker) {
    for (std::size_t t = begin; t < end; ++t) body(t, roots[t], per_task[t], worker);
  });
  if (stats)
    for (const auto& s : per_task) *stats += s;
}

/// For each query point (rows in original order) its k nearest reference points, or with self its
/// k nearest other points; distances through Metric::to_distance.
template <class Metric, class T, int Dim, class Space>
NeighborLists<T> knn_join_trees(const BoundedTree<T, Dim>& queries, const BoundedTree<T, Dim>& reference, std::size_t k,
                                bool self, const Space& space, unsigned threads, JoinStats* stats) {
  // The table keeps its rows in the result's memory (in huge pages where enabled),
  // reserved, then filled with the table's placeholders in one pass.
  const std::size_t n = queries.size();
  NeighborLists<T> out;
  reserve_in_huge_pages(out.offsets, n + 1);
  out.offsets.resize(n + 1);
  for (std::size_t q = 0; q <= n; ++q) out.offsets[q] = q * k;
  reserve_in_huge_pages(out.neighbors, n * k);
  out.neighbors.assign(n * k, KnnTable<T>::placeholder());
  KnnTable<T> table(out.neighbors.data(), n, k);
  std::vector<T> node_bound(queries.node_count(), std::numeric_limits<T>::infinity());
  using Rule = KnnRule<T, Dim, Space>;
  for_each_task(queries, threads, stats, [&](std::size_t, std::uint32_t root, JoinStats& task_stats, unsigned) {
    Rule rule(queries, reference, space, self, table, node_bound, task_stats);
    DualTraversal<Rule>(rule, task_stats).run(root, 0, {});
  });
  table.template finish<Metric>(queries.indices());  // rows by original index
  return out;
}

/// The orders of the pairs of one first point: by the second point (the `.pairs` order), or by
/// (distance, index) (neighbour lists).
struct BySecondIndex {
  template <class Record>
  bool operator()(const Record& x, const Record& y) const {
    return x.b < y.b;
  }
};
struct NearestFirst {
  template <class Found>
  bool operator()(const Found& x, const Found& y) const {
    return (x.dist < y.dist) | ((x.dist == y.dist) & (x.b < y.b));  // without branches (place_run)
  }
};

/// Every pair within `limit` (internal units), through a sink of type Sink (PairSink or
/// DistanceSink), ordered by a, then by less_within_a.
template <class Sink, class Found, class T, int Dim, class Space, class Less>
std::vector<Found> range_join_trees(const BoundedTree<T, Dim>& queries, const BoundedTree<T, Dim>& reference, T limit,
                                    bool self, const Space& space, unsigned threads, JoinStats* stats,
                                    Less&& less_within_a) {
  std::vector<FirstIndexBuckets<Found>> per_worker(resolve_threads(threads), FirstIndexBuckets<Found>(queries.size()));
  using Rule = RangeRule<T, Dim, Space, Sink>;
  for_each_task(queries, threads, stats, [&](std::size_t, std::uint32_t root, JoinStats& task_stats, unsigned worker) {
    Sink sink(per_worker[worker], self);
    Rule rule(queries, reference, space, self, limit, sink, task_stats);
    DualTraversal<Rule>(rule, task_stats).run(root, 0, {});
  });
  return sort_by_first_index(per_worker, less_within_a);
}

/// Bin counts of every pair (Count = std::uint64_t) or of their weights (Count = double) over the
/// internal radii `radii` (ascending, then +inf); the bins of the tasks summed in task order.
template <class Count, class T, int Dim, class Space>
std::vector<Count> count_join_trees(const BoundedTree<T, Dim>& queries, const BoundedTree<T, Dim>& reference,
                                    const std::vector<T>& radii, bool self, const Space& space, const NodeWeights* query_weights,
                                    const NodeWeights* reference_weights, unsigned threads, JoinStats* stats) {
  std::vector<std::vector<Count>> per_task(task_roots(queries, task_points(queries.size())).size(),
                                           std::vector<Count>(radii.size(), Count(0)));
  using Rule = CountRule<T, Dim, Space, Count>;
  for_each_task(queries, threads, stats, [&](std::size_t task, std::uint32_t root, JoinStats& task_stats, unsigned) {
    Rule rule(queries, reference, space, self, radii, query_weights, reference_weights, per_task[task], task_stats);
    DualTraversal<Rule>(rule, task_stats).run(root, 0, rule.all_bins());
  });
  std::vector<Count> bins(radii.size(), Count(0));
  for (const auto& task_bins : per_task)
    for (std::size_t j = 0; j < bins.size(); ++j) bins[j] += task_bins[j];
  return bins;
}

}  // namespace kdspace::detail
