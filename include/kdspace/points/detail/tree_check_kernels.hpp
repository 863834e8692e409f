// The two inner loops of a loaded point tree's check (tree_check.hpp) compiled for wider instruction
// sets, chosen at run time: 3-D float points against their cell eight at a time with AVX2 (also the
// leaf test of the AVX2 walk, tree_check_walk3.hpp), and the
// point order's bits set with BMI2's shifts after an AVX2 range check of the values (no clamp a
// value): about a third fewer instructions a value; that range check alone is Verify::safety's
// check of the order. They decide exactly what the baseline loops
// decide; the tests run both (KDSPACE_NO_AVX2, ctest entry `baseline_without_avx2_index`).
#pragma once

#include <cstddef>
#include <cstdint>

#include "kdspace/detail/avx2_dispatch.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(KDSPACE_AVX2_DISPATCH)
#include <immintrin.h>
#endif

namespace kdspace::detail {

#if defined(__SSE2__)
/// A 3-D cell's bounds (four floats: x y z, then any) in the three lane orders of 3-D points read
/// four floats at a time: x y z x, y z x y, z x y z.
struct CellLanes3 {
  __m128 order[3];
};
inline CellLanes3 cell_lanes3(const float* bounds) {
  const __m128 cell = _mm_loadu_ps(bounds);
  return {{_mm_shuffle_ps(cell, cell, _MM_SHUFFLE(0, 2, 1, 0)),
           _mm_shuffle_ps(cell, cell, _MM_SHUFFLE(1, 0, 2, 1)),
           _mm_shuffle_ps(cell, cell, _MM_SHUFFLE(2, 1, 0, 2))}};
}
#endif

/// Whether the kernels below may run: avx2_dispatch() and a processor with BMI2 (every AVX2
/// processor has it; both read once per process).
inline bool tree_check_kernels() {
#if defined(KDSPACE_AVX2_DISPATCH)
  static const bool yes = avx2_dispatch() && __builtin_cpu_supports("bmi2");
  return yes;
#else
  return false;
#endif
}

#if defined(KDSPACE_AVX2_DISPATCH)

/// Lanes where low <= p <= high (false where p is NaN).
__attribute__((target("avx2"), always_inline)) inline __m256 within8(__m256 low, __m256 p, __m256 high) {
  return _mm256_and_ps(_mm256_cmp_ps(low, p, _CMP_LE_OQ), _mm256_cmp_ps(p, high, _CMP_LE_OQ));
}

/// Lanes where the eight 3-D points at p lie in the cell whose lanes are put in the three orders of
/// their floats (see below).
__attribute__((target("avx2"), always_inline)) inline __m256 eight_points3_inside(const float* p, __m256 lo0,
                                                                                  __m256 lo1, __m256 lo2,
                                                                                  __m256 hi0, __m256 hi1,
                                                                                  __m256 hi2) {
  return _mm256_and_ps(
      _mm256_and_ps(within8(lo0, _mm256_loadu_ps(p), hi0), within8(lo1, _mm256_loadu_ps(p + 8), hi1)),
      within8(lo2, _mm256_loadu_ps(p + 16), hi2));
}

/// Whether lo <= p <= hi for every 3-D point p of rows [0, count) (false where a coordinate is NaN);
/// lo and hi hold x y z in their first three lanes. Eight points are 24 floats, three 8-float loads
/// whose lanes hold the axes x y z x y z x y, z x y z x y z x, y z x y z x y z: the cell's lanes are
/// put in those orders by one permute each. A leaf of 8k + r points (k >= 1) ends with the eight
/// points that end it (r of them tested a second time); one of fewer than eight point by point.
__attribute__((target("avx2"), always_inline)) inline bool points3_in_cell_avx2(const float* rows,
                                                                                std::size_t count, __m128 lo,
                                                                                __m128 hi) {
  if (count >= 8) {
    const __m256i order0 = _mm256_setr_epi32(0, 1, 2, 0, 1, 2, 0, 1);
    const __m256i order1 = _mm256_setr_epi32(2, 0, 1, 2, 0, 1, 2, 0);
    const __m256i order2 = _mm256_setr_epi32(1, 2, 0, 1, 2, 0, 1, 2);
    const __m256 low = _mm256_castps128_ps256(lo), high = _mm256_castps128_ps256(hi);
    const __m256 lo0 = _mm256_permutevar8x32_ps(low, order0), hi0 = _mm256_permutevar8x32_ps(high, order0);
    const __m256 lo1 = _mm256_permutevar8x32_ps(low, order1), hi1 = _mm256_permutevar8x32_ps(high, order1);
    const __m256 lo2 = _mm256_permutevar8x32_ps(low, order2), hi2 = _mm256_permutevar8x32_ps(high, order2);
    __m256 ok = eight_points3_inside(rows + 3 * (count - 8), lo0, lo1, lo2, hi0, hi1, hi2);
    for (std::size_t i = 0; i + 8 < count; i += 8)
      ok = _mm256_and_ps(ok, eight_points3_inside(rows + 3 * i, lo0, lo1, lo2, hi0, hi1, hi2));
    return _mm256_movemask_ps(ok) == 255;
  }
  alignas(16) float low_lanes[4], high_lanes[4];
  _mm_store_ps(low_lanes, lo);
  _mm_store_ps(high_lanes, hi);
  unsigned inside = 1;
  for (std::size_t i = 0; i < count; ++i, rows += 3)
    for (std::size_t a = 0; a < 3; ++a)
      inside &=
          static_cast<unsigned>(low_lanes[a] <= rows[a]) & static_cast<unsigned>(rows[a] <= high_lanes[a]);
  return inside != 0;
}

/// The same for a cell of four floats in memory (x y z, then any).
__attribute__((target("avx2"))) inline bool points3_inside_avx2(const float* rows, std::size_t count,
                                                                const float* lo, const float* hi) {
  return points3_in_cell_avx2(rows, count, _mm_loadu_ps(lo), _mm_loadu_ps(hi));
}

/// The largest of values [0, count), eight at a time (0 for none).
__attribute__((target("avx2"))) inline std::uint32_t largest_value_avx2(const std::uint32_t* values,
                                                                        std::size_t count) {
  __m256i most = _mm256_setzero_si256();
  std::size_t i = 0;
  for (; i + 8 <= count; i += 8)
    most = _mm256_max_epu32(most, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(values + i)));
  alignas(32) std::uint32_t lanes[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), most);
  std::uint32_t largest = 0;
  for (std::uint32_t v : lanes) largest = v > largest ? v : largest;
  for (; i < count; ++i) largest = values[i] > largest ? values[i] : largest;
  return largest;
}

/// Sets bit v of `bits` for each value v of values [0, count) and returns true, when every value is
/// below n; else returns false (having set none). The values are first checked eight at a time (they
/// are in the first-level cache: the checksum has just read them), so the marking needs no clamp.
__attribute__((target("avx2,bmi2"))) inline bool mark_values_avx2(const std::uint32_t* values,
                                                                  std::size_t count, std::uint32_t n,
                                                                  std::uint64_t* bits) {
  if (count != 0 && largest_value_avx2(values, count) >= n) return false;
  std::size_t i = 0;
  for (; i + 4 <= count; i += 4)  // four independent updates a step
    for (std::size_t j = i; j < i + 4; ++j) bits[values[j] >> 6] |= std::uint64_t{1} << (values[j] & 63);
  for (; i < count; ++i) bits[values[i] >> 6] |= std::uint64_t{1} << (values[i] & 63);
  return true;
}

#endif

}  // namespace kdspace::detail
