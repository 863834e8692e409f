// The layout the traversal reads: the builds' depth-first nodes as BoxNodes, and each leaf's boxes
// copied into LeafBlocks (four boxes per block, stored per coordinate) for the traversal's
// four-at-a-time box test, its references padded to a multiple of 4 alike.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "build_common.hpp"
#include "kdspace/boxes/box_tree.hpp"

namespace kdspace::detail {

struct TreeLayout {
  std::vector<BoxNode> nodes;
  std::vector<std::uint32_t> references;
  std::vector<LeafBlock> blocks;
};

/// The traversal layout of `built`, a tree over `boxes`.
TreeLayout lay_out(const TreeWriter& built, const std::vector<Box3f>& boxes);
/// The same into `out`, reusing its vectors' memory (BoxTree::refit, frame after frame).
void lay_out(const TreeWriter& built, const std::vector<Box3f>& boxes, TreeLayout& out);

/// Reference slots a leaf of `count` boxes takes: count rounded up to a multiple of 4.
inline std::size_t padded_size(std::size_t count) { return (count + 3) / 4 * 4; }

/// Writes one leaf of `count` boxes, ids[0 .. count) (ascending): padded_size(count) references to
/// `references` and padded_size(count) / 4 blocks to `blocks`, the slots past count repeating its
/// last box. Shared by lay_out and BoxTree::refit, which rewrites only the leaves that changed.
void write_leaf(const std::uint32_t* ids, std::uint32_t count, const Box3f* boxes, std::uint32_t* references,
                LeafBlock* blocks);

}  // namespace kdspace::detail
