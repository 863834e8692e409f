// Records with a first index a (found pairs), kept as they are found in buckets of consecutive a, and
// put in order (by a, then by a rule within a) once all are found.
//
// The order of the result does not depend on which bucket set a record went to, nor on when: a
// join's records are distinct, and the order within a is total on distinct records, so one set of
// buckets per worker thread gives the same result on any number of threads.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"

namespace kdspace::detail {

template <class Record>
class FirstIndexBuckets {
 public:
  /// At most 1024 buckets (1024 write streams stay within the caches), each of 2^shift values of a.
  static constexpr std::size_t max_buckets = 1024;

  /// For records with a < n_a.
  explicit FirstIndexBuckets(std::size_t n_a) : shift_(shift_for(n_a)), buckets_((n_a >> shift_) + 1) {}

  void add(const Record& r) { buckets_[std::size_t{r.a} >> shift_].push_back(r); }

  static unsigned shift_for(std::size_t n_a) {
    unsigned shift = 0;
    while ((n_a >> shift) >= max_buckets) ++shift;
    return shift;
  }

  unsigned shift() const { return shift_; }
  std::vector<Record>& bucket(std::size_t k) { return buckets_[k]; }
  std::size_t bucket_count() const { return buckets_.size(); }

 private:
  unsigned shift_;
  std::vector<std::vector<Record>> buckets_;
};

/// Writes the run [first, first + m) of the records of one first point to out, sorted. A short run (a
/// point's pairs within r number a few) is placed by ranks: each record goes to the count of the
/// run's records that come before it, which is its place as the records are distinct and the order
/// total on them. That takes m * m comparisons but no branch that depends on their values, where an
/// insertion sort mispredicted the end of about every insertion (callgrind --branch-sim, pairs
/// within r of 2e5 uniform 3-D points: 910,000 mispredictions for 955,000 pairs). Longer runs are
/// copied and go to std::sort.
template <class Record, class Less>
void place_run(const Record* first, std::size_t m, Record* out, Less&& less) {
  constexpr std::size_t short_run = 16;
  if (m > short_run) {
    std::copy(first, first + m, out);
    std::sort(out, out + m, less);
    return;
  }
  for (std::size_t i = 0; i < m; ++i) {
    std::size_t place = 0;
    for (std::size_t j = 0; j < m; ++j) place += less(first[j], first[i]) ? 1 : 0;
    out[place] = first[i];
  }
}

/// The records of every set of buckets (all made for the same n_a), ordered by a, then by
/// less_within_a; the buckets are emptied.
///
/// Bucket by bucket, within the cache: a counting pass by a (a table of counts as wide as a bucket)
/// moves the bucket's records of every set into a scratch run in order of a, each run of equal a
/// (one point's pairs, a few) is placed in order at the result's end (grown a bucket at a time, so
/// that what its growth zeroes is still in the cache when the runs overwrite it). Putting the
/// records in buckets as they are found (rather than in one list per task, moved into buckets
/// after) saves a pass over all records. (Perf
/// samples in the ordering, 1e6 uniform 3-D points, 4.8e6 pairs: counting sorts by b then by a
/// 1122, one counting sort by a over all of them 875-953, by buckets 795-813.)
template <class Record, class Less>
std::vector<Record> sort_by_first_index(std::vector<FirstIndexBuckets<Record>>& sets, Less&& less_within_a) {
  std::vector<Record> sorted;
  if (sets.empty()) return sorted;
  std::size_t total = 0;
  for (auto& set : sets)
    for (std::size_t k = 0; k < set.bucket_count(); ++k) total += set.bucket(k).size();
  reserve_in_huge_pages(sorted, total);
  const unsigned shift = sets.front().shift();
  const std::size_t width = std::size_t{1} << shift;
  std::vector<std::size_t> next(width + 1);
  std::vector<Record> scratch;
  for (std::size_t k = 0; k < sets.front().bucket_count(); ++k) {
    const std::size_t first_a = k << shift;
    std::fill(next.begin(), next.end(), std::size_t{0});
    for (auto& set : sets)
      for (const Record& r : set.bucket(k)) ++next[r.a - first_a + 1];
    for (std::size_t a = 0; a < width; ++a) next[a + 1] += next[a];
    scratch.resize(next[width]);
    for (auto& set : sets) {
      for (const Record& r : set.bucket(k)) scratch[next[r.a - first_a]++] = r;
      std::vector<Record>().swap(set.bucket(k));
    }
    // Now next[a] is where the run of first_a + a ends (and that of the next a begins).
    const std::size_t at = sorted.size();
    sorted.resize(at + scratch.size());
    Record* out = sorted.data() + at;
    std::size_t begin = 0;
    for (std::size_t a = 0; a < width; ++a) {
      const std::size_t end = next[a];
      place_run(scratch.data() + begin, end - begin, out + begin, less_within_a);
      begin = end;
    }
  }
  return sorted;
}

}  // namespace kdspace::detail
