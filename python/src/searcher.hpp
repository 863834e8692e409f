// The queries of SciPy's cKDTree over one kd-tree, for one metric: k nearest (a strict upper bound,
// k above the number of points, eps), points within a radius (lists, counts, distances) and pair
// counts at many radii, optionally on a periodic box; batches spread over threads.
//
// The pair methods (pairs within a distance, sparse distance matrices) go through the library's
// dual-tree joins (kdspace/joins/joins.hpp) for p = 1, 2 and infinity; other p, and two trees of
// different types, take the single-tree path (ball_matches). Pair counts stay on the single-tree
// path (pair_histogram), measured faster than count_pairs up to ~100 pairs per point (README).
//
// Searcher<T> is what the Python layer holds: T is the scalar of the caller's queries and distances
// (the data's, float32 or float64). TreeSearcher<Tree, T> implements it over one PointTree; its
// with_metric() copies the tree into another metric (PointTree's copying constructor: no new
// build), so one build answers every p. A float tree asked for a general p is widened to double
// (exactly), as p-th powers overflow float's range early.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "kdspace/joins/joins.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/point_tree.hpp"
#include "periodic.hpp"
#include "result_sets.hpp"

namespace kdspace::python {

/// A row of the caller's data (NumPy's intp).
using RowId = std::int64_t;

/// The tree's point i is row ids[i] of the caller's data (rows holding NaN or infinity are left out
/// of the tree); `missing` is the row count, SciPy's index of a missing neighbour.
struct RowMap {
  std::vector<RowId> ids;  // empty: point i is row i
  RowId missing = 0;
  RowId operator()(std::uint32_t i) const { return ids.empty() ? static_cast<RowId>(i) : ids[i]; }
};

/// A point found within a radius: its row and distance.
struct Match {
  RowId row;
  double distance;
};

/// Pairs as rows: (first[i], second[i]), ordered by first then second; distance[i] when asked for.
struct PairRows {
  std::vector<RowId> first, second;
  std::vector<double> distance;
};

/// Options every query shares: threads (0 = all) and the periodic box (null: none).
struct QueryOptions {
  unsigned threads = 1;
  const PeriodicBox<double>* box = nullptr;
};

template <class T>
class Searcher {
 public:
  virtual ~Searcher() = default;

  /// For nq queries (row-major, dim() each): the k nearest rows with distance < upper_bound, nearest
  /// first, ties by smaller row; missing ones as (inf, map.missing). dist and rows hold nq * k.
  virtual void knn(const T* queries, std::size_t nq, std::size_t k, double eps, double upper_bound,
                   const QueryOptions& options, T* dist, RowId* rows) const = 0;
  /// How many points lie within radii[q] of query q (closed ball).
  virtual void ball_counts(const T* queries, std::size_t nq, const double* radii, const QueryOptions& options,
                           RowId* counts) const = 0;
  /// The points within radii[q] of query q: rows ascending when `sort_rows`, otherwise in no set order;
  /// with their distances.
  virtual void ball_matches(const T* queries, std::size_t nq, const double* radii, bool sort_rows,
                            const QueryOptions& options, std::vector<std::vector<Match>>& out) const = 0;
  /// Pair counts: bins[b] += w(query) * w(point) for every pair whose distance is within radii[b] and
  /// above radii[b - 1] (radii true distances, ascending, distinct). query_weights (by query) and
  /// point_weights (by the caller's row) may be null (weight 1).
  virtual void pair_histogram(const T* queries, const double* query_weights, std::size_t nq,
                              const std::vector<double>& radii, const double* point_weights,
                              const QueryOptions& options, double* bins) const = 0;

  /// The pairs (this tree's row, other's row) within r (closed; r < 0: none), with distances if
  /// `distances`, by a join; other null: the pairs of this tree's distinct points, each once
  /// (first < second). False, doing nothing, where the joins do not apply (a metric they do not
  /// serve, p not 1, 2 or infinity; other of another type): the caller takes the single-tree path.
  virtual bool join_pairs(const Searcher<T>* other, double r, bool distances, const JoinParams& params,
                          PairRows& out) const = 0;

  /// The same tree searched with the Minkowski p-norm (1, 2, infinity or any p >= 1).
  virtual std::shared_ptr<const Searcher<T>> with_metric(double p) const = 0;

