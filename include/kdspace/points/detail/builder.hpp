// Builds the node array of a PointTree: recursive splitting by the split rules, one pass over a
// node's points per split, subtrees near the root built on several threads.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/points/detail/node.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/row_bounds.hpp"
#include "kdspace/points/detail/split_rules.hpp"
#include "kdspace/points/params.hpp"

namespace kdspace::detail {

template <class T>
struct BuiltTree {
  // In huge pages where enabled (detail/huge_pages.hpp), as the buffers below.
  HugePageVector<PointNode<T>> nodes;
  HugePageVector<T> points;             ///< the points in leaf order, row-major
  HugePageVector<std::uint32_t> order;  ///< original index of each point, in leaf order
  std::size_t depth = 0;             ///< depth of the deepest leaf (a lone root leaf has depth 0)
  std::size_t leaves = 0;
};

/// The rows of a build and the moves between its buffers: the part of the build the split rules do
/// not decide, kept apart from them so that its code is compiled once per scalar and dimension rather
/// than once per pair of rules. The root reads the caller's rows (`input_buffer`); then the levels
/// alternate between the result buffer (0) and a spare one (1).
template <class T, int Dim>
class RowBuffers {
 protected:
  static constexpr int input_buffer = -1;  // the caller's rows, original order

  struct Buffer {
    T* points;
    std::uint32_t* order;
  };
  /// A node's rows [begin, end), its depth, and the buffer that holds them.
  struct Range {
    std::size_t begin, end, depth;
    int buffer;
  };

  RowBuffers(const T* coords, std::size_t n, std::size_t dimension) : coords_(coords), n_(n), dim_(dimension) {}

  /// The result buffer's storage (the tree's points and order), and a spare of the same size.
  void attach(BuiltTree<T>& tree) {
    tree.points.resize(n_ * dim());
    tree.order.resize(n_);
    buffers_[0] = {tree.points.data(), tree.order.data()};
    spare_points_.resize(n_ * dim());
    spare_order_.resize(n_);
    buffers_[1] = {spare_points_.data(), spare_order_.data()};
  }

  std::size_t dim() const {
    if constexpr (Dim > 0)
      return static_cast<std::size_t>(Dim);
    else
      return dim_;
  }
  const T* rows(int buffer, std::size_t i) const {
    return (buffer == input_buffer ? coords_ : buffers_[buffer].points) + i * dim();
  }

  /// Moves the rows of `r` into the same rows of buffer `to`, the left side (see Plane) from the
  /// front and the right side from the back, and sets each side's bounds; returns the left count.
  std::size_t move_split(const Range& r, int to, std::size_t axis, Plane<T> plane, T* left_lo, T* left_hi,
                         T* right_lo, T* right_hi) const {
    T* sides[4] = {left_lo, left_hi, right_lo, right_hi};
    return with_kernel_dim([&](auto kernel_dim) {
      constexpr int D = decltype(kernel_dim)::value;
      const T v = plane.value;
      if (plane.equal_left == 0) return move_split_as<D>(r, to, axis, sides, [v](T c) { return c < v; });
      if (plane.equal_left == all_equal_left)
        return move_split_as<D>(r, to, axis, sides, [v](T c) { return c <= v; });
      return move_split_as<D>(r, to, axis, sides,
                              [v, taken = std::size_t{0}, quota = plane.equal_left](T c) mutable {
                                const bool left = c < v || (c == v && taken < quota);
                                taken += c == v && left ? 1 : 0;
                                return left;
                              });
    });
  }

