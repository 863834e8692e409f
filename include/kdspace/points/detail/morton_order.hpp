// morton_order: the rows of a batch in Z-order (Morton order) of their cells in a grid over a box,
// so that consecutive queries lie near each other.
//
// Why: a k-NN query on a 3-D scan visits about 17 nodes and 31 points, and its cost is the descent:
// a dependent load and a near/far branch per level that a random query order mispredicts about
// every other time. Queries taken in Z-order descend along nearly the same path as the previous
// one, so the branches are predicted and the nodes and points are in cache. The order costs no tree
// descent: a key of a few shifts and table look-ups per row and a radix sort, linear in the batch.
// (Morton, "A computer oriented geodetic data base and a new technique in file sequencing", IBM 1966;
// the key interleaves the bits of the cell coordinates.)
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"

namespace kdspace::detail {

/// Dimensions up to this get a Z-order key of at least 4 bits an axis in 32 bits.
inline constexpr std::size_t morton_max_dim = 8;

/// Bits per axis of the grid for a batch of `count` rows: enough for about 8 cells per row (uniform
/// rows), at most 16 an axis and 32 in all; fewer bits mean fewer radix passes, and a finer order than
/// the rows' spacing buys nothing.
inline std::size_t morton_bits_per_axis(std::size_t count, std::size_t dim) {
  std::size_t count_bits = 0;
  while (count >> count_bits) ++count_bits;
  return std::min({std::size_t{16}, 32 / dim, (count_bits + 3 + dim - 1) / dim});
}

/// The numbers first .. last - 1 of rows (row-major, `dim` coordinates, dim <= morton_max_dim,
/// finite) in Z-order of their cells in a grid over the box [lo, hi] (rows outside it count as in
/// its nearest cell); rows in one cell keep their order. last - first < 2^32.
template <class T>
std::vector<std::size_t> morton_order(const T* rows, std::size_t first, std::size_t last, std::size_t dim,
                                      const T* lo, const T* hi) {
  const std::size_t count = last - first;
  if (count == 0) return {};
  const std::size_t bits = morton_bits_per_axis(count, dim);
  const double cells = static_cast<double>(std::uint64_t{1} << bits);
  const double top = cells - 1;  // the last cell's number
  // spread[v]: the bits of byte v placed dim apart (bit i at i * dim).
  // (Bits beyond 32 fall off; a cell has at most 32 / dim bits, so they are never set.)
  // spread_high[v]: the same for the cell's second byte (bits > 8 happens only up to 3-D).
  std::array<std::uint32_t, 256> spread{}, spread_high{};
  for (std::uint32_t v = 1; v < 256; ++v) {
    spread[v] = (dim < 32 ? spread[v >> 1] << dim : 0u) | (v & 1u);
    spread_high[v] = bits > 8 ? spread[v] << (8 * dim) : 0u;
  }
  // Grid scale in double: hi - lo may overflow a float.
  std::vector<double> scale(dim);
  for (std::size_t a = 0; a < dim; ++a) {
    const double extent = static_cast<double>(hi[a]) - static_cast<double>(lo[a]);
    scale[a] = extent > 0 ? cells / extent : 0;
  }
  HugePageVector<std::uint64_t> keyed(count), sorted(count);  // Z-order key, then the row's offset
  for (std::size_t i = 0; i < count; ++i) {
    const T* x = rows + (first + i) * dim;
    std::uint32_t key = 0;
    for (std::size_t a = 0; a < dim; ++a) {
      // Clamped to the grid without a branch; a NaN (infinite extent times a zero scale) goes to cell 0.
      const double t = (static_cast<double>(x[a]) - static_cast<double>(lo[a])) * scale[a];
      const std::uint32_t cell = static_cast<std::uint32_t>(std::min(top, std::max(0.0, t)));
      key |= (spread[cell & 0xffu] | spread_high[cell >> 8]) << a;
    }
    keyed[i] = (std::uint64_t{key} << 32) | i;
  }
  // LSD radix sort on the key's bytes; stable, so equal keys keep the rows' order.
  for (std::size_t shift = 32; shift < 32 + bits * dim; shift += 8) {
    std::array<std::size_t, 257> start{};
    for (const std::uint64_t k : keyed) ++start[((k >> shift) & 0xffu) + 1];
    if (start[((keyed[0] >> shift) & 0xffu) + 1] == count) continue;  // one bucket: nothing moves
    for (std::size_t b = 1; b < 257; ++b) start[b] += start[b - 1];
    for (const std::uint64_t k : keyed) sorted[start[(k >> shift) & 0xffu]++] = k;
    keyed.swap(sorted);
  }
  std::vector<std::size_t> order(count);
  for (std::size_t i = 0; i < count; ++i) order[i] = first + static_cast<std::uint32_t>(keyed[i]);
  return order;
}

}  // namespace kdspace::detail
