// The range rule: every pair (query point, reference point) within a distance (closed ball), or, in a
// self-join, every unordered pair of distinct points once.
//
// Self-joins visit each unordered pair once by the points' leaf-order positions: a pair (i, j) is kept
// only when i < j, so a node pair whose reference points all come before its query points is skipped,
// and two leaves that are one compare each point only with those after it (the node-id ordering of
// the traversal: ids and positions follow the same depth-first order).
//
// A pair of cells whose upper bound is within the radius is handed to the sink whole (its pairs need
// no distance); one whose lower bound is beyond it is pruned. What is kept is the sink's business:
// index pairs (PairSink), or pairs with their distances (DistanceSink, the sparse distance matrix and
// radius lists).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/index_pair.hpp"
#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/first_index_buckets.hpp"
#include "kdspace/joins/join_stats.hpp"
#include "kdspace/joins/traversal.hpp"

namespace kdspace::detail {

/// A pair within the radius: original indices and internal distance.
template <class T>
struct FoundPair {
  std::uint32_t a;
  std::uint32_t b;
  T dist;
};

/// Whether a self-join node pair can hold a pair i < j, and whether all its pairs (i in q, j in r)
/// have i < j (so that they may be taken whole): nodes are nested or disjoint ranges of positions.
struct SelfOrder {
  template <class Node>
  static bool any_ordered(const Node& q, const Node& r) {
    return r.end > q.begin + 1;
  }
  template <class Node>
  static bool all_ordered_or_same(const Node& q, const Node& r) {
    return q.end <= r.begin || (q.begin == r.begin && q.end == r.end);
  }
};

template <class T, int Dim, class Space, class Sink>
class RangeRule {
 public:
  using Tree = BoundedTree<T, Dim>;
  struct Context {};
  static constexpr bool nearest_first = false;

  /// limit: the radius in internal units (squared for L2).
  RangeRule(const Tree& queries, const Tree& reference, const Space& space, bool self, T limit, Sink& sink,
            JoinStats& stats)
      : queries_(queries), reference_(reference), space_(space), self_(self), limit_(limit), sink_(sink), stats_(stats) {}

  const Tree& query_tree() const { return queries_; }
  const Tree& reference_tree() const { return reference_; }

  JoinScore<T, Context> score(std::uint32_t q, std::uint32_t r, const Context&) {
    const auto& qn = queries_.node(q);
    const auto& rn = reference_.node(r);
    if (self_ && !SelfOrder::any_ordered(qn, rn)) return {false, T(0), {}};
    const T* qlo = queries_.lo(q);
    const T* qhi = queries_.hi(q);
    const T* rlo = reference_.lo(r);
    const T* rhi = reference_.hi(r);
    const T lower = space_.lower(qlo, qhi, rlo, rhi, dim());
    if (lower > limit_) return {false, lower, {}};
    if ((!self_ || SelfOrder::all_ordered_or_same(qn, rn)) && space_.upper(qlo, qhi, rlo, rhi, dim()) <= limit_) {
      take_whole(qn, rn);
      return {false, lower, {}};
    }
    return {true, lower, {}};
  }

  bool rescore(std::uint32_t, std::uint32_t, T) const { return true; }
  void query_done(std::uint32_t) {}

  template <class Isa>
  void base_case(std::uint32_t q, std::uint32_t r, const Context&, Isa) {
    const auto& rn = reference_.node(r);
    const bool same_leaf = self_ && q == r;
    const auto limits = same_limit<T, Tree::column_block>(limit_);
    points_near_box<Isa>(
        queries_, q, reference_.lo(r), reference_.hi(r), space_, [&](std::uint32_t) { return limits.data(); },
        [&](std::uint32_t i) {
          const std::uint32_t first = same_leaf ? i + 1 : rn.begin;
          const std::uint32_t a_index = queries_.index(i);
          stats_.distances += rn.end - first;
          distances_to_leaf<Isa>(reference_, r, first, queries_.point(i), space_, limit_,
                            [&](std::uint32_t j, T d) { sink_.add(a_index, reference_.index(j), d); });
        });
  }

 private:
  std::size_t dim() const { return queries_.dim(); }

  template <class Node>
  void take_whole(const Node& qn, const Node& rn) {
    const bool same = self_ && qn.begin == rn.begin;
    for (std::uint32_t i = qn.begin; i < qn.end; ++i) {
      const std::uint32_t first = same ? i + 1 : rn.begin;
      stats_.bulk_pairs += rn.end - first;
      sink_.add_all(queries_, reference_, i, first, rn.end, space_, stats_);
    }
  }

  const Tree& queries_;
  const Tree& reference_;
  const Space& space_;
  bool self_;
  T limit_;
  Sink& sink_;
  JoinStats& stats_;
};

/// The smaller of two indices by arithmetic: which one is smaller is as good as random, and a branch
/// on it (what std::min became here) was mispredicted for one pair in five (callgrind --branch-sim,
/// pairs within r of 2e5 uniform 3-D points: 206,000 times).
inline std::uint32_t smaller_index(std::uint32_t a, std::uint32_t b) {
  return a ^ ((a ^ b) & (0u - static_cast<std::uint32_t>(b < a)));
}

/// Keeps index pairs; in a self-join each as (smaller index, larger index).
class PairSink {
 public:
  PairSink(FirstIndexBuckets<IndexPair>& out, bool self) : out_(out), self_(self) {}

  template <class T>
  void add(std::uint32_t a, std::uint32_t b, T) {
    const std::uint32_t first = self_ ? smaller_index(a, b) : a;
    out_.add(IndexPair{first, a ^ b ^ first});
  }

  /// Query point at position i with reference positions [first, last): no distance needed.
  template <class Tree, class Space>
  void add_all(const Tree& queries, const Tree& reference, std::uint32_t i, std::uint32_t first, std::uint32_t last,
               const Space&, JoinStats&) {
    const std::uint32_t a = queries.index(i);
    for (std::uint32_t j = first; j < last; ++j) add(a, reference.index(j), 0);
  }

 private:
  FirstIndexBuckets<IndexPair>& out_;
  bool self_;
};

/// Keeps pairs with their internal distances; in a self-join each as (smaller index, larger index).
template <class T>
class DistanceSink {
 public:
  DistanceSink(FirstIndexBuckets<FoundPair<T>>& out, bool self) : out_(out), self_(self) {}

  void add(std::uint32_t a, std::uint32_t b, T dist) {
    const std::uint32_t first = self_ ? smaller_index(a, b) : a;
    out_.add(FoundPair<T>{first, a ^ b ^ first, dist});
  }

  template <class Tree, class Space>
  void add_all(const Tree& queries, const Tree& reference, std::uint32_t i, std::uint32_t first, std::uint32_t last,
               const Space& space, JoinStats& stats) {
    const T* p = queries.point(i);
    stats.distances += last - first;
    for (std::uint32_t j = first; j < last; ++j)
      add(queries.index(i), reference.index(j), space.distance(p, reference.point(j), queries.dim()));
  }

 private:
  FirstIndexBuckets<FoundPair<T>>& out_;
  bool self_;
};

}  // namespace kdspace::detail
