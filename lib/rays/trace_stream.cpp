// Ray streams: many incoherent rays through the BoxTree together, in the manner of the ray stream
// traversals of Wald, Gribble, Boulos & Kensler (2007, "SIMD ray stream tracing") and Barringer &
// Akenine-Moller (2014, "Dynamic ray stream traversal"), for the kd-tree's near/far order.
//
// A batch's random rays (no two alike, so no packets) each walk about a dozen inner nodes, each step
// a dependent load and a choice the branch predictor cannot guess. Streamed, the rays of one
// direction octant go through the tree depth first together: at an inner node every ray of the
// node's set is split into the near child's set and the far child's set by the comparisons of a
// single descent (descent.hpp), and the near set is traced before the far one. Rays of one octant
// agree on which child is near at every node, so each ray still meets its cells in its own
// front-to-back order, and when the far set's turn comes each of its rays is dropped if its best hit
// lies before the cell (the test of a single traversal's pop). A node is read once for all its rays,
// and the per-ray work of a node is a few arithmetic operations on arrays, without a branch on the ray.
// At a leaf reached by enough rays, the leaf's boxes are tested one at a time against eight rays at a
// time; below stream_min_rays rays an inner node's rays walk on alone (walk.hpp) from that cell with
// their intervals and their best hits so far.
//
// Every ray makes exactly the decisions of its single traversal (the same float parameters, the same
// widened comparisons, the same leaf tests in the same order), so the hits and the counts
// (RayStats) are those of single traces.
#include "trace_stream.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>

#include "kdspace/detail/avx2_dispatch.hpp"
#include "kdspace/rays/detail/slab.hpp"
#include "traversal_ray.hpp"
#include "walk.hpp"
#if defined(KDSPACE_AVX2_DISPATCH)
#include <immintrin.h>
#endif

namespace kdspace::detail {

namespace {

constexpr float minus_infinity = -std::numeric_limits<float>::infinity();

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

/// Per lane: t widened down / up (widen_down, widen_up, in their order of operations).
__attribute__((target("avx2"))) inline __m256 widening8(__m256 t) {
  const __m256 magnitude = _mm256_and_ps(t, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff)));
  return _mm256_add_ps(_mm256_mul_ps(magnitude, _mm256_set1_ps(Widening<float>::relative)),
                       _mm256_set1_ps(Widening<float>::absolute));
}

/// Per lane: whether the entry's ray is still short of its best hit on entering the cell (a single
/// trace's pop: t_entry widened down, entry_low, not above the ray's bound); lanes not `valid`, none.
/// The test of split_entries_avx and of a leaf's entering rays (entering_avx).
__attribute__((target("avx2"))) inline __m256 still_short8(__m256 entry_low, __m256 bound, __m256i valid) {
  return _mm256_and_ps(_mm256_cmp_ps(entry_low, bound, _CMP_NGT_UQ), _mm256_castsi256_ps(valid));
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
  const __m256 split = _mm256_set1_ps(node.split);
  const __m256i lane_index = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  std::uint64_t visited = 0;
  // The set ends and the node's arrays in locals: through the references, the compiler reloaded
  // them from memory after every store to the entry arrays.
  std::size_t near_at = near_end, far_at = far_end;
  const float *const origins = node.origin, *const inverses = node.inverse, *const bounds = node.bound;
  for (std::uint32_t e = begin; e < end; e += 8) {
    // Lanes past `end` read entries that are not the set's: their slot is taken as 0 and they are
    // dropped from both children.
    const __m256i valid = _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(end - e)), lane_index);
    const __m256i ray =
        _mm256_and_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(slot + e)), valid);
    const __m256 t_entry = _mm256_loadu_ps(enter + e), t_exit = _mm256_loadu_ps(exit + e);
    const __m256 bound = _mm256_i32gather_ps(bounds, ray, 4);
    const __m256 origin = _mm256_i32gather_ps(origins, ray, 4);
    const __m256 inverse = _mm256_i32gather_ps(inverses, ray, 4);
    const __m256 entry_low = _mm256_sub_ps(t_entry, widening8(t_entry));
    const __m256 exit_high = _mm256_add_ps(t_exit, widening8(t_exit));
    const __m256 alive = still_short8(entry_low, bound, valid);
    const __m256 t_split = _mm256_mul_ps(_mm256_sub_ps(split, origin), inverse);
    const __m256 far_only = _mm256_cmp_ps(t_split, entry_low, _CMP_LT_OQ);
    const __m256 reaches_far = _mm256_cmp_ps(t_split, exit_high, _CMP_NGT_UQ);
    const auto alive_bits = static_cast<unsigned>(_mm256_movemask_ps(alive));
    const auto near_bits = static_cast<unsigned>(_mm256_movemask_ps(_mm256_andnot_ps(far_only, alive)));
    const auto far_bits =
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_and_ps(_mm256_or_ps(far_only, reaches_far), alive)));
    visited += static_cast<std::uint64_t>(__builtin_popcount(alive_bits));
    const __m256i near_order = pack_permutation(near_bits), far_order = pack_permutation(far_bits);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(slot + near_at), _mm256_permutevar8x32_epi32(ray, near_order));
    _mm256_storeu_ps(enter + near_at, _mm256_permutevar8x32_ps(t_entry, near_order));
    _mm256_storeu_ps(exit + near_at, _mm256_permutevar8x32_ps(_mm256_min_ps(t_split, t_exit), near_order));
    near_at += static_cast<std::size_t>(__builtin_popcount(near_bits));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(slot + far_at), _mm256_permutevar8x32_epi32(ray, far_order));
    _mm256_storeu_ps(enter + far_at, _mm256_permutevar8x32_ps(_mm256_max_ps(t_split, t_entry), far_order));
    _mm256_storeu_ps(exit + far_at, _mm256_permutevar8x32_ps(t_exit, far_order));
    far_at += static_cast<std::size_t>(__builtin_popcount(far_bits));
  }
  near_end = near_at;
  far_end = far_at;
  return visited;
}
#endif

