// Four rays through the BoxTree at once: the packet traversal of Wald, Slusallek, Benthin & Wagner
// (2001, "Interactive rendering with coherent ray tracing"), for the batches' coherent rays.
//
// Four rays whose direction components have the same signs (the neighbouring pixels of a camera)
// agree at every node on which child is near and which far, so they can walk the tree together:
// one node load and one decision for four rays, each ray with its own interval [t_entry, t_exit] in
// one SSE lane. A child is entered when some ray needs it, with the rays that do; a ray that needs
// neither child of a node, or whose best hit lies before a pending cell, drops out of that subtree.
// So each ray visits exactly the cells, in the same order, that its own single traversal
// (traverse.cpp) would, with the same widened comparisons, and tests the same boxes with the same
// filter and the same double test: the hits and the statistics are those of four single traces.
// Rays that do not fit (different signs, a zero component, parameters beyond the float range) are
// traced one by one.
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

/// Per lane: the ray's parameter widened down / up (detail::widen_down, widen_up) in SSE.
inline __m128 widen_down4(__m128 t) {
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  return _mm_sub_ps(
      t, _mm_add_ps(_mm_mul_ps(_mm_and_ps(t, magnitude), _mm_set1_ps(detail::Widening<float>::relative)),
                    _mm_set1_ps(detail::Widening<float>::absolute)));
}
inline __m128 widen_up4(__m128 t) {
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  return _mm_add_ps(
      t, _mm_add_ps(_mm_mul_ps(_mm_and_ps(t, magnitude), _mm_set1_ps(detail::Widening<float>::relative)),
                    _mm_set1_ps(detail::Widening<float>::absolute)));
}

/// A pending far child: its node and the four rays' intervals in it, with the rays that enter it.
struct PacketEntry {
  __m128 t_entry, t_exit;
  std::uint32_t node;
  unsigned active;  ///< bit l: ray l enters the cell
};

}  // namespace

bool BoxTree::packet_fits(const Ray* rays) const {
  if (!float_range_ || boxes_.empty()) return false;
  // The signs first, of all four rays: incoherent rays (four random rays share their signs one
  // time in 512) are turned away before the costlier range checks.
  for (int l = 0; l < 4; ++l)
    for (int a = 0; a < 3; ++a) {
      const float d = rays[l].direction[a];
      if (d == 0 || std::signbit(d) != std::signbit(rays[0].direction[a])) return false;
    }
  for (int l = 0; l < 4; ++l)
    if (!detail::fits_float_traversal(rays[l], float_trace_limit)) return false;
  return true;
}

