// Overlapping pairs of closed 3-D boxes by sort and sweep along x (the classic broad phase): boxes
// ordered by their lower x face; each box is compared with the boxes whose lower x face lies within
// its x extent, and a pair is kept when the boxes also meet on y and z.
//
// An interim for kdspace.BoxTree.overlaps: the library's own overlap queries on the BoxTree (the
// collide module) are to replace it. Worst case quadratic (boxes all spanning x), like any sweep.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <vector>

#include "kdspace/box.hpp"

namespace kdspace::python {

inline bool meet_on_yz(const Box3f& a, const Box3f& b) {
  return a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] && a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2];
}

/// Positions of the boxes ordered by lower x face (then position).
inline std::vector<std::uint32_t> by_lower_x(const std::vector<Box3f>& boxes) {
  std::vector<std::uint32_t> order(boxes.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](std::uint32_t i, std::uint32_t j) {
    return boxes[i].lo[0] < boxes[j].lo[0] || (boxes[i].lo[0] == boxes[j].lo[0] && i < j);
  });
  return order;
}

/// Pairs (i, j), i < j, of overlapping boxes of one set, flattened and sorted.
inline std::vector<std::int64_t> overlaps_within(const std::vector<Box3f>& boxes) {
  const auto order = by_lower_x(boxes);
  std::vector<std::pair<std::int64_t, std::int64_t>> pairs;
  for (std::size_t s = 0; s < order.size(); ++s) {
    const Box3f& a = boxes[order[s]];
    for (std::size_t t = s + 1; t < order.size() && boxes[order[t]].lo[0] <= a.hi[0]; ++t)
      if (meet_on_yz(a, boxes[order[t]]))
        pairs.emplace_back(std::min(order[s], order[t]), std::max(order[s], order[t]));
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<std::int64_t> flat;
  flat.reserve(2 * pairs.size());
  for (const auto& [i, j] : pairs) flat.push_back(i), flat.push_back(j);
  return flat;
}

/// Pairs (i, j) of overlapping boxes, i in `first`, j in `second`, flattened and sorted. A pair is
/// found from the box whose lower x face comes first (from the first set on a tie).
inline std::vector<std::int64_t> overlaps_between(const std::vector<Box3f>& first, const std::vector<Box3f>& second) {
  const auto order_a = by_lower_x(first), order_b = by_lower_x(second);
  std::vector<std::pair<std::int64_t, std::int64_t>> pairs;
  auto sweep = [&](const std::vector<Box3f>& from, const std::vector<std::uint32_t>& from_order,
                   const std::vector<Box3f>& to, const std::vector<std::uint32_t>& to_order, bool from_is_first) {
    std::size_t start = 0;
    for (std::uint32_t i : from_order) {
      const Box3f& a = from[i];
      // The first box of `to` whose lower x face is at or after a's (strictly after when `to` is
      // the first set, so that a tie is found once).
      while (start < to_order.size() && (from_is_first ? to[to_order[start]].lo[0] < a.lo[0]
                                                       : to[to_order[start]].lo[0] <= a.lo[0]))
        ++start;
      for (std::size_t t = start; t < to_order.size() && to[to_order[t]].lo[0] <= a.hi[0]; ++t)
        if (meet_on_yz(a, to[to_order[t]]))
          pairs.emplace_back(from_is_first ? i : to_order[t], from_is_first ? to_order[t] : i);
    }
  };
  sweep(first, order_a, second, order_b, true);
  sweep(second, order_b, first, order_a, false);
  std::sort(pairs.begin(), pairs.end());
  std::vector<std::int64_t> flat;
  flat.reserve(2 * pairs.size());
  for (const auto& [i, j] : pairs) flat.push_back(i), flat.push_back(j);
  return flat;
}

}  // namespace kdspace::python