  // The tree's shape, for the node view: nodes depth first, and the rows in leaf order.
  virtual std::size_t size() const = 0;  ///< points in the tree
  virtual std::size_t node_count() const = 0;
  virtual std::size_t dim() const = 0;
  /// Per node: split axis (-1 for a leaf), the first and one-past-last leaf-order position it covers,
  /// its children (-1 for a leaf), and the tight bounds of its children along the axis.
  virtual void node_table(RowId* axis, RowId* start, RowId* end, RowId* lesser, RowId* greater,
                          double* left_max, double* right_min) const = 0;
  virtual void leaf_rows(RowId* rows) const = 0;
};

template <class Tree, class T>
class TreeSearcher final : public Searcher<T> {
  using S = typename Tree::Scalar;  // the tree's scalar: T, or double for a widened float tree
  static_assert(std::is_same_v<S, T> || std::is_same_v<S, double>, "a tree holds T or double");
  using Metric = std::decay_t<decltype(std::declval<const Tree&>().metric())>;
  // The metrics the joins serve (kdspace/joins/space.hpp).
  static constexpr bool joinable =
      std::is_same_v<S, T> &&
      (std::is_same_v<Metric, L2> || std::is_same_v<Metric, L1> || std::is_same_v<Metric, Linf>);

 public:
  TreeSearcher(Tree tree, std::shared_ptr<const RowMap> map) : tree_(std::move(tree)), map_(std::move(map)) {}

  const Tree& tree() const { return tree_; }

  void knn(const T* queries, std::size_t nq, std::size_t k, double eps, double upper_bound,
           const QueryOptions& options, T* dist, RowId* rows) const override {
    const std::size_t found = std::min(k, tree_.size());  // the rest is missing
    const SearchParams params{eps};
    auto write = [&](std::size_t q, const detail::Candidate<S>* first, std::size_t count) {
      for (std::size_t i = 0; i < k; ++i) {
        const bool hit = i < count;
        dist[q * k + i] = hit ? static_cast<T>(tree_.metric().to_distance(first[i].dist)) : infinity();
        rows[q * k + i] = hit ? (*map_)(first[i].index) : map_->missing;
      }
    };
    if (!options.box && std::isinf(upper_bound) && upper_bound > 0) {
      batch_knn(queries, nq, found, k, params, options.threads, dist, rows);
      return;
    }
    const S limit = strictly_below(internal_limit(upper_bound));
    for_queries(
        queries, nq, options.threads,
        [&](const S* q, std::size_t i, Scratch& scratch) {
          auto& kept = scratch.candidates;
          if (options.box) {
            knn_periodic(q, found, limit, params, *scratch.box, scratch);
          } else {
            detail::KnnResults<S> results(found, limit, kept);
            tree_.query_with(q, results, params);
            results.sorted();
          }
          write(i, kept.data(), std::min(kept.size(), found));
        },
        options.box);
  }

  void ball_counts(const T* queries, std::size_t nq, const double* radii, const QueryOptions& options,
                   RowId* counts) const override {
    for_queries(
        queries, nq, options.threads,
        [&](const S* q, std::size_t i, Scratch& scratch) {
          const S limit = internal_limit(radii[i]);
          if (options.box) {
            within_periodic(q, limit, *scratch.box, scratch);
            counts[i] = static_cast<RowId>(scratch.candidates.size());
            return;
          }
          CountWithin<S> counter(limit);
          tree_.query_with(q, counter);
          counts[i] = static_cast<RowId>(counter.count());
        },
        options.box);
  }

  void ball_matches(const T* queries, std::size_t nq, const double* radii, bool sort_rows,
                    const QueryOptions& options, std::vector<std::vector<Match>>& out) const override {
    out.assign(nq, {});
    for_queries(
        queries, nq, options.threads,
        [&](const S* q, std::size_t i, Scratch& scratch) {
          const S limit = internal_limit(radii[i]);
          if (options.box) {
            within_periodic(q, limit, *scratch.box, scratch);
          } else {
            Within<S> within(limit, scratch.candidates);
            tree_.query_with(q, within);
          }
          auto& row = out[i];
          row.reserve(scratch.candidates.size());
          for (const auto& c : scratch.candidates)
            row.push_back({(*map_)(c.index), static_cast<double>(tree_.metric().to_distance(c.dist))});
          if (sort_rows)
            std::sort(row.begin(), row.end(), [](const Match& a, const Match& b) { return a.row < b.row; });
        },
        options.box);
  }

