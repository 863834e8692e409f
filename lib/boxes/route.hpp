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

namespace kdspace::detail {

/// The most references a tree holds: they are counted in 30 bits (BoxNode).
inline constexpr std::size_t reference_limit = (std::size_t{1} << 30) - 1;

/// Calls leaf(node) for every leaf of `nodes` that box b goes to.
template <class Leaf>
void for_each_leaf_of(const std::vector<BoxNode>& nodes, const Box3f& b, Leaf&& leaf) {
  std::array<std::uint32_t, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    std::uint32_t node = stack[--top];
    for (;;) {
      const BoxNode& at = nodes[node];
      if (at.is_leaf()) {
        leaf(node);
        break;
      }
      const int axis = at.axis();
      const float p = at.split();
      const bool lower = b.lo[axis] < p || b.hi[axis] <= p, upper = b.hi[axis] > p;
      if (lower && upper) {
        stack[top++] = at.right_child();
        node = node + 1;
      } else {
        node = lower ? node + 1 : at.right_child();
      }
    }
  }
}

/// Fills the leaves of `nodes` (inner nodes as they are, leaves rewritten) with boxes[0 .. n).
/// Returns false, with nothing changed, when the leaves would hold more than max_references
/// references.
bool route_boxes(std::vector<BoxNode>& nodes, const Box3f* boxes, std::size_t n, std::size_t max_references,
                 std::vector<std::uint32_t>& references);

}  // namespace kdspace::detail
