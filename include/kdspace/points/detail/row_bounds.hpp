// The bounding box of contiguous rows, in a form the compiler vectorizes for any dimension.
#pragma once

#include <algorithm>
#include <cstddef>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

/// Running minimum and maximum over a flat array of `width` values (width a multiple of the vector
/// width): acc_lo[j] = min(acc_lo[j], x[j]) and likewise the max, lane by lane. The compiler does not
/// turn std::min on floating point into vector minimums without -ffinite-math-only (NaN), so on x86
/// the SSE2 instructions are named; min and max are exact, the result is the same either way.
template <class T, std::size_t width>
inline void min_max_lanes(const T* x, T* acc_lo, T* acc_hi) {
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, float> && width % 4 == 0) {
    for (std::size_t j = 0; j < width; j += 4) {
      const __m128 v = _mm_loadu_ps(x + j);
      _mm_storeu_ps(acc_lo + j, _mm_min_ps(v, _mm_loadu_ps(acc_lo + j)));
      _mm_storeu_ps(acc_hi + j, _mm_max_ps(v, _mm_loadu_ps(acc_hi + j)));
    }
    return;
  } else if constexpr (std::is_same_v<T, double> && width % 2 == 0) {
    for (std::size_t j = 0; j < width; j += 2) {
      const __m128d v = _mm_loadu_pd(x + j);
      _mm_storeu_pd(acc_lo + j, _mm_min_pd(v, _mm_loadu_pd(acc_lo + j)));
      _mm_storeu_pd(acc_hi + j, _mm_max_pd(v, _mm_loadu_pd(acc_hi + j)));
    }
    return;
  }
#endif
  for (std::size_t j = 0; j < width; ++j) {
    acc_lo[j] = std::min(acc_lo[j], x[j]);
    acc_hi[j] = std::max(acc_hi[j], x[j]);
  }
}

/// lo[a] = min(lo[a], x[a]) and hi[a] = max(hi[a], x[a]) over one row of `dim` values, with the
/// SSE2 minimum and maximum where they apply (as in min_max_lanes).
template <class T>
inline void widen_by_row(const T* x, std::size_t dim, T* lo, T* hi) {
  std::size_t a = 0;
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, float>) {
    for (; a + 4 <= dim; a += 4) {
      const __m128 v = _mm_loadu_ps(x + a);
      _mm_storeu_ps(lo + a, _mm_min_ps(v, _mm_loadu_ps(lo + a)));
      _mm_storeu_ps(hi + a, _mm_max_ps(v, _mm_loadu_ps(hi + a)));
    }
  } else if constexpr (std::is_same_v<T, double>) {
    for (; a + 2 <= dim; a += 2) {
      const __m128d v = _mm_loadu_pd(x + a);
      _mm_storeu_pd(lo + a, _mm_min_pd(v, _mm_loadu_pd(lo + a)));
      _mm_storeu_pd(hi + a, _mm_max_pd(v, _mm_loadu_pd(hi + a)));
    }
  }
#endif
  for (std::size_t rest = dim - a; rest > 0; --rest, ++a) {
    lo[a] = std::min(lo[a], x[a]);
    hi[a] = std::max(hi[a], x[a]);
  }
}

/// Widens lo / hi (dim values each) to take in `count` rows of `dim` coordinates, row-major. With
/// CheckFinite, also returns the sum of x - x over every coordinate x: 0 when all are finite, NaN
/// when one is not (infinite or NaN), so the same pass checks the input without a branch per
/// coordinate (without it, returns 0).
///
/// Dim in 1..16 (fixed at compile time): rows are taken four at a time as one flat block of 4 * Dim
/// values with a running minimum and maximum per position of the block (independent lanes, in vector
/// registers whatever Dim is, 3 included), folded onto the axes at the end.
template <int Dim, bool CheckFinite = false, class T>
T widen_bounds(const T* rows, std::size_t count, std::size_t dim, T* lo, T* hi) {
  T not_finite = 0;
  std::size_t i = 0;
  if constexpr (Dim > 0 && Dim <= 16) {
    constexpr std::size_t D = static_cast<std::size_t>(Dim), block = 4 * D;
    if (count >= 8) {
      T block_lo[block], block_hi[block], block_bad[block] = {};
      std::copy_n(rows, block, block_lo);
      std::copy_n(rows, block, block_hi);
      for (; i + 4 <= count; i += 4) {
        const T* x = rows + i * D;
        min_max_lanes<T, block>(x, block_lo, block_hi);
        if constexpr (CheckFinite)
          for (std::size_t j = 0; j < block; ++j) block_bad[j] += x[j] - x[j];
      }
      for (std::size_t r = 0; r < 4; ++r)
        for (std::size_t a = 0; a < D; ++a) {
          lo[a] = std::min(lo[a], block_lo[r * D + a]);
          hi[a] = std::max(hi[a], block_hi[r * D + a]);
          not_finite += block_bad[r * D + a];
        }
    }
  }
  if constexpr (Dim > 0) dim = static_cast<std::size_t>(Dim);
  for (; i < count; ++i) {
    const T* x = rows + i * dim;
    for (std::size_t a = 0; a < dim; ++a) {
      lo[a] = std::min(lo[a], x[a]);
      hi[a] = std::max(hi[a], x[a]);
      if constexpr (CheckFinite) not_finite += x[a] - x[a];
    }
  }
  return not_finite;
}

}  // namespace kdspace::detail
