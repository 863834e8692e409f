// Builds the node array of a PointTree: recursive splitting of an index array by the split rules,
// subtrees near the root built on several threads.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <thread>
#include <vector>

#include "kdspace/points/detail/node.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/split_rules.hpp"
#include "kdspace/points/params.hpp"

namespace kdspace::detail {

template <class T>
struct BuiltTree {
  std::vector<PointNode<T>> nodes;
  std::vector<T> points;             ///< the points in leaf order, row-major
  std::vector<std::uint32_t> order;  ///< original index of each point, in leaf order
  std::size_t depth = 0;             ///< depth of the deepest leaf (a lone root leaf has depth 0)
  std::size_t leaves = 0;
};

/// Splits nodes recursively. Every node's points are contiguous rows [begin, end) of one of two
/// buffers: a split reads them from one buffer and writes them, reordered left then right, into the
/// same rows of the other, working out both children's bounds in that one pass. The levels thus
/// alternate between the buffers; a leaf whose rows sit in the spare buffer copies them back, so the
/// result ends up in leaf order in the first. All scratch (spare buffer, indices, keys) is allocated
/// once, and nodes built at the same time own disjoint rows of it, so subtrees near the root are
/// built on several threads without locks.
template <class T, class AxisRule, class PositionRule>
class Builder {
 public:
  Builder(const T* coords, std::size_t n, std::size_t dim, const BuildParams& params)
      : coords_(coords), n_(n), dim_(dim), params_(params) {}

  BuiltTree<T> build(const T* root_lo, const T* root_hi) {
    BuiltTree<T> tree;
    tree.points.assign(coords_, coords_ + n_ * dim_);
    tree.order.resize(n_);
    for (std::size_t i = 0; i < n_; ++i) tree.order[i] = static_cast<std::uint32_t>(i);
    buffers_[0] = {tree.points.data(), tree.order.data()};
    spare_points_.resize(n_ * dim_);
    spare_order_.resize(n_);
    buffers_[1] = {spare_points_.data(), spare_order_.data()};
    local_.resize(n_);
    keyed_.resize(n_);
    std::vector<T> cell_lo(root_lo, root_lo + dim_), cell_hi(root_hi, root_hi + dim_);
    std::vector<T> point_lo = cell_lo, point_hi = cell_hi;
    const unsigned threads = resolve_threads(params_.threads);
    std::size_t parallel_levels = 0;  // levels whose two subtrees are built on two threads
    while ((std::size_t{1} << parallel_levels) < threads && parallel_levels < 8) ++parallel_levels;
    Subtree sub = build_node(NodeRange{0, n_, 0, 0}, cell_lo, cell_hi, point_lo, point_hi, parallel_levels);
    tree.nodes = std::move(sub.nodes);
    tree.depth = sub.depth;
    for (const auto& node : tree.nodes) tree.leaves += node.is_leaf() ? 1 : 0;
    return tree;
  }

 private:
  struct Subtree {
    std::vector<PointNode<T>> nodes;  // links of inner nodes are relative to nodes[0]
    std::size_t depth = 0;
  };
  struct Buffer {
    T* points;
    std::uint32_t* order;
  };
  /// A node's rows [begin, end), its depth, and the buffer (0 or 1) that holds them.
  struct NodeRange {
    std::size_t begin, end, depth;
    int buffer;
  };

  T* row(int buffer, std::size_t i) const { return buffers_[buffer].points + i * dim_; }

  // Builds the node into a vector of its own (for a subtree built on another thread).
  Subtree build_node(const NodeRange& r, std::vector<T> cell_lo, std::vector<T> cell_hi, const std::vector<T>& point_lo,
                     const std::vector<T>& point_hi, std::size_t parallel_levels) const {
    Subtree out;
    append_node(out, r, cell_lo, cell_hi, point_lo, point_hi, parallel_levels);
    return out;
  }

