// The layout the traversal reads: the builds' depth-first nodes as BoxNodes, and each leaf's boxes
// copied into LeafBlocks (four boxes per block, stored per coordinate) for the traversal's
// four-at-a-time box test, its references padded to a multiple of 4 alike.
#pragma once

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

}  // namespace kdspace::detail
