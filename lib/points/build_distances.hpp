// The rows the neighbour graph's build scores when the points are not bytes: each coordinate
// rounded to an integer of 16 bits, on one scale for all axes, and squared L2 distances between
// such rows in integer arithmetic, 8 coordinates to a vector.
//
// The build only compares distances with each other (the graph keeps no distance), so it may
// compare those of a copy of the points at a finer grain than their spread: an offset per axis does
// not change any distance, and one scale for every axis changes all of them by the same factor.
// The scale puts the widest axis's robust range (quantize_rows()) on [0, top] (more than half of it), top
// chosen so that a squared distance fits in 32 bits (14,654 for 20 coordinates, 10,494 for 39, 2,115 for
// 960); the rounding then moves a distance by far less than the gaps between a point's neighbours. Against
// float rows scored 4 coordinates a vector, the build over 95k music frames (20-D) took 3% fewer instructions
// in all (callgrind, net of the 0.08 billion the rounding costs) and about 2% less time, for the same recall
// at every ef within 0.0005; the copy takes half the memory of float rows while the graph is built.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "graph_search.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

/// Rows of the sample that quantize_rows() reads each axis's robust range from, and the share of
/// its values left out at each end.
constexpr std::size_t grid_sample_rows = 8192;
constexpr double grid_tail_share = 0.001;
/// The grid steps the typical axis (the median of the axes' robust ranges) must span for the grid
/// to be used: below it the rows are scored as they are (BuildFloatScorer).
constexpr double least_grid_steps = 256;

/// The rows (n of `dim` values of U) on the grid described above, or nothing when the grid would
/// be too coarse.
///
/// The scale is set by each axis's robust range (the central 99.8% of its values in an even sample
/// of the rows), not its whole range: one row far from the rest would otherwise widen the grid's
/// step beyond the spread of all the others, put them on a few cells, and leave their order to ties
/// by row. The grid's window on an axis is centred on that range, then moved to cover as much of the
/// axis's whole range as it can; a coordinate outside it saturates at 0 or top (the graph only needs
/// the near distances right; a query's distances are computed again from the points). When even the
/// robust ranges leave the typical axis fewer than least_grid_steps steps (most axes narrow beside a
/// few wide ones, or many outliers), a distance would be decided by a few axes' rounding: nothing is
/// returned, and the build scores the rows themselves.
template <class U>
std::optional<std::vector<std::uint16_t>> quantize_rows(const U* rows, std::size_t n, std::size_t dim) {
  std::vector<double> least(dim, std::numeric_limits<double>::infinity()), most(dim, -least[0]);
  for (std::size_t r = 0; r < n; ++r)
    for (std::size_t a = 0; a < dim; ++a) {
      const double x = static_cast<double>(rows[r * dim + a]);
      least[a] = std::min(least[a], x), most[a] = std::max(most[a], x);
    }
  // Each axis's robust range, from rows spread evenly over the set.
  const std::size_t m = std::min(n, grid_sample_rows);
  const auto cut = static_cast<std::size_t>(grid_tail_share * static_cast<double>(m > 0 ? m - 1 : 0));
  std::vector<double> centre(dim, 0), spread(dim, 0), values(m);
  for (std::size_t a = 0; a < dim && m > 0; ++a) {
    for (std::size_t i = 0; i < m; ++i) values[i] = static_cast<double>(rows[(i * n / m) * dim + a]);
    const auto rank = [&](std::size_t at) {
      std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(at), values.end());
      return values[at];
    };
    const double robust_low = rank(cut), robust_high = rank(m - 1 - cut);
    centre[a] = 0.5 * (robust_low + robust_high), spread[a] = robust_high - robust_low;
  }
  const double widest = dim > 0 ? *std::max_element(spread.begin(), spread.end()) : 0;
  // Each coordinate's difference fits in int16, a pair of squares in int32, a row's sum in uint32.
  const double top = std::min(
      32767.0, std::floor(std::sqrt(4294967295.0 / static_cast<double>(std::max<std::size_t>(dim, 1)))));
  // A power of two (at most one bit of resolution lost): integer coordinates then stay integers,
  // every distance is the same multiple of their own (a power of four) and converts to T with the
  // same rounding, so points of integer values get the graph their byte rows get.
  const double scale = widest > 0 ? std::exp2(std::floor(std::log2(top / widest))) : 0;
  // Rows that differ need a finite, positive scale: not so when every robust range is 0 though some
  // axis varies (nearly all rows copies of one, or each axis non-zero in under 0.1% of the rows),
  // nor when a range overflows or is too small for top / widest. The rows are then scored as they are.
  bool varies = false;
  for (std::size_t a = 0; a < dim; ++a) varies = varies || most[a] > least[a];
  if (varies && !(scale > 0 && std::isfinite(scale))) return std::nullopt;
  if (dim > 0) {
    std::vector<double> typical = spread;
    std::nth_element(typical.begin(), typical.begin() + static_cast<std::ptrdiff_t>(dim / 2), typical.end());
    if (typical[dim / 2] * scale < least_grid_steps && typical[dim / 2] > 0) return std::nullopt;
  }
  // The grid's window on each axis: from the axis's least value when the whole range fits in it,
  // else centred on the robust range and moved to lie within the whole range, its start a whole
  // number of steps.
  const double window = scale > 0 ? top / scale : 0;
  std::vector<double> low(least);
  for (std::size_t a = 0; a < dim; ++a)
    if (most[a] - least[a] > window)
      low[a] = std::floor(std::clamp(centre[a] - 0.5 * window, least[a], most[a] - window) * scale) / scale;
  std::vector<std::uint16_t> out(n * dim);
  for (std::size_t r = 0; r < n; ++r)
    for (std::size_t a = 0; a < dim; ++a) {
      const double x = (static_cast<double>(rows[r * dim + a]) - low[a]) * scale;
      out[r * dim + a] = static_cast<std::uint16_t>(std::clamp(x + 0.5, 0.0, top));  // rounded half up
    }
  return out;
}

