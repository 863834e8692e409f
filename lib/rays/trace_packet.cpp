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
// Rays that do not fit (different signs, a zero component, parameters beyond the float range:
// detail::packet_key) are traced one by one.
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
  static V min(V a, V b) { return _mm_min_ps(a, b); }
  static V max(V a, V b) { return _mm_max_ps(a, b); }
  static V abs(V a) { return _mm_and_ps(a, _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff))); }
  static unsigned less(V a, V b) { return static_cast<unsigned>(_mm_movemask_ps(_mm_cmplt_ps(a, b))); }
  static unsigned less_equal(V a, V b) { return static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(a, b))); }
};

#if defined(KDSPACE_AVX2_DISPATCH)
// GCC warns that passing __m256 by value without AVX changes the calling convention; the functions
// of this file that take or return it are internal and inlined into the AVX2 compilation
// (trace_packet_wide), never called across the boundary. (The warning comes where templates are
// instantiated, at the end of the file, so it is off for the rest of the file.)
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
  KDSPACE_AVX2_TARGET static V min(V a, V b) { return _mm256_min_ps(a, b); }
  KDSPACE_AVX2_TARGET static V max(V a, V b) { return _mm256_max_ps(a, b); }
  KDSPACE_AVX2_TARGET static V abs(V a) {
    return _mm256_and_ps(a, _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff)));
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

/// Per lane: the ray's parameter widened down / up (detail::widen_down, widen_up).
template <class L>
inline typename L::V widen_down(typename L::V t) {
  return L::sub(t, L::add(L::mul(L::abs(t), L::set1(detail::Widening<float>::relative)),
                          L::set1(detail::Widening<float>::absolute)));
}
template <class L>
inline typename L::V widen_up(typename L::V t) {
  return L::add(t, L::add(L::mul(L::abs(t), L::set1(detail::Widening<float>::relative)),
                          L::set1(detail::Widening<float>::absolute)));
}

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
  std::array<std::optional<detail::TraversalRay<float>>, Width> lane_ray;
  alignas(32) float lane_origin[3][Width], lane_inverse[3][Width];
  for (int l = 0; l < Width; ++l) {
    lane_ray[l].emplace(rays[l]);
    for (int a = 0; a < 3; ++a) {
      lane_origin[a][l] = lane_ray[l]->origin[a];
      lane_inverse[a][l] = lane_ray[l]->inverse[a];
    }
  }
  const detail::TraversalRay<float>& r0 = *lane_ray[0];  // its signs are the packet's
  V origin[3], inverse[3];
  for (int a = 0; a < 3; ++a) {
    origin[a] = L::load(lane_origin[a]);
    inverse[a] = L::load(lane_inverse[a]);
  }
  stats.rays += Width;
  for (int l = 0; l < Width; ++l) hits[l] = Hit{};

  // The scene's bounds, as clip_widened does it for one ray.
  V t_entry = L::set1(range.t_min), t_exit = L::set1(range.t_max);
  for (int a = 0; a < 3; ++a) {
    V t0 = L::mul(L::sub(L::set1(bounds.lo[a]), origin[a]), inverse[a]);
    V t1 = L::mul(L::sub(L::set1(bounds.hi[a]), origin[a]), inverse[a]);
    if (r0.negative[a]) std::swap(t0, t1);
    t_entry = L::max(t_entry, widen_down<L>(t0));
    t_exit = L::min(t_exit, widen_up<L>(t1));
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
  const std::uint32_t negative_axes = r0.negative[0] | r0.negative[1] << 1 | r0.negative[2] << 2;

  std::array<PacketEntry<L>, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = PacketEntry<L>{t_entry, t_exit, 0, active};
  while (top > 0) {
    const PacketEntry<L> entry = stack[--top];
    // Rays whose best hit lies before the cell, or that are done, skip it.
    active = entry.active & ~done & L::less_equal(widen_down<L>(entry.t_entry), L::load(best_bound.data()));
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
        for (unsigned rest = active; rest != 0; rest &= rest - 1) {
          const auto l = static_cast<unsigned>(__builtin_ctz(rest));
          const LeafBlock* blocks = tree.leaf_blocks().data() + node.first() / 4;
          const std::uint32_t* ids = tree.references().data() + node.first();
          for (std::uint32_t first = 0; first < count;
               first += 4 * step_blocks, blocks += step_blocks, ids += 4 * step_blocks) {
            // No mask on the lanes past count: they repeat the last box (as in traverse.cpp).
            unsigned lanes = detail::leaf_step_candidates<float, WideLeaves>(
                blocks, count - first, *lane_ray[l], range.t_min, best_bound[l]);
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
      const V t_split = L::mul(L::sub(L::set1(node.split()), origin[axis]), inverse[axis]);
      const unsigned far_only = L::less(t_split, widen_down<L>(t_entry));
      const unsigned near_only = L::less(widen_up<L>(t_exit), t_split);
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
