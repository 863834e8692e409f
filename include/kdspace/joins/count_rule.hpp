// The counting rule: the number of pairs within each of many radii, in one traversal (the two-point
// correlation function of Gray and Moore 2000; SciPy's count_neighbors). Pairs are binned: bin j holds
// the pairs whose distance d has radius j as the smallest radius with d <= radius; the cumulative sums
// of the bins are the counts.
//
// A node pair carries the range of bins its pairs can still fall into. Its cell bounds [lower, upper]
// narrow that range to the bins from the first radius >= lower to the first radius >= upper; when
// that is one bin, every pair of the two cells goes there without a distance (Moore et al. 2001,
// "Fast algorithms and efficient statistics: N-point correlation functions"). Leaves count 8 distances
// at a time against each open radius (count_block). Self-joins count each unordered pair once.
//
// Weighted counts add w_a * w_b for each pair instead of 1; a pair of cells settled whole adds the
// product of the cells' weight sums, so the float sum is taken in an order of its own (exact for
// integer weights while sums stay below 2^53). A self-join never settles a cell with itself that way.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "kdspace/joins/bounded_tree.hpp"
#include "kdspace/joins/join_stats.hpp"
#include "kdspace/joins/range_rule.hpp"
#include "kdspace/joins/traversal.hpp"

namespace kdspace::detail {

/// Per-node weight sums of a tree (in node-id order), and the weights in leaf order.
struct NodeWeights {
  std::vector<double> by_position;
  std::vector<double> node_sum;

  template <class Tree>
  NodeWeights(const Tree& tree, const double* weights) : by_position(tree.size()), node_sum(tree.node_count()) {
    for (std::size_t pos = 0; pos < tree.size(); ++pos) by_position[pos] = weights[tree.index(pos)];
    for (std::size_t id = tree.node_count(); id-- > 0;) {
      const auto& node = tree.node(static_cast<std::uint32_t>(id));
      if (node.is_leaf()) {
        double sum = 0;
        for (std::uint32_t pos = node.begin; pos < node.end; ++pos) sum += by_position[pos];
        node_sum[id] = sum;
      } else {
        node_sum[id] = node_sum[node.left] + node_sum[node.right];
      }
    }
  }
};

/// Count is std::uint64_t (no weights) or double (weights).
template <class T, int Dim, class Space, class Count>
class CountRule {
 public:
  using Tree = BoundedTree<T, Dim>;
  /// The bins [lo, hi] the pairs of a node pair can fall into.
  struct Context {
    std::uint32_t lo;
    std::uint32_t hi;
  };
  static constexpr bool nearest_first = false;

  /// radii: internal radii in ascending order, followed by +inf (the bin of pairs beyond them all).
  /// weights: null for plain counts; else the weights of the queries' and the reference's points.
  CountRule(const Tree& queries, const Tree& reference, const Space& space, bool self, const std::vector<T>& radii,
            const NodeWeights* query_weights, const NodeWeights* reference_weights, std::vector<Count>& bins,
            JoinStats& stats)
      : queries_(queries),
        reference_(reference),
        space_(space),
        self_(self),
        radii_(radii),
        query_weights_(query_weights),
        reference_weights_(reference_weights),
        bins_(bins),
        stats_(stats) {}

  const Tree& query_tree() const { return queries_; }
  const Tree& reference_tree() const { return reference_; }

  /// The context of a traversal's first pair: every bin.
  Context all_bins() const { return {0, static_cast<std::uint32_t>(radii_.size() - 1)}; }

  JoinScore<T, Context> score(std::uint32_t q, std::uint32_t r, const Context& parent) {
    const auto& qn = queries_.node(q);
    const auto& rn = reference_.node(r);
    if (self_ && !SelfOrder::any_ordered(qn, rn)) return {false, T(0), parent};
    const T* qlo = queries_.lo(q);
    const T* qhi = queries_.hi(q);
    const T* rlo = reference_.lo(r);
    const T* rhi = reference_.hi(r);
    const T lower = space_.lower(qlo, qhi, rlo, rhi, dim());
    const std::uint32_t lo = first_at_least(parent.lo, parent.hi, lower);
    const std::uint32_t last = static_cast<std::uint32_t>(radii_.size() - 1);
    if (lo == last) return {false, lower, parent};  // beyond every radius
    const T upper = space_.upper(qlo, qhi, rlo, rhi, dim());
    const std::uint32_t hi = first_at_least(lo, parent.hi, upper);
    if (lo == hi && can_take_whole(qn, rn)) {
      const std::uint64_t pairs = pair_count(qn, rn);
      stats_.bulk_pairs += pairs;
      if constexpr (std::is_same_v<Count, double>)
        bins_[lo] += query_weights_->node_sum[q] * reference_weights_->node_sum[r];
      else
        bins_[lo] += pairs;
      return {false, lower, parent};
    }
    return {true, lower, Context{lo, hi}};
  }

