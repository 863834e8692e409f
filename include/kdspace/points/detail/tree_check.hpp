// The parts of a PointTree (what an index file stores) and the check that makes parts from outside
// (a loaded file) safe and exact to search.
//
// check_point_tree() accepts exactly the trees the builder makes: nodes in depth-first order (an
// inner node's left child next to it, its right child where its left subtree ends), leaves whose
// point ranges tile [0, n) in that order, no path deeper than max_tree_depth (the search recurses),
// split axes below the dimension, finite bounds of all points (the root cell) and points that lie
// inside them and on the sides of every split their leaves are under (left subtree <= left_max <=
// right_min <= right subtree: the bounds the search prunes with), identical-point leaves that hold identical
// points in ascending index order, and an index array that is a permutation of [0, n). A tree that passes
// cannot make a query read out of bounds, recurse without end, or lose a neighbour: its answers are those of
// brute force over its points. It runs in O(n * dim + nodes), one pass over the points.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <future>
#include <limits>
#include <memory>
#include <string>
#include <system_error>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "kdspace/detail/storage.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/node.hpp"
#include "kdspace/points/params.hpp"

namespace kdspace::detail {

/// The deepest tree a search accepts: the builder's cap on max_depth.
inline constexpr std::size_t max_tree_depth = 256;

/// Everything a PointTree is made of. `backing` keeps borrowed storage alive (null when all is owned).
template <class T>
struct PointTreeParts {
  std::size_t dim = 0;
  BuildParams params;
  Storage<T> points;                ///< n * dim coordinates, rows in leaf order
  Storage<std::uint32_t> order;     ///< original index of each row
  Storage<PointNode<T>> nodes;      ///< depth first; nodes[0] is the root
  std::vector<T> root_lo, root_hi;  ///< bounds of all points (the root cell)
  std::shared_ptr<const void> backing;
};

/// What the check works out on the way: the figures a PointTree keeps besides its arrays.
struct TreeShape {
  std::size_t depth = 0;
  std::size_t leaves = 0;
};

/// Trees of at least this many points check their order on a second thread (a thread's start costs
/// tens of microseconds, the check about a nanosecond a point).
inline constexpr std::size_t parallel_order_check = std::size_t{1} << 17;

template <class T>
class TreeChecker {
 public:
  explicit TreeChecker(const PointTreeParts<T>& p)
      : p_(p), n_(p.order.size()), dim_(p.dim), lo_(p.root_lo), hi_(p.root_hi) {}

  TreeShape run() {
    if (dim_ == 0) fail("dimension 0");
    if (n_ == 0) fail("no points");
    if (n_ >= (std::size_t{1} << 30)) fail(std::to_string(n_) + " points (at most 2^30 - 1)");
    if (p_.points.size() / dim_ != n_ || p_.points.size() % dim_ != 0)
      fail(std::to_string(p_.points.size()) + " coordinates for " + std::to_string(n_) +
           " points of dimension " + std::to_string(dim_));
    if (p_.nodes.empty()) fail("no nodes");
    if (p_.params.leaf_size == 0) fail("leaf_size 0");
    if (p_.params.max_depth > max_tree_depth)
      fail("max_depth " + std::to_string(p_.params.max_depth) + " above 256");
    if (p_.root_lo.size() != dim_ || p_.root_hi.size() != dim_) fail("bounds of the wrong dimension");
    for (std::size_t a = 0; a < dim_; ++a)
      if (!std::isfinite(lo_[a]) || !std::isfinite(hi_[a]) || lo_[a] > hi_[a])
        fail("bounds of coordinate " + std::to_string(a + 1) + " are not finite and ordered");
    // The order check and the walk over nodes and points read different arrays: for a large tree the
    // order check runs on a second thread meanwhile. Errors come out as on one thread (the order's first).
    std::future<void> order;
    if (n_ >= parallel_order_check) order = start_order_check();
    if (!order.valid()) check_order();
    try {
      visit(0);
    } catch (const Error&) {
      if (order.valid()) order.get();
      throw;
    }
    if (order.valid()) order.get();
    if (next_node_ != p_.nodes.size())
      fail("nodes " + std::to_string(next_node_) + " to " + std::to_string(p_.nodes.size() - 1) +
           " are not reached from the root");
    if (next_point_ != n_)
      fail("the leaves hold points [0, " + std::to_string(next_point_) + "), expected [0, " +
           std::to_string(n_) + ")");
    return shape_;
  }