/// One stream: the rays of one octant, their state by slot (SoA), the sets of the pending cells.
template <bool AnyHit, bool Wide>
class Stream {
 public:
  Stream(const BoxTree& tree, const Ray* rays, RayRange range, RayStats& stats, StreamScratch& s)
      : tree_(tree), view_(view_of(tree)), rays_(rays), range_(range), stats_(stats), s_(s) {}

  /// Traces rays[ids[0 .. n)], writing hits[ids[i]] for those that meet the scene's bounds (the
  /// others' stay Hit{}).
  void run(const std::uint32_t* ids, std::size_t n, Hit* hits) {
    admit(ids, n);
    s_.tasks.clear();
    if (count_ > 0) s_.tasks.push_back(StreamScratch::Task{0, 0, static_cast<std::uint32_t>(count_)});
    while (!s_.tasks.empty()) {
      const StreamScratch::Task task = s_.tasks.back();
      s_.tasks.pop_back();
      const BoxNode node = view_.nodes[task.node];
      if (node.is_leaf())
        at_leaf(node, task);
      else if (task.end - task.begin < stream_min_rays)
        for (std::uint32_t e = task.begin; e < task.end; ++e)
          walk_alone(s_.slot[e], task.node, s_.enter[e], s_.exit[e]);
      else
        split(node, task);
    }
    for (std::size_t slot = 0; slot < count_; ++slot) {  // a miss: Hit{} (t = +inf)
      const std::int32_t box = s_.best_box[slot];
      hits[s_.ray_of[slot]] =
          Hit{box, select_bits(box != Hit::none, to_float_t(s_.best_t[slot]), Hit{}.t)};
    }
  }

