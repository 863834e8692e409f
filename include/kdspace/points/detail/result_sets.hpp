// Result sets: the one place that decides what a query keeps. The traversal offers every scored
// point and prunes every cell farther than bound(); it knows nothing else about the query.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

/// A scored point: internal distance and original index.
template <class T>
struct Candidate {
  T dist;
  std::uint32_t index;
};

/// The order of results: ascending distance, ties by ascending index. A function object, so that
/// the heap and sort algorithms inline it.
struct ComesBefore {
  template <class T>
  bool operator()(const Candidate<T>& a, const Candidate<T>& b) const {
    return a.dist < b.dist || (a.dist == b.dist && a.index < b.index);
  }
};
inline constexpr ComesBefore comes_before{};

/// Keeps the k first candidates in (distance, index) order among those with dist <= limit.
/// A max-heap on that order; its top is the one to evict.
template <class T>
class KnnResults {
 public:
  KnnResults(std::size_t k, T limit, std::vector<Candidate<T>>& storage) : k_(k), limit_(limit), heap_(storage) {
    heap_.clear();
    heap_.reserve(k);
  }

  /// The largest distance a candidate may have and still be kept (ties may still enter by index).
  T bound() const { return heap_.size() == k_ ? heap_.front().dist : limit_; }

  /// Whether k candidates are kept.
  bool full() const { return heap_.size() == k_; }

  /// Offers a candidate; false when it was not kept.
  bool offer(T dist, std::uint32_t index) {
    const Candidate<T> c{dist, index};
    if (heap_.size() < k_) {
      if (!(dist <= limit_)) return false;
      heap_.push_back(c);
      std::push_heap(heap_.begin(), heap_.end(), comes_before);
      return true;
    }
    if (!comes_before(c, heap_.front())) return false;
    std::pop_heap(heap_.begin(), heap_.end(), comes_before);
    heap_.back() = c;
    std::push_heap(heap_.begin(), heap_.end(), comes_before);
    return true;
  }

  /// The kept candidates in result order.
  std::vector<Candidate<T>>& sorted() {
    std::sort_heap(heap_.begin(), heap_.end(), comes_before);
    return heap_;
  }

 private:
  std::size_t k_;
  T limit_;
  std::vector<Candidate<T>>& heap_;
};

/// The same as KnnResults for k = 1: the best candidate so far and its distance, which is the bound
/// once one is kept. An offer is two comparisons and two selections, where the sorted array paid
/// for its general insertion (about 25 instructions an offer, 3-6 offers a 1-NN query on a 3-D scan).
template <class T>
class NearestResults {
 public:
  NearestResults(T limit, std::vector<Candidate<T>>& storage) : bound_(limit), out_(storage) {}

  T bound() const { return bound_; }
  bool full() const { return full_; }

  bool offer(T dist, std::uint32_t index) {
    // Before anything is kept bound_ is the limit, and any index within it enters.
    const bool before = dist < bound_ || (dist == bound_ && (index < index_ || !full_));
    if (before) {
      bound_ = dist;
      index_ = index;
      full_ = true;
    }
    return before;
  }

  std::vector<Candidate<T>>& sorted() {
    out_.clear();
    if (full_) out_.push_back({bound_, index_});
    return out_;
  }

 private:
  T bound_;
  std::uint32_t index_ = 0;
  bool full_ = false;
  std::vector<Candidate<T>>& out_;
};

/// The same as KnnResults for small k, kept as a sorted array: a new candidate is inserted by
/// shifting the worse ones, and the bound is the last entry, read without a branch on the heap. For
/// k up to small_k this beats the heap (fewer comparisons, no sift down at each insertion); beyond
/// it the O(k) shifts would not.
template <class T>
class SortedKnnResults {
 public:
  static constexpr std::size_t small_k = 32;

  SortedKnnResults(std::size_t k, T limit, std::vector<Candidate<T>>& storage)
      : k_(k), limit_(limit), bound_(limit), kept_(storage) {
    kept_.resize(k);
  }

  T bound() const { return bound_; }
  bool full() const { return size_ == k_; }