  void pair_histogram(const T* queries, const double* query_weights, std::size_t nq,
                      const std::vector<double>& radii, const double* point_weights,
                      const QueryOptions& options, double* bins) const override {
    std::vector<S> limits;
    for (double r : radii) limits.push_back(internal_limit(r));
    std::vector<double> weights;  // by the tree's own index
    if (point_weights) {
      weights.resize(tree_.size());
      for (std::size_t i = 0; i < tree_.size(); ++i)
        weights[i] = point_weights[(*map_)(static_cast<std::uint32_t>(i))];
    }
    const double* by_index = point_weights ? weights.data() : nullptr;
    const std::size_t nbins = radii.size();
    std::vector<std::vector<double>> per_worker(detail::resolve_threads(options.threads),
                                                std::vector<double>(nbins));
    for_queries(
        queries, nq, options.threads,
        [&](const S* q, std::size_t i, Scratch& scratch, unsigned worker) {
          std::vector<double>& local = scratch.bins;
          local.assign(nbins, 0.0);
          RadiusHistogram<S, double> histogram(limits, by_index, local.data());
          if (options.box) {
            within_periodic(q, limits.back(), *scratch.box, scratch);
            for (const auto& c : scratch.candidates) histogram.offer(c.dist, c.index);
          } else {
            tree_.query_with(q, histogram);
          }
          const double w = query_weights ? query_weights[i] : 1.0;
          for (std::size_t b = 0; b < nbins; ++b) per_worker[worker][b] += w * local[b];
        },
        options.box);
    for (std::size_t b = 0; b < nbins; ++b) {
      bins[b] = 0;
      for (const auto& w : per_worker) bins[b] += w[b];
    }
  }

  bool join_pairs(const Searcher<T>* other, double r, bool distances, const JoinParams& params,
                  PairRows& out) const override {
    if constexpr (!joinable) {
      return false;
    } else {
      const auto* b = dynamic_cast<const TreeSearcher*>(other);
      if (other && !b) return false;
      out = {};
      if (r < 0) return true;
      const RowMap& other_rows = b ? *b->map_ : *map_;
      auto put = [&](std::uint32_t x, std::uint32_t y) {
        out.first.push_back((*map_)(x));
        out.second.push_back(other_rows(y));
      };
      // Rows ascend with the tree's indices (row_ids ascend), so the joins' (a, b) order is the rows'.
      if (distances) {
        const auto found = b ? distances_within(tree_, b->tree_, radius_of(r), params)
                             : distances_within(tree_, radius_of(r), params);
        out.distance.reserve(found.size());
        for (const auto& f : found) {
          put(f.a, f.b);
          out.distance.push_back(static_cast<double>(f.distance));
        }
      } else {
        const auto found = b ? pairs_within(tree_, b->tree_, radius_of(r), params)
                             : pairs_within(tree_, radius_of(r), params);
        out.first.reserve(found.size());
        out.second.reserve(found.size());
        for (const auto& f : found) put(f.a, f.b);
      }
      return true;
    }
  }

  std::shared_ptr<const Searcher<T>> with_metric(double p) const override {
    if (p == 2) return copy_into<S, L2>(L2{});
    if (p == 1) return copy_into<S, L1>(L1{});
    if (std::isinf(p)) return copy_into<S, Linf>(Linf{});
    return copy_into<double, Minkowski>(Minkowski(p));
  }

  std::size_t size() const override { return tree_.size(); }
  std::size_t node_count() const override { return tree_.node_count(); }
  std::size_t dim() const override { return tree_.dim(); }

