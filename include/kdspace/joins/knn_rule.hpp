// The k-NN join rule: for every query point its k nearest reference points (the first k in the order
// (internal distance, index), as PointTree::knn), or, in a self-join, its k nearest other points.
//
// Each query point keeps its k best candidates in a flat table; a query node keeps
// B(N_q), the largest k-th candidate distance over its points (+inf while one has fewer than k): the
// first bound of Curtin et al. 2013, section 4 (Gray and Moore's all-nearest-neighbour bound). A pair
// (N_q, N_r) is pruned when the lower bound of its cells exceeds B(N_q): then no reference point in
// N_r can enter any heap of N_q, not even by a tie on index. The bound being exact (space.hpp), the
// result does not depend on the order of the visits, so it is the same on any number of threads.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/join_stats.hpp"
#include "kdspace/joins/traversal.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace::detail {

/// The k best candidates of each of n query points, kept in the memory of the join's result: row i
/// (query point i in the query tree's leaf order) is rows[i * k, i * k + k), as Neighbor{index,
/// internal distance}; kth(i) is the distance of its k-th once it holds k, +inf before. finish()
/// then puts the rows in the result's order (in place) with true distances. (The rows used to be a
/// table of their own, copied into the result at the end: for 1e6 points at k = 10, double, 160 MB
/// more memory to touch for the first time, whose page faults the single-tree batch does not pay;
/// see the README, joins.)
///
/// Every row starts full of placeholders (+inf, largest index), which any real candidate comes
/// before (a real index is smaller; +inf distances included): so an offer is one comparison with the
/// row's last (or top) entry whether or not the row is full, and kth(i) is that entry's distance
/// (a sorted row also counts its real entries, only to start the search for a place after them). A join offers k or more real points to every row (k is at most the points available),
/// so no placeholder is left at the end.
///
/// For k up to sorted_rows_up_to a row is kept in result order ((distance, index) ascending): a join
/// offers each point a few dozen candidates, most refused by one comparison with kth(i), and an
/// accepted one moves the few entries after its place (for k = 10 about a quarter of the instructions
/// of a heap's pop and push, and no sort at the end). Larger rows are max-heaps in that order (what
/// KnnResults does), as moving half a long row per accepted candidate would cost O(k).
template <class T>
class KnnTable {
 public:
  static constexpr std::size_t sorted_rows_up_to = 32;
  using Entry = Neighbor<T>;  ///< a candidate: its index, and its internal distance until finish()

  /// What every entry of the rows starts as (the caller fills them, in one pass with the allocation).
  static constexpr Entry placeholder() {
    return Entry{std::numeric_limits<std::uint32_t>::max(), std::numeric_limits<T>::infinity()};
  }

  /// rows: n * k entries, all placeholder(), which outlive the table.
  KnnTable(Entry* rows, std::size_t n, std::size_t k)
      : k_(k),
        n_(n),
        sorted_rows_(k <= sorted_rows_up_to),
        rows_(rows),
        kth_(n, std::numeric_limits<T>::infinity()),
        held_(sorted_rows_ ? n : 0, HeldCount{0}) {}

  T kth(std::size_t i) const { return kth_[i]; }
  /// kth(i) onwards from row `first`: the limits of a block of query points (points_near_box).
  const T* kths(std::size_t first) const { return kth_.data() + first; }

  /// The largest kth(i) over [first, last), 0 for none. Four running maxima, which the compiler
  /// keeps in one vector register (one max instruction for four rows, where a single running
  /// maximum took a load, a max and the loop's three instructions a row); the maximum of values
  /// that are never NaN does not depend on the order it is taken in.
  T largest_kth(std::size_t first, std::size_t last) const {
    std::array<T, 4> lanes{};
    std::size_t i = first;
    for (; i + 4 <= last; i += 4)
      for (std::size_t j = 0; j < 4; ++j) lanes[j] = larger(lanes[j], kth_[i + j]);
    T largest = larger(larger(lanes[0], lanes[1]), larger(lanes[2], lanes[3]));
    for (; i < last; ++i) largest = larger(largest, kth_[i]);
    return largest;
  }

