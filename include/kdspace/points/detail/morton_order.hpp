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

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace kdspace::detail {

/// Dimensions up to this get a Z-order key of at least 4 bits an axis in 32 bits.
inline constexpr std::size_t morton_max_dim = 8;

/// The numbers first .. last - 1 of rows (row-major, `dim` coordinates, dim <= morton_max_dim,
/// finite) in Z-order of their cells in a grid over the box [lo, hi] (rows outside it count as in
/// its nearest cell); rows in one cell keep their order. last - first < 2^32.
template <class T>
std::vector<std::size_t> morton_order(const T* rows, std::size_t first, std::size_t last, std::size_t dim, const T* lo,
                                      const T* hi) {
  const std::size_t bits = 32 / dim;  // per axis: 10 in 3-D, 16 in 2-D, 4 in 8-D
  const double cells = static_cast<double>(std::uint64_t{1} << bits);
  const std::uint32_t last_cell = static_cast<std::uint32_t>((std::uint64_t{1} << bits) - 1);
  // spread[v]: the bits of byte v placed dim apart (bit i at i * dim).
  std::array<std::uint32_t, 256> spread{};
  for (std::uint32_t v = 0; v < 256; ++v)
    for (std::size_t i = 0; i < 8 && i * dim < 32; ++i) spread[v] |= ((v >> i) & 1u) << (i * dim);
  // Grid scale in double: hi - lo may overflow a float.
  std::vector<double> scale(dim);
  for (std::size_t a = 0; a < dim; ++a) {
    const double extent = static_cast<double>(hi[a]) - static_cast<double>(lo[a]);
    scale[a] = extent > 0 ? cells / extent : 0;
  }
  const std::size_t count = last - first;
  std::vector<std::uint64_t> keyed(count), sorted(count);  // Z-order key, then the row's offset
  for (std::size_t i = 0; i < count; ++i) {
    const T* x = rows + (first + i) * dim;
    std::uint32_t key = 0;
    for (std::size_t a = 0; a < dim; ++a) {
      const double t = (static_cast<double>(x[a]) - static_cast<double>(lo[a])) * scale[a];
      const std::uint32_t cell = t <= 0 ? 0u : t >= cells ? last_cell : static_cast<std::uint32_t>(t);
      std::uint32_t spread_cell = 0;
      for (std::size_t byte = 0; byte * 8 < bits; ++byte)
        spread_cell |= spread[(cell >> (8 * byte)) & 0xffu] << (8 * byte * dim);
      key |= spread_cell << a;
    }
    keyed[i] = (std::uint64_t{key} << 32) | i;
  }
  // LSD radix sort on the key's four bytes; stable, so equal keys keep the rows' order.
  for (unsigned shift = 32; shift < 64; shift += 8) {
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
