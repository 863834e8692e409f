// A ray prepared for the BoxTree traversal in float or in double, the widening that keeps the
// traversal's decisions conservative, and the box filter of the float traversal (four boxes at a
// time with SSE2, eight with AVX2).
//
// Why float is safe (TraversalRay<float>): for a scene and an origin within +-2^62 and direction
// components 0 or of magnitude 2^-64 .. 2^64, a ray parameter t = (plane - origin) * (1 / direction)
// is at most 2^127, so nothing overflows. Computed in float it carries three roundings (the
// difference, the reciprocal, the product), each of relative size at most 2^-24, and an absolute
// error below 2^-149 where the product underflows; the double value the hit rule uses differs from
// the exact one by a few 2^-53. So |t_float - t_double| <= 2^-22 |t| + 2^-149, and widening every
// float parameter by 2^-20 |t| + 2^-126 (widen_down / widen_up) keeps every cell interval and every
// box interval of the float traversal around the double one: the float traversal may visit more and
// let more boxes through to the double test, never fewer.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/ray.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include "kdspace/detail/avx2_dispatch.hpp"
#if defined(KDSPACE_AVX2_DISPATCH)
#include <immintrin.h>
#endif

namespace kdspace::detail {

/// How far the traversal in Real widens a ray parameter: relative and absolute parts.
template <class Real>
struct Widening;
template <>
struct Widening<float> {
  static constexpr float relative = 0x1p-20f;
  static constexpr float absolute = 0x1p-126f;
};
template <>
struct Widening<double> {
  // Far above double rounding: the double traversal's own parameters are computed as the hit rule's.
  static constexpr double relative = 0x1p-40;
  static constexpr double absolute = 0x1p-1022;
};

template <class Real>
inline Real widen_down(Real t) {
  return t - (std::abs(t) * Widening<Real>::relative + Widening<Real>::absolute);
}
template <class Real>
inline Real widen_up(Real t) {
  return t + (std::abs(t) * Widening<Real>::relative + Widening<Real>::absolute);
}

/// The float filter's test of a box interval [t_near, t_far] whose t_near is known to be >= 0 (it
/// starts at a t_min >= 0), in two operations instead of two widenings: t_near shrunk by 2^-18 of
/// itself and 2^-124 must not exceed t_far. It accepts every interval that widen_down(t_near) <=
/// widen_up(t_far) accepts (and a few more; the double test decides): for t_far >= 0 that test
/// implies t_near <= t_far (1 + 2^-19 + 2^-22) + 2^-124, float roundings of both sides included, and
/// the shrink and its two roundings take away more; for t_far < 0 it implies t_near - t_far < 2^-124.
/// Tested against the widenings on random and edge values (tests/test_rays.cpp).
struct FromNonNegative {
  static constexpr float shrink = 1 - 0x1p-18f;
  static constexpr float slack = 0x1p-124f;
};
inline bool may_hit_from_nonnegative(float t_near, float t_far) {
  return t_near * FromNonNegative::shrink - FromNonNegative::slack <= t_far;
}
#if defined(__SSE2__)
/// may_hit_from_nonnegative on four lanes: bit l for lane l.
inline unsigned may_hit_from_nonnegative4(__m128 t_near, __m128 t_far) {
  const __m128 shrunk = _mm_sub_ps(_mm_mul_ps(t_near, _mm_set1_ps(FromNonNegative::shrink)),
                                   _mm_set1_ps(FromNonNegative::slack));
  return static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(shrunk, t_far)));
}
#endif
#if defined(KDSPACE_AVX2_DISPATCH)
/// may_hit_from_nonnegative on eight lanes: bit l for lane l.
__attribute__((target("avx2"))) inline unsigned may_hit_from_nonnegative8(__m256 t_near, __m256 t_far) {
  const __m256 shrunk = _mm256_sub_ps(_mm256_mul_ps(t_near, _mm256_set1_ps(FromNonNegative::shrink)),
                                      _mm256_set1_ps(FromNonNegative::slack));
  return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(shrunk, t_far, _CMP_LE_OQ)));
}
#endif

/// `take ? a : b` by masking their bits: compiled without a branch, where GCC made one of a ternary
/// or of std::min on doubles (keep_if_closer, to_float_t: a branch on whether a ray hit mispredicts).
template <class T>
inline T select_bits(bool take, T a, T b) {
  static_assert(std::is_trivially_copyable_v<T> && (sizeof(T) == 4 || sizeof(T) == 8));
  using Bits = std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>;
  Bits x, y;
  std::memcpy(&x, &a, sizeof x);
  std::memcpy(&y, &b, sizeof y);
  const Bits mask = Bits{0} - static_cast<Bits>(take);
  const Bits chosen = (x & mask) | (y & ~mask);
  T out;
  std::memcpy(&out, &chosen, sizeof out);
  return out;
}

