// Ray streams: many incoherent rays through the BoxTree together, in the manner of the ray stream
// traversals of Wald, Gribble, Boulos & Kensler (2007, "SIMD ray stream tracing") and Barringer &
// Akenine-Moller (2014, "Dynamic ray stream traversal"), for the kd-tree's near/far order.
//
// A batch's random rays (no two alike, so no packets) each walk about a dozen inner nodes, each step
// a dependent load and a choice the branch predictor cannot guess. Streamed, the rays of one
// direction octant go through the tree depth first together: at an inner node every ray of the
// node's set is split into the near child's set and the far child's set by the same comparisons a
// single descent makes (descent.hpp), and the near set is traced before the far one. Rays of one
// octant agree on which child is near at every node, so each ray still meets its cells in its own
// front-to-back order, and when the far set's turn comes each of its rays is dropped if its best hit
// lies before the cell (the test of a single traversal's pop). A node is read once for all its rays,
// and the per-ray work of a node is a few arithmetic operations on arrays, without a branch on the ray.
// Where a set falls below stream_min_rays rays, or at a leaf, each ray walks on alone (walk.hpp) from
// that cell with its interval and its best hit so far.
//
// Every ray makes exactly the decisions of its single traversal (the same float parameters, the same
// widened comparisons, the same leaf tests in the same order), so the hits and the counts
// (RayStats) are those of single traces.
#include "trace_stream.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include "kdspace/detail/avx2_dispatch.hpp"
#if defined(KDSPACE_AVX2_DISPATCH)
#include <immintrin.h>
#endif
#include "traversal_ray.hpp"
#include "walk.hpp"

namespace kdspace::detail {
namespace {

/// Grows the entry arrays to hold at least `size` entries.
void reserve_entries(StreamScratch& s, std::size_t size) {
  if (s.slot.size() >= size) return;
  const std::size_t grown = std::max(size, 2 * s.slot.size());
  s.slot.resize(grown);
  s.enter.resize(grown);
  s.exit.resize(grown);
}

/// The rays of an inner node's set, split between its children: descend's step (descent.hpp) for
/// each ray that its best hit so far does not stop (a single trace's pop test).
struct Split {
  float split;
  const float* origin;   ///< the rays' origins on the node's axis, by slot
  const float* inverse;  ///< their reciprocal directions on that axis
  const float* bound;    ///< their best hits, rounded up
};

/// The set entries [begin, end) split into the near child's, written from near_end on, and the far
/// child's, from far_end on; returns the rays that entered the node (their count).
inline std::uint64_t split_entries(const Split& node, std::uint32_t* slot, float* enter, float* exit,
                                   std::uint32_t begin, std::uint32_t end, std::size_t& near_end,
                                   std::size_t& far_end) {
  std::uint64_t visited = 0;
  for (std::uint32_t e = begin; e < end; ++e) {
    const std::uint32_t ray = slot[e];
    const float t_entry = enter[e], t_exit = exit[e];
    const float entry_low = widen_down(t_entry);
    if (entry_low > node.bound[ray]) continue;  // every hit in it is farther
    ++visited;
    const float t_split = (node.split - node.origin[ray]) * node.inverse[ray];
    const bool far_only = t_split < entry_low;
    const bool push = !far_only && !(t_split > widen_up(t_exit));
    if (!far_only) {
      slot[near_end] = ray;
      enter[near_end] = t_entry;
      exit[near_end] = t_split < t_exit ? t_split : t_exit;
      ++near_end;
    }
    if (far_only || push) {
      slot[far_end] = ray;
      enter[far_end] = t_split > t_entry ? t_split : t_entry;
      exit[far_end] = t_exit;
      ++far_end;
    }
  }
  return visited;
}

#if defined(KDSPACE_AVX2_DISPATCH)
/// For each 8-bit mask, the positions of its set bits, lowest first, three bits each: the lane
/// permutation that packs a register's chosen lanes to its start.
constexpr std::array<std::uint32_t, 256> make_pack_table() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t mask = 0; mask < 256; ++mask) {
    std::uint32_t packed = 0, next = 0;
    for (std::uint32_t lane = 0; lane < 8; ++lane)
      if (mask >> lane & 1u) packed |= lane << (3 * next++);
    table[mask] = packed;
  }
  return table;
}
constexpr std::array<std::uint32_t, 256> pack_table = make_pack_table();