  // point_lo / point_hi: the bounds of the node's points, worked out by the parent's split.
  void append_node(Subtree& out, const NodeRange& r, std::vector<T>& cell_lo, std::vector<T>& cell_hi,
                   const std::vector<T>& point_lo, const std::vector<T>& point_hi, std::size_t parallel_levels) const {
    out.depth = std::max(out.depth, r.depth);
    const std::size_t count = r.end - r.begin;
    bool identical = true;
    for (std::size_t a = 0; a < dim_ && identical; ++a) identical = !(point_hi[a] > point_lo[a]);

    if (count == 0 || count <= params_.leaf_size || r.depth >= params_.max_depth || identical) {
      if (r.buffer == 1 && count > 0) {  // back to the result buffer
        std::copy_n(row(1, r.begin), count * dim_, row(0, r.begin));
        std::copy_n(buffers_[1].order + r.begin, count, buffers_[0].order + r.begin);
      }
      std::uint32_t* ids = buffers_[0].order;
      if (identical && count > 1) std::sort(ids + r.begin, ids + r.end);  // duplicates are scanned in index order
      PointNode<T> leaf{};
      leaf.link = static_cast<std::uint32_t>(r.begin);
      // count == 0: the empty side of a `middle` split, never entered by the search.
      leaf.info = PointNode<T>::leaf_bit | (identical && count > 1 ? PointNode<T>::identical_bit : 0u) |
                  static_cast<std::uint32_t>(count);
      out.nodes.push_back(leaf);
      return;
    }

    std::uint32_t* local = local_.data() + r.begin;
    for (std::size_t i = 0; i < count; ++i) local[i] = static_cast<std::uint32_t>(i);
    SplitInput<T> in{row(r.buffer, r.begin), dim_,          local,         local + count, point_lo.data(),
                     point_hi.data(),        cell_lo.data(), cell_hi.data(), r.depth,      keyed_.data() + r.begin};
    const std::size_t axis = AxisRule::choose(in);
    const Partition<T> part = PositionRule::split(in, axis);
    const std::size_t mid = r.begin + part.left_count;

    // One pass: the rows into the other buffer in the rule's order, and each side's bounds.
    const int to = 1 - r.buffer;
    std::vector<T> left_lo(dim_, std::numeric_limits<T>::infinity()), left_hi(dim_, -std::numeric_limits<T>::infinity());
    std::vector<T> right_lo = left_lo, right_hi = left_hi;
    const T* src = row(r.buffer, r.begin);
    const std::uint32_t* src_order = buffers_[r.buffer].order + r.begin;
    T* dst = row(to, r.begin);
    std::uint32_t* dst_order = buffers_[to].order + r.begin;
    auto move_side = [&](std::size_t first, std::size_t last, std::vector<T>& lo, std::vector<T>& hi) {
      for (std::size_t i = first; i < last; ++i) {
        const T* p = src + std::size_t{local[i]} * dim_;
        T* q = dst + i * dim_;
        for (std::size_t a = 0; a < dim_; ++a) {
          q[a] = p[a];
          lo[a] = std::min(lo[a], p[a]);
          hi[a] = std::max(hi[a], p[a]);
        }
        dst_order[i] = src_order[local[i]];
      }
    };
    move_side(0, part.left_count, left_lo, left_hi);
    move_side(part.left_count, count, right_lo, right_hi);

    PointNode<T> node{};
    node.info = static_cast<std::uint32_t>(axis);
    node.left_max = left_hi[axis];    // -inf for an empty side: never entered
    node.right_min = right_lo[axis];  // +inf likewise
    const std::size_t self = out.nodes.size();
    out.nodes.push_back(node);

    const NodeRange left{r.begin, mid, r.depth + 1, to}, right{mid, r.end, r.depth + 1, to};
    if (parallel_levels > 0) {
      std::vector<T> left_cell_hi = cell_hi, right_cell_lo = cell_lo;
      left_cell_hi[axis] = part.plane;
      right_cell_lo[axis] = part.plane;
      Subtree left_tree, right_tree;
      fork_join([&] { left_tree = build_node(left, cell_lo, left_cell_hi, left_lo, left_hi, parallel_levels - 1); },
                [&] { right_tree = build_node(right, right_cell_lo, cell_hi, right_lo, right_hi, parallel_levels - 1); });
      append_subtree(out, left_tree);
      out.nodes[self].link = static_cast<std::uint32_t>(out.nodes.size());
      append_subtree(out, right_tree);
      return;
    }
    const T saved_hi = cell_hi[axis], saved_lo = cell_lo[axis];
    cell_hi[axis] = part.plane;
    append_node(out, left, cell_lo, cell_hi, left_lo, left_hi, 0);
    cell_hi[axis] = saved_hi;
    out.nodes[self].link = static_cast<std::uint32_t>(out.nodes.size());
    cell_lo[axis] = part.plane;
    append_node(out, right, cell_lo, cell_hi, right_lo, right_hi, 0);
    cell_lo[axis] = saved_lo;
  }

  static void append_subtree(Subtree& out, const Subtree& sub) {
    const std::uint32_t offset = static_cast<std::uint32_t>(out.nodes.size());
    for (PointNode<T> node : sub.nodes) {
      if (!node.is_leaf()) node.link += offset;
      out.nodes.push_back(node);
    }
    out.depth = std::max(out.depth, sub.depth);
  }

  const T* coords_;
  std::size_t n_;
  std::size_t dim_;
  BuildParams params_;
  Buffer buffers_[2] = {};
  std::vector<T> spare_points_;
  std::vector<std::uint32_t> spare_order_;
  mutable std::vector<std::uint32_t> local_;  // node-local indices, rows [begin, end) for the node there
  mutable std::vector<Keyed<T>> keyed_;       // the position rule's scratch, likewise
};

}  // namespace kdspace::detail
