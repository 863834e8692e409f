// Dual-tree joins of point sets: every point's k nearest in another set (or its k nearest others),
// every pair within a distance, the sparse distance matrix within a distance, pair counts at many
// radii; in ordinary space or on a torus (periodic boundaries, JoinParams::boxsize).
//
// Two PointTrees (or one, for a self-join) are walked together (traversal.hpp), pruned by the bounds
// of their cells. Exactly the answers of the single-tree queries: the same distances bit for bit (one
// distance kernel, and cell bounds that are exact, see space.hpp), the same tie rule (distance, then
// smaller index), the same answers on any number of threads.
//
//   knn_join(queries, reference, k)      row q: the k nearest reference points of query point q
//   self_knn_join(points, k)             row i: the k nearest points other than i
//   radius_join(queries, reference, r)   row q: the reference points within r, nearest first
//   pairs_within(a, b, r) / (points, r)  index pairs, sorted by (a, b); for one set a < b, each once
//   distances_within(...)                the same pairs with their distances (a sparse matrix)
//   count_pairs(a, b, radii) / (points, radii)            pairs within each radius (cumulative)
//   count_weighted_pairs(a, b, radii, wa, wb) / (points, radii, w)   sums of w_a * w_b instead
//
// Radii are true distances (not squared) and closed: a pair at distance exactly r is within r.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/index_pair.hpp"
#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/box_rule.hpp"
#include "kdspace/joins/join_stats.hpp"
#include "kdspace/joins/run_join.hpp"
#include "kdspace/joins/space.hpp"
#include "kdspace/points/neighbor.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace {

struct JoinParams {
  /// Threads; 0 = all hardware threads. The answers are the same on any number.
  unsigned threads = 0;
  /// Periodic boundaries: the size L of the box on each axis (one value: every axis). Points must
  /// lie in [0, L) there, and a coordinate difference d counts as min(|d|, L - |d|) (a torus, as
  /// SciPy's cKDTree `boxsize`). 0 on an axis: not periodic. Empty: no axis is periodic.
  std::vector<double> boxsize = {};
};

/// A pair within a distance, with that distance (true, not squared): an entry of a sparse matrix.
template <class T>
struct PairDistance {
  std::uint32_t a;
  std::uint32_t b;
  T distance;

  friend bool operator==(const PairDistance& x, const PairDistance& y) {
    return x.a == y.a && x.b == y.b && x.distance == y.distance;
  }
};

namespace detail {

// The largest subtrees a join takes as leaves, compared point by point a block of 8 at a time:
// larger leaves mean fewer pairs of nodes and more distances. Measured (CPU time, 3e5 uniform 3-D
// points, double, the tree's default leaf of 16): k-NN (k = 10) 16: 0.35 s, 32: 0.30 s, 64: 0.31 s;
// pairs within r 16: 0.135 s, 32: 0.135 s, 64: 0.105 s, 128: slower; counts at 20 radii 16: 1.21 s,
// 32: 1.31 s, 64: 1.70 s (block counts of leaves, callgrind, 2e5 points: 16: 5.45e9, 32: 5.64e9).
// With the AVX2 base cases, whose distances cost less, larger leaves still lose (callgrind, 2e5
// uniform 3-D points, double, whole program): k-NN 32: 1.315e9, 48: 1.343e9, 64: 1.394e9; pairs
// 64: 0.587e9, 96: 0.612e9, 128: 0.653e9. Since a self-join offers a point's own leaf nearer first
// (knn_rule.hpp), its insertions no longer grow with the leaf, and 48 beats 32 (callgrind
// --branch-sim, 2e5 points, whole program, instructions / mispredicted branches: k = 10 1218.9e6 /
// 11.08e6 -> 1208.1e6 / 10.54e6; k = 20 2236.5e6 / 17.17e6 -> 2159.5e6 / 16.06e6; k = 1 611.6e6 /
// 3.24e6 -> 622.2e6 / 2.99e6), 64 does not (k = 10 1225.2e6 / 10.03e6). A join of two sets, and a
// PeriodicTree, offer no leaf nearer first, so they keep 32 (the 1.315e9 above).
inline constexpr std::size_t knn_leaf_points = 32;
inline constexpr std::size_t self_knn_leaf_points = 48;
inline constexpr std::size_t range_leaf_points = 64;
inline constexpr std::size_t count_leaf_points = 16;

/// The joins of one tree type; compiled once in the library for the common types.
template <class T, int Dim, class Metric>
struct Joins {
  using Tree = PointTree<T, Dim, Metric>;
  using Bounded = BoundedTree<T, Dim>;

