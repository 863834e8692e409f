// Selection and sorting of distinct 64-bit keys without branches on the keys' values: the graph's
// build orders candidates (distance bits above the row) that come in random order, where the
// compare branches of std::nth_element and std::sort are mispredicted about half of the time.
// Each partition swaps every key to the front end and moves that end on when the key is below the
// pivot (Lomuto's scheme, the move an addition); runs of at most 8 keys are sorted by insertion
// with minimum and maximum instead of a search for the place.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>

namespace kdspace::detail {

/// Partitions keys[low, high) (at least 2 keys) around the median of its first, middle and last
/// keys; returns the pivot's position p: keys[low, p) < keys[p] < keys(p, high).
inline std::size_t partition_keys(std::uint64_t* keys, std::size_t low, std::size_t high) {
  const std::size_t mid = low + (high - low) / 2;
  if (keys[mid] < keys[low]) std::swap(keys[mid], keys[low]);
  if (keys[high - 1] < keys[mid]) std::swap(keys[high - 1], keys[mid]);
  if (keys[mid] < keys[low]) std::swap(keys[mid], keys[low]);
  std::swap(keys[mid], keys[high - 1]);
  const std::uint64_t pivot = keys[high - 1];
  std::size_t below = low;
  for (std::size_t i = low; i + 1 < high; ++i) {
    const std::uint64_t x = keys[i];
    keys[i] = keys[below];
    keys[below] = x;
    below += x < pivot ? 1 : 0;
  }
  std::swap(keys[below], keys[high - 1]);
  return below;
}

/// Moves the `keep` smallest of the distinct keys[0, count) to the front, in any order.
inline void select_smallest(std::uint64_t* keys, std::size_t count, std::size_t keep) {
  // Invariant: keys[0, low) < keys[low, high) < keys[high, count), and low <= keep <= high.
  std::size_t low = 0, high = count;
  while (low < keep && keep < high) {
    const std::size_t p = partition_keys(keys, low, high);
    if (keep <= p)
      high = p;
    else
      low = p + 1;
  }
}

/// Sorts the distinct keys[0, count).
inline void sort_keys(std::uint64_t* keys, std::size_t count) {
  if (count > 8) {
    const std::size_t p = partition_keys(keys, 0, count);
    sort_keys(keys, p);
    sort_keys(keys + p + 1, count - p - 1);
    return;
  }
  // Insertion of keys[i] into the sorted keys[0, i): each place takes the larger of the key before
  // it and the smaller of its own and the new one.
  for (std::size_t i = 1; i < count; ++i) {
    const std::uint64_t x = keys[i];
    for (std::size_t j = i; j > 0; --j) keys[j] = std::max(keys[j - 1], std::min(keys[j], x));
    keys[0] = std::min(keys[0], x);
  }
}

}  // namespace kdspace::detail