  /// Calls f(std::integral_constant<int, D>): D = Dim, or for a run-time dimension from 1 to 8 that
  /// dimension as a constant (else -1: run time). The per-point loops of the move and of the bounds
  /// then unroll as in a compile-time tree: without it a run-time tree of 3-D points built 2.2x
  /// slower than PointTree<T, 3>, for the price of eight copies of two short loops.
  template <class F>
  decltype(auto) with_kernel_dim(F&& f) const {
    if constexpr (Dim > 0) {
      return f(std::integral_constant<int, Dim>{});
    } else {
      switch (dim_) {
        case 1:
          return f(std::integral_constant<int, 1>{});
        case 2:
          return f(std::integral_constant<int, 2>{});
        case 3:
          return f(std::integral_constant<int, 3>{});
        case 4:
          return f(std::integral_constant<int, 4>{});
        case 5:
          return f(std::integral_constant<int, 5>{});
        case 6:
          return f(std::integral_constant<int, 6>{});
        case 7:
          return f(std::integral_constant<int, 7>{});
        case 8:
          return f(std::integral_constant<int, 8>{});
        default:
          return f(std::integral_constant<int, -1>{});
      }
    }
  }

  /// Long rows (from 16 coordinates on) take their side's bounds as they move: a row is then long
  /// enough for the vector minimum and maximum, and a second pass over the rows would cost a read of
  /// all of them. Short rows take them in a pass afterwards, over each side's rows, now contiguous
  /// (and, below the top levels, in cache): a flat min / max in vector registers, where doing it in
  /// the move would pick one side's bounds per point, a few coordinates at a time.
  template <int D, class GoesLeft>
  std::size_t move_split_as(const Range& r, int to, std::size_t axis, T* const* sides,
                            GoesLeft goes_left) const {
    const std::size_t d = D > 0 ? static_cast<std::size_t>(D) : dim();
    const bool bounds_in_move = d >= 16;
    for (std::size_t a = 0; a < d; ++a) {
      sides[0][a] = sides[2][a] = std::numeric_limits<T>::infinity();
      sides[1][a] = sides[3][a] = -std::numeric_limits<T>::infinity();
    }
    const T* src = rows(r.buffer, r.begin);
    // The root reads the caller's rows, whose order is the identity: the spare buffer, free until the
    // root's children are split, holds it.
    const std::uint32_t* src_order =
        (r.buffer == input_buffer ? buffers_[1] : buffers_[r.buffer]).order + r.begin;
    if (r.buffer == input_buffer)
      for (std::size_t i = r.begin; i < r.end; ++i) buffers_[1].order[i] = static_cast<std::uint32_t>(i);
    T* dst = buffers_[to].points + r.begin * d;
    std::uint32_t* dst_order = buffers_[to].order + r.begin;
    const std::size_t count = r.end - r.begin;
    std::size_t next_left = 0, next_right = count;
    for (std::size_t i = 0; i < count; ++i, src += d) {
      const bool left = goes_left(src[axis]);
      // Branch-free: which side a point takes is as good as random to the branch predictor.
      next_right -= left ? 0 : 1;
      const std::size_t slot = left ? next_left : next_right;
      next_left += left ? 1 : 0;
      T* to_row = dst + slot * d;
      for (std::size_t a = 0; a < d; ++a) to_row[a] = src[a];
      dst_order[slot] = src_order[i];
      if (bounds_in_move) widen_by_row(src, d, sides[left ? 0 : 2], sides[left ? 1 : 3]);
    }
    if (!bounds_in_move) {
      widen_bounds<D>(dst, next_left, d, sides[0], sides[1]);
      widen_bounds<D>(dst + next_left * d, count - next_left, d, sides[2], sides[3]);
    }
    return next_left;
  }

