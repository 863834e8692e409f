// Squared L2 distances from one query to a few rows at once, each the same bit for bit as
// internal_distance<L2>(query, row, dim), with an early exit once every row is sure to be too far.
//
// internal_distance() keeps 8 lanes (lane j takes axes j, j+8, ...), combines them pairwise (j and
// j+4, then j and j+2, then 0 and 1) and adds the remaining axes one by one. Each lane is a chain of
// dependent additions, so one row at a time leaves the adder waiting on its own latency; R rows
// computed together give R independent chains with the same operations per row, hence the same
// results. With SSE2 (every x86-64) the float kernel is written with intrinsics, which also convert
// byte rows to float in a few instructions (compilers otherwise convert them one value at a time);
// elsewhere, and for double, a portable loop does the same arithmetic.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "kdspace/metric.hpp"
#include "kdspace/points/detail/fixed_distance.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

/// Blocks of 8 axes between two checks of the early exit, and the fewest blocks worth checking.
inline constexpr std::size_t blocks_between_checks = 4;

/// Portable form: for each of R rows b[r], internal_distance<L2>(a, b[r], dim), or, once every row's
/// partial sum exceeds `limit` (partial sums combined in the same order only grow: every term is
/// >= 0 and rounding is monotone), those partial sums, all above `limit`.
template <std::size_t R, class T, class U>
void l2_distances_or_more_portable(const T* a, const U* const* b, std::size_t dim, T limit, T* out) {
  constexpr std::size_t lanes = 8;
  const std::size_t blocks = dim / lanes;
  const bool early_exit = blocks >= 2 * blocks_between_checks;
  T acc[R][lanes] = {};
  auto combine = [&](std::size_t r) {
    T v[lanes];
    std::copy(acc[r], acc[r] + lanes, v);
    for (std::size_t width = lanes / 2; width > 0; width /= 2)
      for (std::size_t j = 0; j < width; ++j) v[j] = L2::accumulate(v[j], v[j + width]);
    return v[0];
  };
  for (std::size_t block = 0; block < blocks; ++block) {
    for (std::size_t r = 0; r < R; ++r) {
      const T* x = a + block * lanes;
      const U* y = b[r] + block * lanes;
      for (std::size_t j = 0; j < lanes; ++j) acc[r][j] = L2::accumulate(acc[r][j], L2::term(x[j] - static_cast<T>(y[j])));
    }
    if (early_exit && (block + 1) % blocks_between_checks == 0 && block + 1 < blocks) {
      bool all_above = true;
      for (std::size_t r = 0; r < R; ++r) all_above = all_above && (out[r] = combine(r)) > limit;
      if (all_above) return;
    }
  }
  for (std::size_t r = 0; r < R; ++r) out[r] = blocks > 0 ? combine(r) : T(0);
  for (std::size_t i = blocks * lanes; i < dim; ++i)
    for (std::size_t r = 0; r < R; ++r) out[r] = L2::accumulate(out[r], L2::term(a[i] - static_cast<T>(b[r][i])));
}

#if defined(__SSE2__)
namespace sse2 {

// Lanes 0-3 and 4-7 of a block of 8 values, as floats.
inline void load_block(const float* p, __m128& low, __m128& high) {
  low = _mm_loadu_ps(p);
  high = _mm_loadu_ps(p + 4);
}
inline void load_block(const std::uint8_t* p, __m128& low, __m128& high) {
  const __m128i zero = _mm_setzero_si128();
  const __m128i words = _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)), zero);
  low = _mm_cvtepi32_ps(_mm_unpacklo_epi16(words, zero));  // exact: integers below 2^24
  high = _mm_cvtepi32_ps(_mm_unpackhi_epi16(words, zero));
}

// The 8 lanes combined as internal_distance() combines them (fixed_distance.hpp).
inline float combine(__m128 low, __m128 high) { return _mm_cvtss_f32(sse2_fixed::combine_lanes(low, high)); }