  bool offer(T dist, std::uint32_t index) {
    const Candidate<T> c{dist, index};
    std::size_t j = size_;
    if (size_ < k_) {
      if (!(dist <= limit_)) return false;
      ++size_;
    } else if (!comes_before(c, kept_[k_ - 1])) {
      return false;
    } else {
      j = k_ - 1;
    }
    for (; j > 0 && comes_before(c, kept_[j - 1]); --j) kept_[j] = kept_[j - 1];
    kept_[j] = c;
    if (size_ == k_) bound_ = kept_[k_ - 1].dist;
    return true;
  }

  std::vector<Candidate<T>>& sorted() {
    kept_.resize(size_);
    return kept_;
  }

 private:
  std::size_t k_;
  T limit_;
  T bound_;
  std::size_t size_ = 0;
  std::vector<Candidate<T>>& kept_;
};

#if defined(__SSE2__)
/// SortedKnnResults for float with SSE2, for k from min_k to max_k: the same candidates, kept in the
/// same order, inserted without a data-dependent branch. The scalar insertion compares the newcomer
/// with the kept ones one at a time until it finds its place, and the exit of that loop is a branch
/// no predictor can learn (the place is random): about 29 of the 60 mispredicted branches of a 10-NN
/// query on a 3-D scan (callgrind --branch-sim, building.ply). Here the distances and the indices sit
/// in two arrays of 4-lane chunks; the newcomer's place is the count of kept entries that come before
/// it (vector comparisons over every chunk, the tie rule included), and each chunk is rewritten in one
/// pass as old lane, newcomer or the lane before, chosen by masks. The entries not yet filled hold
/// (+inf, the largest index), which nothing comes after, so they never count. Measured (one thread,
/// held-out queries of real 3-D scans, 10-NN batches, busy machine): 1.32x the queries a second on
/// kitten, 1.04x on armadillo, no change beyond the noise on building and uniform 3-D; below 5
/// neighbours the scalar loop is short and wins (1-NN: 0.71-0.88x), and beyond 16 the work on every
/// chunk outweighs the mispredictions (32-NN: 0.80x). README, "Choosing the defaults", has the figures.
class ChunkedKnnResults {
 public:
  static constexpr std::size_t min_k = 5, max_k = 16;

  ChunkedKnnResults(std::size_t k, float limit, std::vector<Candidate<float>>& storage)
      : k_(k), chunks_((k + 3) / 4), bound_(limit), out_(storage) {
    const __m128 infinity = _mm_set1_ps(std::numeric_limits<float>::infinity());
    const __m128i last_index = _mm_set1_epi32(biased(UINT32_MAX));
    for (std::size_t c = 0; c < chunks_; ++c) {
      _mm_store_ps(dist_ + 4 * c, infinity);
      _mm_store_si128(reinterpret_cast<__m128i*>(index_ + 4 * c), last_index);
      // Lanes at or beyond k take a shifted-out entry, never a place: masked out of the count.
      const auto lane = [&](std::size_t j) { return 4 * c + j < k ? -1 : 0; };
      valid_[c] = _mm_set_epi32(lane(3), lane(2), lane(1), lane(0));
    }
  }

  float bound() const { return bound_; }
  bool full() const { return size_ == k_; }