/// t rounded to float; a hit beyond the float range reports the largest finite float.
inline float to_float_t(double t) {
  constexpr double largest = std::numeric_limits<float>::max();
  return static_cast<float>(select_bits(t > largest, largest, t));
}

/// The smallest Real >= t (t a double); +-inf stay.
template <class Real>
inline Real round_up(double t) {
  if constexpr (std::is_same_v<Real, double>) {
    return t;
  } else {
    if (!(std::abs(t) <= std::numeric_limits<float>::max()))
      return t > 0 ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::max();
    // One float up where the conversion rounded down, without a branch on it (a hit's t rounds
    // either way as often): one more in the bits of an f >= +0 (+0 becomes the smallest
    // subnormal), one less in those of an f < 0 (a range that starts below 0: the branch on the
    // sign is taken the same way ray after ray). An f of -0 never rounded down: it comes from t = -0
    // or from a t just below it.
    const auto f = static_cast<float>(t);
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    const std::uint32_t rounded_down = static_cast<double>(f) < t ? 1u : 0u;
    if (f < 0)
      bits -= rounded_down;
    else
      bits += rounded_down;
    float up;
    std::memcpy(&up, &bits, sizeof up);
    return up;
  }
}

/// True when the ray can be traced in float through a scene within BoxTree's float range (see the
/// top of this file): origin within +-limit, direction components 0 or of magnitude 2^-64 .. 2^64.
inline bool fits_float_traversal(const Ray& ray, float limit) {
  for (int a = 0; a < 3; ++a) {
    const float d = std::abs(ray.direction[a]);
    if (!(std::abs(ray.origin[a]) <= limit)) return false;
    if (d != 0 && !(d >= 0x1p-64f && d <= 0x1p64f)) return false;
  }
  return true;
}

/// The bits of a float that is the power of two 2^e (-126 <= e <= 127).
constexpr std::uint32_t power_of_two_bits(int e) {
  return static_cast<std::uint32_t>(127 + e) << 23;
}

/// Which rays can go through the tree together in a packet (trace_packet.cpp): rays with equal keys
/// below 8. The key is the direction's sign bits (bit a: the ray runs towards -a), with bit 3 set
/// when the ray cannot join a packet: a zero direction component, or a ray fits_float_traversal
/// turns away (origin beyond +-2^62, direction component beyond 2^-64 .. 2^64). Integer operations
/// on the bits and no branch: a batch computes it for every ray, and for camera rays the checks
/// with branches cost a sixth of the packet traversal's instructions (callgrind).
inline std::uint32_t packet_key(const Ray& ray) {
  static_assert(sizeof(Ray) == 6 * sizeof(float), "Ray: origin and direction, three floats each");
  std::uint32_t bits[6];
  std::memcpy(bits, &ray, sizeof bits);
  constexpr std::uint32_t magnitude = 0x7fffffffu;
  std::uint32_t key = 0, misfit = 0;
  for (int a = 0; a < 3; ++a) {
    const std::uint32_t origin = bits[a] & magnitude, direction = bits[3 + a] & magnitude;
    key |= (bits[3 + a] >> 31) << a;
    // In the bits of non-negative floats, order is numeric order, and NaN lies above +inf.
    misfit |= static_cast<std::uint32_t>(origin > power_of_two_bits(62)) |
              static_cast<std::uint32_t>(direction < power_of_two_bits(-64)) |
              static_cast<std::uint32_t>(direction > power_of_two_bits(64));
  }
  return key | misfit << 3;
}

/// The ray in Real: origin, reciprocal direction, and per axis whether it runs towards -axis (sign
/// bit set, -0 included).
template <class Real>
struct TraversalRay {
  Real origin[3];
  Real inverse[3];            ///< 1 / direction: +-inf on an axis the ray is parallel to (+0 or -0)
  std::uint32_t negative[3];  ///< 1 when the direction's sign bit is set, else 0
#if defined(__SSE2__)
  __m128 origin4[3], inverse4[3];  ///< float only: the same, in every lane
#endif

  TraversalRay() = default;  ///< uninitialized: for arrays filled on demand (packets)
  explicit TraversalRay(const Ray& r) {
    for (int a = 0; a < 3; ++a) {
      origin[a] = static_cast<Real>(r.origin[a]);
      negative[a] = std::signbit(r.direction[a]) ? 1u : 0u;
      // A float direction, even +-0, has a reciprocal in Real (+-inf for +-0).
      inverse[a] = Real(1) / static_cast<Real>(r.direction[a]);
#if defined(__SSE2__)
      if constexpr (std::is_same_v<Real, float>) {
        origin4[a] = _mm_set1_ps(origin[a]);
        inverse4[a] = _mm_set1_ps(inverse[a]);
      }
#endif
    }
  }
};

