// Sending boxes down fixed split planes to the leaves they overlap: the second step of the binned
// build, and all of BoxTree::refit (the planes kept, the boxes moved).
//
// The side rule is the builds': a box goes to the lower child of a split at p when its lower face is
// below p or it lies flat in the plane, and to the upper child when its upper face is above p (to
// both when it straddles p). Each leaf's ids stay ascending.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "build_common.hpp"

namespace kdspace::detail {

/// The most references a tree holds: they are counted in 30 bits (BoxNode).
inline constexpr std::size_t reference_limit = (std::size_t{1} << 30) - 1;

/// The split of an inner node, read alike from the builds' nodes and the tree's.
inline int split_axis(const BuiltNode& n) { return n.axis; }
inline float split_position(const BuiltNode& n) { return n.split; }
inline std::uint32_t right_child(const BuiltNode& n) { return n.right; }
inline int split_axis(const BoxNode& n) { return n.axis(); }
inline float split_position(const BoxNode& n) { return n.split(); }
inline std::uint32_t right_child(const BoxNode& n) { return n.right_child(); }

/// Calls leaf(node) for every leaf of `nodes` (an array of BuiltNodes or BoxNodes) that box b goes to.
template <class Nodes, class Leaf>
void for_each_leaf_of(const Nodes& nodes, const Box3f& b, Leaf&& leaf) {
  std::array<std::uint32_t, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    std::uint32_t node = stack[--top];
    for (;;) {
      const auto& at = nodes[node];
      if (at.is_leaf()) {
        leaf(node);
        break;
      }
      const int axis = split_axis(at);
      const float p = split_position(at);
      const bool lower = b.lo[axis] < p || b.hi[axis] <= p, upper = b.hi[axis] > p;
      if (lower && upper) {
        stack[top++] = right_child(at);
        node = node + 1;
      } else {
        node = lower ? node + 1 : right_child(at);
      }
    }
  }
}

/// Fills the leaves of `nodes` (inner nodes as they are, leaves rewritten) with boxes[0 .. n), their
/// references unpadded and ascending per leaf (the layout pass pads them). Returns false, with
/// nothing changed, when the leaves would hold more than max_references references.
bool route_boxes(std::vector<BuiltNode>& nodes, const Box3f* boxes, std::size_t n, std::size_t max_references,
                 std::vector<std::uint32_t>& references);

}  // namespace kdspace::detail
