// What the three BoxTree builds share: box references with clipped bounds, the split record, the
// tree writer, and the recursive driver that turns a build method's decisions into nodes.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"

namespace kdspace::detail {

/// A box as seen from a node: its index and its bounds clipped to the node's cell. Clipping is what
/// makes splits "perfect" (W&H 2006): only the part of a box inside the cell proposes
/// candidate planes, and a clipped box is exact (min/max, no rounding).
struct BoxRef {
  Box3f bounds;
  std::uint32_t box;
};

/// A chosen split: the plane axis = position, and the side of boxes lying flat in it.
struct Split {
  int axis = 0;
  float position = 0;
  bool planar_left = true;
  std::size_t n_left = 0;   ///< boxes the left child will hold
  std::size_t n_right = 0;  ///< boxes the right child will hold
};

/// Which child a box goes to. Boxes ending at the plane go left, boxes starting at it go right, boxes
/// lying flat in it go where the split says (the "planar events" of W&H 2006).
enum class Side : std::uint8_t { left, right, both };

inline Side classify(const Box3f& b, const Split& s) {
  const float lo = b.lo[s.axis], hi = b.hi[s.axis], p = s.position;
  if (lo == p && hi == p) return s.planar_left ? Side::left : Side::right;
  if (hi <= p) return Side::left;
  if (lo >= p) return Side::right;
  return Side::both;
}

inline Box3f left_cell(Box3f cell, const Split& s) {
  cell.hi[s.axis] = s.position;
  return cell;
}
inline Box3f right_cell(Box3f cell, const Split& s) {
  cell.lo[s.axis] = s.position;
  return cell;
}

/// True when the plane lies strictly inside the cell. Planes on the boundary are never candidates:
/// they would make a child as large as its parent and the recursion would make no progress.
inline bool inside_cell(const Box3f& cell, int axis, float p) {
  return cell.lo[axis] < p && p < cell.hi[axis];
}

/// Splits a reference list at s; a straddling box appears on both sides, clipped to each cell.
inline void split_references(const std::vector<BoxRef>& refs, const Split& s, std::vector<BoxRef>& left,
                             std::vector<BoxRef>& right) {
  for (const BoxRef& r : refs) {
    switch (classify(r.bounds, s)) {
      case Side::left:
        left.push_back(r);
        break;
      case Side::right:
        right.push_back(r);
        break;
      case Side::both: {
        BoxRef l = r, rr = r;
        l.bounds.hi[s.axis] = s.position;
        rr.bounds.lo[s.axis] = s.position;
        left.push_back(l);
        right.push_back(rr);
        break;
      }
    }
  }
}

/// The references of the whole scene: every box, clipped to nothing (the root cell holds them all).
inline std::vector<BoxRef> root_references(const std::vector<Box3f>& boxes) {
  std::vector<BoxRef> refs(boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) refs[i] = BoxRef{boxes[i], static_cast<std::uint32_t>(i)};
  return refs;
}

/// A node as the builds write it: depth first, an inner node's left child next to it and its right
/// child's index stored; a leaf's first reference and count (into TreeWriter::references, unpadded).
/// The layout pass (layout.hpp) turns these, one for one and in the same order, into 8-byte BoxNodes,
/// pads each leaf's references to a multiple of 4 and copies its boxes into LeafBlocks.
struct BuiltNode {
  float split = 0;          ///< inner nodes
  std::uint32_t first = 0;  ///< leaf: first reference
  std::uint32_t count = 0;  ///< leaf: boxes
  std::uint32_t right = 0;  ///< inner: index of the right child
  std::int8_t axis = -1;    ///< 0..2, or -1 for a leaf

  bool is_leaf() const { return axis < 0; }
};

/// Collects nodes depth first. Subtrees built on other threads are written into their own writer
/// and appended, their links shifted.
class TreeWriter {
 public:
  std::vector<BuiltNode> nodes;
  std::vector<std::uint32_t> references;
  std::size_t depth = 0;

  void add_leaf(std::vector<std::uint32_t> box_ids, std::size_t at_depth) {
    std::sort(box_ids.begin(), box_ids.end());
    check_limits(nodes.size() + 1, references.size() + box_ids.size());
    BuiltNode leaf;
    leaf.first = static_cast<std::uint32_t>(references.size());
    leaf.count = static_cast<std::uint32_t>(box_ids.size());
    nodes.push_back(leaf);
    references.insert(references.end(), box_ids.begin(), box_ids.end());
    depth = std::max(depth, at_depth);
  }

  /// Adds an inner node whose right child is not known yet; returns its index.
  std::size_t add_inner(const Split& s) {
    check_limits(nodes.size() + 1, references.size());
    BuiltNode inner;
    inner.axis = static_cast<std::int8_t>(s.axis);
    inner.split = s.position;
    nodes.push_back(inner);
    return nodes.size() - 1;
  }
  /// The next node to be written becomes the right child of inner node `index`.
  void link_right_child(std::size_t index) { nodes[index].right = static_cast<std::uint32_t>(nodes.size()); }