  bool offer(float dist, std::uint32_t index) {
    if (!(dist <= bound_)) return false;  // bound_ is limit_ until k are kept
    const __m128 d = _mm_set1_ps(dist);
    const __m128i i = _mm_set1_epi32(biased(index));
    // place = #{kept entries before (dist, index)}: dist' < dist, or dist' == dist and index' < index.
    __m128i count = _mm_setzero_si128();
    for (std::size_t c = 0; c < chunks_; ++c) {
      const __m128 kd = _mm_load_ps(dist_ + 4 * c);
      const __m128i ki = _mm_load_si128(reinterpret_cast<const __m128i*>(index_ + 4 * c));
      const __m128i before = comes_before_lanes(kd, ki, d, i);
      count = _mm_sub_epi32(count, _mm_and_si128(before, valid_[c]));  // -(-1) per lane before
    }
    count = _mm_add_epi32(count, _mm_shuffle_epi32(count, _MM_SHUFFLE(1, 0, 3, 2)));
    count = _mm_add_epi32(count, _mm_shuffle_epi32(count, _MM_SHUFFLE(2, 3, 0, 1)));
    const int place = _mm_cvtsi128_si32(count);
    if (place >= static_cast<int>(k_)) return false;  // a tie with the k-th, of a larger index
    // Lane l becomes: itself if l < place, the newcomer if l == place, lane l - 1 if l > place.
    const __m128i at = _mm_set1_epi32(place);
    __m128i lanes = _mm_set_epi32(3, 2, 1, 0);
    __m128i previous_d = _mm_setzero_si128(), previous_i = _mm_setzero_si128();  // lane 3 of the chunk before
    for (std::size_t c = 0; c < chunks_; ++c) {
      __m128i* dp = reinterpret_cast<__m128i*>(dist_ + 4 * c);
      __m128i* ip = reinterpret_cast<__m128i*>(index_ + 4 * c);
      const __m128i kd = _mm_load_si128(dp), ki = _mm_load_si128(ip);
      const __m128i keep = _mm_cmplt_epi32(lanes, at), here = _mm_cmpeq_epi32(lanes, at);
      const __m128i shifted_d = _mm_or_si128(_mm_slli_si128(kd, 4), previous_d);
      const __m128i shifted_i = _mm_or_si128(_mm_slli_si128(ki, 4), previous_i);
      _mm_store_si128(dp, select(keep, kd, select(here, _mm_castps_si128(d), shifted_d)));
      _mm_store_si128(ip, select(keep, ki, select(here, i, shifted_i)));
      previous_d = _mm_srli_si128(kd, 12);
      previous_i = _mm_srli_si128(ki, 12);
      lanes = _mm_add_epi32(lanes, _mm_set1_epi32(4));
    }
    if (size_ < k_) ++size_;
    if (size_ == k_) bound_ = dist_[k_ - 1];
    return true;
  }

  /// Whether nothing is kept yet: the first leaf a query reaches.
  bool empty() const { return size_ == 0; }

  /// The same as offering the m <= max_fill candidates one by one to an empty set, without their
  /// insertions: each candidate's place is the count of the others that come before it (vector
  /// comparisons of every pair, the tie rule included; the indices are distinct, so the places are
  /// too), and those placed before k are written at their place. Offered one by one, about 15 of
  /// the 24 points of a query's first leaf are inserted in turn for 10-NN on a 3-D scan, each
  /// insertion a pass over every chunk. A candidate beyond the limit is never before one within
  /// it, so it only has to be kept out.
  static constexpr std::size_t max_fill = 32;
  void fill(const float* dist, const std::uint32_t* index, std::size_t m) {
    alignas(16) float d[max_fill];
    alignas(16) std::int32_t i[max_fill];
    const std::size_t padded = (m + 3) & ~std::size_t{3};
    for (std::size_t j = 0; j < padded; ++j) {  // the pads fill the last chunk; their places go unread
      d[j] = j < m ? dist[j] : std::numeric_limits<float>::infinity();
      i[j] = biased(j < m ? index[j] : UINT32_MAX);
    }
    const std::size_t chunks = padded / 4;
    __m128i place[max_fill / 4];  // lane l of chunk c: how many of the m come before candidate 4c + l
    for (std::size_t c = 0; c < chunks; ++c) place[c] = _mm_setzero_si128();
    for (std::size_t j = 0; j < m; ++j) {
      const __m128 od = _mm_set1_ps(d[j]);
      const __m128i oi = _mm_set1_epi32(i[j]);
      for (std::size_t c = 0; c < chunks; ++c) {
        const __m128 cd = _mm_load_ps(d + 4 * c);
        const __m128i ci = _mm_load_si128(reinterpret_cast<const __m128i*>(i + 4 * c));
        place[c] = _mm_sub_epi32(place[c], comes_before_lanes(od, oi, cd, ci));
      }
    }
    alignas(16) std::int32_t places[max_fill];
    for (std::size_t c = 0; c < chunks; ++c)
      _mm_store_si128(reinterpret_cast<__m128i*>(places + 4 * c), place[c]);
    const float limit = bound_;
    std::size_t kept = 0;
    for (std::size_t j = 0; j < m; ++j) {
      // Written at its place if kept, else in the spare slot past the chunks: no branch to mispredict.
      const bool keep = places[j] < static_cast<std::int32_t>(k_) && d[j] <= limit;
      const std::size_t at = keep ? static_cast<std::size_t>(places[j]) : max_k;
      dist_[at] = d[j];
      index_[at] = i[j];
      kept += keep;
    }
    size_ = kept;
    if (size_ == k_) bound_ = dist_[k_ - 1];
  }

