// Squared L2 distance between two float rows of a dimension known at compile time, the same bit for
// bit as internal_distance<L2>(a, b, D), written with SSE2 so that it costs a few instructions per
// four axes.
//
// internal_distance() (combine_axes, metric.hpp) keeps 8 lanes (lane j takes axes j, j+8, ...),
// combines them pairwise ((j, j+4), then (j, j+2), then (0, 1)) and adds the remaining axes one by
// one. Left to the compiler, that order at 13 axes came to about 66 instructions a point in the
// leaf scan (callgrind, mfcc13 1-NN); 34 with this kernel. Here the squares are
// computed four at a time, the lanes combined as above, and the remaining squares (four at a time
// while four remain, then one by one) added one after the other in axis order: the same additions on
// the same values.
// (A square is never -0, so starting a lane from its first square instead of 0 + square changes no
// bit.) Every load lies within the D values of a row.
#pragma once

#include <cstddef>

#include "kdspace/metric.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

#if defined(__SSE2__)
namespace sse2_fixed {

// (a - b)^2 for the four values at a and b.
[[gnu::always_inline]] inline __m128 squares4(const float* a, const float* b) {
  const __m128 d = _mm_sub_ps(_mm_loadu_ps(a), _mm_loadu_ps(b));
  return _mm_mul_ps(d, d);
}

// The 8 lanes of squares or sums (low: lanes 0-3, high: 4-7) combined as internal_distance()
// combines them: (j, j+4), then (j, j+2), then (0, 1); the result in lane 0 (row_distances.hpp's
// combine uses it too).
[[gnu::always_inline]] inline __m128 combine_lanes(__m128 low, __m128 high) {
  const __m128 four = _mm_add_ps(low, high);                       // lane j + lane j+4, j < 4
  const __m128 two = _mm_add_ps(four, _mm_movehl_ps(four, four));  // (0+2), (1+3)
  return _mm_add_ss(two, _mm_shuffle_ps(two, two, 1));
}

// total + v[0] + v[1] + v[2] + v[3], added in that order.
[[gnu::always_inline]] inline __m128 add_in_order(__m128 total, __m128 v) {
  total = _mm_add_ss(total, v);
  total = _mm_add_ss(total, _mm_shuffle_ps(v, v, 1));
  total = _mm_add_ss(total, _mm_movehl_ps(v, v));
  return _mm_add_ss(total, _mm_shuffle_ps(v, v, 3));
}

}  // namespace sse2_fixed
#endif

/// internal_distance<L2>(a, b, D) for float rows, bit for bit.
template <std::size_t D>
[[gnu::always_inline]] inline float l2_distance_fixed(const float* a, const float* b) {
#if defined(__SSE2__)
  using namespace sse2_fixed;
  constexpr std::size_t blocks = D / distance_lanes;
  __m128 total = _mm_setzero_ps();
  if constexpr (blocks > 0) {
    __m128 low = squares4(a, b), high = squares4(a + 4, b + 4);
    for (std::size_t block = 1; block < blocks; ++block) {
      low = _mm_add_ps(low, squares4(a + 8 * block, b + 8 * block));
      high = _mm_add_ps(high, squares4(a + 8 * block + 4, b + 8 * block + 4));
    }
    total = combine_lanes(low, high);
  }
  std::size_t i = blocks * distance_lanes;
  for (; i + 4 <= D; i += 4) total = add_in_order(total, squares4(a + i, b + i));
  float sum = _mm_cvtss_f32(total);
  // term and accumulate as separate calls, as in internal_distance: one expression a * b + c could be
  // contracted into a fused multiply-add (clang's default -ffp-contract=on where FMA is enabled).
  for (; i < D; ++i) sum = L2::accumulate(sum, L2::term(a[i] - b[i]));
  return sum;
#else
  return internal_distance<L2>(a, b, D);
#endif
}

}  // namespace kdspace::detail
