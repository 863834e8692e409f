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

#include "kdspace/index_pair.hpp"
#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/count_rule.hpp"
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

/// Runs body(task, root, stats) for each query subtree on `threads` threads; sums the stats.
template <class Tree, class Body>
void for_each_task(const Tree& queries, unsigned threads, JoinStats* stats, Body&& body) {
  const std::vector<std::uint32_t> roots = task_roots(queries, task_points(queries.size()));
  std::vector<JoinStats> per_task(roots.size());
  parallel_for(roots.size(), threads, 1, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t t = begin; t < end; ++t) body(t, roots[t], per_task[t]);
  });
  if (stats)
    for (const auto& s : per_task) *stats += s;
}

/// For each query point (rows in original order) its k nearest reference points, or with self its
/// k nearest other points; distances through Metric::to_distance.
template <class Metric, class T, int Dim, class Space>
NeighborLists<T> knn_join_trees(const BoundedTree<T, Dim>& queries, const BoundedTree<T, Dim>& reference, std::size_t k,
                                bool self, const Space& space, unsigned threads, JoinStats* stats) {
  KnnTable<T> table(queries.size(), k);
  std::vector<T> node_bound(queries.node_count(), std::numeric_limits<T>::infinity());
  using Rule = KnnRule<T, Dim, Space>;
  for_each_task(queries, threads, stats, [&](std::size_t, std::uint32_t root, JoinStats& task_stats) {
    Rule rule(queries, reference, space, self, table, node_bound, task_stats);
    DualTraversal<Rule>(rule, task_stats).run(root, 0, {});
  });
  NeighborLists<T> out;
  out.offsets.resize(queries.size() + 1);
  for (std::size_t q = 0; q <= queries.size(); ++q) out.offsets[q] = q * k;
  out.neighbors.resize(queries.size() * k);
  for (std::size_t pos = 0; pos < queries.size(); ++pos) {
    const Candidate<T>* sorted = table.sorted_row(pos);
    Neighbor<T>* row = out.neighbors.data() + std::size_t{queries.index(pos)} * k;
    for (std::size_t i = 0; i < k; ++i) row[i] = Neighbor<T>{sorted[i].index, Metric::to_distance(sorted[i].dist)};
  }
  return out;
}

/// Every pair within `limit` (internal units), through a sink of type Sink (PairSink or
/// DistanceSink); the pairs of all tasks, in task order.
template <class Sink, class Found, class T, int Dim, class Space>
std::vector<Found> range_join_trees(const BoundedTree<T, Dim>& queries, const BoundedTree<T, Dim>& reference, T limit,
                                    bool self, const Space& space, unsigned threads, JoinStats* stats) {
  std::vector<std::vector<Found>> per_task(task_roots(queries, task_points(queries.size())).size());
  using Rule = RangeRule<T, Dim, Space, Sink>;
  for_each_task(queries, threads, stats, [&](std::size_t task, std::uint32_t root, JoinStats& task_stats) {
    Sink sink(per_task[task], self);
    Rule rule(queries, reference, space, self, limit, sink, task_stats);
    DualTraversal<Rule>(rule, task_stats).run(root, 0, {});
  });
  std::size_t total = 0;
  for (const auto& found : per_task) total += found.size();
  std::vector<Found> all;
  all.reserve(total);
  for (auto& found : per_task) {
    all.insert(all.end(), found.begin(), found.end());
    std::vector<Found>().swap(found);
  }
  return all;
}

/// Moves the records of `from` into `to` ordered by key(record) < keys, stably (a counting sort).
template <class Record, class Key>
void counting_sort(const std::vector<Record>& from, std::vector<Record>& to, std::size_t keys, Key&& key) {
  std::vector<std::size_t> next(keys + 1, 0);
  for (const Record& r : from) ++next[std::size_t{key(r)} + 1];
  for (std::size_t k = 0; k < keys; ++k) next[k + 1] += next[k];
  to.resize(from.size());
  for (const Record& r : from) to[next[key(r)]++] = r;
}

/// Sorts records with fields a < n_a and b < n_b by (a, b): by b, then stably by a (least
/// significant first), in time linear in their number and without comparisons.
template <class Record>
void sort_by_indices(std::vector<Record>& records, std::size_t n_a, std::size_t n_b) {
  std::vector<Record> by_b;
  counting_sort(records, by_b, n_b, [](const Record& r) { return r.b; });
  counting_sort(by_b, records, n_a, [](const Record& r) { return r.a; });
}

/// Sorts records with fields a < n_a and b by a, then by less_within_a (each run of equal a is as
/// short as a point's neighbour list).
template <class Record, class Less>
void sort_by_first_index(std::vector<Record>& records, std::size_t n_a, Less&& less_within_a) {
  std::vector<Record> sorted;
  counting_sort(records, sorted, n_a, [](const Record& r) { return r.a; });
  auto run = sorted.begin();
  while (run != sorted.end()) {
    const auto end = std::find_if(run, sorted.end(), [&](const Record& r) { return r.a != run->a; });
    std::sort(run, end, less_within_a);
    run = end;
  }
  records.swap(sorted);
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
  for_each_task(queries, threads, stats, [&](std::size_t task, std::uint32_t root, JoinStats& task_stats) {
    Rule rule(queries, reference, space, self, radii, query_weights, reference_weights, per_task[task], task_stats);
    DualTraversal<Rule>(rule, task_stats).run(root, 0, rule.all_bins());
  });
  std::vector<Count> bins(radii.size(), Count(0));
  for (const auto& task_bins : per_task)
    for (std::size_t j = 0; j < bins.size(); ++j) bins[j] += task_bins[j];
  return bins;
}

}  // namespace kdspace::detail
