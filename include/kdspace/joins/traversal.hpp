// The dual-tree traversal: one depth-first walk over pairs (query node, reference node) that knows
// nothing of what is computed. A rule says it (Curtin, March, Ram, Anderson, Gray, Isbell: "Tree-
// Independent Dual-Tree Algorithms", ICML 2013; mlpack's split of traversal and rules):
//
//   score(q, r, context)    -> JoinScore: whether to visit the pair (a rule may also settle the whole
//                              pair there, e.g. count every pair when the cells lie within the radius,
//                              and decline the visit), an ordering key, and the context the pair's
//                              descendants inherit (the radii still undecided, for counting)
//   rescore(q, r, key)      -> whether a pair scored earlier is still worth visiting (a k-NN bound
//                              may have shrunk while its sibling was visited)
//   base_case(q, r, context, isa)  two leaves: compare their points (isa: the instruction set the
//                              base case is compiled for, BaselineIsa or Avx2Isa)
//   query_done(q)              both children of query node q are done (k-NN: refresh q's bound)
//   nearest_first              visit the nearer reference child first (k-NN) or in tree order
//
// Which node to split (mlpack's dual depth-first order): both when neither is a leaf, so that each
// query child meets first the reference child nearest to it (in a self-join, itself), which gives its
// points good k-th distances early; else the one that is not a leaf. Empty nodes (the empty side of a
// `middle` split) are never scored.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "kdspace/detail/avx2_dispatch.hpp"
#if defined(KDSPACE_AVX2_DISPATCH)
#include <immintrin.h>
#endif
#include "kdspace/joins/join_stats.hpp"

// The leaf-pair base cases run in their AVX2 compilation where the processor has it
// (avx2_dispatch.hpp): the loops over a block of 8 points (space.hpp's distances and lower bounds)
// then take 4 doubles or 8 floats per instruction rather than 2 or 4, with the same answers. The
// rules' base cases are given the instruction set they are compiled for (BaselineIsa, Avx2Isa), and
// pass it to the block comparisons (at_most, not_above_each), whose AVX2 forms compare a block of 8
// doubles in two 256-bit registers rather than four 128-bit ones (the compiler does not widen the
// SSE2 intrinsics by itself).

namespace kdspace::detail {

/// The instruction set a base case is compiled for: the baseline, or AVX2 inside with_avx2.
struct BaselineIsa {};
struct Avx2Isa {};

template <class T, class Context>
struct JoinScore {
  bool visit;
  T key;  ///< a lower bound on the pair's distances: the nearer pair goes first when the rule asks
  Context context;
};

template <class Rule>
class DualTraversal {
 public:
  using Context = typename Rule::Context;

  DualTraversal(Rule& rule, JoinStats& stats) : rule_(rule), stats_(stats), avx2_(avx2_dispatch()) {}

  /// Visits the pairs below (q, r), starting with the rule's score of (q, r) itself.
  void run(std::uint32_t q, std::uint32_t r, const Context& context) {
    const auto s = score(q, r, context);
    if (s.visit) traverse(q, r, s.context);
  }

 private:
  using Score = decltype(std::declval<Rule&>().score(0u, 0u, std::declval<const Context&>()));

  Score score(std::uint32_t q, std::uint32_t r, const Context& context) {
    if (rule_.query_tree().node(q).count() == 0 || rule_.reference_tree().node(r).count() == 0)
      return Score{false, {}, context};
    ++stats_.node_pairs;
    return rule_.score(q, r, context);
  }

  void traverse(std::uint32_t q, std::uint32_t r, const Context& context) {
    const auto& qn = rule_.query_tree().node(q);
    const auto& rn = rule_.reference_tree().node(r);
    if (qn.is_leaf() && rn.is_leaf()) {
      ++stats_.leaf_pairs;
      base_case(q, r, context);
      return;
    }
    if (qn.is_leaf()) {
      visit_reference_children(q, rn, context);
      return;
    }
    for (const std::uint32_t child : {qn.left, qn.right}) {
      if (rn.is_leaf()) {
        const Score s = score(child, r, context);
        if (s.visit) traverse(child, r, s.context);
      } else {
        visit_reference_children(child, rn, context);
      }
    }
    rule_.query_done(q);
  }