  static NeighborLists<T> knn(const Tree& queries, const Tree* reference, std::size_t k, const JoinParams& params,
                              JoinStats* stats) {
    const bool self = reference == nullptr;
    const Tree& ref = self ? queries : *reference;
    check_pair(queries, ref);
    const std::size_t available = self ? ref.size() - 1 : ref.size();
    if (k == 0) throw Error("k must be at least 1");
    if (k > available)
      throw Error("k = " + std::to_string(k) + " exceeds the number of " + (self ? "other points (" : "points (") +
                  std::to_string(available) + ")");
    const BoundedPair trees(queries, reference, self ? self_knn_leaf_points : knn_leaf_points);
    const std::vector<T> period = trees.periods(params);
    return with_space(period, [&](const auto& space) {
      return knn_join_trees<Metric>(trees.first, trees.second(), k, self, space, params.threads, stats);
    });
  }

  static NeighborLists<T> radius(const Tree& queries, const Tree& reference, T r, const JoinParams& params, JoinStats* stats) {
    return neighbor_lists(found_within(queries, &reference, r, params, stats, NearestFirst{}), queries.size());
  }

  // ---- one query against a reference prepared once (PeriodicTree) --------------------------------

  static std::vector<Neighbor<T>> knn_one(const Bounded& reference, const std::vector<T>& period, const T* q,
                                          std::size_t k) {
    const std::uint32_t index = 0;
    const Bounded query(q, reference.dim(), &index);
    const NeighborLists<T> found = with_space(period, [&](const auto& space) {
      return knn_join_trees<Metric>(query, reference, k, false, space, 1, nullptr);
    });
    return std::vector<Neighbor<T>>(found.neighbors.begin(), found.neighbors.end());
  }

  static std::vector<Neighbor<T>> radius_one(const Bounded& reference, const std::vector<T>& period, const T* q, T r) {
    const T limit = internal_radius(r);
    const std::uint32_t index = 0;
    const Bounded query(q, reference.dim(), &index);
    const NeighborLists<T> found = neighbor_lists(with_space(period, [&](const auto& space) {
      return range_join_trees<DistanceSink<T>, FoundPair<T>>(query, reference, limit, false, space, 1, nullptr,
                                                             NearestFirst{});
    }), 1);
    return std::vector<Neighbor<T>>(found.neighbors.begin(), found.neighbors.end());
  }

  /// The points in box [lo, hi], which wraps around periodic axes where lo > hi; ascending indices.
  static std::vector<Index> box_one(const Bounded& reference, const T* lo, const T* hi) {
    const std::uint32_t index = 0;
    const Bounded query(lo, reference.dim(), &index);
    std::vector<Index> found;
    BoxRule<T, Dim> rule(query, reference, lo, hi, found);
    JoinStats stats;
    DualTraversal<BoxRule<T, Dim>>(rule, stats).run(0, 0, {});
    std::sort(found.begin(), found.end());
    return found;
  }

  static std::vector<IndexPair> pairs(const Tree& a, const Tree* b, T r, const JoinParams& params, JoinStats* stats) {
    const T limit = internal_radius(r);
    const bool self = b == nullptr;
    check_pair(a, self ? a : *b);
    const BoundedPair trees(a, b, range_leaf_points);
    const std::vector<T> period = trees.periods(params);
    std::vector<IndexPair> found = with_space(period, [&](const auto& space) {
      return range_join_trees<PairSink, IndexPair>(trees.first, trees.second(), limit, self, space, params.threads, stats,
                                                   BySecondIndex{});
    });
    return found;
  }