  std::vector<Candidate<float>>& sorted() {
    out_.resize(size_);
    for (std::size_t j = 0; j < size_; ++j)
      out_[j] = {dist_[j], static_cast<std::uint32_t>(index_[j]) ^ 0x80000000u};
    return out_;
  }

 private:
  // Indices compared as signed 32-bit integers (SSE2 has no unsigned comparison): biased by 2^31.
  static std::int32_t biased(std::uint32_t index) { return static_cast<std::int32_t>(index ^ 0x80000000u); }
  // All ones in the lanes where (a_dist, a_index) comes before (b_dist, b_index): the tie rule, 4 lanes.
  static __m128i comes_before_lanes(__m128 a_dist, __m128i a_index, __m128 b_dist, __m128i b_index) {
    return _mm_or_si128(
        _mm_castps_si128(_mm_cmplt_ps(a_dist, b_dist)),
        _mm_and_si128(_mm_castps_si128(_mm_cmpeq_ps(a_dist, b_dist)), _mm_cmplt_epi32(a_index, b_index)));
  }
  static __m128i select(__m128i mask, __m128i a, __m128i b) {
    return _mm_or_si128(_mm_and_si128(mask, a), _mm_andnot_si128(mask, b));
  }

  std::size_t k_, chunks_;
  float bound_;  // the limit until k are kept, then the k-th distance
  std::size_t size_ = 0;
  std::vector<Candidate<float>>& out_;
  alignas(16) float dist_[max_k + 1];  // + the spare slot of fill()
  alignas(16) std::int32_t index_[max_k + 1];
  __m128i valid_[max_k / 4];
};
#endif

/// Whether a result set takes a whole leaf at once while empty (fill(dist, index, m), m <= max_fill).
template <class Results, class = void>
inline constexpr bool fills_at_once = false;
template <class Results>
inline constexpr bool fills_at_once<Results, std::void_t<decltype(&Results::fill)>> = true;

/// Calls f(results) with the k-NN result set that suits k: ChunkedKnnResults for float where it
/// applies, NearestResults for k = 1, else SortedKnnResults up to its small_k, else KnnResults. All keep the
/// same candidates.
template <class T, class F>
decltype(auto) with_knn_results(std::size_t k, T limit, std::vector<Candidate<T>>& storage, F&& f) {
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, float>) {
    if (k >= ChunkedKnnResults::min_k && k <= ChunkedKnnResults::max_k) {
      ChunkedKnnResults results(k, limit, storage);
      return f(results);
    }
  }
#endif
  if (k == 1) {
    NearestResults<T> results(limit, storage);
    return f(results);
  }
  if (k <= SortedKnnResults<T>::small_k) {
    SortedKnnResults<T> results(k, limit, storage);
    return f(results);
  }
  KnnResults<T> results(k, limit, storage);
  return f(results);
}

/// Keeps every candidate with dist <= limit.
template <class T>
class RangeResults {
 public:
  RangeResults(T limit, std::vector<Candidate<T>>& storage) : limit_(limit), found_(storage) { found_.clear(); }

  T bound() const { return limit_; }

  /// A range query keeps looking until the whole ball is covered.
  bool full() const { return false; }

  bool offer(T dist, std::uint32_t index) {
    if (!(dist <= limit_)) return false;
    found_.push_back({dist, index});
    return true;
  }

  std::vector<Candidate<T>>& sorted() {
    std::sort(found_.begin(), found_.end(), comes_before);
    return found_;
  }

 private:
  T limit_;
  std::vector<Candidate<T>>& found_;
};

}  // namespace kdspace::detail