  /// Offers a candidate to row i: kept when it comes before the row's k-th in (distance, index)
  /// order (the decision of KnnResults::offer); false when refused.
  bool offer(std::size_t i, T dist, std::uint32_t index) {
    Entry* row = rows_ + i * k_;
    if (!sorted_rows_) return offer_to_heap(i, row, Entry{index, dist});
    if (!(dist < row[k_ - 1].distance || (dist == row[k_ - 1].distance && index < row[k_ - 1].index))) return false;
    // The search for its place starts after the real entries: the placeholders come after every
    // real candidate, and stepping over them one by one cost 45 moves a point for k = 10. A full
    // row's last entry is the one dropped. (Without a branch: whether the row is full is as good
    // as random from one offer to the next.)
    const std::size_t held = held_[i];
    std::size_t place = held - (held == k_);
    held_[i] = static_cast<HeldCount>(place + 1);
    // Past the entries it comes before: one loop, whose test on the index runs only on equal
    // distances (a second loop for ties cost its test on every insertion: callgrind 1090.3e6 ->
    // 1084.5e6 instructions, 2e5 uniform 3-D points, k = 10).
    for (; place > 0; --place) {
      const T before = row[place - 1].distance;
      if (!(dist < before || (dist == before && index < row[place - 1].index))) break;
      row[place] = row[place - 1];
    }
    // Field by field: a candidate made on the stack and copied whole was read back as 16 bytes
    // right after its two parts were written (a store-forwarding stall on each insertion).
    row[place].distance = dist;
    row[place].index = index;
    kth_[i] = row[k_ - 1].distance;
    return true;
  }

  /// Once all offers are made: each row in result order with true distances (Metric::to_distance),
  /// and row i moved to row result_row[i] (result_row: a permutation of [0, n)), in place, cycle by
  /// cycle: each row is read and written once, as the copy into a result of its own did.
  template <class Metric>
  void finish(const std::uint32_t* result_row) {
    std::vector<bool> placed(n_, false);
    std::vector<Entry> carried(k_);
    for (std::size_t start = 0; start < n_; ++start) {
      if (placed[start]) continue;
      // Row `start` is carried to its place, the row found there to its own, and so on until the
      // cycle comes back to `start` (for a random order about ln n cycles in all).
      Entry* row = rows_ + start * k_;
      std::copy(row, row + k_, carried.begin());
      finish_row<Metric>(carried.data());
      // Each row's place comes from its predecessor's, so the misses on the rows would come one
      // after the other: the rows some steps ahead on the cycle are asked for in advance (1e6
      // uniform 3-D points, k = 10, interleaved runs: the join's user time 0.85-0.92 s without,
      // 0.79-0.84 s with, as before the rows moved into the result; 16 steps no better than 8).
      std::size_t ahead = start;
      for (std::size_t step = 0; step < prefetch_steps; ++step) ahead = result_row[ahead];
      for (std::size_t to = result_row[start]; to != start; to = result_row[to]) {
        ahead = result_row[ahead];
        prefetch_row(rows_ + ahead * k_);
        Entry* there = rows_ + to * k_;
        if (sorted_rows_) {  // exchanged and finished in one loop
          for (std::size_t j = 0; j < k_; ++j) {
            const Entry found = there[j];
            there[j] = carried[j];
            carried[j] = Entry{found.index, Metric::to_distance(found.distance)};
          }
        } else {
          std::swap_ranges(there, there + k_, carried.begin());
          finish_row<Metric>(carried.data());
        }
        placed[to] = true;
      }
      std::copy(carried.begin(), carried.end(), row);
      placed[start] = true;
    }
  }

 private:
  static constexpr std::size_t prefetch_steps = 8;
  void prefetch_row(const Entry* row) const {
#if defined(__GNUC__)
    const char* first = reinterpret_cast<const char*>(row);
    for (std::size_t byte = 0; byte < k_ * sizeof(Entry); byte += 64) __builtin_prefetch(first + byte, 1);
#else
    (void)row;
#endif
  }

  // (internal distance, index) ascending, the order of ComesBefore; a function object, so that the
  // heap algorithms inline it.
  struct ComesFirst {
    bool operator()(const Entry& a, const Entry& b) const {
      return a.distance < b.distance || (a.distance == b.distance && a.index < b.index);
    }
  };
  static constexpr ComesFirst comes_first{};

  // A row in result order, with true distances.
  template <class Metric>
  void finish_row(Entry* row) const {
    if (!sorted_rows_) std::sort_heap(row, row + k_, comes_first);
    for (std::size_t j = 0; j < k_; ++j) row[j].distance = Metric::to_distance(row[j].distance);
  }

  // Out of line, so that the sorted rows' offer stays small enough to be inlined where it is made.
#if defined(__GNUC__)
  __attribute__((noinline))
#endif
  bool offer_to_heap(std::size_t i, Entry* row, const Entry& c) {
    if (!comes_first(c, row[0])) return false;
    std::pop_heap(row, row + k_, comes_first);
    row[k_ - 1] = c;
    std::push_heap(row, row + k_, comes_first);
    kth_[i] = row[0].distance;
    return true;
  }

