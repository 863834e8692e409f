// PeriodicTree: the single-tree queries of a PointTree (k-NN, radius, box, and their batches) on a
// torus: periodic boundaries with a box size per axis, as SciPy's cKDTree `boxsize`.
//
// A wrapper, so that PointTree's own search stays as it is: it keeps a reference to the tree and the
// bounding box of every node (BoundedTree), and answers each query as a join of a one-point query
// set with the tree (the dual-tree traversal and its rules, joins/), the batches as joins of a tree
// built over the queries. Distances are min(|d|, L - |d|) per periodic axis, combined in the order of
// internal_distance, so the answers equal a brute force on the torus bit for bit, ties by index.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/joins/joins.hpp"
#include "kdspace/points/detail/input_checks.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace {

template <class T, int Dim = Dynamic, class Metric = L2>
class PeriodicTree {
 public:
  using Tree = PointTree<T, Dim, Metric>;

  /// Searches `tree` (which must outlive this) on a torus: boxsize as JoinParams::boxsize (one size,
  /// or one per axis; 0: that axis is not periodic; at least one axis periodic). Throws Error if a
  /// point lies outside [0, L) on a periodic axis (the message names its row).
  PeriodicTree(const Tree& tree, std::vector<double> boxsize)
      : tree_(tree), bounded_(tree, detail::knn_leaf_points) {
    params_.boxsize = std::move(boxsize);
    period_ = detail::periods_from_boxsize<T>(params_.boxsize, tree.dim());
    if (period_.empty()) throw Error("boxsize: no axis is periodic (give a size > 0 for at least one axis)");
    detail::check_in_box(bounded_, period_);
  }

  std::size_t size() const { return tree_.size(); }
  std::size_t dim() const { return tree_.dim(); }
  /// The period of each axis: its box size, or +inf where it is not periodic.
  const std::vector<T>& periods() const { return period_; }

  /// The k nearest points to q on the torus, (distance, index) order. 1 <= k <= size().
  std::vector<Neighbor<T>> knn(const T* q, std::size_t k) const {
    detail::check_k(k, size());
    check_query(q, "query");
    return detail::Joins<T, Dim, Metric>::knn_one(bounded_, period_, q, k);
  }

  /// Every point within distance r of q on the torus (closed ball), (distance, index) order.
  std::vector<Neighbor<T>> radius(const T* q, T r) const {
    check_query(q, "query");
    return detail::Joins<T, Dim, Metric>::radius_one(bounded_, period_, q, r);
  }

  /// The points p with lo <= p <= hi on every axis, ascending indices. On a periodic axis lo and hi
  /// lie in [0, L], and lo > hi means the box wraps around: [lo, L) and [0, hi]. On other axes
  /// lo <= hi.
  std::vector<Index> box(const T* lo, const T* hi) const {
    detail::check_finite(lo, dim(), "box lower corner");
    detail::check_finite(hi, dim(), "box upper corner");
    for (std::size_t a = 0; a < dim(); ++a) {
      const std::string axis = "box: coordinate " + std::to_string(a + 1);
      if (std::isinf(period_[a])) {
        if (lo[a] > hi[a])
          throw Error(axis + ": lower corner exceeds upper corner on an axis that is not periodic (" +
                      std::to_string(lo[a]) + " > " + std::to_string(hi[a]) + ")");
      } else if (!(lo[a] >= 0 && lo[a] <= period_[a] && hi[a] >= 0 && hi[a] <= period_[a])) {
        throw Error(axis + ": corners must lie in [0, " + std::to_string(period_[a]) + "] on a periodic axis");
      }
    }
    return detail::Joins<T, Dim, Metric>::box_one(bounded_, lo, hi);
  }

  /// knn for nq queries (row-major), as a join of a tree over the queries with this one.
  NeighborLists<T> knn_batch(const T* queries, std::size_t nq, std::size_t k, unsigned threads = 0,
                             JoinStats* stats = nullptr) const {
    detail::check_k(k, size());
    if (nq == 0) return {};
    const Tree query_tree = tree_of(queries, nq);
    return detail::Joins<T, Dim, Metric>::knn(query_tree, &tree_, k, with_threads(threads), stats);
  }

  /// radius for nq queries, as a join.
  NeighborLists<T> radius_batch(const T* queries, std::size_t nq, T r, unsigned threads = 0,
                                JoinStats* stats = nullptr) const {
    if (nq == 0) return {};
    const Tree query_tree = tree_of(queries, nq);
    return detail::Joins<T, Dim, Metric>::radius(query_tree, tree_, r, with_threads(threads), stats);
  }

 private:
  void check_query(const T* q, const std::string& what) const {
    detail::check_finite(q, dim(), what);
    for (std::size_t a = 0; a < dim(); ++a)
      if (!detail::inside_period(q[a], period_[a]))
        throw Error(what + ": coordinate " + std::to_string(a + 1) + " = " + std::to_string(q[a]) +
                    " lies outside the periodic box [0, " + std::to_string(period_[a]) + ")");
  }

  // Queries are checked here so that a bad one is named "query row R".
  Tree tree_of(const T* queries, std::size_t nq) const {
    detail::check_query_rows(queries, nq, dim());
    try {
      detail::check_in_box(queries, nq, dim(), period_);
    } catch (const Error& e) {
      throw Error(std::string("query ") + e.what());
    }
    return Tree(queries, nq, dim());
  }

  JoinParams with_threads(unsigned threads) const {
    JoinParams p = params_;
    p.threads = threads;
    return p;
  }

  const Tree& tree_;
  detail::BoundedTree<T, Dim> bounded_;
  JoinParams params_;
  std::vector<T> period_;
};

}  // namespace kdspace
