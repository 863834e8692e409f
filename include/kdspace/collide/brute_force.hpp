// References for the collision queries, independent of the tree: what tests, the demo and the
// command's checks compare the BoxTree's answers with.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/collide/detail/contact_window.hpp"
#include "kdspace/index_pair.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace {

/// The ids of the boxes that overlap `query` (closed), ascending: every box tested.
inline std::vector<std::uint32_t> brute_force_overlapping(const std::vector<Box3f>& boxes,
                                                          const Box3f& query) {
  std::vector<std::uint32_t> ids;
  for (std::size_t i = 0; i < boxes.size(); ++i)
    if (boxes[i].overlaps(query)) ids.push_back(static_cast<std::uint32_t>(i));
  return ids;
}

/// Every pair (i, j) with i < j of overlapping boxes, sorted: sweep and prune along x (the boxes in
/// order of lower x face; each is tested against the ones that start no later than it ends), so that
/// a reference for 1e5 boxes takes well under a second, with nothing shared with the tree.
inline std::vector<IndexPair> brute_force_pairs(const std::vector<Box3f>& boxes) {
  std::vector<std::uint32_t> order(boxes.size());
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](std::uint32_t i, std::uint32_t j) {
    return boxes[i].lo[0] < boxes[j].lo[0] || (boxes[i].lo[0] == boxes[j].lo[0] && i < j);
  });
  std::vector<IndexPair> pairs;
  for (std::size_t s = 0; s < order.size(); ++s) {
    const Box3f& b = boxes[order[s]];
    for (std::size_t t = s + 1; t < order.size() && boxes[order[t]].lo[0] <= b.hi[0]; ++t)
      if (b.overlaps(boxes[order[t]]))
        pairs.push_back({std::min(order[s], order[t]), std::max(order[s], order[t])});
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

/// Every pair (a, b) with box a of `first` overlapping box b of `second`, sorted: every pair tested.
inline std::vector<IndexPair> brute_force_pairs(const std::vector<Box3f>& first,
                                                const std::vector<Box3f>& second) {
  std::vector<IndexPair> pairs;
  for (std::size_t a = 0; a < first.size(); ++a)
    for (std::size_t b = 0; b < second.size(); ++b)
      if (first[a].overlaps(second[b]))
        pairs.push_back({static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b)});
  return pairs;
}

/// The first contact of `moving` + t * motion, t in [0, t_max], with any of the boxes: every box's
/// contact window computed as the tree computes it (detail::contact_window), the smallest t kept,
/// equal t to the smaller index. The t is the double rounded to float, as first_contact reports it.
inline Hit brute_force_first_contact(const std::vector<Box3f>& boxes, const Box3f& moving,
                                     const Vec3f& motion,
                                     float t_max = std::numeric_limits<float>::infinity()) {
  const detail::PreparedMotion m(moving, motion);
  double best_t = std::numeric_limits<double>::infinity();
  std::int32_t best = Hit::none;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    double t_enter = 0, t_exit = t_max;
    if (detail::contact_window(boxes[i], m, t_enter, t_exit) && t_enter < best_t) {
      best_t = t_enter;
      best = static_cast<std::int32_t>(i);
    }
  }
  if (best == Hit::none) return Hit{};
  constexpr double largest = std::numeric_limits<float>::max();
  return Hit{best, static_cast<float>(best_t > largest ? largest : best_t)};
}

}  // namespace kdspace