/// The children of the inner node `index` (left: index + 1, right: `right`) in the order the ray
/// meets them, near first; `towards_negative` is 1 when the ray runs towards -axis of the node's
/// split. Bit arithmetic, not a branch: for incoherent rays the sign on the node's axis is
/// unpredictable, and as a branch it was the traversal's most mispredicted one (callgrind's branch
/// simulation: 4.4 of 22 mispredictions per random ray through a scanned mesh's triangle boxes).
inline void order_children(std::uint32_t index, std::uint32_t right, std::uint32_t towards_negative,
                           std::uint32_t& near, std::uint32_t& far) {
  const std::uint32_t left = index + 1, differ = (left ^ right) & (0u - towards_negative);
  near = left ^ differ;
  far = right ^ differ;
}

/// Narrows [t_lo, t_hi] to the part of the ray inside the closed box, widened (a superset of what
/// the double slab test finds); false when that part is empty.
template <class Real>
inline bool clip_widened(const Box3f& b, const TraversalRay<Real>& r, Real& t_lo, Real& t_hi) {
  for (int a = 0; a < 3; ++a) {
    const Real lo = b.lo[a], hi = b.hi[a];
    if (std::isinf(r.inverse[a])) {  // parallel: inside the slab or never (exact comparisons)
      if (r.origin[a] < lo || r.origin[a] > hi) return false;
      continue;
    }
    const Real t0 = (lo - r.origin[a]) * r.inverse[a], t1 = (hi - r.origin[a]) * r.inverse[a];
    // Entered at the smaller parameter, left at the larger (neither is NaN: the direction is not 0
    // on this axis). A min and a max, not a swap on the direction's sign: as a branch that was
    // mispredicted 1.5 times a random ray (callgrind's branch simulation).
    t_lo = std::max(t_lo, widen_down(std::min(t0, t1)));
    t_hi = std::min(t_hi, widen_up(std::max(t0, t1)));
  }
  return t_lo <= t_hi;
}

/// The box in `lane` of a leaf block.
inline Box3f box_in_lane(const LeafBlock& block, unsigned lane) {
  Box3f b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = block.plane[a][lane];
    b.hi[a] = block.plane[3 + a][lane];
  }
  return b;
}

/// Lanes of `block` whose box the ray may hit within [t_lo, t_hi]: bit l for lane l. A filter: it
/// lets through every box the double slab test accepts over that range (and a few more): the float
/// parameters widened (widen_down, widen_up), or from t_lo >= 0 compared by may_hit_from_nonnegative.
/// In double it lets all four through and the double test decides alone.
template <class Real>
inline unsigned block_candidates(const LeafBlock& block, const TraversalRay<Real>& r, Real t_lo, Real t_hi);

template <>
inline unsigned block_candidates<double>(const LeafBlock& /*block*/, const TraversalRay<double>& /*r*/,
                                         double /*t_lo*/, double /*t_hi*/) {
  return 0xfu;
}

template <>
inline unsigned block_candidates<float>(const LeafBlock& block, const TraversalRay<float>& r, float t_lo,
                                        float t_hi) {
  // Per axis the ray enters the slab at the face it meets first: max for a ray towards +axis, min for
  // one towards -axis (-0 included). On a parallel axis the reciprocal is +-inf, which gives -inf /
  // +inf (no bound) for an origin inside the slab, a rejection outside, and NaN (0 * inf) for an
  // origin in a face plane; max/min below ignore a NaN in their first operand, so such a face
  // bounds nothing and the double test decides.
#if defined(__SSE2__)
  __m128 t_near = _mm_set1_ps(t_lo), t_far = _mm_set1_ps(t_hi);
  for (int a = 0; a < 3; ++a) {
    const int enter = a + 3 * static_cast<int>(r.negative[a]),
              leave = a + 3 - 3 * static_cast<int>(r.negative[a]);
    const __m128 t0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(block.plane[enter]), r.origin4[a]), r.inverse4[a]);
    const __m128 t1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(block.plane[leave]), r.origin4[a]), r.inverse4[a]);
    t_near = _mm_max_ps(t0, t_near);  // MAXPS/MINPS return the second operand when either is NaN
    t_far = _mm_min_ps(t1, t_far);
  }
  if (t_lo >= 0) return may_hit_from_nonnegative4(t_near, t_far);  // then t_near >= 0
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 relative = _mm_set1_ps(Widening<float>::relative);
  const __m128 absolute = _mm_set1_ps(Widening<float>::absolute);
  t_near = _mm_sub_ps(t_near, _mm_add_ps(_mm_mul_ps(_mm_and_ps(t_near, magnitude), relative), absolute));
  t_far = _mm_add_ps(t_far, _mm_add_ps(_mm_mul_ps(_mm_and_ps(t_far, magnitude), relative), absolute));
  return static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(t_near, t_far)));
