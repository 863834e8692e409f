// Brute force: the reference every exact query is checked against, and the fallback for tiny data.
#pragma once

#include <algorithm>
#include <cstddef>
#include <limits>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace {

/// The k first points in (distance, index) order: the contract of PointTree::knn, by scanning all.
/// `metric` matters only for a metric with state (Minkowski(p)).
template <class Metric, class T>
std::vector<Neighbor<T>> brute_force_knn(const Metric& metric, const T* rows, std::size_t n, std::size_t dim,
                                         const T* q, std::size_t k) {
  if (k == 0 || k > n) throw Error("brute_force_knn: k must be in [1, n]");
  std::vector<detail::Candidate<T>> all(n);
  for (std::size_t i = 0; i < n; ++i)
    all[i] = {internal_distance(metric, q, rows + i * dim, dim), static_cast<std::uint32_t>(i)};
  std::partial_sort(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(k), all.end(), detail::comes_before);
  std::vector<Neighbor<T>> out;
  for (std::size_t i = 0; i < k; ++i) out.push_back({all[i].index, metric.to_distance(all[i].dist)});
  return out;
}

template <class Metric = L2, class T>
std::vector<Neighbor<T>> brute_force_knn(const T* rows, std::size_t n, std::size_t dim, const T* q, std::size_t k) {
  return brute_force_knn(Metric{}, rows, n, dim, q, k);
}

/// Every point within distance r (closed ball), in (distance, index) order.
template <class Metric, class T>
std::vector<Neighbor<T>> brute_force_radius(const Metric& metric, const T* rows, std::size_t n, std::size_t dim,
                                            const T* q, T r) {
  const T limit = metric.to_internal(r);
  std::vector<detail::Candidate<T>> found;
  for (std::size_t i = 0; i < n; ++i) {
    const T d = internal_distance(metric, q, rows + i * dim, dim);
    if (d <= limit) found.push_back({d, static_cast<std::uint32_t>(i)});
  }
  std::sort(found.begin(), found.end(), detail::comes_before);
  std::vector<Neighbor<T>> out;
  for (const auto& c : found) out.push_back({c.index, metric.to_distance(c.dist)});
  return out;
}

template <class Metric = L2, class T>
std::vector<Neighbor<T>> brute_force_radius(const T* rows, std::size_t n, std::size_t dim, const T* q, T r) {
  return brute_force_radius(Metric{}, rows, n, dim, q, r);
}

}  // namespace kdspace