 private:
  [[noreturn]] static void fail(const std::string& what) { throw Error("point tree: " + what); }
  [[noreturn]] static void fail_node(std::size_t id, const std::string& what) {
    fail("node " + std::to_string(id) + ": " + what);
  }

  // check_order() on a second thread; no future when no thread is to be had.
  std::future<void> start_order_check() {
    try {
      return std::async(std::launch::async, [this] { check_order(); });
    } catch (const std::system_error&) {
      return {};
    }
  }

  // A permutation of [0, n): n values below n whose bits cover [0, n) (a value given twice leaves
  // another out). The loop only sets bits, without a branch on each value; a second pass finds the
  // culprit for the message when the check fails.
  void check_order() {
    std::vector<std::uint64_t> seen((n_ + 63) / 64, 0);
    const std::uint32_t* order = p_.order.data();
    const auto n = static_cast<std::uint32_t>(n_);
    std::uint32_t out_of_range = 0;
    for (std::size_t i = 0; i < n_; ++i) out_of_range |= static_cast<std::uint32_t>(order[i] >= n);
    if (out_of_range == 0) {
      auto set = [&seen](std::uint32_t v) { seen[v >> 6] |= std::uint64_t{1} << (v & 63); };
      std::size_t i = 0;
      for (; i + 4 <= n_; i += 4) {  // four independent updates a step: a third faster than one
        set(order[i]);
        set(order[i + 1]);
        set(order[i + 2]);
        set(order[i + 3]);
      }
      for (; i < n_; ++i) set(order[i]);
      std::uint64_t missing = 0;
      for (std::size_t w = 0; w + 1 < seen.size(); ++w) missing |= ~seen[w];
      const std::size_t tail = n_ % 64;
      missing |= ~seen.back() & (tail ? (std::uint64_t{1} << tail) - 1 : ~std::uint64_t{0});
      if (missing == 0) return;
      std::fill(seen.begin(), seen.end(), 0);
    }
    for (std::size_t i = 0; i < n_; ++i) {
      const std::uint32_t v = order[i];
      const std::uint64_t bit = std::uint64_t{1} << (v & 63);
      if (v >= n_ || (seen[v >> 6] & bit) != 0)
        fail("index " + std::to_string(i) + " of the point order is " + std::to_string(v) +
             (v >= n_ ? " (out of range)" : " (given twice)"));
      seen[v >> 6] |= bit;
    }
  }

  void visit(std::size_t depth) {
    const std::size_t id = next_node_++;
    if (id >= p_.nodes.size()) fail("a right child lies past the last node");
    if (depth > max_tree_depth) fail_node(id, "deeper than " + std::to_string(max_tree_depth));
    const PointNode<T>& node = p_.nodes[id];
    if (node.is_leaf()) return visit_leaf(id, node, depth);
    const std::size_t axis = node.axis();
    if (axis >= dim_) fail_node(id, "split axis " + std::to_string(axis) + " is not below the dimension");
    if (std::isnan(node.left_max) || std::isnan(node.right_min) || node.left_max > node.right_min)
      fail_node(id, "split bounds are not ordered (left_max " + std::to_string(node.left_max) +
                        ", right_min " + std::to_string(node.right_min) + ")");
    const T saved_hi = hi_[axis], saved_lo = lo_[axis];
    hi_[axis] = std::min(hi_[axis], node.left_max);
    visit(depth + 1);
    hi_[axis] = saved_hi;
    if (node.right_child() != next_node_)
      fail_node(id, "right child " + std::to_string(node.right_child()) + ", expected " +
                        std::to_string(next_node_));
    lo_[axis] = std::max(lo_[axis], node.right_min);
    visit(depth + 1);
    lo_[axis] = saved_lo;
  }