#else
  unsigned mask = 0;
  for (int lane = 0; lane < 4; ++lane) {
    float t_near = t_lo, t_far = t_hi;
    for (int a = 0; a < 3; ++a) {
      const int enter = a + 3 * static_cast<int>(r.negative[a]),
                leave = a + 3 - 3 * static_cast<int>(r.negative[a]);
      const float t0 = (block.plane[enter][lane] - r.origin[a]) * r.inverse[a];
      const float t1 = (block.plane[leave][lane] - r.origin[a]) * r.inverse[a];
      if (t0 > t_near) t_near = t0;  // false for NaN, as above
      if (t1 < t_far) t_far = t1;
    }
    if (t_lo >= 0 ? may_hit_from_nonnegative(t_near, t_far) : widen_down(t_near) <= widen_up(t_far))
      mask |= 1u << lane;
  }
  return mask;
#endif
}

#if defined(KDSPACE_AVX2_DISPATCH)
/// block_candidates<float> for eight boxes at once: the leaf's blocks `first` (bits 0-3) and
/// `second` (bits 4-7), each half of a 256-bit register. The same filter lane by lane.
__attribute__((target("avx2"))) inline unsigned block_pair_candidates(const LeafBlock& first,
                                                                      const LeafBlock& second,
                                                                      const TraversalRay<float>& r,
                                                                      float t_lo, float t_hi) {
  __m256 t_near = _mm256_set1_ps(t_lo), t_far = _mm256_set1_ps(t_hi);
  for (int a = 0; a < 3; ++a) {
    const int enter = a + 3 * static_cast<int>(r.negative[a]),
              leave = a + 3 - 3 * static_cast<int>(r.negative[a]);
    const __m256 origin = _mm256_set1_ps(r.origin[a]), inverse = _mm256_set1_ps(r.inverse[a]);
    const __m256 enter_planes =
        _mm256_set_m128(_mm_load_ps(second.plane[enter]), _mm_load_ps(first.plane[enter]));
    const __m256 leave_planes =
        _mm256_set_m128(_mm_load_ps(second.plane[leave]), _mm_load_ps(first.plane[leave]));
    const __m256 t0 = _mm256_mul_ps(_mm256_sub_ps(enter_planes, origin), inverse);
    const __m256 t1 = _mm256_mul_ps(_mm256_sub_ps(leave_planes, origin), inverse);
    t_near = _mm256_max_ps(t0, t_near);  // as MAXPS/MINPS: the second operand when either is NaN
    t_far = _mm256_min_ps(t1, t_far);
  }
  if (t_lo >= 0) return may_hit_from_nonnegative8(t_near, t_far);  // then t_near >= 0
  const __m256 magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 relative = _mm256_set1_ps(Widening<float>::relative);
  const __m256 absolute = _mm256_set1_ps(Widening<float>::absolute);
  t_near = _mm256_sub_ps(t_near,
                         _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(t_near, magnitude), relative), absolute));
  t_far =
      _mm256_add_ps(t_far, _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(t_far, magnitude), relative), absolute));
  return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(t_near, t_far, _CMP_LE_OQ)));
}
#endif

/// Lanes of a leaf's next blocks whose box the ray may hit within [t_lo, t_hi] (block_candidates):
/// one block (bits 0-3), or two (bits 0-7) when Wide. `remaining` (> 0) counts the leaf's boxes from
/// `blocks` on; a leaf's last block, when it is alone, is tested twice and its second copy's lanes
/// dropped, so no block past the leaf is read.
template <class Real, bool Wide>
inline unsigned leaf_step_candidates(const LeafBlock* blocks, std::uint32_t remaining,
                                     const TraversalRay<Real>& r, Real t_lo, Real t_hi) {
#if defined(KDSPACE_AVX2_DISPATCH)
  if constexpr (Wide) {
    const std::uint32_t two = remaining > 4;
    return block_pair_candidates(blocks[0], blocks[two], r, t_lo, t_hi) & (0x0fu | (0xf0u & (0u - two)));
  }
#endif
  return block_candidates<Real>(blocks[0], r, t_lo, t_hi);
}

}  // namespace kdspace::detail
