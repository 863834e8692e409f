// The traversal layout (see layout.hpp).
#include "layout.hpp"

#include <algorithm>

namespace kdspace::detail {

void write_leaf(const std::uint32_t* ids, std::uint32_t count, const Box3f* boxes, std::uint32_t* references,
                LeafBlock* blocks) {
  for (std::uint32_t i = 0; i < count; i += 4) {
    LeafBlock& block = *blocks++;
    for (std::uint32_t lane = 0; lane < 4; ++lane) {
      const std::uint32_t id = ids[std::min(i + lane, count - 1)];
      *references++ = id;
      const Box3f& b = boxes[id];
      for (int a = 0; a < 3; ++a) {
        block.plane[a][lane] = b.lo[a];
        block.plane[3 + a][lane] = b.hi[a];
      }
    }
  }
}

TreeLayout lay_out(const TreeWriter& built, const std::vector<Box3f>& boxes) {
  TreeLayout out;
  lay_out(built, boxes, out);
  return out;
}

void lay_out(const TreeWriter& built, const std::vector<Box3f>& boxes, TreeLayout& out) {
  out.nodes.clear();
  out.nodes.reserve(built.nodes.size());
  std::size_t padded = 0;
  for (const BuiltNode& n : built.nodes)
    if (n.is_leaf()) padded += padded_size(n.count);
  out.references.resize(padded);
  out.blocks.resize(padded / 4);
  std::uint32_t first = 0;
  for (const BuiltNode& n : built.nodes) {
    if (!n.is_leaf()) {
      out.nodes.push_back(BoxNode::inner(n.axis, n.split, n.right));
      continue;
    }
    write_leaf(built.references.data() + n.first, n.count, boxes.data(), out.references.data() + first,
               out.blocks.data() + first / 4);
    out.nodes.push_back(BoxNode::leaf(first, n.count));
    first += static_cast<std::uint32_t>(padded_size(n.count));
  }
}

}  // namespace kdspace::detail