__attribute__((target("avx2"))) inline __m256i pack_permutation(unsigned mask) {
  const __m256i shifts = _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21);
  return _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(static_cast<int>(pack_table[mask])), shifts),
                          _mm256_set1_epi32(7));
}

/// split_entries eight entries at a time: the same arithmetic and comparisons lane by lane (MINPS
/// and MAXPS return their second operand for a NaN, as the scalar selects do), the chosen lanes
/// packed by a permutation and stored whole (the lanes past the count are overwritten later, or
/// lie in the slack past the sets: up to 8 entries).
__attribute__((target("avx2"))) inline std::uint64_t split_entries_avx(const Split& node, std::uint32_t* slot,
                                                                      float* enter, float* exit,
                                                                      std::uint32_t begin, std::uint32_t end,
                                                                      std::size_t& near_end,
                                                                      std::size_t& far_end) {
  const __m256 magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 relative = _mm256_set1_ps(Widening<float>::relative);
  const __m256 absolute = _mm256_set1_ps(Widening<float>::absolute);
  const __m256 split = _mm256_set1_ps(node.split);
  const __m256i lane_index = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  std::uint64_t visited = 0;
  for (std::uint32_t e = begin; e < end; e += 8) {
    // Lanes past `end` read entries that are not the set's: their slot is taken as 0 and they are
    // dropped from both children.
    const __m256i valid = _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(end - e)), lane_index);
    const __m256i ray =
        _mm256_and_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(slot + e)), valid);
    const __m256 t_entry = _mm256_loadu_ps(enter + e), t_exit = _mm256_loadu_ps(exit + e);
    const __m256 bound = _mm256_i32gather_ps(node.bound, ray, 4);
    const __m256 origin = _mm256_i32gather_ps(node.origin, ray, 4);
    const __m256 inverse = _mm256_i32gather_ps(node.inverse, ray, 4);
    const __m256 entry_low = _mm256_sub_ps(
        t_entry, _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(t_entry, magnitude), relative), absolute));
    const __m256 exit_high = _mm256_add_ps(
        t_exit, _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(t_exit, magnitude), relative), absolute));
    const __m256 alive = _mm256_and_ps(_mm256_cmp_ps(entry_low, bound, _CMP_NGT_UQ), _mm256_castsi256_ps(valid));
    const __m256 t_split = _mm256_mul_ps(_mm256_sub_ps(split, origin), inverse);
    const __m256 far_only = _mm256_cmp_ps(t_split, entry_low, _CMP_LT_OQ);
    const __m256 reaches_far = _mm256_cmp_ps(t_split, exit_high, _CMP_NGT_UQ);
    const auto alive_bits = static_cast<unsigned>(_mm256_movemask_ps(alive));
    const auto near_bits = static_cast<unsigned>(_mm256_movemask_ps(_mm256_andnot_ps(far_only, alive)));
    const auto far_bits =
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_and_ps(_mm256_or_ps(far_only, reaches_far), alive)));
    visited += static_cast<std::uint64_t>(__builtin_popcount(alive_bits));
    const __m256i near_order = pack_permutation(near_bits), far_order = pack_permutation(far_bits);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(slot + near_end), _mm256_permutevar8x32_epi32(ray, near_order));
    _mm256_storeu_ps(enter + near_end, _mm256_permutevar8x32_ps(t_entry, near_order));
    _mm256_storeu_ps(exit + near_end, _mm256_permutevar8x32_ps(_mm256_min_ps(t_split, t_exit), near_order));
    near_end += static_cast<std::size_t>(__builtin_popcount(near_bits));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(slot + far_end), _mm256_permutevar8x32_epi32(ray, far_order));
    _mm256_storeu_ps(enter + far_end, _mm256_permutevar8x32_ps(_mm256_max_ps(t_split, t_entry), far_order));
    _mm256_storeu_ps(exit + far_end, _mm256_permutevar8x32_ps(t_exit, far_order));
    far_end += static_cast<std::size_t>(__builtin_popcount(far_bits));
  }
  return visited;
}
#endif