  bool rescore(std::uint32_t, std::uint32_t, T) const { return true; }
  void query_done(std::uint32_t) {}

  template <class Isa>
  void base_case(std::uint32_t q, std::uint32_t r, const Context& context, Isa) {
    const auto& rn = reference_.node(r);
    const bool same_leaf = self_ && q == r;
    // Pairs beyond the last radius fall in no count: the leaves bin only up to it.
    const std::uint32_t hi = std::min(context.hi, static_cast<std::uint32_t>(radii_.size() - 2));
    const T largest = radii_[hi];
    if constexpr (std::is_same_v<Count, std::uint64_t>)
      std::fill(within_.begin() + context.lo, within_.begin() + hi + 1, 0);
    const auto limits = same_limit<T, Tree::column_block>(largest);
    points_near_box<Isa>(
        queries_, q, reference_.lo(r), reference_.hi(r), space_, [&](std::uint32_t) { return limits.data(); },
        [&](std::uint32_t i) {
          const std::uint32_t first = same_leaf ? i + 1 : rn.begin;
          stats_.distances += rn.end - first;
          if constexpr (std::is_same_v<Count, double>) {
            distances_to_leaf<Isa>(reference_, r, first, queries_.point(i), space_, largest, [&](std::uint32_t j, T d) {
              bins_[first_at_least(context.lo, hi, d)] +=
                  query_weights_->by_position[i] * reference_weights_->by_position[j];
            });
          } else {
            distance_blocks(reference_, r, first, queries_.point(i), space_,
                            [&](const auto& dist, unsigned keep, std::uint32_t) { count_block<Isa>(dist, keep, context.lo, hi); });
          }
        });
    if constexpr (std::is_same_v<Count, std::uint64_t>) {
      bins_[context.lo] += within_[context.lo];
      for (std::uint32_t j = context.lo + 1; j <= hi; ++j) bins_[j] += within_[j] - within_[j - 1];
    }
  }

 private:
  std::size_t dim() const { return queries_.dim(); }

  // The first bin in [lo, hi] whose radius is >= value (hi when none before it is): a binary search
  // whose steps choose by a conditional move, not a branch (the comparisons are unpredictable).
  std::uint32_t first_at_least(std::uint32_t lo, std::uint32_t hi, T value) const {
    const T* first = radii_.data() + lo;
    for (std::uint32_t n = hi - lo + 1; n > 1;) {
      const std::uint32_t half = n / 2;
      first += half * static_cast<std::uint32_t>(first[half - 1] < value);
      n -= half;
    }
    return static_cast<std::uint32_t>(first - radii_.data());
  }

  // Adds to within_[j], for j in [lo, hi], the distances of a block (those marked in `keep`) that
  // are at most radius j: one vector comparison per radius, instead of a search per pair; once a
  // radius holds every pair of the block left, so do the larger ones.
  template <class Isa, class Block>
  void count_block(const Block& dist, unsigned keep, std::uint32_t lo, std::uint32_t hi) {
    const unsigned inside = at_most(dist, radii_[hi], Isa{}) & keep;
    if (!inside) return;
    const std::uint64_t all = bits_set(inside);
    std::uint32_t j = lo;
    for (; j < hi; ++j) {
      const unsigned near = at_most(dist, radii_[j], Isa{}) & inside;
      within_[j] += bits_set(near);
      if (near == inside) break;
    }
    for (j = j < hi ? j + 1 : hi; j <= hi; ++j) within_[j] += all;
  }

  template <class Node>
  bool can_take_whole(const Node& qn, const Node& rn) const {
    if (!self_) return true;
    if (qn.end <= rn.begin) return true;
    // A cell with itself: n (n - 1) / 2 pairs; with weights its sum is taken pair by pair instead.
    return !std::is_same_v<Count, double> && qn.begin == rn.begin && qn.end == rn.end;
  }

  template <class Node>
  std::uint64_t pair_count(const Node& qn, const Node& rn) const {
    const std::uint64_t nq = qn.count(), nr = rn.count();
    return self_ && qn.begin == rn.begin ? nq * (nq - 1) / 2 : nq * nr;
  }

  const Tree& queries_;
  const Tree& reference_;
  const Space& space_;
  bool self_;
  const std::vector<T>& radii_;
  const NodeWeights* query_weights_;
  const NodeWeights* reference_weights_;
  std::vector<Count>& bins_;
  JoinStats& stats_;
  // A leaf pair's pairs within each radius (count_block).
  std::vector<std::uint64_t> within_ = std::vector<std::uint64_t>(radii_.size());
};

}  // namespace kdspace::detail
