// BoundedTree: a PointTree seen by the dual-tree traversal: every node with its point range and its
// bounding box (the tight box of its points).
//
// PointTree's nodes keep only what a single query needs (the two child bounds along the split axis);
// comparing two cells needs the whole box of each. The boxes are worked out once per join, in one pass
// over the leaf-ordered points and one over the nodes (for 1e6 3-D points about 131,000 nodes, 4 MB,
// a few milliseconds), rather than stored in every tree. This file is also the one place that reads
// PointTree's node layout for the joins.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/error.hpp"
#include "kdspace/joins/space.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace::detail {

template <class T, int Dim>
class BoundedTree {
 public:
  struct Node {
    std::uint32_t begin;  ///< the node's points are [begin, end) in leaf order
    std::uint32_t end;
    std::uint32_t left;   ///< children; 0 for a leaf (the root, node 0, is nobody's child)
    std::uint32_t right;
    bool all_identical;   ///< a leaf whose points coincide (their indices ascend)

    bool is_leaf() const { return left == 0; }
    std::uint32_t count() const { return end - begin; }
  };

  /// The nodes and boxes of `tree`, which must outlive this. Subtrees of at most `leaf_points`
  /// points are taken as leaves (joins compare leaves point by point; larger ones than the tree's
  /// mean fewer node pairs).
  template <class Metric>
  BoundedTree(const PointTree<T, Dim, Metric>& tree, std::size_t leaf_points)
      : dim_(tree.dim()),
        points_(tree.points_in_leaf_order().data()),
        indices_(tree.leaf_order().data()),
        size_(tree.size()) {
    const auto& tree_nodes = tree.nodes();
    nodes_.resize(tree_nodes.size());
    boxes_.assign(tree_nodes.size() * 2 * dim_, T(0));
    // Children come after their parent in depth-first order, so one backward pass sees them first.
    for (std::size_t id = tree_nodes.size(); id-- > 0;) {
      const auto& source = tree_nodes[id];
      Node& node = nodes_[id];
      T* lo = boxes_.data() + id * 2 * dim_;
      T* hi = lo + dim_;
      if (source.is_leaf()) {
        node = Node{source.first(), source.first() + source.count(), 0, 0, source.all_identical()};
        leaf_box(node, lo, hi);
        continue;
      }
      const std::uint32_t left = static_cast<std::uint32_t>(id + 1), right = source.right_child();
      node = Node{nodes_[left].begin, nodes_[right].end, left, right, false};
      const T* llo = this->lo(left);
      const T* rlo = this->lo(right);
      for (std::size_t a = 0; a < dim_; ++a) {
        lo[a] = std::min(llo[a], rlo[a]);
        hi[a] = std::max(llo[dim_ + a], rlo[dim_ + a]);
      }
    }
    // From the root down: small subtrees become leaves, and every leaf's points are stored by column
    // (the columns' room reserved first: grown leaf by leaf, the vector was copied at every doubling;
    // reserved, the cells of 1e6 uniform 3-D points took about half the time, interleaved runs on a
    // busy machine, medians 0.14 s -> 0.066 s).
    column_offset_.assign(nodes_.size(), 0);
    std::vector<std::uint32_t> leaves, stack{0};
    std::size_t column_values = 0;
    while (!stack.empty()) {
      const std::uint32_t id = stack.back();
      Node& node = nodes_[id];
      stack.pop_back();
      if (!node.is_leaf() && node.count() > leaf_points) {
        stack.push_back(node.right);
        stack.push_back(node.left);
        continue;
      }
      node.left = node.right = 0;
      leaves.push_back(id);
      column_values += column_stride(node) * dim();
    }
    columns_.reserve(column_values);
    for (const std::uint32_t id : leaves) {
      column_offset_[id] = columns_.size();
      add_columns(nodes_[id]);
    }
  }

  /// One point as a tree of one leaf (a single query); `point` must outlive this.
  BoundedTree(const T* point, std::size_t dim, const std::uint32_t* index)
      : dim_(dim), points_(point), indices_(index), size_(1), column_offset_{0} {
    nodes_.push_back(Node{0, 1, 0, 0, false});
    add_columns(nodes_[0]);
    boxes_.assign(point, point + dim);
    boxes_.insert(boxes_.end(), point, point + dim);
  }