  void base_case(std::uint32_t q, std::uint32_t r, const Context& context) {
#if defined(KDSPACE_AVX2_DISPATCH)
    if (avx2_) {
      with_avx2([&] { rule_.base_case(q, r, context, Avx2Isa{}); });
      return;
    }
#endif
    rule_.base_case(q, r, context, BaselineIsa{});
  }

  // Scores (q, both children of rn) and visits them, the nearer first when the rule asks.
  template <class Node>
  void visit_reference_children(std::uint32_t q, const Node& rn, const Context& context) {
    std::uint32_t first = rn.left, second = rn.right;
    Score first_score = score(q, first, context), second_score = score(q, second, context);
    if (Rule::nearest_first && second_score.key < first_score.key) {
      std::swap(first, second);
      std::swap(first_score, second_score);
    }
    if (first_score.visit) traverse(q, first, first_score.context);
    if (second_score.visit && rule_.rescore(q, second, second_score.key)) traverse(q, second, second_score.context);
  }

  Rule& rule_;
  JoinStats& stats_;
  bool avx2_;  ///< base cases in their AVX2 compilation
};

/// The bits of the values of a block that are <= limit (bit j for value j), so that a block with
/// nothing near costs no branch per value. With SSE2, a vector comparison and a mask move per two
/// doubles or four floats (a loop of scalar comparisons would read the block back from memory one
/// value at a time).
template <std::size_t N, class T>
unsigned at_most(const T* values, T limit) {
  static_assert(N <= 32, "a block fits in the bits of an unsigned");
  unsigned bits = 0;
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, double> && N % 2 == 0) {
    const __m128d bound = _mm_set1_pd(limit);
    for (std::size_t j = 0; j < N; j += 2)
      bits |= static_cast<unsigned>(_mm_movemask_pd(_mm_cmple_pd(_mm_loadu_pd(values + j), bound))) << j;
    return bits;
  } else if constexpr (std::is_same_v<T, float> && N % 4 == 0) {
    const __m128 bound = _mm_set1_ps(limit);
    for (std::size_t j = 0; j < N; j += 4)
      bits |= static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(_mm_loadu_ps(values + j), bound))) << j;
    return bits;
  }
#endif
  for (std::size_t j = 0; j < N; ++j) bits |= static_cast<unsigned>(values[j] <= limit) << j;
  return bits;
}

template <class T, std::size_t N>
unsigned at_most(const std::array<T, N>& values, T limit) {
  return at_most<N>(values.data(), limit);
}

/// The bits of the values of a block that are not above their own limits (bit j: !(values[j] >
/// limits[j]), so a NaN counts as not above), by vector comparisons as at_most.
template <class T, std::size_t N>
unsigned not_above_each(const std::array<T, N>& values, const T* limits) {
  unsigned bits = 0;
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, double> && N % 2 == 0) {
    for (std::size_t j = 0; j < N; j += 2)
      bits |= static_cast<unsigned>(_mm_movemask_pd(_mm_cmpngt_pd(_mm_loadu_pd(values.data() + j), _mm_loadu_pd(limits + j))))
              << j;
    return bits;
  } else if constexpr (std::is_same_v<T, float> && N % 4 == 0) {
    for (std::size_t j = 0; j < N; j += 4)
      bits |= static_cast<unsigned>(_mm_movemask_ps(_mm_cmpngt_ps(_mm_loadu_ps(values.data() + j), _mm_loadu_ps(limits + j))))
              << j;
    return bits;
  }
#endif
  for (std::size_t j = 0; j < N; ++j) bits |= static_cast<unsigned>(!(values[j] > limits[j])) << j;
  return bits;
}

template <std::size_t N, class T>
unsigned at_most(const T* values, T limit, BaselineIsa) {
  return at_most<N>(values, limit);
}
template <class T, std::size_t N>
unsigned at_most(const std::array<T, N>& values, T limit, BaselineIsa) {
  return at_most<N>(values.data(), limit);
}
template <class T, std::size_t N>
unsigned not_above_each(const std::array<T, N>& values, const T* limits, BaselineIsa) {
  return not_above_each(values, limits);
}

