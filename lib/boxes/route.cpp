#include "route.hpp"

#include <algorithm>

namespace kdspace::detail {

bool route_boxes(std::vector<BuiltNode>& nodes, const Box3f* boxes, std::size_t n, std::size_t max_references,
                 std::vector<std::uint32_t>& references) {
  // One descent a box, then a counting sort by leaf (stable, so a leaf's ids stay ascending).
  const std::size_t limit = std::min(max_references, reference_limit);
  std::vector<std::uint32_t> leaf_of;                 // the leaves reached, box after box
  std::vector<std::uint32_t> reached(n);              // how many leaves box i reached
  std::vector<std::uint32_t> count(nodes.size(), 0);  // how many boxes reached each leaf
  leaf_of.reserve(n + n / 2);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t before = leaf_of.size();
    for_each_leaf_of(nodes, boxes[i], [&](std::uint32_t leaf) {
      leaf_of.push_back(leaf);
      ++count[leaf];
    });
    reached[i] = static_cast<std::uint32_t>(leaf_of.size() - before);
    if (leaf_of.size() > limit) return false;
  }
  std::vector<std::uint32_t> next(nodes.size());
  std::uint32_t first = 0;
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    if (!nodes[node].is_leaf()) continue;
    next[node] = first;
    nodes[node].first = first;
    nodes[node].count = count[node];
    first += count[node];
  }
  references.resize(leaf_of.size());
  std::size_t e = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::uint32_t k = 0; k < reached[i]; ++k)
      references[next[leaf_of[e++]]++] = static_cast<std::uint32_t>(i);
  return true;
}

}  // namespace kdspace::detail
