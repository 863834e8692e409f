#include "pair_sort.hpp"

#include <algorithm>
#include <cstdint>

namespace kdspace::detail {

void sort_pairs(std::vector<IndexPair>& pairs, std::size_t a_count) {
  // Below this size, or with far more boxes than pairs, counting costs more than comparing.
  if (pairs.size() < 4096 || a_count > 4 * pairs.size()) {
    std::sort(pairs.begin(), pairs.end());
    return;
  }
  std::vector<std::size_t> start(a_count + 1, 0);
  for (const IndexPair& p : pairs) ++start[p.a + 1];
  for (std::size_t a = 0; a < a_count; ++a) start[a + 1] += start[a];
  std::vector<IndexPair> placed(pairs.size());
  {
    std::vector<std::size_t> next(start.begin(), start.end() - 1);
    for (const IndexPair& p : pairs) placed[next[p.a]++] = p;
  }
  for (std::size_t a = 0; a < a_count; ++a) {
    IndexPair* first = placed.data() + start[a];
    IndexPair* last = placed.data() + start[a + 1];
    if (last - first <= 16) {  // insertion sort on b
      for (IndexPair* p = first + 1; p < last; ++p) {
        const IndexPair v = *p;
        IndexPair* q = p;
        for (; q > first && v.b < (q - 1)->b; --q) *q = *(q - 1);
        *q = v;
      }
    } else {
      std::sort(first, last, [](const IndexPair& x, const IndexPair& y) { return x.b < y.b; });
    }
  }
  pairs.swap(placed);
}

std::vector<IndexPair> merge_and_sort(std::vector<std::vector<IndexPair>>& lists, std::size_t a_count) {
  std::size_t total = 0;
  for (const auto& list : lists) total += list.size();
  std::vector<IndexPair> all;
  if (lists.size() == 1) {
    all.swap(lists[0]);
  } else {
    all.reserve(total);
    for (auto& list : lists) {
      all.insert(all.end(), list.begin(), list.end());
      std::vector<IndexPair>().swap(list);
    }
  }
  sort_pairs(all, a_count);
  return all;
}

}  // namespace kdspace::detail
