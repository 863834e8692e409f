#include "route.hpp"

#include <algorithm>

namespace kdspace::detail {

namespace {

/// References are counted in 30 bits (BoxNode).
constexpr std::size_t reference_limit = (std::size_t{1} << 30) - 1;

/// The leaves that boxes[ids] reach, box after box: leaf_of lists them, reached[k] counts those of
/// the k-th box, count[leaf] those of each leaf. False as soon as there are more than `limit`.
template <class Ids>
bool descend_all(const std::vector<BoxNode>& nodes, const Box3f* boxes, std::size_t m, Ids&& id_of,
                 std::size_t limit, std::vector<std::uint32_t>& leaf_of, std::vector<std::uint32_t>& reached,
                 std::vector<std::uint32_t>& count) {
  leaf_of.reserve(m + m / 2);
  reached.resize(m);
  count.assign(nodes.size(), 0);
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t before = leaf_of.size();
    for_each_leaf_of(nodes, boxes[id_of(k)], [&](std::uint32_t leaf) {
      leaf_of.push_back(leaf);
      ++count[leaf];
    });
    reached[k] = static_cast<std::uint32_t>(leaf_of.size() - before);
    if (leaf_of.size() > limit) return false;
  }
  return true;
}

}  // namespace

bool route_boxes(std::vector<BoxNode>& nodes, const Box3f* boxes, std::size_t n, std::size_t max_references,
                 std::vector<std::uint32_t>& references) {
  // One descent a box, then a counting sort by leaf (stable, so a leaf's ids stay ascending).
  std::vector<std::uint32_t> leaf_of, reached, count;
  if (!descend_all(nodes, boxes, n, [](std::size_t k) { return k; }, std::min(max_references, reference_limit),
                   leaf_of, reached, count))
    return false;
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
