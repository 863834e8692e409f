// The traversal layout (see layout.hpp).
#include "layout.hpp"

#include <algorithm>

namespace kdspace::detail {

TreeLayout lay_out(const TreeWriter& built, const std::vector<Box3f>& boxes) {
  TreeLayout out;
  out.nodes.reserve(built.nodes.size());
  std::size_t padded = 0;
  for (const BuiltNode& n : built.nodes)
    if (n.is_leaf()) padded += (n.count + 3) / 4 * 4;
  out.references.reserve(padded);
  out.blocks.reserve(padded / 4);
  for (const BuiltNode& n : built.nodes) {
    if (!n.is_leaf()) {
      out.nodes.push_back(BoxNode::inner(n.axis, n.split, n.right));
      continue;
    }
    // A leaf's references and boxes, padded to a multiple of 4 with its last box.
    const auto first = static_cast<std::uint32_t>(out.references.size());
    const std::uint32_t* ids = built.references.data() + n.first;
    for (std::uint32_t i = 0; i < n.count; i += 4) {
      LeafBlock block;
      for (std::uint32_t lane = 0; lane < 4; ++lane) {
        const std::uint32_t id = ids[std::min(i + lane, n.count - 1)];
        out.references.push_back(id);
        const Box3f& b = boxes[id];
        for (int a = 0; a < 3; ++a) {
          block.plane[a][lane] = b.lo[a];
          block.plane[3 + a][lane] = b.hi[a];
        }
      }
      out.blocks.push_back(block);
    }
    out.nodes.push_back(BoxNode::leaf(first, n.count));
  }
  return out;
}

}  // namespace kdspace::detail