#if defined(KDSPACE_AVX2_DISPATCH)
/// at_most and not_above_each in AVX2: the same comparisons (the same predicates, NaN included),
/// 4 doubles or 8 floats each.
template <std::size_t N, class T>
__attribute__((target("avx2"))) unsigned at_most(const T* values, T limit, Avx2Isa) {
  unsigned bits = 0;
  if constexpr (std::is_same_v<T, double> && N % 4 == 0) {
    const __m256d bound = _mm256_set1_pd(limit);
    for (std::size_t j = 0; j < N; j += 4)
      bits |= static_cast<unsigned>(_mm256_movemask_pd(_mm256_cmp_pd(_mm256_loadu_pd(values + j), bound, _CMP_LE_OS)))
              << j;
    return bits;
  } else if constexpr (std::is_same_v<T, float> && N % 8 == 0) {
    const __m256 bound = _mm256_set1_ps(limit);
    for (std::size_t j = 0; j < N; j += 8)
      bits |= static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(_mm256_loadu_ps(values + j), bound, _CMP_LE_OS)))
              << j;
    return bits;
  }
  return at_most<N>(values, limit);
}
template <class T, std::size_t N>
__attribute__((target("avx2"))) unsigned at_most(const std::array<T, N>& values, T limit, Avx2Isa) {
  return at_most<N>(values.data(), limit, Avx2Isa{});
}
template <class T, std::size_t N>
__attribute__((target("avx2"))) unsigned not_above_each(const std::array<T, N>& values, const T* limits, Avx2Isa) {
  unsigned bits = 0;
  if constexpr (std::is_same_v<T, double> && N % 4 == 0) {
    for (std::size_t j = 0; j < N; j += 4)
      bits |= static_cast<unsigned>(_mm256_movemask_pd(
                  _mm256_cmp_pd(_mm256_loadu_pd(values.data() + j), _mm256_loadu_pd(limits + j), _CMP_NGT_US)))
              << j;
    return bits;
  } else if constexpr (std::is_same_v<T, float> && N % 8 == 0) {
    for (std::size_t j = 0; j < N; j += 8)
      bits |= static_cast<unsigned>(_mm256_movemask_ps(
                  _mm256_cmp_ps(_mm256_loadu_ps(values.data() + j), _mm256_loadu_ps(limits + j), _CMP_NGT_US)))
              << j;
    return bits;
  }
  return not_above_each(values, limits);
}
#endif

/// The lowest set bit's position, and that bit cleared (`bits` unsigned or std::uint64_t, not 0).
template <class Bits>
unsigned take_lowest_bit(Bits& bits) {
  static_assert(std::is_same_v<Bits, unsigned> || std::is_same_v<Bits, std::uint64_t>);
#if defined(__GNUC__)
  unsigned j;
  if constexpr (std::is_same_v<Bits, unsigned>)
    j = static_cast<unsigned>(__builtin_ctz(bits));
  else
    j = static_cast<unsigned>(__builtin_ctzll(bits));
#else
  unsigned j = 0;
  while (!(bits >> j & 1u)) ++j;
#endif
  bits &= bits - 1;
  return j;
}

/// The distances from point `a` to the points [first, leaf.end) of reference leaf `id`, computed a
/// block at a time from the leaf's columns (vector instructions): visit(distances, keep, base) for
/// each block, where bit j of `keep` marks the positions base + j in [first, leaf.end) (positions
/// before `first` in the first block, and the padding past the end in the last, are masked off).
template <class Tree, class Space, class T, class Visit>
void distance_blocks(const Tree& reference, std::uint32_t id, std::uint32_t first, const T* a, const Space& space,
                     Visit&& visit) {
  constexpr std::size_t block = Tree::column_block;
  const auto& leaf = reference.node(id);
  const std::size_t stride = Tree::column_stride(leaf);
  const T* columns = reference.columns(id);
  std::size_t start = (first - leaf.begin) / block * block;
  unsigned keep = ~0u << (first - leaf.begin - start);
  for (; start < leaf.count(); start += block, keep = ~0u) {
    const std::array<T, block> dist = space.template distances<block>(a, columns + start, stride, reference.dim());
    if (leaf.count() - start < block) keep &= (1u << (leaf.count() - start)) - 1;
    visit(dist, keep, leaf.begin + static_cast<std::uint32_t>(start));
  }
}