 private:
  /// A slot for each ray that meets the scene's bounds, with its interval there as the root's set;
  /// the others miss.
  void admit(const std::uint32_t* ids, std::size_t n) {
    // 8 slots of slack past n in every per-ray array (by axis too), for admit_avx's whole-register
    // stores.
    capacity_ = n + 8;
    s_.origin.resize(3 * capacity_);
    s_.direction.resize(3 * capacity_);
    s_.inverse.resize(3 * capacity_);
    s_.best_t.resize(capacity_);
    s_.best_bound.resize(capacity_);
    s_.best_box.resize(capacity_);
    s_.ray_of.resize(capacity_);
    reserve_entries(s_, n + 16);
    count_ = 0;
    stats_.rays += n;
    if (n == 0) return;
    {
      std::uint32_t direction[3];
      std::memcpy(direction, rays_[ids[0]].direction.data(), sizeof direction);
      negative_ = direction[0] >> 31 | (direction[1] >> 31) << 1 | (direction[2] >> 31) << 2;
    }
    std::size_t i = 0;
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide) i = admit_avx(ids, n);
#endif
    for (; i < n; ++i) {
      const TraversalRay<float> r(rays_[ids[i]]);
      float t_entry = range_.t_min, t_exit = range_.t_max;
      if (!clip_widened(tree_.bounds(), r, t_entry, t_exit)) continue;  // a miss: hits[ids[i]] stays Hit{}
      const std::size_t slot = count_++;
      for (int a = 0; a < 3; ++a) {
        s_.origin[a * capacity_ + slot] = r.origin[a];
        s_.direction[a * capacity_ + slot] = rays_[ids[i]].direction[a];
        s_.inverse[a * capacity_ + slot] = r.inverse[a];
      }
      s_.best_t[slot] = range_.t_max;
      s_.best_bound[slot] = range_.t_max;
      s_.best_box[slot] = Hit::none;
      s_.ray_of[slot] = ids[i];
      s_.slot[slot] = static_cast<std::uint32_t>(slot);
      s_.enter[slot] = t_entry;
      s_.exit[slot] = t_exit;
    }
  }

#if defined(KDSPACE_AVX2_DISPATCH)
  /// How far ahead of its group of eight admit_avx asks for the rays it will read (two groups: the
  /// rays arrive from the last-level cache or memory in time, measured on rays_walk).
  static constexpr std::size_t prefetch_rays_ahead = 16;

  /// admit's loop eight rays at a time, as far as whole groups of eight go; returns the rays done.
  /// The same arithmetic as TraversalRay and clip_widened lane by lane (min and max with their
  /// operands in std::min's and std::max's order); a stream's rays have no zero direction
  /// component (the packet range), so no axis is parallel.
  __attribute__((target("avx2"))) std::size_t admit_avx(const std::uint32_t* ids, std::size_t n) {
    // Rays are gathered by 32-bit word offsets from the first one: a chunk is far smaller than this.
    if (ids[n - 1] - ids[0] >= (1u << 26)) return 0;
    const float* words = rays_[ids[0]].origin.data();
    const Box3f& bounds = tree_.bounds();
    const __m256i first = _mm256_set1_epi32(static_cast<int>(ids[0]));
    const __m256i lane_index = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256 one = _mm256_set1_ps(1.0f);
    std::size_t i = 0;
    for (; i + 8 <= n; i += 8) {
      // An octant's rays lie scattered in the batch (ascending ids, random gaps), where the
      // processor's prefetchers cannot follow them: ask for the rays two groups ahead.
      const std::size_t prefetch_end = std::min(n, i + prefetch_rays_ahead + 8);
      for (std::size_t ahead = i + prefetch_rays_ahead; ahead < prefetch_end; ++ahead) {
        const char* ray_bytes = reinterpret_cast<const char*>(rays_ + ids[ahead]);
        _mm_prefetch(ray_bytes, _MM_HINT_T0);
        _mm_prefetch(ray_bytes + sizeof(Ray) - 1, _MM_HINT_T0);
      }
      const __m256i id = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(ids + i));
      const __m256i offset = _mm256_mullo_epi32(_mm256_sub_epi32(id, first), _mm256_set1_epi32(6));
      __m256 origin[3], direction[3], inverse[3];
      __m256 t_lo = _mm256_set1_ps(range_.t_min), t_hi = _mm256_set1_ps(range_.t_max);
      for (int a = 0; a < 3; ++a) {
        origin[a] = _mm256_i32gather_ps(words + a, offset, 4);
        direction[a] = _mm256_i32gather_ps(words + 3 + a, offset, 4);
        inverse[a] = _mm256_div_ps(one, direction[a]);
        const __m256 t0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(bounds.lo[a]), origin[a]), inverse[a]);
        const __m256 t1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(bounds.hi[a]), origin[a]), inverse[a]);
        const __m256 enter = _mm256_min_ps(t1, t0), leave = _mm256_max_ps(t1, t0);
        t_lo = _mm256_max_ps(_mm256_sub_ps(enter, widening8(enter)), t_lo);
        t_hi = _mm256_min_ps(_mm256_add_ps(leave, widening8(leave)), t_hi);
      }
      const auto inside = static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(t_lo, t_hi, _CMP_LE_OQ)));
      const __m256i order = pack_permutation(inside);
      const std::size_t m = count_;
      for (int a = 0; a < 3; ++a) {
        _mm256_storeu_ps(s_.origin.data() + a * capacity_ + m, _mm256_permutevar8x32_ps(origin[a], order));
        _mm256_storeu_ps(s_.direction.data() + a * capacity_ + m,
                         _mm256_permutevar8x32_ps(direction[a], order));
        _mm256_storeu_ps(s_.inverse.data() + a * capacity_ + m, _mm256_permutevar8x32_ps(inverse[a], order));
      }
      _mm256_storeu_ps(s_.enter.data() + m, _mm256_permutevar8x32_ps(t_lo, order));
      _mm256_storeu_ps(s_.exit.data() + m, _mm256_permutevar8x32_ps(t_hi, order));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(s_.ray_of.data() + m), _mm256_permutevar8x32_epi32(id, order));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(s_.slot.data() + m),
                          _mm256_add_epi32(_mm256_set1_epi32(static_cast<int>(m)), lane_index));
      _mm256_storeu_ps(s_.best_bound.data() + m, _mm256_set1_ps(range_.t_max));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(s_.best_box.data() + m), _mm256_set1_epi32(Hit::none));
      const __m256d t_max = _mm256_set1_pd(range_.t_max);
      _mm256_storeu_pd(s_.best_t.data() + m, t_max);
      _mm256_storeu_pd(s_.best_t.data() + m + 4, t_max);
      count_ += static_cast<std::size_t>(__builtin_popcount(inside));
    }
    return i;
  }
