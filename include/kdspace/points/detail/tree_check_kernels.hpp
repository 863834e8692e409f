// The two inner loops of a loaded point tree's check (tree_check.hpp) compiled for wider instruction
// sets, chosen at run time: 3-D float points against their cell eight at a time with AVX2, and the
// point order's bits set with BMI2's shifts after an AVX2 range check of the values (no clamp a
// value): about a third fewer instructions a value. They decide exactly what the baseline loops
// decide; the tests run both (KDSPACE_NO_AVX2, ctest entry `baseline_without_avx2`).
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

/// Whether lo <= p <= hi for every 3-D float point p of rows [0, count), count >= 8; lo and hi hold
/// four floats (the cell's three, then any). Eight points are 24 floats, three 8-float loads whose
/// lanes hold the axes x y z x y z x y, z x y z x y z x, y z x y z x y z; a leaf of 8k + r points
/// ends with the eight points that end it (r of them checked a second time). A NaN fails.
__attribute__((target("avx2"))) inline bool points3_inside_avx2(const float* rows, std::size_t count,
                                                                const float* lo, const float* hi) {
  // The three lane orders of four lanes, paired into eight.
  const CellLanes3 low = cell_lanes3(lo), high = cell_lanes3(hi);
  const __m128 l0 = low.order[0], l1 = low.order[1], l2 = low.order[2];
  const __m128 h0 = high.order[0], h1 = high.order[1], h2 = high.order[2];
  const __m256 lo0 = _mm256_set_m128(l1, l0), lo1 = _mm256_set_m128(l0, l2), lo2 = _mm256_set_m128(l2, l1);
  const __m256 hi0 = _mm256_set_m128(h1, h0), hi1 = _mm256_set_m128(h0, h2), hi2 = _mm256_set_m128(h2, h1);
  __m256 ok = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  for (std::size_t i = 0;; i += 8) {
    const float* p = rows + 3 * (i + 8 <= count ? i : count - 8);
    ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_and_ps(within8(lo0, _mm256_loadu_ps(p), hi0),
                                                       within8(lo1, _mm256_loadu_ps(p + 8), hi1)),
                                         within8(lo2, _mm256_loadu_ps(p + 16), hi2)));
    if (i + 8 >= count) break;
  }
  return _mm256_movemask_ps(ok) == 255;
}

/// Sets bit v of `bits` for each value v of values [0, count) and returns true, when every value is
/// below n; else returns false (having set none). The values are first checked eight at a time (they
/// are in the first-level cache: the checksum has just read them), so the marking needs no clamp.
__attribute__((target("avx2,bmi2"))) inline bool mark_values_avx2(const std::uint32_t* values,
                                                                  std::size_t count, std::uint32_t n,
                                                                  std::uint64_t* bits) {
  __m256i most = _mm256_setzero_si256();
  std::size_t i = 0;
  for (; i + 8 <= count; i += 8)
    most = _mm256_max_epu32(most, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(values + i)));
  alignas(32) std::uint32_t lanes[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), most);
  std::uint32_t largest = 0;
  for (std::uint32_t v : lanes) largest = v > largest ? v : largest;
  for (; i < count; ++i) largest = values[i] > largest ? values[i] : largest;
  if (count != 0 && largest >= n) return false;
  for (i = 0; i + 4 <= count; i += 4)  // four independent updates a step
    for (std::size_t j = i; j < i + 4; ++j) bits[values[j] >> 6] |= std::uint64_t{1} << (values[j] & 63);
  for (; i < count; ++i) bits[values[i] >> 6] |= std::uint64_t{1} << (values[i] & 63);
  return true;
}

#endif

}  // namespace kdspace::detail
