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

bool route_moved_boxes(std::vector<BoxNode>& nodes, const Box3f* boxes, std::size_t n, const std::uint32_t* moved,
                       std::size_t m, std::size_t max_references, std::vector<std::uint32_t>& references) {
  std::vector<char> is_moved(n, 0);
  for (std::size_t k = 0; k < m; ++k) is_moved[moved[k]] = 1;
  std::vector<std::uint32_t> leaf_of, reached, added;
  if (!descend_all(nodes, boxes, m, [&](std::size_t k) { return moved[k]; }, reference_limit, leaf_of, reached,
                   added))
    return false;

  // The moved boxes' new references, by leaf (stable: ids ascending within a leaf).
  std::vector<std::uint32_t> added_first(nodes.size() + 1, 0);
  for (std::size_t node = 0; node < nodes.size(); ++node) added_first[node + 1] = added_first[node] + added[node];
  std::vector<std::uint32_t> added_ids(leaf_of.size());
  {
    std::vector<std::uint32_t> next(added_first.begin(), added_first.end() - 1);
    std::size_t e = 0;
    for (std::size_t k = 0; k < m; ++k)
      for (std::uint32_t r = 0; r < reached[k]; ++r) added_ids[next[leaf_of[e++]]++] = moved[k];
  }

  // Each leaf: its unmoved references merged with its new ones.
  std::size_t total = 0;
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    const BoxNode& at = nodes[node];
    if (!at.is_leaf()) continue;
    for (std::uint32_t r = at.first(); r < at.first() + at.count(); ++r) total += is_moved[references[r]] ? 0 : 1;
    total += added[node];
  }
  if (total > std::min(max_references, reference_limit)) return false;
  std::vector<std::uint32_t> merged;
  merged.reserve(total);
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    if (!nodes[node].is_leaf()) continue;
    const auto first = static_cast<std::uint32_t>(merged.size());
    const std::uint32_t* old_ref = references.data() + nodes[node].first();
    const std::uint32_t* old_end = old_ref + nodes[node].count();
    const std::uint32_t* new_ref = added_ids.data() + added_first[node];
    const std::uint32_t* new_end = added_ids.data() + added_first[node + 1];
    for (;;) {
      while (old_ref < old_end && is_moved[*old_ref]) ++old_ref;
      if (old_ref == old_end) {
        merged.insert(merged.end(), new_ref, new_end);
        break;
      }
      if (new_ref == new_end || *old_ref < *new_ref) {
        merged.push_back(*old_ref++);
      } else {
        merged.push_back(*new_ref++);
      }
    }
    nodes[node] = BoxNode::leaf(first, static_cast<std::uint32_t>(merged.size()) - first);
  }
  references.swap(merged);
  return true;
}

}  // namespace kdspace::detail