namespace {

/// BoxTree::trace_packet with leaf tests of four boxes, or of eight when Wide (AVX2).
template <bool AnyHit, bool Wide>
void trace_packet_of(const BoxTree& tree, const Ray* rays, RayRange range, Hit* hits, RayStats& stats) {
  constexpr std::uint32_t step_blocks = Wide ? 2 : 1;  // leaf blocks tested together
  const Box3f& bounds = tree.bounds();
  std::array<detail::TraversalRay<float>, 4> lane_ray{
      detail::TraversalRay<float>(rays[0]), detail::TraversalRay<float>(rays[1]),
      detail::TraversalRay<float>(rays[2]), detail::TraversalRay<float>(rays[3])};
  const detail::TraversalRay<float>& r0 = lane_ray[0];  // its signs are the packet's
  __m128 origin[3], inverse[3];
  for (int a = 0; a < 3; ++a) {
    origin[a] = _mm_setr_ps(lane_ray[0].origin[a], lane_ray[1].origin[a], lane_ray[2].origin[a],
                            lane_ray[3].origin[a]);
    inverse[a] = _mm_setr_ps(lane_ray[0].inverse[a], lane_ray[1].inverse[a], lane_ray[2].inverse[a],
                             lane_ray[3].inverse[a]);
  }
  stats.rays += 4;
  for (int l = 0; l < 4; ++l) hits[l] = Hit{};

  // The scene's bounds, as clip_widened does it for one ray.
  __m128 t_entry = _mm_set1_ps(range.t_min), t_exit = _mm_set1_ps(range.t_max);
  for (int a = 0; a < 3; ++a) {
    __m128 t0 = _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(bounds.lo[a]), origin[a]), inverse[a]);
    __m128 t1 = _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(bounds.hi[a]), origin[a]), inverse[a]);
    if (r0.negative[a]) std::swap(t0, t1);
    t_entry = _mm_max_ps(t_entry, widen_down4(t0));
    t_exit = _mm_min_ps(t_exit, widen_up4(t1));
  }
  unsigned active = static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(t_entry, t_exit)));
  if (active == 0) return;

  std::array<double, 4> best_t;
  std::array<std::int32_t, 4> best_box;
  alignas(16) std::array<float, 4> best_bound;  // best_t rounded up to float
  best_t.fill(range.t_max);
  best_box.fill(Hit::none);
  best_bound.fill(range.t_max);
  unsigned done = 0;  // any hit: rays that have found one
  std::array<std::optional<PreparedRay>, 4> exact;
  const std::uint32_t negative_axes = r0.negative[0] | r0.negative[1] << 1 | r0.negative[2] << 2;

  std::array<PacketEntry, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = PacketEntry{t_entry, t_exit, 0, active};
  while (top > 0) {
    const PacketEntry entry = stack[--top];
    // Rays whose best hit lies before the cell, or that are done, skip it.
    active = entry.active & ~done &
             static_cast<unsigned>(
                 _mm_movemask_ps(_mm_cmple_ps(widen_down4(entry.t_entry), _mm_load_ps(best_bound.data()))));
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
        for (unsigned l = 0; l < 4; ++l) {
          if (!(active >> l & 1u)) continue;
          const LeafBlock* blocks = tree.leaf_blocks().data() + node.first() / 4;
          const std::uint32_t* ids = tree.references().data() + node.first();
          for (std::uint32_t first = 0; first < count;
               first += 4 * step_blocks, blocks += step_blocks, ids += 4 * step_blocks) {
            // No mask on the lanes past count: they repeat the last box (as in traverse.cpp).
            unsigned lanes = detail::leaf_step_candidates<float, Wide>(blocks, count - first, lane_ray[l],
                                                                       range.t_min, best_bound[l]);
            while (lanes != 0) {
              const auto lane = static_cast<unsigned>(__builtin_ctz(lanes));
              lanes &= lanes - 1;
              double t_near = range.t_min, t_far = best_t[l];
              if (!exact[l]) exact[l].emplace(rays[l]);
              if (!clip_to_box(detail::box_in_lane(blocks[lane / 4], lane % 4), *exact[l], t_near, t_far))
                continue;
              const auto box = static_cast<std::int32_t>(ids[lane]);
              if constexpr (AnyHit) {
                best_t[l] = t_near;
                best_box[l] = box;
                done |= 1u << l;
                break;
              } else {
                if (t_near < best_t[l] || best_box[l] == Hit::none || box < best_box[l]) {
                  best_t[l] = t_near;
                  best_box[l] = box;
                  best_bound[l] = detail::round_up<float>(t_near);
                }
              }
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
      const __m128 t_split = _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(node.split()), origin[axis]), inverse[axis]);
      const unsigned far_only =
          static_cast<unsigned>(_mm_movemask_ps(_mm_cmplt_ps(t_split, widen_down4(t_entry))));
      const unsigned near_only =
          static_cast<unsigned>(_mm_movemask_ps(_mm_cmpgt_ps(t_split, widen_up4(t_exit))));
      const unsigned need_near = active & ~far_only, need_far = active & ~near_only;
      if (need_far == 0) {
        index = near;
        t_exit = _mm_min_ps(t_exit, t_split);  // a near-only ray: its exit lies before the plane anyway
        active = need_near;
      } else if (need_near == 0) {
        index = far;
        t_entry = _mm_max_ps(t_entry, t_split);  // a far-only ray: its entry lies past the plane anyway
        active = need_far;
      } else {
        stack[top++] = PacketEntry{_mm_max_ps(t_entry, t_split), t_exit, far, need_far};
        index = near;
        t_exit = _mm_min_ps(t_exit, t_split);
        active = need_near;
      }
    }
  }
  for (int l = 0; l < 4; ++l)
    if (best_box[l] != Hit::none) hits[l] = Hit{best_box[l], detail::to_float_t(best_t[l])};
}

#if defined(KDSPACE_AVX2_DISPATCH)
// Compiled for AVX2: `flatten` inlines the packet traversal here, and the eight-box filter into it.
template <bool AnyHit>
__attribute__((target("avx2"), flatten)) void trace_packet_wide(const BoxTree& tree, const Ray* rays,
                                                                RayRange range, Hit* hits, RayStats& stats) {
  trace_packet_of<AnyHit, true>(tree, rays, range, hits, stats);
}
#endif

}  // namespace

template <bool AnyHit>
void BoxTree::trace_packet(const Ray* rays, RayRange range, Hit* hits, RayStats& stats) const {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (detail::avx2_dispatch()) return trace_packet_wide<AnyHit>(*this, rays, range, hits, stats);
#endif
  trace_packet_of<AnyHit, false>(*this, rays, range, hits, stats);
}

#else  // no SSE2: no packets, every ray alone

bool BoxTree::packet_fits(const Ray* /*rays*/) const {
  return false;
}

template <bool AnyHit>
void BoxTree::trace_packet(const Ray* /*rays*/, RayRange /*range*/, Hit* /*hits*/,
                           RayStats& /*stats*/) const {}

#endif

template void BoxTree::trace_packet<false>(const Ray*, RayRange, Hit*, RayStats&) const;
template void BoxTree::trace_packet<true>(const Ray*, RayRange, Hit*, RayStats&) const;

}  // namespace kdspace