#endif

  /// The ray of `slot` as the batch gave it, from the stream's own arrays (the batch's copy lies
  /// farther away in memory: read again for each exact test, it missed the caches).
  Ray batch_ray(std::uint32_t slot) const {
    Ray ray;
    for (int a = 0; a < 3; ++a) {
      ray.origin[a] = s_.origin[a * capacity_ + slot];
      ray.direction[a] = s_.direction[a * capacity_ + slot];
    }
    return ray;
  }

  TraversalRay<float> ray_at(std::uint32_t slot) const {
    TraversalRay<float> r;
    for (int a = 0; a < 3; ++a) {
      r.origin[a] = s_.origin[a * capacity_ + slot];
      r.inverse[a] = s_.inverse[a * capacity_ + slot];
      r.negative[a] = (negative_ >> a) & 1u;
#if defined(__SSE2__)
      r.origin4[a] = _mm_set1_ps(r.origin[a]);
      r.inverse4[a] = _mm_set1_ps(r.inverse[a]);
#endif
    }
    return r;
  }
  BestHit<float> best_at(std::uint32_t slot) const {
    BestHit<float> best(range_.t_max);
    best.t = s_.best_t[slot];
    best.box = s_.best_box[slot];
    best.bound = s_.best_bound[slot];
    return best;
  }
  void keep(std::uint32_t slot, const BestHit<float>& best) {
    s_.best_t[slot] = best.t;
    s_.best_box[slot] = best.box;
    // An any-hit ray is done at its first hit: no cell is entered for it again.
    s_.best_bound[slot] = AnyHit && best.box != Hit::none ? minus_infinity : best.bound;
  }

  /// One ray walks on alone from `node` over [t_entry, t_exit].
  void walk_alone(std::uint32_t slot, std::uint32_t node, float t_entry, float t_exit) {
    const TraversalRay<float> r = ray_at(slot);
    DescentRayOf<float> descent{};
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide) descent = descent_ray(r);
#endif
    BestHit<float> best = best_at(slot);
    walk<float, AnyHit, Wide>(view_, batch_ray(slot), r, descent, StackEntry<float>{node, t_entry, t_exit},
                              range_.t_min, best, stats_);
    keep(slot, best);
  }

  /// The rays of a task at a leaf: each ray still short of its best hit tests the leaf's boxes, in
  /// the leaf's order.
  void at_leaf(const BoxNode& leaf, const StreamScratch::Task& task) {
    std::uint32_t* entering = s_.leaf_rays.data();
    std::size_t n = 0;
    std::uint32_t e = task.begin;
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide) {
      n = entering_avx(task, entering);
      e = task.end;
    }
