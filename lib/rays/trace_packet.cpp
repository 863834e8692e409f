// Eight (AVX2) or four (SSE) rays through the BoxTree at once: the packet traversal of Wald,
// Slusallek, Benthin & Wagner (2001, "Interactive rendering with coherent ray tracing"), for the
// batches' coherent rays.
//
// Rays whose direction components have the same signs (the neighbouring pixels of a camera) agree
// at every node on which child is near and which far, so they can walk the tree together: one node
// load and one decision for all of them, each ray with its own interval [t_entry, t_exit] in one
// lane of a register. A child is entered when some ray needs it, with the rays that do; a ray that
// needs neither child of a node, or whose best hit lies before a pending cell, drops out of that
// subtree. So each ray visits exactly the cells, in the same order, that its own single traversal
// (traverse.cpp) would, with the same widened comparisons, and meets each leaf's boxes in the same
// order, through the same float filter (ray by ray eight or four boxes at a time, or box by box for
// all the rays at once) and the same double test: the hits and the statistics are those of single
// traces. Rays that do not fit (different signs, a zero component, parameters beyond the float
// range: detail::packet_key) are traced one by one.
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/detail/slab.hpp"
#include "traversal_ray.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace {

#if defined(__SSE2__)

namespace {

using detail::clip_to_box;
using detail::PreparedRay;

/// The operations of the packet traversal on one register of Width floats, one ray a lane: SSE for
/// four rays, AVX (compiled for AVX2 and used only where avx2_dispatch() says so) for eight.
template <int Width>
struct Lanes;

template <>
struct Lanes<4> {
  using V = __m128;
  static V set1(float x) { return _mm_set1_ps(x); }
  static V load(const float* p) { return _mm_load_ps(p); }
  static V add(V a, V b) { return _mm_add_ps(a, b); }
  static V sub(V a, V b) { return _mm_sub_ps(a, b); }
  static V mul(V a, V b) { return _mm_mul_ps(a, b); }
  static V div(V a, V b) { return _mm_div_ps(a, b); }
  static V min(V a, V b) { return _mm_min_ps(a, b); }
  static V max(V a, V b) { return _mm_max_ps(a, b); }
  /// Per lane: the ray's parameter widened down / up (detail::widen_down, widen_up).
  static V widen_down(V t) { return _mm_sub_ps(t, widening(t)); }
  static V widen_up(V t) { return _mm_add_ps(t, widening(t)); }
  static V widening(V t) {
    const V magnitude = _mm_and_ps(t, _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff)));
    return _mm_add_ps(_mm_mul_ps(magnitude, _mm_set1_ps(detail::Widening<float>::relative)),
                      _mm_set1_ps(detail::Widening<float>::absolute));
  }
  static unsigned less(V a, V b) { return static_cast<unsigned>(_mm_movemask_ps(_mm_cmplt_ps(a, b))); }
  static unsigned less_equal(V a, V b) { return static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(a, b))); }
};

#if defined(KDSPACE_AVX2_DISPATCH)
// GCC warns that a call returning __m256 without AVX enabled changes the calling convention: the
// packet traversal below calls these functions, but only where trace_packet_wide, compiled for
// AVX2, has inlined it (`flatten`), so no such call is made across that boundary. (The warning comes
// where templates are instantiated, at the end of the file, so it is off for the rest of the file.)
#pragma GCC diagnostic ignored "-Wpsabi"
#define KDSPACE_AVX2_TARGET __attribute__((target("avx2")))
template <>
struct Lanes<8> {
  using V = __m256;
  KDSPACE_AVX2_TARGET static V set1(float x) { return _mm256_set1_ps(x); }
  KDSPACE_AVX2_TARGET static V load(const float* p) { return _mm256_load_ps(p); }
  KDSPACE_AVX2_TARGET static V add(V a, V b) { return _mm256_add_ps(a, b); }
  KDSPACE_AVX2_TARGET static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
  KDSPACE_AVX2_TARGET static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
  KDSPACE_AVX2_TARGET static V div(V a, V b) { return _mm256_div_ps(a, b); }
  KDSPACE_AVX2_TARGET static V min(V a, V b) { return _mm256_min_ps(a, b); }
  KDSPACE_AVX2_TARGET static V max(V a, V b) { return _mm256_max_ps(a, b); }
  KDSPACE_AVX2_TARGET static V widen_down(V t) { return _mm256_sub_ps(t, widening(t)); }
  KDSPACE_AVX2_TARGET static V widen_up(V t) { return _mm256_add_ps(t, widening(t)); }
  KDSPACE_AVX2_TARGET static V widening(V t) {
    const V magnitude = _mm256_and_ps(t, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff)));
    return _mm256_add_ps(_mm256_mul_ps(magnitude, _mm256_set1_ps(detail::Widening<float>::relative)),
                         _mm256_set1_ps(detail::Widening<float>::absolute));
  }
  KDSPACE_AVX2_TARGET static unsigned less(V a, V b) {
    return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LT_OQ)));
  }
  KDSPACE_AVX2_TARGET static unsigned less_equal(V a, V b) {
    return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LE_OQ)));
  }
};
#undef KDSPACE_AVX2_TARGET
#endif