  std::size_t k_;
  std::size_t n_;
  bool sorted_rows_;
  Entry* rows_;
  // In huge pages where enabled (detail/huge_pages.hpp).
  HugePageVector<T> kth_;
  // Not a byte: a store through unsigned char may alias anything, and the compiler reloaded the
  // tables' pointers after each (callgrind: 40e6 more instructions than it saved).
  using HeldCount = std::uint16_t;
  static_assert(sorted_rows_up_to <= 65535, "a sorted row's count of real entries fits in HeldCount");
  HugePageVector<HeldCount> held_;  ///< sorted rows: the real candidates row i holds (at most k)
};

template <class T, int Dim, class Space>
class KnnRule {
 public:
  using Tree = BoundedTree<T, Dim>;
  struct Context {};
  static constexpr bool nearest_first = true;

  /// `table` rows are the query tree's leaf-order positions; `node_bound` holds B(N_q) per query node
  /// (+inf to start). self: queries and reference are the same tree, and a point is not its own
  /// neighbour.
  KnnRule(const Tree& queries, const Tree& reference, const Space& space, bool self, KnnTable<T>& table,
          std::vector<T>& node_bound, JoinStats& stats)
      : queries_(queries),
        reference_(reference),
        space_(space),
        self_(self),
        table_(table),
        node_bound_(node_bound),
        stats_(stats) {}

  const Tree& query_tree() const { return queries_; }
  const Tree& reference_tree() const { return reference_; }

  JoinScore<T, Context> score(std::uint32_t q, std::uint32_t r, const Context&) const {
    const T lower = space_.lower(queries_.lo(q), queries_.hi(q), reference_.lo(r), reference_.hi(r), dim());
    return {!(lower > node_bound_[q]), lower, {}};
  }

  bool rescore(std::uint32_t q, std::uint32_t, T key) const { return !(key > node_bound_[q]); }

  template <class Isa>
  void base_case(std::uint32_t q, std::uint32_t r, const Context&, Isa) {
    const auto& qn = queries_.node(q);
    const auto& rn = reference_.node(r);
    const bool same_leaf = self_ && q == r;
    // The leaf's box may lie beyond a point's k-th even when it does not beyond the node's bound.
    // A block's k-th distances are read in place, but for the leaf's last block: the rows after
    // the leaf's may be another task's, being written.
    constexpr std::size_t block = Tree::column_block;
    std::array<T, block> last_block{};
    const auto limits = [&](std::uint32_t base) {
      if (base + block <= qn.end) return table_.kths(base);
      for (std::uint32_t j = 0; base + j < qn.end; ++j) last_block[j] = table_.kth(base + j);
      return static_cast<const T*>(last_block.data());
    };
    points_near_box<Isa>(
        queries_, q, reference_.lo(r), reference_.hi(r), space_, limits, [&](std::uint32_t i) {
          const T* a = queries_.point(i);
          if (rn.all_identical) {
            offer_identical(i, a, rn);
            return;
          }
          T kth = table_.kth(i);
          stats_.distances += rn.count();
          const auto offer = [&](std::uint32_t j, T d) {
            if (d <= kth && !(same_leaf && j == i) && table_.offer(i, d, reference_.index(j))) kth = table_.kth(i);
          };
          // In its own leaf a point is offered first the points within the k-th distance of the
          // point before it (a neighbour in the leaf, with a k-th of about the same size).
          if (same_leaf && i > qn.begin)
            distances_to_leaf_nearer_first<Isa>(reference_, r, a, space_, kth, table_.kth(i - 1), offer);
          else
            distances_to_leaf<Isa>(reference_, r, rn.begin, a, space_, kth, offer);
        });
    node_bound_[q] = table_.largest_kth(qn.begin, qn.end);
  }

  void query_done(std::uint32_t q) {
    const auto& node = queries_.node(q);
    node_bound_[q] = std::max(bound_of(node.left), bound_of(node.right));
  }

 private:
  std::size_t dim() const { return queries_.dim(); }

  // An empty child never bounds its parent.
  T bound_of(std::uint32_t child) const {
    return queries_.node(child).count() == 0 ? T(0) : node_bound_[child];
  }

  // A leaf of coinciding points: one distance serves all, and as their indices ascend the first
  // refusal ends the offers.
  void offer_identical(std::uint32_t i, const T* a, const typename Tree::Node& rn) {
    const T d = space_.distance(a, reference_.point(rn.begin), dim());
    ++stats_.distances;
    for (std::uint32_t j = rn.begin; j < rn.end; ++j) {
      if (self_ && j == i) continue;
      if (!table_.offer(i, d, reference_.index(j))) break;
    }
  }

  const Tree& queries_;
  const Tree& reference_;
  const Space& space_;
  bool self_;
  KnnTable<T>& table_;
  std::vector<T>& node_bound_;
  JoinStats& stats_;
};

}  // namespace kdspace::detail