  static std::vector<PairDistance<T>> distances(const Tree& a, const Tree* b, T r, const JoinParams& params,
                                                JoinStats* stats) {
    const std::vector<FoundPair<T>> found = found_within(a, b, r, params, stats, BySecondIndex{});
    std::vector<PairDistance<T>> out;
    out.reserve(found.size());
    for (const auto& f : found) out.push_back(PairDistance<T>{f.a, f.b, Metric::to_distance(f.dist)});
    return out;
  }

  static std::vector<std::uint64_t> count(const Tree& a, const Tree* b, const std::vector<T>& radii,
                                          const JoinParams& params, JoinStats* stats) {
    return count_as<std::uint64_t>(a, b, radii, nullptr, nullptr, params, stats);
  }

  static std::vector<double> count_weighted(const Tree& a, const Tree* b, const std::vector<T>& radii,
                                            const double* weights_a, const double* weights_b, const JoinParams& params,
                                            JoinStats* stats) {
    return count_as<double>(a, b, radii, weights_a, weights_b, params, stats);
  }

 private:
  /// Count: std::uint64_t (pairs; no weights) or double (sums of weight products).
  template <class Count>
  static std::vector<Count> count_as(const Tree& a, const Tree* b, const std::vector<T>& radii, const double* weights_a,
                                     const double* weights_b, const JoinParams& params, JoinStats* stats) {
    const bool self = b == nullptr;
    check_pair(a, self ? a : *b);
    if (radii.empty()) throw Error("no radii: give at least one");
    std::vector<std::size_t> order(radii.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::vector<T> internal;
    for (const T r : radii) internal.push_back(internal_radius(r));
    std::stable_sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) { return internal[x] < internal[y]; });
    std::vector<T> sorted;
    for (const std::size_t j : order) sorted.push_back(internal[j]);
    sorted.push_back(std::numeric_limits<T>::infinity());  // the bin of pairs beyond every radius

    const BoundedPair trees(a, b, count_leaf_points);
    const std::vector<T> period = trees.periods(params);
    std::vector<NodeWeights> weights;
    if constexpr (std::is_same_v<Count, double>) {
      check_weights(weights_a, a.size(), "weights");
      weights.emplace_back(trees.first, weights_a);
      if (!self) {
        check_weights(weights_b, b->size(), "weights of the second set");
        weights.emplace_back(trees.second(), weights_b);
      }
    }
    const NodeWeights* wa = weights.empty() ? nullptr : &weights.front();
    const NodeWeights* wb = weights.empty() ? nullptr : &weights.back();
    const std::vector<Count> bins = with_space(period, [&](const auto& space) {
      return count_join_trees<Count>(trees.first, trees.second(), sorted, self, space, wa, wb, params.threads, stats);
    });
    std::vector<Count> counts(radii.size());
    Count running = 0;
    for (std::size_t j = 0; j < radii.size(); ++j) counts[order[j]] = running += bins[j];
    return counts;
  }

  // Lists of neighbours by query (rows in original order) from pairs in (a, distance, index) order.
  static NeighborLists<T> neighbor_lists(const std::vector<FoundPair<T>>& found, std::size_t queries) {
    NeighborLists<T> out;
    out.offsets.assign(queries + 1, 0);
    for (const auto& f : found) ++out.offsets[std::size_t{f.a} + 1];
    for (std::size_t q = 0; q < queries; ++q) out.offsets[q + 1] += out.offsets[q];
    out.neighbors.reserve(found.size());
    for (const auto& f : found) out.neighbors.push_back(Neighbor<T>{f.b, Metric::to_distance(f.dist)});
    return out;
  }