template <bool AnyHit, bool Wide>
inline void stream(const BoxTree& tree, const Ray* rays, const std::uint32_t* ids, std::size_t n, RayRange range,
                   Hit* hits, RayStats& stats, StreamScratch& s) {
  const BoxTreeView view = view_of(tree);
  const std::size_t capacity = n;
  s.origin.resize(3 * capacity);
  s.inverse.resize(3 * capacity);
  s.best_t.resize(capacity);
  s.best_bound.resize(capacity);
  s.best_box.resize(capacity);
  reserve_entries(s, capacity + 16);

  // The rays that meet the scene's bounds, one slot each; the others miss.
  std::vector<std::uint32_t> ray_of;  // by slot: the ray's position in the batch
  ray_of.reserve(n);
  std::uint32_t negative = 0;  // bit a: the rays run towards -a
  std::size_t m = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Ray& ray = rays[ids[i]];
    ++stats.rays;
    const TraversalRay<float> r(ray);
    float t_entry = range.t_min, t_exit = range.t_max;
    if (!clip_widened(tree.bounds(), r, t_entry, t_exit)) {
      hits[ids[i]] = Hit{};
      continue;
    }
    negative = negative_axes(r);
    for (int a = 0; a < 3; ++a) {
      s.origin[a * capacity + m] = r.origin[a];
      s.inverse[a * capacity + m] = r.inverse[a];
    }
    s.best_t[m] = range.t_max;
    s.best_bound[m] = range.t_max;
    s.best_box[m] = Hit::none;
    s.slot[m] = static_cast<std::uint32_t>(m);
    s.enter[m] = t_entry;
    s.exit[m] = t_exit;
    ray_of.push_back(ids[i]);
    ++m;
  }

  const auto ray_at = [&](std::uint32_t slot) {
    TraversalRay<float> r;
    for (int a = 0; a < 3; ++a) {
      r.origin[a] = s.origin[a * capacity + slot];
      r.inverse[a] = s.inverse[a * capacity + slot];
      r.negative[a] = (negative >> a) & 1u;
#if defined(__SSE2__)
      r.origin4[a] = _mm_set1_ps(r.origin[a]);
      r.inverse4[a] = _mm_set1_ps(r.inverse[a]);
#endif
    }
    return r;
  };
  const auto best_at = [&](std::uint32_t slot) {
    BestHit<float> best(range.t_max);
    best.t = s.best_t[slot];
    best.box = s.best_box[slot];
    best.bound = s.best_bound[slot];
    return best;
  };
  const auto keep = [&](std::uint32_t slot, const BestHit<float>& best) {
    s.best_t[slot] = best.t;
    s.best_box[slot] = best.box;
    // An any-hit ray is done at its first hit: no cell is entered for it again.
    s.best_bound[slot] = AnyHit && best.box != Hit::none ? -std::numeric_limits<float>::infinity() : best.bound;
  };
  // One ray walks on alone from `node` over [t_entry, t_exit].
  const auto walk_alone = [&](std::uint32_t slot, std::uint32_t node, float t_entry, float t_exit) {
    const TraversalRay<float> r = ray_at(slot);
    DescentRayOf<float> descent{};
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide) descent = descent_ray(r);
#endif
    BestHit<float> best = best_at(slot);
    walk<float, AnyHit, Wide>(view, rays[ray_of[slot]], r, descent, StackEntry<float>{node, t_entry, t_exit},
                              range.t_min, best, stats);
    keep(slot, best);
  };
  // The rays of a task at a leaf: each ray still short of its best hit tests the leaf's boxes.
  const auto at_leaf = [&](const BoxNode& leaf, const StreamScratch::Task& task) {
    std::uint64_t visited = 0;
    for (std::uint32_t e = task.begin; e < task.end; ++e) {
      const std::uint32_t slot = s.slot[e];
      if (widen_down(s.enter[e]) > s.best_bound[slot]) continue;  // a single trace's pop
      ++visited;
      if (leaf.count() == 0) continue;
      const TraversalRay<float> r = ray_at(slot);
      BestHit<float> best = best_at(slot);
      std::optional<PreparedRay> exact;
      test_leaf<float, AnyHit, Wide>(view, leaf, rays[ray_of[slot]], r, range.t_min, exact, best, stats);
      keep(slot, best);
    }
    stats.nodes_visited += visited;
  };

  s.tasks.clear();
  if (m > 0) s.tasks.push_back(StreamScratch::Task{0, 0, static_cast<std::uint32_t>(m)});
  while (!s.tasks.empty()) {
    const StreamScratch::Task task = s.tasks.back();
    s.tasks.pop_back();
    const BoxNode node = view.nodes[task.node];
    const std::size_t count = task.end - task.begin;
    if (node.is_leaf()) {
      at_leaf(node, task);
      continue;
    }
    if (count < stream_min_rays) {
      for (std::uint32_t e = task.begin; e < task.end; ++e)
        walk_alone(s.slot[e], task.node, s.enter[e], s.exit[e]);
      continue;
    }
    // The far set goes to [top, top + count), the near set to [top + count + 8, ...): the entries
    // above this task's are free (its children and their subtrees are done), and 8 entries of
    // slack past each set take the whole-register stores of split_entries_avx.
    const std::size_t top = task.end;
    reserve_entries(s, top + 2 * count + 32);
    const int axis = node.axis();
    const std::uint32_t left = task.node + 1, right = node.right_child();
    const bool towards_negative = (negative >> axis) & 1u;
    const std::uint32_t near = towards_negative ? right : left, far = towards_negative ? left : right;
    const Split split{node.split(), s.origin.data() + axis * capacity, s.inverse.data() + axis * capacity,
                      s.best_bound.data()};
    const std::size_t near_begin = top + count + 8;
    std::size_t far_end = top, near_end = near_begin;
    std::uint64_t visited;
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide)
      visited = split_entries_avx(split, s.slot.data(), s.enter.data(), s.exit.data(), task.begin, task.end,
                                  near_end, far_end);
    else