/// Squared L2 distances from a quantized row to 4 quantized rows at once, exact in integers (then
/// converted to T).
template <class T>
class QuantizedRowScorer {
 public:
  using Scalar = T;
  static constexpr std::size_t group = 4;

  QuantizedRowScorer(const std::uint16_t* rows, std::size_t dim, const std::uint16_t* q)
      : rows_(rows), dim_(dim), q_(q) {
#if defined(__SSE2__)
    // The last block of a row whose dimension is not a multiple of 8 is its last 8 coordinates,
    // with the lanes a full block already counted masked off (no read past a row).
    const std::size_t left = dim % 8;
    alignas(16) std::int16_t lanes[8];
    for (std::size_t j = 0; j < 8; ++j) lanes[j] = left > 0 && j >= 8 - left ? -1 : 0;
    tail_mask_ = _mm_load_si128(reinterpret_cast<const __m128i*>(lanes));
#endif
  }
  void prefetch(std::uint32_t row) const {
    prefetch_bytes(rows_ + std::size_t{row} * dim_, dim_ * sizeof(std::uint16_t));
  }
  /// Distances of the rows ids[0, 4).
  void operator()(const std::uint32_t* ids, T, T* out) const {
    const std::uint16_t* r[group];
    for (std::size_t g = 0; g < group; ++g) r[g] = rows_ + std::size_t{ids[g]} * dim_;
#if defined(__SSE2__)
    if (dim_ >= 8) {
      __m128i acc[group];
      for (std::size_t g = 0; g < group; ++g) acc[g] = _mm_setzero_si128();
      std::size_t i = 0;
      for (; i + 8 <= dim_; i += 8) {
        const __m128i x = load(q_ + i);
        for (std::size_t g = 0; g < group; ++g) {
          const __m128i d = _mm_sub_epi16(x, load(r[g] + i));
          acc[g] = _mm_add_epi32(acc[g], _mm_madd_epi16(d, d));
        }
      }
      if (i < dim_) {
        const std::size_t last = dim_ - 8;
        const __m128i x = load(q_ + last);
        for (std::size_t g = 0; g < group; ++g) {
          const __m128i d = _mm_and_si128(_mm_sub_epi16(x, load(r[g] + last)), tail_mask_);
          acc[g] = _mm_add_epi32(acc[g], _mm_madd_epi16(d, d));
        }
      }
      // The horizontal sums of the four accumulators (32-bit lanes that wrap as unsigned: the
      // total fits in 32 bits, a pair of squares in 31).
      const __m128i t0 = _mm_unpacklo_epi32(acc[0], acc[1]), t1 = _mm_unpackhi_epi32(acc[0], acc[1]);
      const __m128i t2 = _mm_unpacklo_epi32(acc[2], acc[3]), t3 = _mm_unpackhi_epi32(acc[2], acc[3]);
      const __m128i s01 = _mm_add_epi32(t0, t1), s23 = _mm_add_epi32(t2, t3);
      const __m128i sums = _mm_add_epi32(_mm_unpacklo_epi64(s01, s23), _mm_unpackhi_epi64(s01, s23));
      alignas(16) std::uint32_t lanes[group];
      _mm_store_si128(reinterpret_cast<__m128i*>(lanes), sums);
      for (std::size_t g = 0; g < group; ++g) out[g] = static_cast<T>(lanes[g]);
      return;
    }
#endif
    for (std::size_t g = 0; g < group; ++g) {
      std::uint32_t sum = 0;
      for (std::size_t i = 0; i < dim_; ++i) {
        const std::int32_t d = std::int32_t{q_[i]} - std::int32_t{r[g][i]};
        sum += static_cast<std::uint32_t>(d * d);
      }
      out[g] = static_cast<T>(sum);
    }
  }

 private:
#if defined(__SSE2__)
  static __m128i load(const std::uint16_t* p) {
    return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p));
  }
  __m128i tail_mask_;
#endif
  const std::uint16_t* rows_;
  std::size_t dim_;
  const std::uint16_t* q_;
};

}  // namespace kdspace::detail