  void visit_leaf(std::size_t id, const PointNode<T>& leaf, std::size_t depth) {
    const std::size_t first = leaf.first(), count = leaf.count();
    if (first != next_point_ || count > n_ - first)
      fail_node(id, "leaf holds points [" + std::to_string(first) + ", " + std::to_string(first + count) +
                        "), expected them to start at " + std::to_string(next_point_) + " and end by " +
                        std::to_string(n_));
    next_point_ += count;
    shape_.depth = std::max(shape_.depth, depth);
    ++shape_.leaves;
    const T* rows = p_.points.data() + first * dim_;
    const T* lo = lo_.data();
    const T* hi = hi_.data();
    // Every coordinate within the root cell and the splits above (finite bounds: no NaN or
    // infinity passes).
    bool inside;
    switch (dim_) {
      case 2:
        inside = all_inside<2>(rows, count, lo, hi);
        break;
      case 3:
        inside = all_inside<3>(rows, count, lo, hi);
        break;
      default:
        inside = all_inside<0>(rows, count, lo, hi);
        break;
    }
    if (!inside) fail_node(id, "a point lies outside the bounds and splits above its leaf, or is not finite");
    if (!leaf.all_identical()) return;
    for (std::size_t i = 1; i < count; ++i) {
      for (std::size_t a = 0; a < dim_; ++a)
        if (!(rows[i * dim_ + a] == rows[a]))
          fail_node(id, "leaf of identical points holds different points");
      if (!(p_.order[first + i - 1] < p_.order[first + i]))
        fail_node(id, "leaf of identical points lists their indices out of order");
    }
  }

  // Whether lo <= p <= hi for every point p of rows [0, count); D: the dimension, known at compile
  // time for the common cases (the loop then keeps the bounds in registers), or 0.
  template <std::size_t D>
  bool all_inside(const T* rows, std::size_t count, const T* lo, const T* hi) const {
#if defined(__SSE2__)
    // 3-D float points, one 4-float load each (the point and the next one's x, whose lane is
    // ignored): half the scalar loop's instructions. The leaf's last point goes through the scalar
    // loop (its fourth float may lie past the array).
    if constexpr (D == 3 && std::is_same_v<T, float>) {
      if (count > 1) {
        const __m128 low = _mm_setr_ps(lo[0], lo[1], lo[2], 0.f);
        const __m128 high = _mm_setr_ps(hi[0], hi[1], hi[2], 0.f);
        __m128 ok = _mm_castsi128_ps(_mm_set1_epi32(-1));
        for (std::size_t i = 0; i + 1 < count; ++i, rows += 3) {
          const __m128 p = _mm_loadu_ps(rows);
          ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmple_ps(low, p), _mm_cmple_ps(p, high)));
        }
        if ((_mm_movemask_ps(ok) & 7) != 7) return false;
        count = 1;
      }
    }
#endif
    const std::size_t d = D ? D : dim_;
    unsigned ok = 1;
    for (std::size_t i = 0; i < count; ++i, rows += d)
      for (std::size_t a = 0; a < d; ++a)
        ok &= static_cast<unsigned>(lo[a] <= rows[a]) & static_cast<unsigned>(rows[a] <= hi[a]);
    return ok != 0;
  }

  const PointTreeParts<T>& p_;
  std::size_t n_, dim_;
  std::vector<T> lo_, hi_;  // the root cell cut by the splits above the node being visited
  std::size_t next_node_ = 0, next_point_ = 0;
  TreeShape shape_;
};

/// Checks parts from outside (see the top of this file); throws Error("point tree: node 12: ...").
template <class T>
TreeShape check_point_tree(const PointTreeParts<T>& parts) {
  return TreeChecker<T>(parts).run();
}

}  // namespace kdspace::detail