#endif
    for (; e < task.end; ++e) {
      const std::uint32_t slot = s_.slot[e];
      entering[n] = slot;
      n += widen_down(s_.enter[e]) > s_.best_bound[slot] ? 0 : 1;  // a single trace's pop
    }
    stats_.nodes_visited += n;
    if (leaf.count() == 0 || n == 0) return;
    std::size_t i = 0;
#if defined(KDSPACE_AVX2_DISPATCH)
    // Groups of eight rays box by box, the last one too if it holds enough of them (a group of a
    // few rays costs as much as a full one); the rest one by one, and all of them one by one for a
    // range that starts below 0 (leaf_by_boxes' comparison needs t_min >= 0).
    if constexpr (Wide)
      for (; range_.t_min >= 0 && i + group_min_rays <= n; i += 8)
        leaf_by_boxes(leaf, entering + i, std::min<std::size_t>(8, n - i));
#endif
    for (; i < n; ++i) {
      const std::uint32_t slot = entering[i];
      const TraversalRay<float> r = ray_at(slot);
      BestHit<float> best = best_at(slot);
      std::optional<PreparedRay> exact;
      test_leaf<float, AnyHit, Wide>(view_, leaf, batch_ray(slot), r, range_.t_min, exact, best, stats_);
      keep(slot, best);
    }
  }

