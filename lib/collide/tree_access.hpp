// How the collision queries see a BoxTree. This is the one file of lib/collide/ that knows the tree's
// layout (its nodes, the references of a leaf and the boxes of those references, through BoxTree's
// const accessors), so that a change of layout is followed here and nowhere else in lib/collide/.
// A leaf's boxes are read from the tree's leaf blocks (per coordinate, four boxes a block, in leaf
// order), not through box(id): KDSPACE_LEAF_BOXES_FROM picks the other for measurement.
//
// It also holds the cells of the nodes and the ownership rule that lets every overlapping pair be
// reported once although a box may be referenced by several leaves (see `owns`).
#pragma once

#include <array>
#include <cstdint>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"

namespace kdspace::detail {

using NodeId = std::uint32_t;

/// The boxes of one leaf, leaf_boxes[i] for i in [0, count): from the leaf blocks, where the slot of
/// the leaf's i-th reference is first + i.
class LeafBlockBoxes {
 public:
  LeafBlockBoxes(const LeafBlock* blocks, std::uint32_t first) : blocks_(blocks), first_(first) {}
  Box3f operator[](std::uint32_t i) const {
    const std::uint32_t r = first_ + i;
    const LeafBlock& block = blocks_[r / 4];
    const std::uint32_t lane = r % 4;
    Box3f b;
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = block.plane[a][lane];
      b.hi[a] = block.plane[3 + a][lane];
    }
    return b;
  }

 private:
  const LeafBlock* blocks_;
  std::uint32_t first_;
};

/// The same boxes read through the leaf's ids from the tree's boxes (one indirection a box).
class IndexedBoxes {
 public:
  IndexedBoxes(const Box3f* boxes, const std::uint32_t* ids) : boxes_(boxes), ids_(ids) {}
  const Box3f& operator[](std::uint32_t i) const { return boxes_[ids_[i]]; }

 private:
  const Box3f* boxes_;
  const std::uint32_t* ids_;
};

class TreeAccess {
 public:
  explicit TreeAccess(const BoxTree& tree)
      : nodes_(tree.nodes().data()),
        ids_(tree.references().data()),
        blocks_(tree.leaf_blocks().data()),
        boxes_(tree.size() > 0 ? &tree.box(0) : nullptr),
        root_cell_(tree.bounds()),
        node_count_(static_cast<NodeId>(tree.node_count())),
        empty_(tree.size() == 0) {}

  /// A tree of no boxes: every query finds nothing (its root cell is empty, lo > hi).
  bool empty() const { return empty_; }
  static constexpr NodeId root() { return 0; }
  /// The cell of the root: it holds every box (the union of the boxes).
  const Box3f& root_cell() const { return root_cell_; }

  /// Nodes are numbered 0 .. node_count() - 1.
  NodeId node_count() const { return node_count_; }
  bool is_leaf(NodeId n) const { return nodes_[n].is_leaf(); }
  int axis(NodeId n) const { return nodes_[n].axis(); }
  float split(NodeId n) const { return nodes_[n].split(); }
  NodeId left(NodeId n) const { return n + 1; }
  NodeId right(NodeId n) const { return nodes_[n].right_child(); }

  /// A leaf's references: leaf_size boxes, their ids ascending, leaf_boxes(n)[i] the box of the i-th.
  std::uint32_t leaf_size(NodeId n) const { return nodes_[n].count(); }
  const std::uint32_t* leaf_ids(NodeId n) const { return ids_ + nodes_[n].first(); }
#ifdef KDSPACE_LEAF_BOXES_FROM_IDS
  IndexedBoxes leaf_boxes(NodeId n) const { return IndexedBoxes(boxes_, leaf_ids(n)); }
#else
  LeafBlockBoxes leaf_boxes(NodeId n) const { return LeafBlockBoxes(blocks_, nodes_[n].first()); }
#endif

  /// Orders the leaves left to right: of two leaves, the one in the left subtree of their lowest
  /// common ancestor has the smaller rank. Nodes are stored depth first, left subtree first, so the
  /// node index is such a rank.
  NodeId leaf_rank(NodeId n) const { return n; }

 private:
  const BoxNode* nodes_;
  const std::uint32_t* ids_;
  const LeafBlock* blocks_;
  const Box3f* boxes_;
  Box3f root_cell_;
  NodeId node_count_;
  bool empty_;
};

/// The cells of the children of a node with plane `split` on `axis`; the closed cells share the plane.
inline Box3f lower_cell(Box3f cell, int axis, float split) {
  cell.hi[axis] = split;
  return cell;
}
inline Box3f upper_cell(Box3f cell, int axis, float split) {
  cell.lo[axis] = split;
  return cell;
}

/// The point where a pair is reported: the lower corner of the intersection of two overlapping boxes,
/// a point of both (closed) boxes, made of their coordinates without rounding.
inline std::array<float, 3> pair_point(const Box3f& a, const Box3f& b) {
  return {a.lo[0] < b.lo[0] ? b.lo[0] : a.lo[0], a.lo[1] < b.lo[1] ? b.lo[1] : a.lo[1],
          a.lo[2] < b.lo[2] ? b.lo[2] : a.lo[2]};
}

/// Whether the node of `cell` owns the point c of box b: of all the leaves that reference b, exactly
/// one owns c, and every node on its path from the root does.
///
/// Why: the builds send a box to the lower child of a split at p when its lower face is below p, to
/// the upper child when its upper face is above p (both when it straddles p), and a box lying flat in
/// the plane to one side. Follow c down from the root: where b goes to one child only, take that
/// child (c lies in b, hence in that child's closed cell); where b goes to both, take the lower child
/// when c < p and the upper one when c >= p. That path ends in one leaf, and it is the one leaf whose
/// cell passes this test: c lies in the closed cell, except on an upper face that b crosses (there
/// the path went up, to the neighbouring cell). Every comparison is exact (floats compared as they
/// are).
///
/// So a pair of boxes (a, b) with pair point c is reported by the traversal that meets a in the leaf
/// that owns (a, c) and b in the leaf that owns (b, c), and by no other: each pair once, with no
/// search for duplicates afterwards. Both leaves' closed cells contain c, so a traversal that visits
/// every leaf whose closed cell meets a query box meets them.
inline bool owns(const Box3f& cell, const Box3f& b, const std::array<float, 3>& c) {
  for (int a = 0; a < 3; ++a) {
    if (c[a] < cell.lo[a] || c[a] > cell.hi[a]) return false;
    if (c[a] == cell.hi[a] && b.hi[a] > cell.hi[a]) return false;
  }
  return true;
}

}  // namespace kdspace::detail