  template <class Less>
  static std::vector<FoundPair<T>> found_within(const Tree& a, const Tree* b, T r, const JoinParams& params,
                                                JoinStats* stats, Less&& less_within_a) {
    const T limit = internal_radius(r);
    const bool self = b == nullptr;
    check_pair(a, self ? a : *b);
    const BoundedPair trees(a, b, range_leaf_points);
    const std::vector<T> period = trees.periods(params);
    return with_space(period, [&](const auto& space) {
      return range_join_trees<DistanceSink<T>, FoundPair<T>>(trees.first, trees.second(), limit, self, space,
                                                             params.threads, stats, less_within_a);
    });
  }

  static void check_pair(const Tree& a, const Tree& b) {
    if (a.dim() != b.dim())
      throw Error("the two point sets differ in dimension (" + std::to_string(a.dim()) + " and " +
                  std::to_string(b.dim()) + ")");
  }

  static T internal_radius(T r) {
    if (std::isnan(r) || r < 0) throw Error("radius must be a non-negative number, got " + std::to_string(r));
    return Metric::to_internal(r);
  }

  static void check_weights(const double* w, std::size_t n, const char* what) {
    if (w == nullptr) throw Error(std::string(what) + ": null pointer");
    for (std::size_t i = 0; i < n; ++i)
      if (!std::isfinite(w[i]))
        throw Error(std::string(what) + ": row " + std::to_string(i + 1) + ": weight is not finite (" +
                    std::to_string(w[i]) + ")");
  }

  // The first tree's cells and, unless it is a self-join, the second's.
  struct BoundedPair {
    Bounded first;
    std::optional<Bounded> other;

    BoundedPair(const Tree& a, const Tree* b, std::size_t leaf_points) : first(a, leaf_points) {
      if (b) other.emplace(*b, leaf_points);
    }
    const Bounded& second() const { return other ? *other : first; }

    // The periods of the axes (empty: none periodic), with the points checked to lie in the box.
    std::vector<T> periods(const JoinParams& params) const {
      std::vector<T> period = periods_from_boxsize<T>(params.boxsize, first.dim());
      check_in_box(first, period);
      if (other) check_in_box(*other, period);
      return period;
    }
  };

  template <class F>
  static auto with_space(const std::vector<T>& period, F&& f) {
    if (period.empty()) return f(FlatSpace<Metric>{});
    return f(TorusSpace<Metric, T>{{period.data()}});
  }
};

}  // namespace detail

template <class T, int Dim, class Metric>
NeighborLists<T> knn_join(const PointTree<T, Dim, Metric>& queries, const PointTree<T, Dim, Metric>& reference,
                          std::size_t k, const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::knn(queries, &reference, k, params, stats);
}

/// Row i: the k nearest points other than point i (a point at the same place as i is another point).
/// k <= size() - 1.
template <class T, int Dim, class Metric>
NeighborLists<T> self_knn_join(const PointTree<T, Dim, Metric>& points, std::size_t k, const JoinParams& params = {},
                               JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::knn(points, nullptr, k, params, stats);
}

template <class T, int Dim, class Metric>
NeighborLists<T> radius_join(const PointTree<T, Dim, Metric>& queries, const PointTree<T, Dim, Metric>& reference,
                             typename PointTree<T, Dim, Metric>::Scalar r, const JoinParams& params = {},
                             JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::radius(queries, reference, r, params, stats);
}

template <class T, int Dim, class Metric>
std::vector<IndexPair> pairs_within(const PointTree<T, Dim, Metric>& a, const PointTree<T, Dim, Metric>& b,
                                    typename PointTree<T, Dim, Metric>::Scalar r, const JoinParams& params = {},
                                    JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::pairs(a, &b, r, params, stats);
}

template <class T, int Dim, class Metric>
std::vector<IndexPair> pairs_within(const PointTree<T, Dim, Metric>& points, typename PointTree<T, Dim, Metric>::Scalar r,
                                    const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::pairs(points, nullptr, r, params, stats);
}

