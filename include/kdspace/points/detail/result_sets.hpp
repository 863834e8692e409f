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