  /// A leaf of the rows of `r`, moved into the result buffer if they are elsewhere.
  PointNode<T> make_leaf(const Range& r, bool identical) const {
    const std::size_t d = dim(), count = r.end - r.begin;
    Buffer result = buffers_[0];
    if (r.buffer == input_buffer) {  // the root is a leaf
      std::copy_n(coords_ + r.begin * d, count * d, result.points + r.begin * d);
      for (std::size_t i = r.begin; i < r.end; ++i) result.order[i] = static_cast<std::uint32_t>(i);
    } else if (r.buffer == 1 && count > 0) {
      std::copy_n(buffers_[1].points + r.begin * d, count * d, result.points + r.begin * d);
      std::copy_n(buffers_[1].order + r.begin, count, result.order + r.begin);
    }
    if (identical && count > 1)
      std::sort(result.order + r.begin, result.order + r.end);  // scanned in index order
    PointNode<T> leaf{};
    leaf.link = static_cast<std::uint32_t>(r.begin);
    // count == 0: the empty side of a `middle` split, never entered by the search.
    leaf.info = PointNode<T>::leaf_bit | (identical && count > 1 ? PointNode<T>::identical_bit : 0u) |
                static_cast<std::uint32_t>(count);
    return leaf;
  }

  const T* coords_;
  std::size_t n_;
  std::size_t dim_;
  Buffer buffers_[2] = {};
  HugePageVector<T> spare_points_;
  HugePageVector<std::uint32_t> spare_order_;
};

/// Splits nodes recursively. Every node's points are contiguous rows [begin, end) of a buffer. A
/// split reads them once and writes them into the same rows of the other buffer, the left side
/// from the front and the right side from the back, and works out both sides' bounds (which the
/// next splits' rules need): one read and one write of each point per level, and no pass of its own
/// for the plane of the midpoint rules. The root reads the caller's rows; then
/// the levels alternate between the result buffer and a spare one, and a leaf that ends in the spare
/// copies its rows back, so that the result is in leaf order in the first. Nothing is allocated per
/// node: the sides' bounds live in a per-level array, the selection scratch of the median rule in
/// one array whose rows [begin, end) belong to the node there. Subtrees built at the same time own
/// disjoint rows, so the levels near the root fork onto several threads without locks.
///
/// Dim > 0 fixes the dimension at compile time (PointTree<T, Dim>): the per-point loops unroll (as
/// they do for a run-time dimension up to 8: RowBuffers::with_kernel_dim).
template <class T, int Dim, class AxisRule, class PositionRule>
class Builder : RowBuffers<T, Dim> {
  using Base = RowBuffers<T, Dim>;
  using Base::dim;
  using Base::input_buffer;
  using typename Base::Range;

 public:
  /// `coords` must stay valid during build(); the root bounds are the caller's (it has checked the
  /// points and taken their bounds in one pass).
  Builder(const T* coords, std::size_t n, std::size_t dimension, const BuildParams& params)
      : Base(coords, n, dimension), params_(params) {}

  BuiltTree<T> build(const T* root_lo, const T* root_hi) {
    BuiltTree<T> tree;
    this->attach(tree);
    const std::size_t n = this->n_;
    if constexpr (PositionRule::needs_scratch) keys_.resize(n);
    const unsigned threads = resolve_threads(params_.threads);
    std::size_t parallel_levels = 0;  // levels whose two subtrees are built on two threads
    while ((std::size_t{1} << parallel_levels) < threads && parallel_levels < 8) ++parallel_levels;
    Task root(dim(), params_.max_depth);
    std::copy_n(root_lo, dim(), root.cell_lo.data());
    std::copy_n(root_hi, dim(), root.cell_hi.data());
    Subtree out;
    out.nodes.reserve(2 * (n / std::max<std::size_t>(params_.leaf_size, 1)) + 16);
    split(out, root, Range{0, n, 0, input_buffer}, root_lo, root_hi, parallel_levels);
    tree.nodes = std::move(out.nodes);
    tree.depth = out.depth;
    for (const auto& node : tree.nodes) tree.leaves += node.is_leaf() ? 1 : 0;
    return tree;
  }

 private:
  struct Subtree {
    HugePageVector<PointNode<T>> nodes;  // links of inner nodes are relative to nodes[0]
    std::size_t depth = 0;
  };
  /// What one thread's recursion works in: the cell (narrowed on the way down, restored on the way
  /// up) and, per level, the bounds of the two sides of that level's split.
  struct Task {
    Task(std::size_t dim, std::size_t max_depth)
        : cell_lo(dim), cell_hi(dim), sides(4 * dim * (max_depth + 1)) {}
    std::vector<T> cell_lo, cell_hi;
    std::vector<T> sides;  // level l: left lo, left hi, right lo, right hi, dim values each
  };