template <class T, int Dim, class Metric>
std::vector<PairDistance<T>> distances_within(const PointTree<T, Dim, Metric>& a, const PointTree<T, Dim, Metric>& b,
                                              typename PointTree<T, Dim, Metric>::Scalar r,
                                              const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::distances(a, &b, r, params, stats);
}

template <class T, int Dim, class Metric>
std::vector<PairDistance<T>> distances_within(const PointTree<T, Dim, Metric>& points,
                                              typename PointTree<T, Dim, Metric>::Scalar r,
                                              const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::distances(points, nullptr, r, params, stats);
}

/// counts[j]: the pairs (a, b) with distance <= radii[j] (a from the first set, b from the second).
template <class T, int Dim, class Metric>
std::vector<std::uint64_t> count_pairs(const PointTree<T, Dim, Metric>& a, const PointTree<T, Dim, Metric>& b,
                                       const std::vector<typename PointTree<T, Dim, Metric>::Scalar>& radii,
                                       const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::count(a, &b, radii, params, stats);
}

/// counts[j]: the unordered pairs of distinct points with distance <= radii[j].
template <class T, int Dim, class Metric>
std::vector<std::uint64_t> count_pairs(const PointTree<T, Dim, Metric>& points,
                                       const std::vector<typename PointTree<T, Dim, Metric>::Scalar>& radii,
                                       const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::count(points, nullptr, radii, params, stats);
}

/// sums[j]: the sum of weights_a[a] * weights_b[b] over the pairs with distance <= radii[j] (weights
/// in the points' original order; finite).
template <class T, int Dim, class Metric>
std::vector<double> count_weighted_pairs(const PointTree<T, Dim, Metric>& a, const PointTree<T, Dim, Metric>& b,
                                         const std::vector<typename PointTree<T, Dim, Metric>::Scalar>& radii,
                                         const double* weights_a, const double* weights_b, const JoinParams& params = {},
                                         JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::count_weighted(a, &b, radii, weights_a, weights_b, params, stats);
}

/// sums[j]: the sum of w[a] * w[b] over unordered pairs of distinct points within radii[j].
template <class T, int Dim, class Metric>
std::vector<double> count_weighted_pairs(const PointTree<T, Dim, Metric>& points,
                                         const std::vector<typename PointTree<T, Dim, Metric>::Scalar>& radii,
                                         const double* weights, const JoinParams& params = {}, JoinStats* stats = nullptr) {
  return detail::Joins<T, Dim, Metric>::count_weighted(points, nullptr, radii, weights, weights, params, stats);
}

}  // namespace kdspace

// The joins of the common tree types are compiled once in the library, in three files so that a
// parallel build shares them out (lib/joins/instances_float.cpp, instances_double.cpp,
// instances_fixed.cpp).
namespace kdspace::detail {
#define KDSPACE_JOIN_INSTANCES_FLOAT(PREFIX)    \
  PREFIX struct Joins<float, Dynamic, L2>;      \
  PREFIX struct Joins<float, Dynamic, L1>;      \
  PREFIX struct Joins<float, Dynamic, Linf>;
#define KDSPACE_JOIN_INSTANCES_DOUBLE(PREFIX)   \
  PREFIX struct Joins<double, Dynamic, L2>;     \
  PREFIX struct Joins<double, Dynamic, L1>;     \
  PREFIX struct Joins<double, Dynamic, Linf>;
#define KDSPACE_JOIN_INSTANCES_FIXED(PREFIX)    \
  PREFIX struct Joins<float, 2, L2>;            \
  PREFIX struct Joins<float, 3, L2>;            \
  PREFIX struct Joins<double, 2, L2>;           \
  PREFIX struct Joins<double, 3, L2>;
#define KDSPACE_JOIN_INSTANCES(PREFIX)          \
  KDSPACE_JOIN_INSTANCES_FLOAT(PREFIX)          \
  KDSPACE_JOIN_INSTANCES_DOUBLE(PREFIX)         \
  KDSPACE_JOIN_INSTANCES_FIXED(PREFIX)
KDSPACE_JOIN_INSTANCES(extern template)
}  // namespace kdspace::detail
