// Sorting lists of pairs by (a, b): what every pair query returns.
#pragma once

#include <cstddef>
#include <vector>

#include "kdspace/index_pair.hpp"

namespace kdspace::detail {

/// Sorts `pairs` by (a, b); every a is below a_count. A counting sort on a (one pass to count, one
/// to place), then each run of equal a sorted on b; runs are short (a box overlaps few others), so
/// this takes about three passes where a comparison sort takes log2(M).
void sort_pairs(std::vector<IndexPair>& pairs, std::size_t a_count);

/// Moves the pairs of every list into one, sorted by (a, b).
std::vector<IndexPair> merge_and_sort(std::vector<std::vector<IndexPair>>& lists, std::size_t a_count);

}  // namespace kdspace::detail