#if defined(KDSPACE_AVX2_DISPATCH)
  /// at_leaf's pop eight entries at a time (still_short8, as split_entries_avx): the slots of
  /// the task's rays still short of their best hits, packed into `entering` (8 entries of slack);
  /// returns their count. A leaf's few rays take one step, whose loop test is then foreseen.
  __attribute__((target("avx2"))) std::size_t entering_avx(const StreamScratch::Task& task, std::uint32_t* entering) {
    const __m256i lane_index = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    std::size_t n = 0;
    for (std::uint32_t e = task.begin; e < task.end; e += 8) {
      const __m256i valid = _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(task.end - e)), lane_index);
      const __m256i slot =
          _mm256_and_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(s_.slot.data() + e)), valid);
      const __m256 t_entry = _mm256_loadu_ps(s_.enter.data() + e);
      const __m256 bound = _mm256_i32gather_ps(s_.best_bound.data(), slot, 4);
      const __m256 alive = still_short8(_mm256_sub_ps(t_entry, widening8(t_entry)), bound, valid);
      const auto alive_bits = static_cast<unsigned>(_mm256_movemask_ps(alive));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(entering + n),
                          _mm256_permutevar8x32_epi32(slot, pack_permutation(alive_bits)));
      n += static_cast<std::size_t>(__builtin_popcount(alive_bits));
    }
    return n;
  }

  /// test_leaf for the rays slots[0 .. rays) (at most 8), all of them against one box at a time: for each
  /// ray the float filter's parameters (block_pair_candidates' operations in its order), compared by
  /// may_hit_from_nonnegative (a range whose t_min >= 0: at_leaf sends no other), and the same double
  /// test, box after box in the leaf's order. A ray's bound drops as its best hit does, so a box is
  /// filtered with the bound the leaf's earlier blocks left (never tighter than its double test,
  /// which decides alone), and an any-hit ray stops at the first box it hits.
  /// The fewest rays leaf_by_boxes takes (of its eight lanes).
  static constexpr std::size_t group_min_rays = 5;

  __attribute__((target("avx2"))) void leaf_by_boxes(const BoxNode& leaf, const std::uint32_t* slots,
                                                     std::size_t rays) {
    const std::uint32_t count = leaf.count();
    stats_.boxes_tested += static_cast<std::uint64_t>(count) * rays;
    // Lanes past `rays` read slots[rays ..] (the leaf ray array has 8 of slack), taken as slot 0, and
    // are closed: bound -inf, so that the filter's far end is -inf and no box passes.
    const __m256i valid =
        _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(rays)), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    int enter_plane[3], leave_plane[3];
    for (int a = 0; a < 3; ++a) {
      const int negative = static_cast<int>((negative_ >> a) & 1u);
      enter_plane[a] = a + 3 * negative;
      leave_plane[a] = a + 3 - 3 * negative;
    }
    const __m256i slot = _mm256_and_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(slots)), valid);
    __m256 origin[3], inverse[3];
    for (int a = 0; a < 3; ++a) {
      origin[a] = _mm256_i32gather_ps(s_.origin.data() + a * capacity_, slot, 4);
      inverse[a] = _mm256_i32gather_ps(s_.inverse.data() + a * capacity_, slot, 4);
    }
    const __m256 t_low = _mm256_set1_ps(range_.t_min);
    __m256 bound = _mm256_blendv_ps(_mm256_set1_ps(minus_infinity), _mm256_i32gather_ps(s_.best_bound.data(), slot, 4),
                                    _mm256_castsi256_ps(valid));
    const LeafBlock* block = view_.blocks + leaf.first() / 4;
    const std::uint32_t* ids = view_.references + leaf.first();
    alignas(32) float bound_of[8];  // `bound` by ray, as the double tests lower it
    _mm256_store_ps(bound_of, bound);
    for (std::uint32_t done = 0; done < count; done += 8, block += 2) {
      // Two blocks' boxes are filtered against the rays' bounds at their start, all eight before one
      // branch on the result: a bound lowered by a hit among them leaves the later boxes' filters
      // looser, never tighter, and the double test decides alone. A leaf's last block, when alone,
      // is filtered twice and its copy's lanes pass nothing, as do lanes past count (a leaf's last
      // block repeats its last box).
      const LeafBlock* const pair[2] = {block, block + (count - done > 4 ? 1 : 0)};
      const unsigned lanes = std::min(8u, count - done);
      std::uint64_t passed_by_lane = 0;  // eight bits (rays) a lane
      for (unsigned lane = 0; lane < 8; ++lane) {
        const LeafBlock& b = *pair[lane / 4];
        __m256 t_near = t_low, t_far = bound;
        for (int a = 0; a < 3; ++a) {
          const __m256 t0 =
              _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(b.plane[enter_plane[a]][lane % 4]), origin[a]), inverse[a]);
          const __m256 t1 =
              _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(b.plane[leave_plane[a]][lane % 4]), origin[a]), inverse[a]);
          t_near = _mm256_max_ps(t0, t_near);  // as block_pair_candidates: the second operand for a NaN
          t_far = _mm256_min_ps(t1, t_far);
        }
        passed_by_lane |= std::uint64_t{may_hit_from_nonnegative8(t_near, t_far)} << (8 * lane);  // t_near >= 0
      }
      passed_by_lane &= lanes == 8 ? ~std::uint64_t{0} : (std::uint64_t{1} << (8 * lanes)) - 1;
      for (; passed_by_lane != 0; passed_by_lane &= passed_by_lane - 1) {
        const auto bit = static_cast<unsigned>(__builtin_ctzll(passed_by_lane));
        const unsigned lane = bit / 8, ray_lane = bit % 8;
        if (AnyHit && bound_of[ray_lane] == minus_infinity) continue;  // done at a box before
        const std::uint32_t ray = slots[ray_lane];
        double t_near_exact = range_.t_min, t_far_exact = s_.best_t[ray];
        const bool hit = clip_to_box(box_in_lane(*pair[lane / 4], lane % 4), PreparedRay(batch_ray(ray)), t_near_exact,
                                     t_far_exact);
        const auto box = static_cast<std::int32_t>(ids[done + lane]);
        if constexpr (AnyHit) {
          if (!hit) continue;
          s_.best_t[ray] = t_near_exact;
          s_.best_box[ray] = box;
          s_.best_bound[ray] = bound_of[ray_lane] = minus_infinity;
        } else {
          keep_if_closer(hit, t_near_exact, box, s_.best_t[ray], s_.best_box[ray], bound_of[ray_lane]);
          s_.best_bound[ray] = bound_of[ray_lane];
        }
      }
      bound = _mm256_load_ps(bound_of);
    }
  }
