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
#include "walk.hpp"

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
  static unsigned may_hit_from_nonnegative(V t_near, V t_far) {
    return detail::may_hit_from_nonnegative4(t_near, t_far);
  }
};

#if defined(KDSPACE_AVX2_DISPATCH)
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
  KDSPACE_AVX2_TARGET static unsigned may_hit_from_nonnegative(V t_near, V t_far) {
    return detail::may_hit_from_nonnegative8(t_near, t_far);
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

#define KDSPACE_PACKET_TRAVERSAL trace_packet_of
#define KDSPACE_PACKET_TARGET
#include "trace_packet_traversal.inc"
#undef KDSPACE_PACKET_TRAVERSAL
#undef KDSPACE_PACKET_TARGET

#if defined(KDSPACE_AVX2_DISPATCH)
#define KDSPACE_PACKET_TRAVERSAL trace_packet_of_avx2
#define KDSPACE_PACKET_TARGET __attribute__((target("avx2")))
#include "trace_packet_traversal.inc"
#undef KDSPACE_PACKET_TRAVERSAL
#undef KDSPACE_PACKET_TARGET

// Compiled for AVX2: `flatten` inlines the packet traversal here, and the eight-box filter into it.
template <int Width, bool AnyHit>
__attribute__((target("avx2"), flatten)) void trace_packet_wide(const BoxTree& tree, const Ray* rays,
                                                                RayRange range, Hit* hits, RayStats& stats) {
  trace_packet_of_avx2<Width, AnyHit, true>(tree, rays, range, hits, stats);
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
