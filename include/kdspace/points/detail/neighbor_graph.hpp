// NeighborGraph: the graph PointForest searches besides its trees. Each point (a row of the forest's
// copy of the points) keeps up to `degree` neighbours, in fixed-width lists stored one after the
// other, so that a point's list is one contiguous read of degree * 4 bytes at a known place.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/detail/storage.hpp"

namespace kdspace::detail {

struct NeighborGraph {
  /// Width of every list (the largest out-degree); 0 = no graph.
  std::size_t degree = 0;
  /// Row r's neighbours are links[r * degree ...], nearest first; a list with fewer than `degree`
  /// neighbours is padded with r itself (a search has marked r as seen before it reads r's list, so
  /// the padding is skipped like any point already seen, and the first r ends the list).
  /// Owned, or borrowed from a mapped index file.
  Storage<std::uint32_t> links;

  bool empty() const { return degree == 0; }
  const std::uint32_t* neighbours(std::uint32_t row) const { return links.data() + std::size_t{row} * degree; }
  std::size_t bytes() const { return links.memory_bytes(); }
  /// Makes n lists of `width` links (all 0) to fill in place; returns where they start.
  std::uint32_t* reset(std::size_t n, std::size_t width) {
    degree = width;
    links = Storage<std::uint32_t>(std::vector<std::uint32_t>(n * width));
    return links.owned_data();
  }
};

}  // namespace kdspace::detail
