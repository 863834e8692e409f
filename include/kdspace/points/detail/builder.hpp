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

/// Splits nodes recursively. It works on a copy of the points that it reorders as it goes, so that
/// every node's points are contiguous: scans and selections read memory in order, and the copy ends
/// up in leaf order, ready for the search.
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
    points_ = tree.points.data();
    order_ = tree.order.data();
    std::vector<T> cell_lo(root_lo, root_lo + dim_), cell_hi(root_hi, root_hi + dim_);
    const unsigned threads = resolve_threads(params_.threads);
    std::size_t parallel_levels = 0;  // levels whose two subtrees are built on two threads
    while ((std::size_t{1} << parallel_levels) < threads && parallel_levels < 8) ++parallel_levels;
    Subtree sub = build_node(0, n_, 0, cell_lo, cell_hi, parallel_levels);
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

  T* row(std::size_t i) const { return points_ + i * dim_; }

  // Builds the node for points [begin, end) into a vector of its own; `cell_*` are taken by value as
  // each child narrows one axis of them.
  Subtree build_node(std::size_t begin, std::size_t end, std::size_t depth, std::vector<T> cell_lo,
                     std::vector<T> cell_hi, std::size_t parallel_levels) const {
    Subtree out;
    append_node(out, begin, end, depth, cell_lo, cell_hi, parallel_levels);
    return out;
  }

  void append_node(Subtree& out, std::size_t begin, std::size_t end, std::size_t depth, std::vector<T>& cell_lo,
                   std::vector<T>& cell_hi, std::size_t parallel_levels) const {
    out.depth = std::max(out.depth, depth);
    const std::size_t count = end - begin;
    if (count == 0) {  // the empty side of a `middle` split
      PointNode<T> leaf{};
      leaf.link = static_cast<std::uint32_t>(begin);
      leaf.info = PointNode<T>::leaf_bit;
      out.nodes.push_back(leaf);
      return;
    }
    std::vector<T> lo(row(begin), row(begin) + dim_), hi(row(begin), row(begin) + dim_);
    for (std::size_t i = begin + 1; i < end; ++i) {
      const T* p = row(i);
      for (std::size_t a = 0; a < dim_; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a]);
      }
    }
    bool identical = true;
    for (std::size_t a = 0; a < dim_ && identical; ++a) identical = !(hi[a] > lo[a]);

    if (count <= params_.leaf_size || depth >= params_.max_depth || identical) {
      if (identical) std::sort(order_ + begin, order_ + end);  // duplicates are scanned in index order
      PointNode<T> leaf{};
      leaf.link = static_cast<std::uint32_t>(begin);
      leaf.info = PointNode<T>::leaf_bit | (identical && count > 1 ? PointNode<T>::identical_bit : 0u) |
                  static_cast<std::uint32_t>(count);
      out.nodes.push_back(leaf);
      return;
    }

    std::vector<std::uint32_t> local(count);
    for (std::size_t i = 0; i < count; ++i) local[i] = static_cast<std::uint32_t>(i);
    SplitInput<T> in{row(begin), dim_, local.data(), local.data() + count, lo.data(), hi.data(),
                     cell_lo.data(), cell_hi.data(), depth};
    const std::size_t axis = AxisRule::choose(in);
    const Partition<T> part = PositionRule::split(in, axis);
    const std::size_t mid = begin + part.left_count;
    move_rows(begin, local);

    PointNode<T> node{};
    node.info = static_cast<std::uint32_t>(axis);
    node.left_max = -std::numeric_limits<T>::infinity();  // an empty side is never entered
    node.right_min = std::numeric_limits<T>::infinity();
    for (std::size_t i = begin; i < mid; ++i) node.left_max = std::max(node.left_max, row(i)[axis]);
    for (std::size_t i = mid; i < end; ++i) node.right_min = std::min(node.right_min, row(i)[axis]);
    const std::size_t self = out.nodes.size();
    out.nodes.push_back(node);

    if (parallel_levels > 0) {
      std::vector<T> left_hi = cell_hi, right_lo = cell_lo;
      left_hi[axis] = part.plane;
      right_lo[axis] = part.plane;
      Subtree left, right;
      fork_join([&] { left = build_node(begin, mid, depth + 1, cell_lo, left_hi, parallel_levels - 1); },
                [&] { right = build_node(mid, end, depth + 1, right_lo, cell_hi, parallel_levels - 1); });
      append_subtree(out, left);
      out.nodes[self].link = static_cast<std::uint32_t>(out.nodes.size());
      append_subtree(out, right);
      return;
    }
    const T saved_hi = cell_hi[axis], saved_lo = cell_lo[axis];
    cell_hi[axis] = part.plane;
    append_node(out, begin, mid, depth + 1, cell_lo, cell_hi, 0);
    cell_hi[axis] = saved_hi;
    out.nodes[self].link = static_cast<std::uint32_t>(out.nodes.size());
    cell_lo[axis] = part.plane;
    append_node(out, mid, end, depth + 1, cell_lo, cell_hi, 0);
    cell_lo[axis] = saved_lo;
  }

  // Puts the rows (and their original indices) of the node starting at `begin` in the order `local`.
  void move_rows(std::size_t begin, const std::vector<std::uint32_t>& local) const {
    const std::size_t count = local.size();
    std::vector<T> rows(count * dim_);
    std::vector<std::uint32_t> ids(count);
    for (std::size_t i = 0; i < count; ++i) {
      std::copy_n(row(begin + local[i]), dim_, rows.data() + i * dim_);
      ids[i] = order_[begin + local[i]];
    }
    std::copy(rows.begin(), rows.end(), row(begin));
    std::copy(ids.begin(), ids.end(), order_ + begin);
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
  T* points_ = nullptr;
  std::uint32_t* order_ = nullptr;
};

}  // namespace kdspace::detail
