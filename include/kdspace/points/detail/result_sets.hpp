// Result sets: the one place that decides what a query keeps. The traversal offers every scored
// point and prunes every cell farther than bound(); it knows nothing else about the query.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

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

/// Calls f(results) with the k-NN result set that suits k: SortedKnnResults up to its small_k, else
/// KnnResults. Both keep the same candidates.
template <class T, class F>
decltype(auto) with_knn_results(std::size_t k, T limit, std::vector<Candidate<T>>& storage, F&& f) {
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