  void split(Subtree& out, Task& task, const Range& r, const T* point_lo, const T* point_hi,
             std::size_t parallel_levels) const {
    const std::size_t d = dim();
    out.depth = std::max(out.depth, r.depth);
    const std::size_t count = r.end - r.begin;
    bool identical = true;
    for (std::size_t a = 0; a < d && identical; ++a) identical = !(point_hi[a] > point_lo[a]);
    if (count == 0 || count <= params_.leaf_size || r.depth >= params_.max_depth || identical) {
      out.nodes.push_back(this->make_leaf(r, identical));
      return;
    }

    const NodeView<T> view{this->rows(r.buffer, r.begin),
                           count,
                           d,
                           point_lo,
                           point_hi,
                           task.cell_lo.data(),
                           task.cell_hi.data(),
                           r.depth,
                           PositionRule::needs_scratch ? keys_.data() + r.begin : nullptr};
    const std::size_t axis = AxisRule::choose(view);
    const Plane<T> plane = PositionRule::split(view, axis);
    T* sides = task.sides.data() + 4 * d * r.depth;
    T *left_lo = sides, *left_hi = sides + d, *right_lo = sides + 2 * d, *right_hi = sides + 3 * d;
    const int to = r.buffer == 0 ? 1 : 0;
    const std::size_t left_count = this->move_split(r, to, axis, plane, left_lo, left_hi, right_lo, right_hi);
    const std::size_t mid = r.begin + left_count;

    PointNode<T> node{};
    node.info = static_cast<std::uint32_t>(axis);
    node.left_max = left_hi[axis];    // -inf for an empty side: never entered
    node.right_min = right_lo[axis];  // +inf likewise
    const std::size_t self = out.nodes.size();
    out.nodes.push_back(node);

    const Range left{r.begin, mid, r.depth + 1, to}, right{mid, r.end, r.depth + 1, to};
    const T saved_lo = task.cell_lo[axis], saved_hi = task.cell_hi[axis];
    if (parallel_levels > 0) {
      Task right_task(d, params_.max_depth);
      right_task.cell_lo = task.cell_lo;
      right_task.cell_hi = task.cell_hi;
      right_task.cell_lo[axis] = plane.value;
      task.cell_hi[axis] = plane.value;
      Subtree left_tree, right_tree;
      fork_join([&] { split(left_tree, task, left, left_lo, left_hi, parallel_levels - 1); },
                [&] { split(right_tree, right_task, right, right_lo, right_hi, parallel_levels - 1); });
      task.cell_hi[axis] = saved_hi;
      append_subtree(out, left_tree);
      out.nodes[self].link = static_cast<std::uint32_t>(out.nodes.size());
      append_subtree(out, right_tree);
      return;
    }
    task.cell_hi[axis] = plane.value;
    split(out, task, left, left_lo, left_hi, 0);
    task.cell_hi[axis] = saved_hi;
    out.nodes[self].link = static_cast<std::uint32_t>(out.nodes.size());
    task.cell_lo[axis] = plane.value;
    split(out, task, right, right_lo, right_hi, 0);
    task.cell_lo[axis] = saved_lo;
  }

  static void append_subtree(Subtree& out, const Subtree& sub) {
    const std::uint32_t offset = static_cast<std::uint32_t>(out.nodes.size());
    for (PointNode<T> node : sub.nodes) {
      if (!node.is_leaf()) node.link += offset;
      out.nodes.push_back(node);
    }
    out.depth = std::max(out.depth, sub.depth);
  }

  BuildParams params_;
  mutable HugePageVector<T> keys_;  // the median rule's selection scratch, rows [begin, end) for the node there
};

}  // namespace kdspace::detail
