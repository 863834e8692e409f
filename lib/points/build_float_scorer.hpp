// The scorer the neighbour graph's build uses on float rows that the 16-bit grid of
// build_distances.hpp would blur (quantize_rows() returns nothing): squared L2 distances from a row
// to 4 rows at once, 4 coordinates to a vector, one vector a coordinate block and row (the last block
// of a row whose dimension is not a multiple of 4 is the row's last 4 coordinates, with the lanes
// already added masked off, so no read goes past a row).
//
// Its sums are not internal_distance()'s (which adds in 8 lanes, then the remaining coordinates one
// by one, so that every answer is the brute-force distance bit for bit): the build only compares
// these distances with each other, and any fixed order gives the same graph on any thread count.
// On 20-D and 39-D rows the exact kernel's scalar tail and lane bookkeeping cost about as much as its
// arithmetic: with this one the build of the graph over 30,000 music frames (20-D) took 13% fewer
// instructions in all (callgrind), for the same recall at every ef.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

class BuildFloatScorer {
 public:
  using Scalar = float;
  static constexpr std::size_t group = 4;

  BuildFloatScorer(const float* rows, std::size_t dim, const float* q)
      : rows_(rows), dim_(dim), q_(q), lines_((dim * sizeof(float) + 63) / 64) {
#if defined(__SSE2__)
    const std::size_t left = dim % 4;  // coordinates of the last block not in a full one
    alignas(16) std::int32_t lanes[4];
    for (std::size_t j = 0; j < 4; ++j) lanes[j] = left > 0 && j >= 4 - left ? -1 : 0;
    tail_mask_ = _mm_castsi128_ps(_mm_load_si128(reinterpret_cast<const __m128i*>(lanes)));
#endif
  }
  void prefetch(std::uint32_t row) const {
    const char* first_byte = reinterpret_cast<const char*>(rows_ + std::size_t{row} * dim_);
    for (std::size_t line = 0; line < lines_; ++line) __builtin_prefetch(first_byte + 64 * line);
  }
  /// Distances of the rows ids[0, 4), or, once all four are sure to be above `limit`, values above it.
  void operator()(const std::uint32_t* ids, float limit, float* out) const {
#if defined(__SSE2__)
    if (dim_ < 4) return scalar(ids, out);
    const float* r0 = rows_ + std::size_t{ids[0]} * dim_;
    const float* r1 = rows_ + std::size_t{ids[1]} * dim_;
    const float* r2 = rows_ + std::size_t{ids[2]} * dim_;
    const float* r3 = rows_ + std::size_t{ids[3]} * dim_;
    __m128 a0 = _mm_setzero_ps(), a1 = a0, a2 = a0, a3 = a0;
    auto add = [](__m128 acc, __m128 x, const float* row) {
      const __m128 d = _mm_sub_ps(x, _mm_loadu_ps(row));
      return _mm_add_ps(acc, _mm_mul_ps(d, d));
    };
    // Long rows stop early once all four partial sums (which only grow) are above the limit.
    const bool early_exit =
        dim_ >= 2 * coordinates_between_checks && limit < std::numeric_limits<float>::infinity();
    std::size_t i = 0;
    for (; i + 4 <= dim_; i += 4) {
      const __m128 x = _mm_loadu_ps(q_ + i);
      a0 = add(a0, x, r0 + i), a1 = add(a1, x, r1 + i), a2 = add(a2, x, r2 + i), a3 = add(a3, x, r3 + i);
      if (early_exit && (i + 4) % coordinates_between_checks == 0 && i + 4 < dim_) {
        sums(a0, a1, a2, a3, out);
        if (out[0] > limit && out[1] > limit && out[2] > limit && out[3] > limit) return;
      }
    }
    if (i < dim_) {
      const std::size_t last = dim_ - 4;
      const __m128 x = _mm_loadu_ps(q_ + last);
      auto add_tail = [&](__m128 acc, const float* row) {
        const __m128 d = _mm_and_ps(_mm_sub_ps(x, _mm_loadu_ps(row + last)), tail_mask_);
        return _mm_add_ps(acc, _mm_mul_ps(d, d));
      };
      a0 = add_tail(a0, r0), a1 = add_tail(a1, r1), a2 = add_tail(a2, r2), a3 = add_tail(a3, r3);
    }
    sums(a0, a1, a2, a3, out);
#else
    (void)limit;
    scalar(ids, out);
#endif
  }

 private:
#if defined(__SSE2__)
  static constexpr std::size_t coordinates_between_checks = 64;

  // The horizontal sums of four accumulators at once (a 4 x 4 transpose, then three adds).
  static void sums(__m128 a0, __m128 a1, __m128 a2, __m128 a3, float* out) {
    _MM_TRANSPOSE4_PS(a0, a1, a2, a3);
    _mm_storeu_ps(out, _mm_add_ps(_mm_add_ps(a0, a1), _mm_add_ps(a2, a3)));
  }
#endif
  // Without SSE2, and for rows of fewer than 4 coordinates.
  void scalar(const std::uint32_t* ids, float* out) const {
    for (std::size_t g = 0; g < group; ++g) {
      const float* row = rows_ + std::size_t{ids[g]} * dim_;
      float sum = 0;
      for (std::size_t i = 0; i < dim_; ++i) sum += (q_[i] - row[i]) * (q_[i] - row[i]);
      out[g] = sum;
    }
  }

  const float* rows_;
  std::size_t dim_;
  const float* q_;
  std::size_t lines_;
#if defined(__SSE2__)
  __m128 tail_mask_;
#endif
};

}  // namespace kdspace::detail