/// The distances from point `a` to the points [first, leaf.end) of reference leaf `id`, of at most
/// leaf_mask_points points, into all[position - leaf.begin], and for each limit the mask of the
/// positions (bit position - leaf.begin) whose distance is at most that limit.
///
/// Written for what GCC makes of it (callgrind, self-join k = 10 of 2e5 uniform 3-D points, whole
/// program, 1195.1e6 -> 1109.7e6 instructions): the positions outside [first, leaf.end) are masked
/// off once for the leaf rather than block by block, and a block's distances are copied into `all`
/// by a loop of their own (std::copy put the block on the stack and copied it from there in halves;
/// computed straight into a block of `all`, they went through general registers).
inline constexpr std::size_t leaf_mask_points = 64;
template <class Isa, std::size_t Limits, class Tree, class Space, class T>
std::array<std::uint64_t, Limits> near_masks(const Tree& reference, std::uint32_t id, std::uint32_t first,
                                             const T* a, const Space& space,
                                             const std::array<T, Limits>& limits,
                                             std::array<T, leaf_mask_points>& all) {
  static_assert(leaf_mask_points == 64, "a leaf's positions are the bits of a 64-bit mask");
  constexpr std::size_t block = Tree::column_block;
  const auto& leaf = reference.node(id);
  const std::size_t stride = Tree::column_stride(leaf), count = leaf.count(), from = first - leaf.begin;
  const T* columns = reference.columns(id);
  std::array<std::uint64_t, Limits> near{};
  for (std::size_t start = from / block * block; start < count; start += block) {
    const std::array<T, block> dist = space.template distances<block>(a, columns + start, stride, reference.dim());
    for (std::size_t l = 0; l < Limits; ++l) near[l] |= std::uint64_t{at_most(dist, limits[l], Isa{})} << start;
    for (std::size_t j = 0; j < block; ++j) all[start + j] = dist[j];
  }
  const std::uint64_t inside =
      (count == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << count) - 1) &
      (from >= 64 ? std::uint64_t{0} : ~std::uint64_t{0} << from);  // from == count == 64: a self range join's last point
  for (std::size_t l = 0; l < Limits; ++l) near[l] &= inside;
  return near;
}

/// visit(begin + j, all[j]) for each bit j of `bits`, in order.
template <class T, class Visit>
void visit_bits(std::uint64_t bits, std::uint32_t begin, const std::array<T, leaf_mask_points>& all,
                Visit&& visit) {
  while (bits) {
    const unsigned j = take_lowest_bit(bits);
    visit(begin + j, all[j]);
  }
}

/// distance_blocks, point by point: visit(position, distance) for the points at most `limit` (read
/// for each block; a k-NN join lowers it as it goes, and checks again what it is offered), in order.
///
/// For a leaf of up to 64 points the blocks' masks go into one 64-bit mask and the points are
/// visited after the last block: one loop over the points found, whose end is mispredicted once,
/// rather than one per block with a point found (callgrind --branch-sim, 2e5 uniform 3-D points:
/// pairs within r 563.1e6 -> 547.5e6 instructions, 3.57e6 -> 3.02e6 mispredicted branches; self-join
/// k = 10 1346e6 -> 1352e6 instructions, 13.23e6 -> 12.49e6 mispredicted).
template <class Isa, class Tree, class Space, class T, class Visit>
void distances_to_leaf(const Tree& reference, std::uint32_t id, std::uint32_t first, const T* a,
                       const Space& space, const T& limit, Visit&& visit) {
  const auto& leaf = reference.node(id);
  if (leaf.count() <= leaf_mask_points) {
    std::array<T, leaf_mask_points> all;
    const auto near = near_masks<Isa>(reference, id, first, a, space, std::array<T, 1>{limit}, all);
    visit_bits(near[0], leaf.begin, all, visit);
    return;
  }
  distance_blocks(reference, id, first, a, space, [&](const auto& dist, unsigned keep, std::uint32_t base) {
    unsigned near = at_most(dist, limit, Isa{}) & keep;
    while (near) {
      const unsigned j = take_lowest_bit(near);
      visit(base + j, dist[j]);
    }
  });
}