#endif
      visited = split_entries(split, s.slot.data(), s.enter.data(), s.exit.data(), task.begin, task.end,
                              near_end, far_end);
    stats.nodes_visited += visited;
    if (far_end > top)
      s.tasks.push_back(StreamScratch::Task{far, static_cast<std::uint32_t>(top), static_cast<std::uint32_t>(far_end)});
    if (near_end > near_begin)
      s.tasks.push_back(StreamScratch::Task{near, static_cast<std::uint32_t>(near_begin),
                                            static_cast<std::uint32_t>(near_end)});
  }

  for (std::size_t slot = 0; slot < m; ++slot) {
    Hit h;
    if (s.best_box[slot] != Hit::none) h = Hit{s.best_box[slot], to_float_t(s.best_t[slot])};
    hits[ray_of[slot]] = h;
  }
}

#if defined(KDSPACE_AVX2_DISPATCH)
template <bool AnyHit>
__attribute__((target("avx2"), flatten)) void stream_wide(const BoxTree& tree, const Ray* rays,
                                                          const std::uint32_t* ids, std::size_t n, RayRange range,
                                                          Hit* hits, RayStats& stats, StreamScratch& s) {
  stream<AnyHit, true>(tree, rays, ids, n, range, hits, stats, s);
}
#endif

}  // namespace

template <bool AnyHit>
void trace_stream(const BoxTree& tree, const Ray* rays, const std::uint32_t* ids, std::size_t n, RayRange range,
                  Hit* hits, RayStats& stats, StreamScratch& scratch) {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (avx2_dispatch()) return stream_wide<AnyHit>(tree, rays, ids, n, range, hits, stats, scratch);
#endif
  stream<AnyHit, false>(tree, rays, ids, n, range, hits, stats, scratch);
}

template void trace_stream<false>(const BoxTree&, const Ray*, const std::uint32_t*, std::size_t, RayRange, Hit*,
                                  RayStats&, StreamScratch&);
template void trace_stream<true>(const BoxTree&, const Ray*, const std::uint32_t*, std::size_t, RayRange, Hit*,
                                 RayStats&, StreamScratch&);

}  // namespace kdspace::detail