template <std::size_t R, class U>
void l2_distances_or_more(const float* a, const U* const* b, std::size_t dim, float limit, float* out) {
  constexpr std::size_t lanes = 8;
  const std::size_t blocks = dim / lanes;
  const bool early_exit = blocks >= 2 * blocks_between_checks;
  __m128 low[R], high[R];
  for (std::size_t r = 0; r < R; ++r) low[r] = high[r] = _mm_setzero_ps();
  for (std::size_t block = 0; block < blocks; ++block) {
    const __m128 x_low = _mm_loadu_ps(a + block * lanes), x_high = _mm_loadu_ps(a + block * lanes + 4);
    for (std::size_t r = 0; r < R; ++r) {
      __m128 y_low, y_high;
      load_block(b[r] + block * lanes, y_low, y_high);
      const __m128 d_low = _mm_sub_ps(x_low, y_low), d_high = _mm_sub_ps(x_high, y_high);
      low[r] = _mm_add_ps(low[r], _mm_mul_ps(d_low, d_low));
      high[r] = _mm_add_ps(high[r], _mm_mul_ps(d_high, d_high));
    }
    if (early_exit && (block + 1) % blocks_between_checks == 0 && block + 1 < blocks) {
      bool all_above = true;
      for (std::size_t r = 0; r < R; ++r) all_above = all_above && (out[r] = combine(low[r], high[r])) > limit;
      if (all_above) return;
    }
  }
  for (std::size_t r = 0; r < R; ++r) out[r] = blocks > 0 ? combine(low[r], high[r]) : 0.f;
  for (std::size_t i = blocks * lanes; i < dim; ++i)
    for (std::size_t r = 0; r < R; ++r) out[r] = L2::accumulate(out[r], L2::term(a[i] - static_cast<float>(b[r][i])));
}

}  // namespace sse2
#endif

/// Squared L2 distances from a byte query (given widened to 16 bits, `a`) to R byte rows b[r], exactly,
/// as integers (each below 2^31 for dim < 33000). With SSE2, 16 coordinates of a row take one load,
/// two unpacks, two subtractions and two multiply-adds (_mm_madd_epi16 squares and pairs the 16-bit
/// differences): about 2.5 times fewer instructions than the byte-to-float kernel below.
template <std::size_t R>
void l2_byte_distances(const std::int16_t* a, const std::uint8_t* const* b, std::size_t dim, std::uint32_t* out) {
  std::size_t done = 0;
#if defined(__SSE2__)
  const std::size_t blocks = dim / 16;
  __m128i acc[R];
  for (std::size_t r = 0; r < R; ++r) acc[r] = _mm_setzero_si128();
  const __m128i zero = _mm_setzero_si128();
  for (std::size_t block = 0; block < blocks; ++block) {
    const __m128i a_low = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + 16 * block));
    const __m128i a_high = _mm_loadu_si128(reinterpret_cast<const __m128i*>(a + 16 * block + 8));
    for (std::size_t r = 0; r < R; ++r) {
      const __m128i bytes = _mm_loadu_si128(reinterpret_cast<const __m128i*>(b[r] + 16 * block));
      const __m128i d_low = _mm_sub_epi16(a_low, _mm_unpacklo_epi8(bytes, zero));
      const __m128i d_high = _mm_sub_epi16(a_high, _mm_unpackhi_epi8(bytes, zero));
      acc[r] = _mm_add_epi32(acc[r], _mm_add_epi32(_mm_madd_epi16(d_low, d_low), _mm_madd_epi16(d_high, d_high)));
    }
  }
  for (std::size_t r = 0; r < R; ++r) {
    alignas(16) std::uint32_t lanes[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(lanes), acc[r]);
    out[r] = lanes[0] + lanes[1] + lanes[2] + lanes[3];
  }
  done = blocks * 16;
#else
  for (std::size_t r = 0; r < R; ++r) out[r] = 0;
#endif
  for (std::size_t i = done; i < dim; ++i)
    for (std::size_t r = 0; r < R; ++r) {
      const int diff = a[i] - static_cast<int>(b[r][i]);
      out[r] += static_cast<std::uint32_t>(diff * diff);
    }
}

/// For each of R rows b[r] (of T, or of bytes), internal_distance<L2>(a, b[r], dim) bit for bit, or,
/// once every row is sure to be farther than `limit`, some values above `limit` for all of them.
template <std::size_t R, class T, class U>
void l2_distances_or_more(const T* a, const U* const* b, std::size_t dim, T limit, T* out) {
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, float>) return sse2::l2_distances_or_more<R>(a, b, dim, limit, out);
#endif
  l2_distances_or_more_portable<R>(a, b, dim, limit, out);
}

}  // namespace kdspace::detail