  std::size_t dim() const {
    if constexpr (Dim == Dynamic) return dim_;
    else return static_cast<std::size_t>(Dim);
  }
  std::size_t size() const { return size_; }
  std::size_t node_count() const { return nodes_.size(); }
  const Node& node(std::uint32_t id) const { return nodes_[id]; }
  const T* lo(std::uint32_t id) const { return boxes_.data() + std::size_t{id} * 2 * dim(); }
  const T* hi(std::uint32_t id) const { return lo(id) + dim(); }
  /// The point at leaf-order position `pos`, and its original index.
  const T* point(std::size_t pos) const { return points_ + pos * dim(); }
  std::uint32_t index(std::size_t pos) const { return indices_[pos]; }
  /// index(pos) for every position: a permutation of [0, size()).
  const std::uint32_t* indices() const { return indices_; }
  /// A leaf's points by column, in blocks of column_block: axis a of its point at position begin + j
  /// is columns(leaf)[a * column_stride(leaf) + j]; the stride rounds the count up to whole blocks
  /// (the padding repeats the last point).
  const T* columns(std::uint32_t leaf) const { return columns_.data() + column_offset_[leaf]; }
  static std::size_t column_stride(const Node& leaf) {
    return (std::size_t{leaf.count()} + column_block - 1) / column_block * column_block;
  }
  static constexpr std::size_t column_block = 8;

 private:
  // An empty leaf (the empty side of a `middle` split) gets the empty box [+inf, -inf], which the
  // union above ignores; the traversal never enters it.
  void leaf_box(const Node& node, T* lo, T* hi) const {
    std::fill(lo, lo + dim_, std::numeric_limits<T>::infinity());
    std::fill(hi, hi + dim_, -std::numeric_limits<T>::infinity());
    const std::uint32_t last = node.all_identical ? node.begin + 1 : node.end;
    for (std::uint32_t pos = node.begin; pos < last; ++pos) {
      const T* p = points_ + std::size_t{pos} * dim_;
      for (std::size_t a = 0; a < dim_; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a]);
      }
    }
  }

  void add_columns(const Node& leaf) {
    const std::size_t stride = column_stride(leaf), start = columns_.size();
    columns_.resize(start + stride * dim());
    T* out = columns_.data() + start;
    for (std::size_t j = 0; j < stride; ++j) {
      const T* p = point(leaf.begin + std::min<std::size_t>(j, leaf.count() - 1));
      for (std::size_t a = 0; a < dim(); ++a) out[a * stride + j] = p[a];
    }
  }

  std::size_t dim_;
  const T* points_;
  const std::uint32_t* indices_;
  std::size_t size_;
  // In huge pages where enabled (detail/huge_pages.hpp): 1e6 3-D points make 3 MB of nodes,
  // 6 MB of boxes and 25 MB of columns.
  HugePageVector<Node> nodes_;
  HugePageVector<T> boxes_;    // node id: lo at [2 * id * dim, +dim), hi right after
  HugePageVector<std::size_t> column_offset_;  // by node id, for leaves
  HugePageVector<T> columns_;                  // each leaf's points by column
};

/// Checks that the points of `tree` lie in [0, L) on each periodic axis (period: L, or +inf);
/// the message names the first offending point by its 1-based row in the given order.
template <class T, int Dim>
void check_in_box(const BoundedTree<T, Dim>& tree, const std::vector<T>& period) {
  if (period.empty()) return;
  const std::size_t dim = tree.dim();
  bool inside = true;
  for (std::size_t a = 0; a < dim; ++a)
    inside = inside && inside_period(tree.lo(0)[a], period[a]) && inside_period(tree.hi(0)[a], period[a]);
  if (inside) return;
  std::size_t worst_pos = tree.size(), worst_axis = 0;
  for (std::size_t pos = 0; pos < tree.size(); ++pos)
    for (std::size_t a = 0; a < dim; ++a) {
      const T v = tree.point(pos)[a];
      if (!inside_period(v, period[a]) && (worst_pos == tree.size() || tree.index(pos) < tree.index(worst_pos)))
        worst_pos = pos, worst_axis = a;
    }
  throw outside_box(tree.index(worst_pos), worst_axis, tree.point(worst_pos)[worst_axis], period[worst_axis]);
}

}  // namespace kdspace::detail
