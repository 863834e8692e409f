// What a query hands back, shared by PointTree and DynamicPointTree: a result set's sorted
// candidates turned into neighbours with true distances, and the statistics of workers summed.
#pragma once

#include <vector>

#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace::detail {

/// Converts to true distances, keeping the order of the internal ones (the metric's to_distance is
/// monotone, so the tie rule decided on internal distances stands).
template <class T, class Metric>
void write_neighbors(const Metric& metric, const std::vector<Candidate<T>>& sorted, Neighbor<T>* out) {
  for (const auto& c : sorted) *out++ = Neighbor<T>{c.index, metric.to_distance(c.dist)};
}

/// The neighbours of one query, and its statistics added to *stats when asked for.
template <class T, class Metric>
std::vector<Neighbor<T>> finish_query(const Metric& metric, const std::vector<Candidate<T>>& sorted,
                                      QueryStats* stats, const QueryStats& local) {
  std::vector<Neighbor<T>> out(sorted.size());
  write_neighbors(metric, sorted, out.data());
  if (stats) *stats += local;
  return out;
}

/// Adds the statistics of a batch's workers to *stats when asked for.
inline void sum_stats(const std::vector<QueryStats>& per_worker, QueryStats* stats) {
  if (!stats) return;
  for (const auto& s : per_worker) *stats += s;
}

}  // namespace kdspace::detail
