// The traversals that the collision queries share. A query supplies only its rule: what it does with
// a leaf (or a pair of leaves) that the traversal reaches, given the leaf's cell.
//
//   for_each_leaf           every leaf of a tree, with its cell             (pairs within one set)
//   for_each_leaf_touching  the leaves whose closed cells meet a closed box  (overlap queries; the
//                                                                            boxes on split planes)
//   for_each_leaf_pair      the pairs of leaves of two trees whose closed     (pairs across two sets)
//                           cells meet
// The first contact of a moving box has its own traversal (contact.cpp): it goes in order of time
// and stops early, which none of these does.
//
// Cells are closed: a query box that touches a split plane visits both children, because a box that
// ends exactly on the plane is referenced on one side only (see `owns` in tree_access.hpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tree_access.hpp"

namespace kdspace::detail {

struct NodeAndCell {
  NodeId node;
  Box3f cell;
};

/// Calls visit(leaf, cell) for every leaf, left to right.
template <class Visit>
void for_each_leaf(const TreeAccess& tree, Visit&& visit) {
  if (tree.empty()) return;
  std::array<NodeAndCell, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = {TreeAccess::root(), tree.root_cell()};
  while (top > 0) {
    NodeAndCell at = stack[--top];
    while (!tree.is_leaf(at.node)) {
      const int axis = tree.axis(at.node);
      const float split = tree.split(at.node);
      stack[top++] = {tree.right(at.node), upper_cell(at.cell, axis, split)};
      at = {tree.left(at.node), lower_cell(at.cell, axis, split)};
    }
    visit(at.node, at.cell);
  }
}

/// Calls visit(leaf, cell) for every leaf whose closed cell meets the closed box `query`, left to
/// right; adds the nodes entered to `nodes_visited`.
template <class Visit>
void for_each_leaf_touching(const TreeAccess& tree, const Box3f& query, std::uint64_t& nodes_visited,
                            Visit&& visit) {
  if (tree.empty() || !query.overlaps(tree.root_cell())) return;
  std::array<NodeAndCell, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = {TreeAccess::root(), tree.root_cell()};
  while (top > 0) {
    NodeAndCell at = stack[--top];
    for (;;) {
      ++nodes_visited;
      if (tree.is_leaf(at.node)) {
        visit(at.node, at.cell);
        break;
      }
      const int axis = tree.axis(at.node);
      const float split = tree.split(at.node);
      const bool lower = query.lo[axis] <= split, upper = query.hi[axis] >= split;
      if (lower && upper) {
        stack[top++] = {tree.right(at.node), upper_cell(at.cell, axis, split)};
        at = {tree.left(at.node), lower_cell(at.cell, axis, split)};
      } else if (lower) {
        at = {tree.left(at.node), lower_cell(at.cell, axis, split)};
      } else {
        at = {tree.right(at.node), upper_cell(at.cell, axis, split)};
      }
    }
  }
}

/// A pair of nodes of two trees, with their cells: a unit of work of for_each_leaf_pair.
struct NodePair {
  NodeAndCell a, b;
};

/// Of a pair of inner nodes, the one to split next: the one whose cell is larger (sum of extents),
/// so that the two cells shrink together.
inline bool split_first_of_pair(const TreeAccess& ta, const NodeAndCell& a, const TreeAccess& tb,
                                const NodeAndCell& b) {
  if (tb.is_leaf(b.node)) return true;
  if (ta.is_leaf(a.node)) return false;
  double size_a = 0, size_b = 0;
  for (int axis = 0; axis < 3; ++axis) {
    size_a += static_cast<double>(a.cell.hi[axis]) - a.cell.lo[axis];
    size_b += static_cast<double>(b.cell.hi[axis]) - b.cell.lo[axis];
  }
  return size_a >= size_b;
}

/// The children of `at` whose closed cells meet `other`.
template <class Push>
void children_touching(const TreeAccess& tree, const NodeAndCell& at, const Box3f& other, Push&& push) {
  const int axis = tree.axis(at.node);
  const float split = tree.split(at.node);
  if (other.hi[axis] >= split) push(NodeAndCell{tree.right(at.node), upper_cell(at.cell, axis, split)});
  if (other.lo[axis] <= split) push(NodeAndCell{tree.left(at.node), lower_cell(at.cell, axis, split)});
}

/// Calls visit(leaf_a, cell_a, leaf_b, cell_b) for every leaf of tree a and leaf of tree b below the
/// nodes of `start` whose closed cells meet; adds the node pairs entered to `pairs_visited`.
template <class Visit>
void for_each_leaf_pair(const TreeAccess& ta, const TreeAccess& tb, const NodePair& start,
                        std::uint64_t& pairs_visited, Visit&& visit) {
  std::vector<NodePair> stack{start};
  while (!stack.empty()) {
    const NodePair at = stack.back();
    stack.pop_back();
    ++pairs_visited;
    if (!at.a.cell.overlaps(at.b.cell)) continue;
    const bool leaf_a = ta.is_leaf(at.a.node), leaf_b = tb.is_leaf(at.b.node);
    if (leaf_a && leaf_b) {
      visit(at.a.node, at.a.cell, at.b.node, at.b.cell);
    } else if (split_first_of_pair(ta, at.a, tb, at.b)) {
      children_touching(ta, at.a, at.b.cell, [&](const NodeAndCell& child) {
        stack.push_back({child, at.b});
      });
    } else {
      children_touching(tb, at.b, at.a.cell, [&](const NodeAndCell& child) {
        stack.push_back({at.a, child});
      });
    }
  }
}

/// Splits the root pair of two trees into at least `wanted` pairs of nodes (fewer when the trees run
/// out of inner nodes) whose leaf pairs together are those of the roots: the tasks of a parallel
/// for_each_leaf_pair.
inline std::vector<NodePair> node_pair_tasks(const TreeAccess& ta, const TreeAccess& tb, std::size_t wanted) {
  std::vector<NodePair> tasks;
  if (ta.empty() || tb.empty()) return tasks;
  tasks.push_back({{TreeAccess::root(), ta.root_cell()}, {TreeAccess::root(), tb.root_cell()}});
  // Breadth first, so that the tasks are of similar size.
  for (std::size_t round = 0; round < 2 * max_box_tree_depth && tasks.size() < wanted; ++round) {
    std::vector<NodePair> next;
    bool split_any = false;
    for (const NodePair& at : tasks) {
      if (!at.a.cell.overlaps(at.b.cell)) continue;
      if (ta.is_leaf(at.a.node) && tb.is_leaf(at.b.node)) {
        next.push_back(at);
      } else if (split_first_of_pair(ta, at.a, tb, at.b)) {
        children_touching(ta, at.a, at.b.cell, [&](const NodeAndCell& child) {
          next.push_back({child, at.b});
        });
        split_any = true;
      } else {
        children_touching(tb, at.b, at.a.cell, [&](const NodeAndCell& child) {
          next.push_back({at.a, child});
        });
        split_any = true;
      }
    }
    tasks.swap(next);
    if (!split_any) break;
  }
  return tasks;
}

}  // namespace kdspace::detail