  void append(const TreeWriter& sub) {
    check_limits(nodes.size() + sub.nodes.size(), references.size() + sub.references.size());
    const auto node_shift = static_cast<std::uint32_t>(nodes.size());
    const auto ref_shift = static_cast<std::uint32_t>(references.size());
    for (BuiltNode n : sub.nodes) {
      if (n.is_leaf())
        n.first += ref_shift;
      else
        n.right += node_shift;
      nodes.push_back(n);
    }
    references.insert(references.end(), sub.references.begin(), sub.references.end());
    depth = std::max(depth, sub.depth);
  }

 private:
  static void check_limits(std::size_t node_count, std::size_t reference_count) {
    // The layout pass pads each leaf's references to a multiple of 4 (at most 4 times as many, still
    // within 32 bits); a BoxNode keeps its right child's index in 30 bits, far above this cap.
    if (node_count >= (std::size_t{1} << 28) || reference_count >= (std::size_t{1} << 30))
      throw Error("box tree too large: more than 2^28 nodes or 2^30 box references (lower max_depth)");
  }
};

/// Builds the subtree of `work` (a method's description of the boxes in `cell`) into `out`.
///
/// A Method provides
///   using Work = ...;                                    the boxes of a node, as the method keeps them
///   std::optional<Split> choose_split(const Work&, const Box3f& cell, std::size_t depth) const;
///   std::pair<Work, Work> partition(Work&&, const Box3f& cell, const Split&) const;
///   std::vector<std::uint32_t> box_ids(const Work&) const;
///   std::size_t size(const Work&) const;                 boxes in the node
///
/// Recursion is bounded by max_depth (at most max_box_tree_depth), so the call stack stays small.
/// `budget` is the node's share of the reference budget (BoxBuildParams::max_references_per_box):
/// a split whose children would together hold more boxes is not made, and the children share the
/// budget in proportion to their boxes, so the leaves never hold more references than the root's
/// budget. With spare_threads > 0 the left subtree is built on a new thread while this one builds
/// the right; the tree is the same whatever the thread count.
template <class Method>
void build_subtree(const Method& method, typename Method::Work work, const Box3f& cell, std::size_t depth,
                   std::size_t max_depth, double budget, TreeWriter& out, unsigned spare_threads) {
  std::optional<Split> split;
  if (depth < max_depth && method.size(work) > 0) split = method.choose_split(work, cell, depth);
  const double children_total = split ? static_cast<double>(split->n_left + split->n_right) : 0.0;
  if (split && children_total > budget) split.reset();
  if (!split) {
    out.add_leaf(method.box_ids(work), depth);
    return;
  }
  const double left_budget = budget * static_cast<double>(split->n_left) / children_total;
  const double right_budget = budget * static_cast<double>(split->n_right) / children_total;
  auto children = method.partition(std::move(work), cell, *split);
  const Box3f lcell = left_cell(cell, *split), rcell = right_cell(cell, *split);
  const std::size_t self = out.add_inner(*split);

  // Below this many boxes a subtree is not worth a thread.
  constexpr std::size_t min_parallel_boxes = 4096;
  if (spare_threads > 0 && method.size(children.first) + method.size(children.second) >= min_parallel_boxes) {
    const unsigned spare = spare_threads - 1;
    TreeWriter left_out, right_out;
    fork_join(
        [&] {
          build_subtree(method, std::move(children.first), lcell, depth + 1, max_depth, left_budget, left_out,
                        spare / 2);
        },
        [&] {
          build_subtree(method, std::move(children.second), rcell, depth + 1, max_depth, right_budget,
                        right_out, spare - spare / 2);
        });
    out.append(left_out);
    out.link_right_child(self);
    out.append(right_out);
  } else {
    build_subtree(method, std::move(children.first), lcell, depth + 1, max_depth, left_budget, out,
                  spare_threads);
    out.link_right_child(self);
    build_subtree(method, std::move(children.second), rcell, depth + 1, max_depth, right_budget, out,
                  spare_threads);
  }
}

/// Throws Error for n >= 2^30 (references are counted in 30 bits), a null pointer, or the first box
/// that is not finite or has min > max ("box 17: min x 3 > max x 1", 1-based).
void check_boxes(const Box3f* boxes, std::size_t n);

/// The reference budget of the root.
inline double root_budget(const BoxBuildParams& params, std::size_t n) {
  return static_cast<double>(params.max_references_per_box) * static_cast<double>(n);
}

/// Threads a build runs on.
inline unsigned build_threads(const BoxBuildParams& params) {
  return params.threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : params.threads;
}

// ---- the methods (build_median.cpp, build_sah.cpp, build_sah_nlogn.cpp, build_binned.cpp) ---------

/// Each builds the tree of `boxes` (already validated, bounds = their union) into `out`.
void build_median(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
                  std::size_t max_depth, TreeWriter& out);
void build_sah(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
               std::size_t max_depth, TreeWriter& out);
void build_sah_nlogn(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
                     std::size_t max_depth, TreeWriter& out);
void build_binned(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
                  std::size_t max_depth, TreeWriter& out);

}  // namespace kdspace::detail
