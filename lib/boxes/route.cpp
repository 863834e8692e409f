#include "route.hpp"

#include <array>

namespace kdspace::detail {

bool route_boxes(std::vector<BoxNode>& nodes, const Box3f* boxes, std::size_t n, std::size_t max_references,
                 std::vector<std::uint32_t>& references) {
  // One descent a box: the leaves it reaches, in box order, then a counting sort by leaf (stable, so
  // a leaf's ids stay ascending).
  std::vector<std::uint32_t> leaf_of;  // the leaves reached, box after box
  std::vector<std::uint32_t> reached(n);  // how many leaves box i reached
  leaf_of.reserve(n + n / 2);
  std::vector<std::uint32_t> count(nodes.size(), 0);
  std::array<std::uint32_t, max_box_tree_depth + 2> stack;
  for (std::size_t i = 0; i < n; ++i) {
    const Box3f& b = boxes[i];
    const std::size_t before = leaf_of.size();
    std::size_t top = 0;
    stack[top++] = 0;
    while (top > 0) {
      std::uint32_t node = stack[--top];
      for (;;) {
        const BoxNode& at = nodes[node];
        if (at.is_leaf()) {
          leaf_of.push_back(node);
          ++count[node];
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
    reached[i] = static_cast<std::uint32_t>(leaf_of.size() - before);
    // References are counted in 30 bits (BoxNode).
    if (leaf_of.size() > max_references || leaf_of.size() >= (std::size_t{1} << 30)) return false;
  }

  std::vector<std::uint32_t> next(nodes.size());
  std::uint32_t first = 0;
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    if (!nodes[node].is_leaf()) continue;
    next[node] = first;
    nodes[node] = BoxNode::leaf(first, count[node]);
    first += count[node];
  }
  references.resize(leaf_of.size());
  std::size_t e = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::uint32_t k = 0; k < reached[i]; ++k) references[next[leaf_of[e++]]++] = static_cast<std::uint32_t>(i);
  return true;
}

}  // namespace kdspace::detail