/// A pending far child: its node and the rays' intervals in it, with the rays that enter it.
template <class L>
struct PacketEntry {
  typename L::V t_entry, t_exit;
  std::uint32_t node;
  unsigned active;  ///< bit l: ray l enters the cell
};

}  // namespace

namespace {

/// BoxTree::trace_packet for Width rays (Lanes<Width>), with leaf tests of four boxes, or of eight
/// when WideLeaves (AVX2).
template <int Width, bool AnyHit, bool WideLeaves>
void trace_packet_of(const BoxTree& tree, const Ray* rays, RayRange range, Hit* hits, RayStats& stats) {
  using L = Lanes<Width>;
  using V = typename L::V;
  constexpr std::uint32_t step_blocks = WideLeaves ? 2 : 1;  // leaf blocks tested together
  const Box3f& bounds = tree.bounds();
  alignas(32) float lane_origin[3][Width], lane_direction[3][Width];
  for (int l = 0; l < Width; ++l)
    for (int a = 0; a < 3; ++a) {
      lane_origin[a][l] = rays[l].origin[a];
      lane_direction[a][l] = rays[l].direction[a];
    }
  // The reciprocals as TraversalRay computes them (a division is correctly rounded, lane by lane).
  V origin[3], inverse[3];
  for (int a = 0; a < 3; ++a) {
    origin[a] = L::load(lane_origin[a]);
    inverse[a] = L::div(L::set1(1.0f), L::load(lane_direction[a]));
  }
  // Each ray alone, for its leaf tests: made at its first leaf box (many camera rays reach none).
  std::array<detail::TraversalRay<float>, Width> lane_ray;
  unsigned lane_ray_made = 0;  // bit l: lane_ray[l] holds ray l
  std::uint32_t negative[3];   // the packet's signs (those of every ray in it)
  for (int a = 0; a < 3; ++a) negative[a] = std::signbit(rays[0].direction[a]) ? 1u : 0u;
  stats.rays += Width;
  for (int l = 0; l < Width; ++l) hits[l] = Hit{};

  // The scene's bounds, as clip_widened does it for one ray.
  V t_entry = L::set1(range.t_min), t_exit = L::set1(range.t_max);
  for (int a = 0; a < 3; ++a) {
    V t0 = L::mul(L::sub(L::set1(bounds.lo[a]), origin[a]), inverse[a]);
    V t1 = L::mul(L::sub(L::set1(bounds.hi[a]), origin[a]), inverse[a]);
    if (negative[a]) std::swap(t0, t1);
    t_entry = L::max(t_entry, L::widen_down(t0));
    t_exit = L::min(t_exit, L::widen_up(t1));
  }
  unsigned active = L::less_equal(t_entry, t_exit);
  if (active == 0) return;

  std::array<double, Width> best_t;
  std::array<std::int32_t, Width> best_box;
  alignas(32) std::array<float, Width> best_bound;  // best_t rounded up to float
  best_t.fill(range.t_max);
  best_box.fill(Hit::none);
  best_bound.fill(range.t_max);
  unsigned done = 0;  // any hit: rays that have found one
  std::array<std::optional<PreparedRay>, Width> exact;
  const std::uint32_t negative_axes = negative[0] | negative[1] << 1 | negative[2] << 2;

  std::array<PacketEntry<L>, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = PacketEntry<L>{t_entry, t_exit, 0, active};
  while (top > 0) {
    const PacketEntry<L> entry = stack[--top];
    // Rays whose best hit lies before the cell, or that are done, skip it.
    active = entry.active & ~done & L::less_equal(L::widen_down(entry.t_entry), L::load(best_bound.data()));
    if (active == 0) continue;
    std::uint32_t index = entry.node;
    t_entry = entry.t_entry;
    t_exit = entry.t_exit;
    for (;;) {
      const unsigned count_active = static_cast<unsigned>(__builtin_popcount(active));
      stats.nodes_visited += count_active;
      const BoxNode node = tree.nodes()[index];
      if (node.is_leaf()) {
        const std::uint32_t count = node.count();
        stats.boxes_tested += static_cast<std::uint64_t>(count) * count_active;
        const LeafBlock* const leaf_blocks = tree.leaf_blocks().data() + node.first() / 4;
        const std::uint32_t* const leaf_ids = tree.references().data() + node.first();
        // The double test of box `id` (lane `lane` of `block`) for ray l, and what it finds.
        const auto test_exactly = [&](unsigned l, const LeafBlock& block, unsigned lane, std::uint32_t id) {
          double t_near = range.t_min, t_far = best_t[l];
          if (!exact[l]) exact[l].emplace(rays[l]);
          if (!clip_to_box(detail::box_in_lane(block, lane), *exact[l], t_near, t_far)) return;
          const auto box = static_cast<std::int32_t>(id);
          if constexpr (AnyHit) {
            best_t[l] = t_near;
            best_box[l] = box;
            done |= 1u << l;
          } else if (t_near < best_t[l] || best_box[l] == Hit::none || box < best_box[l]) {
            best_t[l] = t_near;
            best_box[l] = box;
            best_bound[l] = detail::round_up<float>(t_near);
          }
        };
        // Box by box, all the rays at once, where that takes fewer filter steps than ray by ray
        // (a few boxes, many rays; a box-by-box step costs about two thirds of a ray-by-ray one:
        // the fewest instructions for camera rays through ChineseDragon's triangle boxes, callgrind,
        // against ratios 1 and 2). Each ray still meets the leaf's boxes in their order, through the
        // same float filter as alone (the same operations lane by lane, against a best hit as recent
        // or more), and the same double test.
        const std::uint32_t steps_ray_by_ray =
            count_active * ((count + 4 * step_blocks - 1) / (4 * step_blocks));
        if (2 * count < 3 * steps_ray_by_ray) {
          const V t_low = L::set1(range.t_min);
          unsigned rays_left = active;
          for (std::uint32_t j = 0; j < count && rays_left != 0; ++j) {
            const LeafBlock& block = leaf_blocks[j / 4];
            const unsigned lane = j % 4;
            V t_near = t_low, t_far = L::load(best_bound.data());
            for (int a = 0; a < 3; ++a) {
              const auto enter = static_cast<unsigned>(a) + 3 * negative[a],
                         leave = static_cast<unsigned>(a) + 3 - 3 * negative[a];
              const V t0 = L::mul(L::sub(L::set1(block.plane[enter][lane]), origin[a]), inverse[a]);
              const V t1 = L::mul(L::sub(L::set1(block.plane[leave][lane]), origin[a]), inverse[a]);
              t_near = L::max(t0, t_near);  // as block_candidates: the second operand when either is NaN
              t_far = L::min(t1, t_far);
            }
            for (unsigned lanes = rays_left & L::less_equal(L::widen_down(t_near), L::widen_up(t_far));
                 lanes != 0; lanes &= lanes - 1)
              test_exactly(static_cast<unsigned>(__builtin_ctz(lanes)), block, lane, leaf_ids[j]);
            if constexpr (AnyHit) rays_left &= ~done;
          }
          break;
        }
        for (unsigned rest = active; rest != 0; rest &= rest - 1) {
          const auto l = static_cast<unsigned>(__builtin_ctz(rest));
          if (count > 0 && !(lane_ray_made >> l & 1u)) {
            lane_ray[l] = detail::TraversalRay<float>(rays[l]);
            lane_ray_made |= 1u << l;
          }
          const LeafBlock* blocks = leaf_blocks;
          const std::uint32_t* ids = leaf_ids;
          for (std::uint32_t first = 0; first < count;
               first += 4 * step_blocks, blocks += step_blocks, ids += 4 * step_blocks) {
            // No mask on the lanes past count: they repeat the last box (as in traverse.cpp).
            for (unsigned lanes = detail::leaf_step_candidates<float, WideLeaves>(
                     blocks, count - first, lane_ray[l], range.t_min, best_bound[l]);
                 lanes != 0; lanes &= lanes - 1) {
              const auto lane = static_cast<unsigned>(__builtin_ctz(lanes));
              test_exactly(l, blocks[lane / 4], lane % 4, ids[lane]);
              if (AnyHit && (done >> l & 1u)) break;
            }
            if (AnyHit && (done >> l & 1u)) break;
          }
        }
        break;
      }
      // As in the single traversal, per lane: the near child when the ray reaches the plane in the
      // cell or before it leaves, the far one when it is past the plane when it leaves, both over
      // the split intervals.
      const int axis = node.axis();
      std::uint32_t near = index + 1, far = node.right_child();
      if ((negative_axes >> axis) & 1u) std::swap(near, far);
      const V t_split = L::mul(L::sub(L::set1(node.split()), origin[axis]), inverse[axis]);
      const unsigned far_only = L::less(t_split, L::widen_down(t_entry));
      const unsigned near_only = L::less(L::widen_up(t_exit), t_split);
      const unsigned need_near = active & ~far_only, need_far = active & ~near_only;
      if (need_far == 0) {
        index = near;
        t_exit = L::min(t_exit, t_split);  // a near-only ray: its exit lies before the plane anyway
        active = need_near;
      } else if (need_near == 0) {
        index = far;
        t_entry = L::max(t_entry, t_split);  // a far-only ray: its entry lies past the plane anyway
        active = need_far;
      } else {
        stack[top++] = PacketEntry<L>{L::max(t_entry, t_split), t_exit, far, need_far};
        index = near;
        t_exit = L::min(t_exit, t_split);
        active = need_near;
      }
    }
  }
  for (int l = 0; l < Width; ++l)
    if (best_box[l] != Hit::none) hits[l] = Hit{best_box[l], detail::to_float_t(best_t[l])};
}

#if defined(KDSPACE_AVX2_DISPATCH)
// Compiled for AVX2: `flatten` inlines the packet traversal here, and the eight-box filter into it.
template <int Width, bool AnyHit>
__attribute__((target("avx2"), flatten)) void trace_packet_wide(const BoxTree& tree, const Ray* rays,
                                                                RayRange range, Hit* hits, RayStats& stats) {
  trace_packet_of<Width, AnyHit, true>(tree, rays, range, hits, stats);
}
#endif

}  // namespace

template <bool AnyHit>
void BoxTree::trace_packet(const Ray* rays, int width, RayRange range, Hit* hits, RayStats& stats) const {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (detail::avx2_dispatch()) {
    if (width == 8) return trace_packet_wide<8, AnyHit>(*this, rays, range, hits, stats);
    return trace_packet_wide<4, AnyHit>(*this, rays, range, hits, stats);
  }
#endif
  trace_packet_of<4, AnyHit, false>(*this, rays, range, hits, stats);
}

#else  // no SSE2: no packets, every ray alone

template <bool AnyHit>
void BoxTree::trace_packet(const Ray* /*rays*/, int /*width*/, RayRange /*range*/, Hit* /*hits*/,
                           RayStats& /*stats*/) const {}

#endif

template void BoxTree::trace_packet<false>(const Ray*, int, RayRange, Hit*, RayStats&) const;
template void BoxTree::trace_packet<true>(const Ray*, int, RayRange, Hit*, RayStats&) const;

}  // namespace kdspace
