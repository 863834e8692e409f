// The leaf scan of 3-D float points under L2, four points a step with SSE2.
//
// Per point, internal_distance<L2>(q, p, 3) is ((q0 - p0)^2 + (q1 - p1)^2) + (q2 - p2)^2 (combine_axes
// adds three axes one by one from 0, and 0 + a square is that square). Here four consecutive points
// (twelve floats, three loads) are turned into one register per axis by seven shuffles, and the same
// subtractions, squares and additions run on the four lanes: the same bits as the scalar distance.
// A leaf of 4m + r points (r > 0) ends with the four points that end it, the r new ones unmasked, so
// no load leaves the leaf; leaves under four points keep the scalar loop.
//
// Measured (valgrind --tool=callgrind, 10 knn_batch calls of armadillo's 2,600 held-out queries on
// PointTree<float>, 1-NN, 31 points scored a query): 44.3M -> 41.4M instructions in all; building
// and kitten 1-NN and 10-NN 7-13% fewer. The scalar loop took about 26 instructions a scored point.
// The whole steps run in a loop of their own and the overlapping last step after it: with the tail's
// choice and mask in every step the loop took 4% more instructions (39.4M against 37.6M, 1-NN with
// NearestResults; 10-NN 138.0M against 135.0M).
#pragma once

#include <cstddef>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace kdspace::detail {

#if defined(__SSE2__)

/// The query's coordinates, each in all four lanes.
struct Query3Lanes {
  __m128 x, y, z;
};
[[gnu::always_inline]] inline Query3Lanes query3_lanes(const float* q) {
  return {_mm_set1_ps(q[0]), _mm_set1_ps(q[1]), _mm_set1_ps(q[2])};
}

/// The squared L2 distances from q to the four 3-D points at rows (twelve floats), lane j for point j,
/// bit for bit internal_distance<L2>(q, rows + 3 j, 3).
[[gnu::always_inline]] inline __m128 l2_distances3x4(const Query3Lanes& q, const float* rows) {
  const __m128 a = _mm_loadu_ps(rows);                                   // x0 y0 z0 x1
  const __m128 b = _mm_loadu_ps(rows + 4);                               // y1 z1 x2 y2
  const __m128 c = _mm_loadu_ps(rows + 8);                               // z2 x3 y3 z3
  const __m128 b2c1 = _mm_shuffle_ps(b, c, _MM_SHUFFLE(1, 1, 2, 2));     // x2 x2 x3 x3
  const __m128 x = _mm_shuffle_ps(a, b2c1, _MM_SHUFFLE(2, 0, 3, 0));     // x0 x1 x2 x3
  const __m128 a1b0 = _mm_shuffle_ps(a, b, _MM_SHUFFLE(0, 0, 1, 1));     // y0 y0 y1 y1
  const __m128 b3c2 = _mm_shuffle_ps(b, c, _MM_SHUFFLE(2, 2, 3, 3));     // y2 y2 y3 y3
  const __m128 y = _mm_shuffle_ps(a1b0, b3c2, _MM_SHUFFLE(2, 0, 2, 0));  // y0 y1 y2 y3
  const __m128 a2b1 = _mm_shuffle_ps(a, b, _MM_SHUFFLE(1, 1, 2, 2));     // z0 z0 z1 z1
  const __m128 z = _mm_shuffle_ps(a2b1, c, _MM_SHUFFLE(3, 0, 2, 0));     // z0 z1 z2 z3
  const __m128 dx = _mm_sub_ps(q.x, x), dy = _mm_sub_ps(q.y, y), dz = _mm_sub_ps(q.z, z);
  const __m128 xy = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy));
  return _mm_add_ps(xy, _mm_mul_ps(dz, dz));
}

/// Writes the squared L2 distances from q to the count >= 4 points at rows into dist[0, count).
inline void l2_distances3(const float* q, const float* rows, std::size_t count, float* dist) {
  const Query3Lanes lanes = query3_lanes(q);
  std::size_t i = 0;
  for (; i + 4 <= count; i += 4) _mm_storeu_ps(dist + i, l2_distances3x4(lanes, rows + 3 * i));
  // The last four points, overlapping the step before: the same values written again.
  if (i < count) _mm_storeu_ps(dist + count - 4, l2_distances3x4(lanes, rows + 3 * (count - 4)));
}

/// Offers to `results` every point of rows[0, count) (count >= 4; index: their original indices)
/// whose distance is at most results.bound(), four points a step: a step whose four distances all
/// exceed the bound (most of them, once the first leaf has been scanned) costs no branch per point.
template <class Results>
inline void scan_leaf3_l2(const float* q, const float* rows, const std::uint32_t* index, std::size_t count,
                          Results& results) {
  const Query3Lanes lanes = query3_lanes(q);
  __m128 worst = _mm_set1_ps(results.bound());
  // The points at..at+3, less the lanes outside `fresh` (offered by the step before).
  const auto step = [&](std::size_t at, unsigned fresh) {
    const __m128 dist = l2_distances3x4(lanes, rows + 3 * at);
    unsigned offered = static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(dist, worst))) & fresh;
    if (offered == 0) return;
    alignas(16) float d[4];
    _mm_store_ps(d, dist);
    do {
      const unsigned j = static_cast<unsigned>(__builtin_ctz(offered));
      offered &= offered - 1;
      results.offer(d[j], index[at + j]);
    } while (offered != 0);
    worst = _mm_set1_ps(results.bound());
  };
  std::size_t i = 0;
  for (; i + 4 <= count; i += 4) step(i, 0xfu);
  // The last four points, of which those before i were offered already.
  if (i < count) step(count - 4, (0xfu << (i - (count - 4))) & 0xfu);
}

#endif

}  // namespace kdspace::detail