#endif

  /// The rays of an inner node's task split into its children's tasks, near last (traced next).
  void split(const BoxNode& node, const StreamScratch::Task& task) {
    const std::size_t count = task.end - task.begin;
    // The far set goes to [top, top + count), the near set to [top + count + 8, ...): the entries
    // above this task's are free (its children and their subtrees are done), and 8 entries of
    // slack past each set take the whole-register stores of split_entries_avx.
    const std::size_t top = task.end;
    reserve_entries(s_, top + 2 * count + 32);
    const int axis = node.axis();
    const std::uint32_t left = task.node + 1, right = node.right_child();
    const bool towards_negative = (negative_ >> axis) & 1u;
    // Chosen by masking, not by a branch on the octant's sign (mispredicted when octants alternate).
    const std::uint32_t swap = (left ^ right) & (0u - static_cast<std::uint32_t>(towards_negative));
    const std::uint32_t near = left ^ swap, far = right ^ swap;
    const Split plane{node.split(), s_.origin.data() + axis * capacity_, s_.inverse.data() + axis * capacity_,
                      s_.best_bound.data()};
    const std::size_t near_begin = top + count + 8;
    std::size_t far_end = top, near_end = near_begin;
    std::uint64_t visited;
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide)
      visited = split_entries_avx(plane, s_.slot.data(), s_.enter.data(), s_.exit.data(), task.begin, task.end,
                                  near_end, far_end);
    else
#endif
      visited = split_entries(plane, s_.slot.data(), s_.enter.data(), s_.exit.data(), task.begin, task.end,
                              near_end, far_end);
    stats_.nodes_visited += visited;
    if (far_end > top)
      s_.tasks.push_back(StreamScratch::Task{far, static_cast<std::uint32_t>(top), static_cast<std::uint32_t>(far_end)});
    if (near_end > near_begin)
      s_.tasks.push_back(StreamScratch::Task{near, static_cast<std::uint32_t>(near_begin),
                                             static_cast<std::uint32_t>(near_end)});
  }

  const BoxTree& tree_;
  const BoxTreeView view_;
  const Ray* rays_;
  const RayRange range_;
  RayStats& stats_;
  StreamScratch& s_;
  std::size_t capacity_ = 0;  ///< slots of the per-ray arrays (by axis: [axis * capacity_ + slot])
  std::size_t count_ = 0;     ///< rays admitted
  std::uint32_t negative_ = 0;  ///< bit a: the stream's rays run towards -a
};

template <bool AnyHit>
void stream_baseline(const BoxTree& tree, const Ray* rays, const std::uint32_t* ids, std::size_t n, RayRange range,
                     Hit* hits, RayStats& stats, StreamScratch& s) {
  Stream<AnyHit, false>(tree, rays, range, stats, s).run(ids, n, hits);
}

#if defined(KDSPACE_AVX2_DISPATCH)
template <bool AnyHit>
__attribute__((target("avx2"), flatten)) void stream_wide(const BoxTree& tree, const Ray* rays,
                                                          const std::uint32_t* ids, std::size_t n, RayRange range,
                                                          Hit* hits, RayStats& stats, StreamScratch& s) {
  Stream<AnyHit, true>(tree, rays, range, stats, s).run(ids, n, hits);
}
#endif

}  // namespace

template <bool AnyHit>
void trace_stream(const BoxTree& tree, const Ray* rays, const std::uint32_t* ids, std::size_t n, RayRange range,
                  Hit* hits, RayStats& stats, StreamScratch& scratch) {
  if (scratch.leaf_rays.size() < n + 8) scratch.leaf_rays.resize(n + 8);
#if defined(KDSPACE_AVX2_DISPATCH)
  if (avx2_dispatch()) return stream_wide<AnyHit>(tree, rays, ids, n, range, hits, stats, scratch);
#endif
  stream_baseline<AnyHit>(tree, rays, ids, n, range, hits, stats, scratch);
}

template void trace_stream<false>(const BoxTree&, const Ray*, const std::uint32_t*, std::size_t, RayRange, Hit*,
                                  RayStats&, StreamScratch&);
template void trace_stream<true>(const BoxTree&, const Ray*, const std::uint32_t*, std::size_t, RayRange, Hit*,
                                 RayStats&, StreamScratch&);

}  // namespace kdspace::detail