  void node_table(RowId* axis, RowId* start, RowId* end, RowId* lesser, RowId* greater, double* left_max,
                  double* right_min) const override {
    const auto& nodes = tree_.nodes();
    // Depth first: a subtree is a run of nodes, its points a run of the leaf order; children first.
    for (std::size_t id = nodes.size(); id-- > 0;) {
      const auto& node = nodes[id];
      if (node.is_leaf()) {
        axis[id] = lesser[id] = greater[id] = -1;
        start[id] = node.first();
        end[id] = static_cast<RowId>(node.first()) + node.count();
        left_max[id] = right_min[id] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      axis[id] = node.axis();
      lesser[id] = static_cast<RowId>(id + 1);
      greater[id] = node.right_child();
      start[id] = start[id + 1];
      end[id] = end[node.right_child()];
      left_max[id] = static_cast<double>(node.left_max);
      right_min[id] = static_cast<double>(node.right_min);
    }
  }

  void leaf_rows(RowId* rows) const override {
    const auto& order = tree_.leaf_order();
    for (std::size_t i = 0; i < order.size(); ++i) rows[i] = (*map_)(order[i]);
  }

 private:
  // Per-worker scratch: the query as S, the candidates of one query, a periodic query's images.
  struct Scratch {
    std::vector<S> query, wrapped;
    std::vector<detail::Candidate<S>> candidates, image_candidates;
    std::vector<double> bins;
    std::unique_ptr<PeriodicBox<S>> box;
  };

  static T infinity() { return std::numeric_limits<T>::infinity(); }

  // A distance (SciPy's upper bound or radius, a double) in the tree's internal units; +inf beyond S.
  // A negative distance holds nothing: its limit is below every internal distance.
  S internal_limit(double distance) const {
    if (distance < 0) return S(-1);
    if (!(distance < static_cast<double>(std::numeric_limits<S>::max())))
      return std::numeric_limits<S>::infinity();
    return tree_.metric().to_internal(static_cast<S>(distance));
  }

  // A radius (>= 0) as the tree's scalar; +inf beyond its range.
  static S radius_of(double r) {
    return r < static_cast<double>(std::numeric_limits<S>::max()) ? static_cast<S>(r)
                                                                   : std::numeric_limits<S>::infinity();
  }

  template <class S2, class M>
  std::shared_ptr<const Searcher<T>> copy_into(const M& metric) const {
    using Copy = PointTree<S2, Dynamic, M>;
    return std::make_shared<TreeSearcher<Copy, T>>(Copy(tree_, metric), map_);
  }

  // Calls body(query as S, query number, scratch[, worker]) for each query, on `threads` threads,
  // taking the queries in leaf order (see leaf_order_of). A periodic query arrives wrapped into the
  // box.
  template <class Body>
  void for_queries(const T* queries, std::size_t nq, unsigned threads, Body&& body,
                   const PeriodicBox<double>* box) const {
    const std::size_t d = tree_.dim();
    const std::vector<std::uint32_t> order = leaf_order_of(queries, nq);
    detail::parallel_for(nq, threads, 64, [&](std::size_t begin, std::size_t end, unsigned worker) {
      Scratch scratch;
      scratch.query.resize(d);
      if (box) {
        scratch.box = std::make_unique<PeriodicBox<S>>();
        scratch.box->size.assign(box->size.begin(), box->size.end());
        scratch.box->lo.assign(box->lo.begin(), box->lo.end());
        scratch.box->hi.assign(box->hi.begin(), box->hi.end());
        scratch.wrapped.resize(d);
      }
      for (std::size_t position = begin; position < end; ++position) {
        const std::size_t i = order[position];
        const S* q = as_scalar(queries + i * d, scratch.query);
        if (box) {
          wrap_into(*scratch.box, q, scratch.wrapped.data(), d);
          q = scratch.wrapped.data();
        }
        if constexpr (std::is_invocable_v<Body, const S*, std::size_t, Scratch&, unsigned>)
          body(q, i, scratch, worker);
        else
          body(q, i, scratch);
      }
    });
  }

  // The query row as S: itself when T is S, otherwise widened (exactly) into `buffer`.
  static const S* as_scalar(const T* q, std::vector<S>& buffer) {
    if constexpr (std::is_same_v<S, T>) {
      return q;
    } else {
      std::copy(q, q + buffer.size(), buffer.begin());
      return buffer.data();
    }
  }

  // Plain k-NN batches through the tree's knn_batch (which may answer high-dimensional batches by
  // its blocked scan), in blocks so that its result lists stay small, and in the order of the leaves
  // the queries fall in (leaf_order_of): consecutive queries then mostly read the same nodes and
  // points, still in cache. `found` <= k columns come from the tree; the rest of each row is missing.
  void batch_knn(const T* queries, std::size_t nq, std::size_t found, std::size_t k,
                 const SearchParams& params, unsigned threads, T* dist, RowId* rows) const {
    constexpr std::size_t block = 1 << 16;
    const std::size_t d = tree_.dim();
    const std::vector<std::uint32_t> order = leaf_order_of(queries, nq);
    std::vector<S> gathered;
    for (std::size_t first = 0; first < nq; first += block) {
      const std::size_t count = std::min(block, nq - first);
      gathered.resize(count * d);
      for (std::size_t q = 0; q < count; ++q) {
        const T* from = queries + std::size_t{order[first + q]} * d;
        std::copy(from, from + d, gathered.begin() + static_cast<std::ptrdiff_t>(q * d));
      }
      NeighborLists<S> lists;
      if (found > 0) lists = tree_.knn_batch(gathered.data(), count, found, params, threads);
      for (std::size_t q = 0; q < count; ++q) {
        const std::size_t out = order[first + q];
        T* dist_row = dist + out * k;
        RowId* row = rows + out * k;
        for (std::size_t i = 0; i < k; ++i) {
          // A distance that overflowed to +inf is never a neighbour (SciPy: inf < inf is false).
          const Neighbor<S>* nb = i < found ? &lists.neighbors[q * found + i] : nullptr;
          const bool hit = nb && !std::isinf(nb->distance);
          dist_row[i] = hit ? static_cast<T>(nb->distance) : infinity();
          row[i] = hit ? (*map_)(nb->index) : map_->missing;
        }
      }
    }
  }

  // The queries' numbers sorted by the leaf each one's descent reaches first (the nearer child at
  // every node, as the search goes): a counting sort on the leaf's node number, depth-first, so
  // queries in neighbouring cells follow each other.
  std::vector<std::uint32_t> leaf_order_of(const T* queries, std::size_t nq) const {
    if (nq > std::numeric_limits<std::uint32_t>::max())
      throw Error("too many queries in one call: " + std::to_string(nq) + " (at most 2^32 - 1)");
    std::vector<std::uint32_t> order(nq);
    const auto& nodes = tree_.nodes();
    const std::size_t d = tree_.dim();
    std::vector<std::uint32_t> leaf(nq), starts(nodes.size() + 1, 0);
    for (std::size_t q = 0; q < nq; ++q) {
      const T* x = queries + q * d;
      std::uint32_t id = 0;
      while (!nodes[id].is_leaf()) {
        const auto& node = nodes[id];
        const S v = static_cast<S>(x[node.axis()]);
        id = v - node.left_max <= node.right_min - v ? id + 1 : node.right_child();
      }
      leaf[q] = id;
      ++starts[id + 1];
    }
    for (std::size_t i = 1; i < starts.size(); ++i) starts[i] += starts[i - 1];
    for (std::size_t q = 0; q < nq; ++q) order[starts[leaf[q]]++] = static_cast<std::uint32_t>(q);
    return order;
  }

  // The k nearest of a wrapped query on the periodic box, into scratch.candidates (sorted).
  void knn_periodic(const S* q, std::size_t k, S limit, const SearchParams& params, const PeriodicBox<S>& box,
                    Scratch& scratch) const {
    auto& kept = scratch.candidates;
    {
      detail::KnnResults<S> results(k, limit, kept);
      tree_.query_with(q, results, params);
      results.sorted();
    }
    if (k == 0) return;
    const S reach = kept.size() == k ? kept.back().dist : limit;  // no image need look farther
    for_each_image(box, tree_.metric(), q, tree_.dim(), reach, [&](const S* image, bool shifted) {
      if (!shifted) return;
      detail::KnnResults<S> results(k, reach, scratch.image_candidates);
      tree_.query_with(image, results, params);
      kept.insert(kept.end(), scratch.image_candidates.begin(), scratch.image_candidates.end());
    });
    nearest_image_only(kept);
    if (kept.size() > k) kept.resize(k);
  }

  // Every point within `limit` of a wrapped query on the periodic box, into scratch.candidates.
  void within_periodic(const S* q, S limit, const PeriodicBox<S>& box, Scratch& scratch) const {
    auto& kept = scratch.candidates;
    kept.clear();
    for_each_image(box, tree_.metric(), q, tree_.dim(), limit, [&](const S* image, bool) {
      Within<S> within(limit, scratch.image_candidates);
      tree_.query_with(image, within);
      kept.insert(kept.end(), scratch.image_candidates.begin(), scratch.image_candidates.end());
    });
    nearest_image_only(kept);
  }

  Tree tree_;
  std::shared_ptr<const RowMap> map_;
};

}  // namespace kdspace::python