/// distances_to_leaf from point `a` to every point of leaf `id`, those at most `guess` first (a
/// guess at the limit that `limit` will come down to: offered the nearer points first, a k-NN row
/// takes fewer that a nearer one evicts later), then the others at most `limit`.
template <class Isa, class Tree, class Space, class T, class Visit>
void distances_to_leaf_nearer_first(const Tree& reference, std::uint32_t id, const T* a, const Space& space,
                                    const T& limit, T guess, Visit&& visit) {
  const auto& leaf = reference.node(id);
  if (leaf.count() > leaf_mask_points)
    return distances_to_leaf<Isa>(reference, id, leaf.begin, a, space, limit, visit);
  std::array<T, leaf_mask_points> all;
  const auto near = near_masks<Isa>(reference, id, leaf.begin, a, space, std::array<T, 2>{limit, guess}, all);
  visit_bits(near[0] & near[1], leaf.begin, all, visit);
  // The others, against the limit the nearer ones have brought down: most are beyond it now (2e5
  // uniform 3-D points, k = 10: 22.5 visits a point before, 13.3 after), and a block's comparison costs
  // less than refusing them one by one.
  std::uint64_t rest = 0;
  for (std::size_t start = 0; start < leaf.count(); start += Tree::column_block)
    rest |= std::uint64_t{at_most<Tree::column_block>(all.data() + start, limit, Isa{})} << start;
  visit_bits(near[0] & ~near[1] & rest, leaf.begin, all, visit);
}

/// The number of set bits of a block's mask of at most 8 bits (a table: the popcnt instruction is
/// not part of baseline x86-64).
inline unsigned bits_set(unsigned bits) {
  static constexpr auto table = [] {
    std::array<unsigned char, 256> t{};
    for (unsigned v = 1; v < 256; ++v) t[v] = static_cast<unsigned char>(t[v >> 1] + (v & 1u));
    return t;
  }();
  return table[bits & 255u];
}

/// The points of query leaf `id` that may have a neighbour in box [lo, hi]: visit(position), in
/// order, for each whose lower bound on its distance to the box is not above its limit, where
/// limits(base) points to the limits of the block of points from position `base`. The bounds are
/// worked out a block of points at a time from the leaf's columns and compared by one mask for the
/// block (which points pass is not predictable: a branch per point would often be mispredicted).
template <class Isa, class Tree, class Space, class T, class Limits, class Visit>
void points_near_box(const Tree& queries, std::uint32_t id, const T* lo, const T* hi, const Space& space,
                     Limits&& limits, Visit&& visit) {
  constexpr std::size_t block = Tree::column_block;
  const auto& leaf = queries.node(id);
  const std::size_t stride = Tree::column_stride(leaf);
  const T* columns = queries.columns(id);
  for (std::size_t start = 0; start < leaf.count(); start += block) {
    const std::array<T, block> bound = space.template lower_many<block>(columns + start, stride, lo, hi, queries.dim());
    const std::size_t count = std::min<std::size_t>(block, leaf.count() - start);
    const std::uint32_t base = leaf.begin + static_cast<std::uint32_t>(start);
    unsigned near = not_above_each(bound, limits(base), Isa{}) & ((1u << count) - 1);
    while (near) visit(base + take_lowest_bit(near));
  }
}

/// A block of equal limits, for points_near_box.
template <class T, std::size_t N>
std::array<T, N> same_limit(T limit) {
  std::array<T, N> limits;
  limits.fill(limit);
  return limits;
}

/// The query subtrees a join's work is split into, in depth-first order: the largest subtrees of at
/// most `max_points` points. They depend on the tree only, never on the number of threads, so the
/// work (and any floating-point sum taken per subtree) is the same on any number of threads.
template <class Tree>
std::vector<std::uint32_t> task_roots(const Tree& tree, std::size_t max_points) {
  std::vector<std::uint32_t> roots, stack{0};
  while (!stack.empty()) {
    const std::uint32_t id = stack.back();
    stack.pop_back();
    const auto& node = tree.node(id);
    if (node.is_leaf() || node.count() <= max_points) {
      if (node.count() > 0) roots.push_back(id);
      continue;
    }
    stack.push_back(node.right);
    stack.push_back(node.left);
  }
  return roots;
}

}  // namespace kdspace::detail
