// The blocked scan of include/kdspace/points/detail/blocked_scan.hpp: matrix products of blocks of
// points against blocks of queries, then either exact integer distances (small-integer data) or
// estimates with a rounding bound and an exact re-check of the candidates (any other data).
//
// Small-integer data (bytes, SIFT descriptors, 8- to 12-bit images): when every coordinate of the
// points and of the queries is an integer and the squared extents of the data add up to less than
// 2^24, each coordinate is shifted by the lowest value on its axis, stored as a
// 16-bit integer, and the dot products are summed exactly in 32-bit integers. |x - q|^2 = |x|^2 +
// |q|^2 - 2 x.q is then exact, and so is internal_distance() on the same points: every term and
// every partial sum is an integer below 2^24, exact in float. The answer needs no bound and no
// re-check, and the 16-bit product (vpmaddwd: 16 multiply-adds an instruction with AVX2) does twice
// the work of a float one a cycle.
//
// Other data: the bound. Let x' and q' be the centred coordinates as rounded, N = |x'|^2 + |q'|^2
// (as computed), u the unit roundoff (epsilon / 2) and d the dimension. The estimate a = |x'|^2 +
// |q'|^2 - 2 x'.q' differs from |x' - q'|^2 by at most about (2 gamma_d + 6u) N (each norm and the
// dot product are sums of d products, whatever order the product kernel adds them in and with or
// without fused multiply-adds, plus three roundings in the combination); the centring moves
// |x - q|^2 by at most about 4u N; internal_distance() differs from the true |x - q|^2 by at most
// gamma_d * 2N. All together under (4d + 16) u N; we use twice that, (4d + 32) epsilon N, plus
// (4d + 32) times the smallest normal number for underflow in tiny data.
//
// Both products have kernels for AVX-512 (float: AVX-512F; 16-bit: AVX-512BW + VNNI, whose
// vpdpwssd does the multiply-adds and the sum in one instruction) and for AVX2 (+FMA for float),
// the widest the processor has chosen at run time, and a portable one (Eigen for float and double,
// plain loops for the integers). The bound above holds whatever the order of the sums, so for every
// kernel. On a processor that runs 512-bit instructions at full width the AVX-512 kernels do about
// twice the work a cycle (kdspace-scan-bench on an AMD EPYC: 1.8x the AVX2 kernel on float data,
// 2.1-2.3x on bytes). The loop
// order: points in blocks of point_block rows outside, so that each point block is converted and
// its norms taken once per call, queries in blocks of query_block inside.
#include "kdspace/points/detail/blocked_scan.hpp"

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/detail/result_sets.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define KDSPACE_X86_KERNELS 1
#include <immintrin.h>
#endif

namespace kdspace::detail {
namespace {

// Points per block (the product's rows; a multiple of 16, the kernels' tile) and queries per block.
// A block of 1024 points of 128 floats takes 512 KiB, of 128 16-bit integers 256 KiB: it stays in
// the second-level cache while every query block goes past it.
constexpr std::size_t point_block = 1024;
constexpr std::size_t query_block = 48;  // a multiple of tile_queries and of wide_queries
constexpr std::size_t tile_points = 16;  // the kernels' register tile: 16 points x 6 queries
constexpr std::size_t tile_queries = 6;
// The AVX-512 kernels' tile: 32 points (two packed tiles) x 12 queries.
constexpr std::size_t wide_points = 32;
constexpr std::size_t wide_queries = 12;
constexpr std::size_t query_padding = 12;  // query rows are padded to a multiple of both tiles' queries

bool has_avx2() {
#if defined(KDSPACE_X86_KERNELS)
  static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return yes;
#else
  return false;
#endif
}

// AVX-512: twice the lanes, and 32 registers for a tile of 32 points x 12 queries. The 16-bit
// kernel needs VNNI (vpdpwssd: the multiply-adds and the sum in one instruction).
bool has_avx512_float() {
#if defined(KDSPACE_X86_KERNELS)
  static const bool yes = __builtin_cpu_supports("avx512f");
  return yes;
#else
  return false;
#endif
}

bool has_avx512_int16() {
#if defined(KDSPACE_X86_KERNELS)
  static const bool yes = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                          __builtin_cpu_supports("avx512vnni");
  return yes;
#else
  return false;
#endif
}

// ---- products of a block of points with a block of queries -------------------------------------
// Points are packed in tiles of 16: tile t holds, axis after axis, that axis's coordinate of its 16
// points (for the 16-bit integers two axes at once, as the pair (a, a + 1) of each point), so that the
// kernel reads a tile front to back and one vector load takes one coordinate of 8 points; queries stay
// row by row and each coordinate is broadcast. The AVX2 kernels keep a tile of 16 points x up to 6
// queries in registers and, rather than storing the products, turn them into distances (or lower
// bounds) at once and compare them with each query's current limit: only the few points that pass
// reach the caller's scalar code (`take`), so the selection costs a vector comparison per 8 entries.

/// Offset of point i's coordinate a (or pair of coordinates) in a packed block.
inline std::size_t packed_at(std::size_t i, std::size_t a, std::size_t width) {
  return (i / tile_points) * width * tile_points + a * tile_points + i % tile_points;
}

#if defined(KDSPACE_X86_KERNELS)
/// Calls take(j, first + i, lanes[i], extra[i]...) for each set bit i of mask: the entries of query
/// j's row of a tile that passed its test.
template <class Value, class Take, class... Extra>
inline void take_lanes(unsigned mask, std::size_t j, std::size_t first, const Value* lanes, Take& take,
                       const Extra*... extra) {
  for (; mask != 0; mask &= mask - 1) {
    const unsigned lane = static_cast<unsigned>(__builtin_ctz(mask));
    take(j, first + lane, lanes[lane], extra[lane]...);
  }
}

// The products of one tile of 16 points with 6 queries, in 12 registers named one by one: held in an
// array, GCC keeps the accumulators in memory and stores them at every step.
#define KDSPACE_TILE_ACCUMULATORS(type, zero) \
  type c00 = zero, c01 = zero, c10 = zero, c11 = zero, c20 = zero, c21 = zero, c30 = zero, c31 = zero, c40 = zero, \
       c41 = zero, c50 = zero, c51 = zero
#define KDSPACE_TILE_STORE(store, out)                                                                          \
  store(out[0], c00), store(out[0] + 8, c01), store(out[1], c10), store(out[1] + 8, c11), store(out[2], c20), \
      store(out[2] + 8, c21), store(out[3], c30), store(out[3] + 8, c31), store(out[4], c40),                 \
      store(out[4] + 8, c41), store(out[5], c50), store(out[5] + 8, c51)

/// Float tile: for each query j < 6 and point i of the tile, the estimate e = (|p|^2 + |q|^2) - 2 p.q
/// and its margin m = scale (|p|^2 + |q|^2) + floor; take(j, i, e, m) where e - m <= limit[j]. The
/// query rows q (6 of them, d apart) may be padding: the caller ignores what it takes from those.
template <class Take>
__attribute__((target("avx2,fma"))) void float_tile(const float* tile, const float* q, std::size_t d,
                                                     const float* p_norm, const float* q_norm, const float* limit,
                                                     float scale, float floor, Take& take) {
  const __m256 zero = _mm256_setzero_ps();
  KDSPACE_TILE_ACCUMULATORS(__m256, zero);
  const float *q0 = q, *q1 = q + d, *q2 = q + 2 * d, *q3 = q + 3 * d, *q4 = q + 4 * d, *q5 = q + 5 * d;
  for (std::size_t a = 0; a < d; ++a) {
    const __m256 p0 = _mm256_loadu_ps(tile + a * tile_points), p1 = _mm256_loadu_ps(tile + a * tile_points + 8);
    __m256 b = _mm256_broadcast_ss(q0 + a);
    c00 = _mm256_fmadd_ps(p0, b, c00), c01 = _mm256_fmadd_ps(p1, b, c01);
    b = _mm256_broadcast_ss(q1 + a);
    c10 = _mm256_fmadd_ps(p0, b, c10), c11 = _mm256_fmadd_ps(p1, b, c11);
    b = _mm256_broadcast_ss(q2 + a);
    c20 = _mm256_fmadd_ps(p0, b, c20), c21 = _mm256_fmadd_ps(p1, b, c21);
    b = _mm256_broadcast_ss(q3 + a);
    c30 = _mm256_fmadd_ps(p0, b, c30), c31 = _mm256_fmadd_ps(p1, b, c31);
    b = _mm256_broadcast_ss(q4 + a);
    c40 = _mm256_fmadd_ps(p0, b, c40), c41 = _mm256_fmadd_ps(p1, b, c41);
    b = _mm256_broadcast_ss(q5 + a);
    c50 = _mm256_fmadd_ps(p0, b, c50), c51 = _mm256_fmadd_ps(p1, b, c51);
  }
  alignas(32) float dots[tile_queries][tile_points];
  KDSPACE_TILE_STORE(_mm256_store_ps, dots);
  const __m256 two = _mm256_set1_ps(2), scale_v = _mm256_set1_ps(scale), floor_v = _mm256_set1_ps(floor);
  for (std::size_t j = 0; j < tile_queries; ++j) {
    const __m256 qn = _mm256_set1_ps(q_norm[j]), lim = _mm256_set1_ps(limit[j]);
    for (std::size_t h = 0; h < 2; ++h) {
      const __m256 sum = _mm256_add_ps(_mm256_loadu_ps(p_norm + 8 * h), qn);
      const __m256 estimate = _mm256_sub_ps(sum, _mm256_mul_ps(two, _mm256_load_ps(dots[j] + 8 * h)));
      const __m256 margin = _mm256_add_ps(_mm256_mul_ps(scale_v, sum), floor_v);
      const unsigned pass = static_cast<unsigned>(
          _mm256_movemask_ps(_mm256_cmp_ps(_mm256_sub_ps(estimate, margin), lim, _CMP_LE_OQ)));
      if (pass == 0) continue;
      alignas(32) float e[8], m[8];
      _mm256_store_ps(e, estimate);
      _mm256_store_ps(m, margin);
      take_lanes(pass, j, 8 * h, e, take, m);
    }
  }
}

__attribute__((target("avx2"))) inline void store_int32(std::int32_t* at, __m256i v) {
  _mm256_store_si256(reinterpret_cast<__m256i*>(at), v);
}

/// 16-bit tile: the exact distance dist = |p|^2 + |q|^2 - 2 p.q; take(j, i, dist) where dist <=
/// limit[j]. The query rows (6, q_stride apart) may be padding, as in float_tile.
template <class Take>
__attribute__((target("avx2"))) void int16_tile(const std::int16_t* tile, const std::int16_t* q, std::size_t pairs,
                                                std::size_t q_stride, const std::int32_t* p_norm,
                                                const std::int32_t* q_norm, const std::int32_t* limit, Take& take) {
  const __m256i zero = _mm256_setzero_si256();
  KDSPACE_TILE_ACCUMULATORS(__m256i, zero);
  auto pair_of = [q, q_stride](std::size_t j, std::size_t a) {
    std::int32_t pair;
    std::memcpy(&pair, q + j * q_stride + 2 * a, sizeof pair);
    return pair;
  };
  for (std::size_t a = 0; a < pairs; ++a) {
    const std::int16_t* p = tile + 2 * a * tile_points;
    const __m256i p0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
    const __m256i p1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p + 16));
    __m256i b = _mm256_set1_epi32(pair_of(0, a));
    c00 = _mm256_add_epi32(c00, _mm256_madd_epi16(p0, b)), c01 = _mm256_add_epi32(c01, _mm256_madd_epi16(p1, b));
    b = _mm256_set1_epi32(pair_of(1, a));
    c10 = _mm256_add_epi32(c10, _mm256_madd_epi16(p0, b)), c11 = _mm256_add_epi32(c11, _mm256_madd_epi16(p1, b));
    b = _mm256_set1_epi32(pair_of(2, a));
    c20 = _mm256_add_epi32(c20, _mm256_madd_epi16(p0, b)), c21 = _mm256_add_epi32(c21, _mm256_madd_epi16(p1, b));
    b = _mm256_set1_epi32(pair_of(3, a));
    c30 = _mm256_add_epi32(c30, _mm256_madd_epi16(p0, b)), c31 = _mm256_add_epi32(c31, _mm256_madd_epi16(p1, b));
    b = _mm256_set1_epi32(pair_of(4, a));
    c40 = _mm256_add_epi32(c40, _mm256_madd_epi16(p0, b)), c41 = _mm256_add_epi32(c41, _mm256_madd_epi16(p1, b));
    b = _mm256_set1_epi32(pair_of(5, a));
    c50 = _mm256_add_epi32(c50, _mm256_madd_epi16(p0, b)), c51 = _mm256_add_epi32(c51, _mm256_madd_epi16(p1, b));
  }
  alignas(32) std::int32_t dots[tile_queries][tile_points];
  KDSPACE_TILE_STORE(store_int32, dots);
  for (std::size_t j = 0; j < tile_queries; ++j) {
    const __m256i qn = _mm256_set1_epi32(q_norm[j]), lim = _mm256_set1_epi32(limit[j]);
    for (std::size_t h = 0; h < 2; ++h) {
      const __m256i sum = _mm256_add_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p_norm + 8 * h)), qn);
      const __m256i dot = _mm256_load_si256(reinterpret_cast<const __m256i*>(dots[j] + 8 * h));
      const __m256i dist = _mm256_sub_epi32(sum, _mm256_add_epi32(dot, dot));
      const unsigned pass = ~static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(dist, lim)))) & 0xffu;
      if (pass == 0) continue;
      alignas(32) std::int32_t value[8];
      _mm256_store_si256(reinterpret_cast<__m256i*>(value), dist);
      take_lanes(pass, j, 8 * h, value, take);
    }
  }
}
#undef KDSPACE_TILE_ACCUMULATORS
#undef KDSPACE_TILE_STORE

// The AVX-512 tiles: 32 points (two packed tiles, 16 d apart) x 12 queries, 24 accumulators. Queries
// come interleaved (interleave_queries): axis a of the 12 queries at q[12 a .. 12 a + 12), so that
// every broadcast reads at a fixed offset from one pointer.
#define KDSPACE_FOR_12(M) M(0) M(1) M(2) M(3) M(4) M(5) M(6) M(7) M(8) M(9) M(10) M(11)

/// As float_tile, on 32 points x 12 interleaved queries.
template <class Take>
__attribute__((target("avx512f"))) void float_tile_wide(const float* tile, const float* q, std::size_t d,
                                                         const float* p_norm, const float* q_norm, const float* limit,
                                                         float scale, float floor, Take& take) {
#define KDSPACE_DECLARE(j) __m512 c##j##0 = _mm512_setzero_ps(), c##j##1 = _mm512_setzero_ps();
#define KDSPACE_STEP(j)                                     \
  b = _mm512_set1_ps(qa[j]);                                \
  c##j##0 = _mm512_fmadd_ps(p0, b, c##j##0);                \
  c##j##1 = _mm512_fmadd_ps(p1, b, c##j##1);
#define KDSPACE_STORE(j) _mm512_store_ps(dots[j], c##j##0), _mm512_store_ps(dots[j] + 16, c##j##1);
  KDSPACE_FOR_12(KDSPACE_DECLARE)
  const float* second = tile + tile_points * d;
  for (std::size_t a = 0; a < d; ++a) {
    const __m512 p0 = _mm512_loadu_ps(tile + a * tile_points), p1 = _mm512_loadu_ps(second + a * tile_points);
    const float* qa = q + a * wide_queries;
    __m512 b;
    KDSPACE_FOR_12(KDSPACE_STEP)
  }
  alignas(64) float dots[wide_queries][wide_points];
  KDSPACE_FOR_12(KDSPACE_STORE)
  const __m512 two = _mm512_set1_ps(2), scale_v = _mm512_set1_ps(scale), floor_v = _mm512_set1_ps(floor);
  for (std::size_t j = 0; j < wide_queries; ++j) {
    const __m512 qn = _mm512_set1_ps(q_norm[j]), lim = _mm512_set1_ps(limit[j]);
    for (std::size_t h = 0; h < 2; ++h) {
      const __m512 sum = _mm512_add_ps(_mm512_loadu_ps(p_norm + 16 * h), qn);
      const __m512 estimate = _mm512_sub_ps(sum, _mm512_mul_ps(two, _mm512_load_ps(dots[j] + 16 * h)));
      const __m512 margin = _mm512_add_ps(_mm512_mul_ps(scale_v, sum), floor_v);
      const unsigned pass = _mm512_cmp_ps_mask(_mm512_sub_ps(estimate, margin), lim, _CMP_LE_OQ);
      if (pass == 0) continue;
      alignas(64) float e[16], m[16];
      _mm512_store_ps(e, estimate);
      _mm512_store_ps(m, margin);
      take_lanes(pass, j, 16 * h, e, take, m);
    }
  }
#undef KDSPACE_DECLARE
#undef KDSPACE_STEP
#undef KDSPACE_STORE
}

/// As int16_tile, on 32 points x 12 interleaved queries (q: the pairs of axes as 32-bit words).
template <class Take>
__attribute__((target("avx512f,avx512bw,avx512vnni"))) void int16_tile_wide(
    const std::int16_t* tile, const std::int32_t* q, std::size_t pairs, const std::int32_t* p_norm,
    const std::int32_t* q_norm, const std::int32_t* limit, Take& take) {
#define KDSPACE_DECLARE(j) __m512i c##j##0 = _mm512_setzero_si512(), c##j##1 = _mm512_setzero_si512();
#define KDSPACE_STEP(j)                                  \
  b = _mm512_set1_epi32(qa[j]);                          \
  c##j##0 = _mm512_dpwssd_epi32(c##j##0, p0, b);         \
  c##j##1 = _mm512_dpwssd_epi32(c##j##1, p1, b);
#define KDSPACE_STORE(j) _mm512_store_si512(dots[j], c##j##0), _mm512_store_si512(dots[j] + 16, c##j##1);
  KDSPACE_FOR_12(KDSPACE_DECLARE)
  const std::int16_t* second = tile + 2 * tile_points * pairs;
  for (std::size_t a = 0; a < pairs; ++a) {
    const __m512i p0 = _mm512_loadu_si512(tile + 2 * a * tile_points);
    const __m512i p1 = _mm512_loadu_si512(second + 2 * a * tile_points);
    const std::int32_t* qa = q + a * wide_queries;
    __m512i b;
    KDSPACE_FOR_12(KDSPACE_STEP)
  }
  alignas(64) std::int32_t dots[wide_queries][wide_points];
  KDSPACE_FOR_12(KDSPACE_STORE)
  for (std::size_t j = 0; j < wide_queries; ++j) {
    const __m512i qn = _mm512_set1_epi32(q_norm[j]), lim = _mm512_set1_epi32(limit[j]);
    for (std::size_t h = 0; h < 2; ++h) {
      const __m512i sum = _mm512_add_epi32(_mm512_loadu_si512(p_norm + 16 * h), qn);
      const __m512i dot = _mm512_load_si512(dots[j] + 16 * h);
      const __m512i dist = _mm512_sub_epi32(sum, _mm512_add_epi32(dot, dot));
      const unsigned pass = _mm512_cmple_epi32_mask(dist, lim);
      if (pass == 0) continue;
      alignas(64) std::int32_t value[16];
      _mm512_store_si512(value, dist);
      take_lanes(pass, j, 16 * h, value, take);
    }
  }
#undef KDSPACE_DECLARE
#undef KDSPACE_STEP
#undef KDSPACE_STORE
}
#undef KDSPACE_FOR_12

/// Queries rows (count a multiple of 12, `width` values each) interleaved for the AVX-512 tiles: the
/// 12 queries of group g, axis a, at [g * width * 12 + a * 12, + 12).
template <class V>
std::vector<V> interleave_queries(const V* rows, std::size_t count, std::size_t width) {
  std::vector<V> out(count * width);
  for (std::size_t j = 0; j < count; ++j)
    for (std::size_t a = 0; a < width; ++a)
      out[(j / wide_queries) * width * wide_queries + a * wide_queries + j % wide_queries] = rows[j * width + a];
  return out;
}

/// Runs tile(i, j) over every tile of step_points points (i) and step_queries queries (j; the query
/// rows are padded up to a multiple of step_queries):
/// queries in blocks of query_block (a block's rows stay in the first-level cache), each block
/// against every tile of the point block (which stays in the second-level cache).
template <class Tile>
void for_each_tile(std::size_t points, std::size_t nq, std::size_t step_points, std::size_t step_queries,
                   Tile&& tile) {
  for (std::size_t j0 = 0; j0 < nq; j0 += query_block) {
    const std::size_t j_end = std::min(nq, j0 + query_block);
    for (std::size_t i = 0; i < points; i += step_points)
      for (std::size_t j = j0; j < j_end; j += step_queries) tile(i, j);
  }
}
#endif


/// Portable product of a packed point block (tiles of 16 points, axis by axis) with bq query rows:
/// dots[j * points + i] = <point i, query j>, by Eigen on each tile.
template <class T>
void product(const T* packed, std::size_t points, std::size_t d, const T* queries, std::size_t bq, T* dots) {
  using Matrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor>;
  const Eigen::Map<const Matrix> q(queries, static_cast<Eigen::Index>(d), static_cast<Eigen::Index>(bq));
  Eigen::Map<Matrix, 0, Eigen::OuterStride<>> out(dots, static_cast<Eigen::Index>(points), static_cast<Eigen::Index>(bq),
                                                  Eigen::OuterStride<>(static_cast<Eigen::Index>(points)));
  for (std::size_t t = 0; t < points; t += tile_points) {
    // Tile t: tile_points rows (points) by d columns (axes), column-major.
    const Eigen::Map<const Matrix> p(packed + t * d, static_cast<Eigen::Index>(tile_points), static_cast<Eigen::Index>(d));
    out.middleRows(static_cast<Eigen::Index>(t), static_cast<Eigen::Index>(tile_points)).noalias() = p * q;
  }
}

// ---- the scan ------------------------------------------------------------------------------------

/// Adds the time since the last lap to one of the profile's phases; does nothing without a profile.
class Laps {
 public:
  explicit Laps(ScanProfile* profile) : profile_(profile) {
    if (profile_) last_ = std::chrono::steady_clock::now();
  }
  void lap(double ScanProfile::*phase) {
    if (!profile_) return;
    const auto now = std::chrono::steady_clock::now();
    profile_->*phase += std::chrono::duration<double>(now - last_).count();
    last_ = now;
  }

 private:
  ScanProfile* profile_;
  std::chrono::steady_clock::time_point last_;
};

template <class T, class U>
void exact_scan(const ScanData<T>& data, const U* rows, const T* q, std::size_t k, Neighbor<T>* out) {
  std::vector<Candidate<T>> storage;
  KnnResults<T> results(k, std::numeric_limits<T>::infinity(), storage);
  for (std::size_t i = 0; i < data.n; ++i)
    results.offer(internal_distance<L2>(q, rows + i * data.dim, data.dim), data.order[i]);
  for (const auto& c : results.sorted()) *out++ = Neighbor<T>{c.index, L2::to_distance(c.dist)};
}

template <class T>
void write_answer(std::vector<Candidate<T>>& sorted, Neighbor<T>* out) {
  for (const auto& c : sorted) *out++ = Neighbor<T>{c.index, L2::to_distance(c.dist)};
}

// Sum over axes of the largest squared centred coordinate, in double: whether estimates may overflow.
template <class T, class U>
double centred_norm_bound(const U* row, const T* centre, std::size_t dim) {
  double s = 0;
  for (std::size_t a = 0; a < dim; ++a) {
    const double v = static_cast<double>(row[a]) - static_cast<double>(centre[a]);
    s += v * v;
  }
  return s;
}

/// The per-axis lowest value (`offset`) of the points and the queries when every coordinate of both
/// is an integer and the squared extents add up to less than `limit`; empty otherwise.
template <class T, class U>
std::vector<T> small_integer_offsets(const ScanData<T>& data, const U* rows, const T* queries, std::size_t nq,
                                     double limit) {
  const std::size_t d = data.dim;
  std::vector<double> lo(d, std::numeric_limits<double>::infinity()), hi(d, -std::numeric_limits<double>::infinity());
  auto take = [&](const auto* x, std::size_t count) {
    for (std::size_t i = 0; i < count; ++i)
      for (std::size_t a = 0; a < d; ++a) {
        const double v = static_cast<double>(x[i * d + a]);
        // An integer, exact in float (NaN fails the first test). Not std::floor: without SSE4.1 it is
        // a library call, and this check reads every coordinate of every call.
        if (!(std::abs(v) < 16777216.0) || static_cast<double>(static_cast<std::int32_t>(v)) != v) return false;
        lo[a] = std::min(lo[a], v);
        hi[a] = std::max(hi[a], v);
      }
    return true;
  };
  if (!take(rows, data.n) || !take(queries, nq)) return {};
  double extent = 0;
  for (std::size_t a = 0; a < d; ++a) extent += (hi[a] - lo[a]) * (hi[a] - lo[a]);
  if (!(extent < limit)) return {};
  return std::vector<T>(lo.begin(), lo.end());
}

/// The k-NN of one query kept across blocks: KnnResults' max-heap on (distance, index).
template <class T>
struct Kept {
  std::vector<Candidate<T>> heap;
  /// Offers c; returns the largest distance still worth offering (the k-th kept, once k are kept).
  T offer(Candidate<T> c, std::size_t k, T limit) {
    if (heap.size() < k) {
      heap.push_back(c);
      std::push_heap(heap.begin(), heap.end(), comes_before);
    } else if (comes_before(c, heap.front())) {
      std::pop_heap(heap.begin(), heap.end(), comes_before);
      heap.back() = c;
      std::push_heap(heap.begin(), heap.end(), comes_before);
    }
    return heap.size() == k ? heap.front().dist : limit;
  }
};

/// Exact distances of small-integer data (see the top of this file) by 16-bit integer products.
template <class T, class U>
void scan_small_integers(const ScanData<T>& data, const U* rows, const T* queries, std::size_t nq, std::size_t k,
                         const std::vector<T>& offset, Neighbor<T>* out) {
  const std::size_t d = data.dim, n = data.n, q_stride = d + (d % 2), pairs = q_stride / 2;
  auto shifted = [&](auto value, std::size_t a) {
    return static_cast<std::int16_t>(static_cast<T>(value) - offset[a]);  // an integer in [0, 4096)
  };
  // Rows padded with zeros up to a multiple of the kernels' queries; what they find is dropped.
  const std::size_t nq_padded = (nq + query_padding - 1) / query_padding * query_padding;
  std::vector<std::int16_t> q16(nq_padded * q_stride, 0);
  std::vector<std::int32_t> q_norm(nq_padded, 0);
  for (std::size_t j = 0; j < nq; ++j)
    for (std::size_t a = 0; a < d; ++a) {
      const std::int16_t v = shifted(queries[j * d + a], a);
      q16[j * q_stride + a] = v;
      q_norm[j] += std::int32_t{v} * v;
    }
  [[maybe_unused]] const bool wide = data.widest == ScanKernel::avx512 && has_avx512_int16();
  [[maybe_unused]] const bool avx2 = data.widest != ScanKernel::portable && has_avx2();
  std::vector<std::int32_t> q_wide;  // the queries' pairs of axes, interleaved for the AVX-512 tile
  if (wide) {
    std::vector<std::int32_t> q_pairs(nq_padded * pairs);
    std::memcpy(q_pairs.data(), q16.data(), q16.size() * sizeof(std::int16_t));
    q_wide = interleave_queries(q_pairs.data(), nq_padded, pairs);
  }
  // Each query's limit: the k-th distance kept so far (every distance is below 2^24).
  std::vector<std::int32_t> limit(nq_padded, std::numeric_limits<std::int32_t>::max());
  std::vector<Kept<T>> kept(nq);
  std::vector<std::int16_t> packed(point_block * q_stride);
  std::vector<std::int32_t> p_norm(point_block);
  Laps laps(data.profile);
  std::size_t offered = 0;
  for (std::size_t p0 = 0; p0 < n; p0 += point_block) {
    laps.lap(&ScanProfile::product_s);
    const std::size_t bp = std::min(point_block, n - p0);
    const std::size_t step = wide ? wide_points : tile_points;  // the kernel's tile of points
    const std::size_t padded = (bp + step - 1) / step * step;
    std::fill(packed.begin(), packed.end(), std::int16_t{0});
    std::fill(p_norm.begin(), p_norm.end(), std::numeric_limits<std::int32_t>::max() / 2);  // padding: far
    for (std::size_t i = 0; i < bp; ++i) {
      std::int32_t norm = 0;
      for (std::size_t a = 0; a < d; ++a) {
        const std::int16_t v = shifted(rows[(p0 + i) * d + a], a);
        packed[2 * packed_at(i, a / 2, pairs) + a % 2] = v;
        norm += std::int32_t{v} * v;
      }
      p_norm[i] = norm;
    }
    laps.lap(&ScanProfile::prepare_s);
    auto take = [&](std::size_t j, std::size_t i, std::int32_t dist) {
      if (i >= bp || j >= nq) return;
      ++offered;
      const T worst = kept[j].offer({static_cast<T>(dist), data.order[p0 + i]}, k, std::numeric_limits<T>::infinity());
      limit[j] = worst < T(2147483647) ? static_cast<std::int32_t>(worst) : limit[j];
    };
#if defined(KDSPACE_X86_KERNELS)
    if (wide) {
      for_each_tile(padded, nq, wide_points, wide_queries, [&](std::size_t i, std::size_t j) {
        auto take_here = [&](std::size_t jj, std::size_t ii, std::int32_t dist) { take(j + jj, i + ii, dist); };
        int16_tile_wide(packed.data() + 2 * i * pairs, q_wide.data() + j * pairs, pairs, p_norm.data() + i,
                        q_norm.data() + j, limit.data() + j, take_here);
      });
      continue;
    }
    if (avx2) {
      for_each_tile(padded, nq, tile_points, tile_queries, [&](std::size_t i, std::size_t j) {
        auto take_here = [&](std::size_t jj, std::size_t ii, std::int32_t dist) { take(j + jj, i + ii, dist); };
        int16_tile(packed.data() + 2 * i * pairs, q16.data() + j * q_stride, pairs, q_stride, p_norm.data() + i,
                   q_norm.data() + j, limit.data() + j, take_here);
      });
      continue;
    }
#endif
    for (std::size_t j = 0; j < nq; ++j)
      for (std::size_t i = 0; i < bp; ++i) {
        std::int32_t dot = 0;
        for (std::size_t a = 0; a < d; ++a) dot += std::int32_t{packed[2 * packed_at(i, a / 2, pairs) + a % 2]} * q16[j * q_stride + a];
        const std::int32_t dist = p_norm[i] + q_norm[j] - 2 * dot;
        if (dist <= limit[j]) take(j, i, dist);
      }
  }
  laps.lap(&ScanProfile::product_s);
  for (std::size_t j = 0; j < nq; ++j) {
    std::sort_heap(kept[j].heap.begin(), kept[j].heap.end(), comes_before);
    write_answer(kept[j].heap, out + j * k);
  }
  laps.lap(&ScanProfile::recheck_s);
  if (data.profile) data.profile->candidates += offered, data.profile->integer_path = true;
}

/// One query's running state in the estimated scan: the k smallest upper bounds seen (a max-heap)
/// and the rows that may be among its k nearest.
template <class T>
struct QueryState {
  std::vector<T> upper;
  std::vector<std::uint32_t> rows;
};

// The scan on estimates, bound and re-check, on rows held as T or as bytes (converted to T exactly
// where they are read).
template <class T, class U>
void scan_estimated(const ScanData<T>& data, const U* rows, const T* queries, std::size_t nq, std::size_t k,
                    Neighbor<T>* out) {
  const std::size_t d = data.dim, n = data.n;
  const T scale = static_cast<T>(4 * d + 32) * std::numeric_limits<T>::epsilon();
  const T floor = static_cast<T>(4 * d + 32) * std::numeric_limits<T>::min();
  // Centred queries, row by row, and their norms; rows padded with zeros up to a multiple of the
  // kernel's 6 queries (what they find is dropped).
  const std::size_t nq_padded = (nq + query_padding - 1) / query_padding * query_padding;
  std::vector<T> qc(nq_padded * d, T(0)), q_norm(nq_padded, T(0));
  for (std::size_t j = 0; j < nq; ++j) {
    T norm = 0;
    for (std::size_t a = 0; a < d; ++a) {
      const T v = queries[j * d + a] - data.centre[a];
      qc[j * d + a] = v;
      norm += v * v;
    }
    q_norm[j] = norm;
  }
  const bool wide = std::is_same_v<T, float> && data.widest == ScanKernel::avx512 && has_avx512_float();
  [[maybe_unused]] const bool avx2 = data.widest != ScanKernel::portable && has_avx2();
  const std::vector<T> q_wide = wide ? interleave_queries(qc.data(), nq_padded, d) : std::vector<T>();
  // Each query's limit: a point is a candidate unless its estimate minus margin exceeds the k-th
  // smallest estimate plus margin seen so far.
  std::vector<T> limit(nq_padded, std::numeric_limits<T>::infinity());
  std::vector<QueryState<T>> state(nq);
  std::vector<T> packed(point_block * d), p_norm(point_block), dots;
  Laps laps(data.profile);
  for (std::size_t p0 = 0; p0 < n; p0 += point_block) {
    laps.lap(&ScanProfile::product_s);
    const std::size_t bp = std::min(point_block, n - p0);
    const std::size_t step = wide ? wide_points : tile_points;  // the kernel's tile of points
    const std::size_t padded = (bp + step - 1) / step * step;
    std::fill(packed.begin(), packed.end(), T(0));
    std::fill(p_norm.begin(), p_norm.end(), T(0));
    for (std::size_t i = 0; i < bp; ++i) {
      const U* p = rows + (p0 + i) * d;
      T norm = 0;
      for (std::size_t a = 0; a < d; ++a) {
        const T v = static_cast<T>(p[a]) - data.centre[a];
        packed[packed_at(i, a, d)] = v;
        norm += v * v;
      }
      p_norm[i] = norm;
    }
    laps.lap(&ScanProfile::prepare_s);
    auto take = [&](std::size_t j, std::size_t i, T estimate, T margin) {
      if (i >= bp || j >= nq || estimate - margin > limit[j]) return;
      QueryState<T>& s = state[j];
      s.rows.push_back(static_cast<std::uint32_t>(p0 + i));
      const T upper = estimate + margin;
      if (s.upper.size() < k) {
        s.upper.push_back(upper);
        std::push_heap(s.upper.begin(), s.upper.end());
      } else if (upper < s.upper.front()) {
        std::pop_heap(s.upper.begin(), s.upper.end());
        s.upper.back() = upper;
        std::push_heap(s.upper.begin(), s.upper.end());
      }
      if (s.upper.size() == k) limit[j] = s.upper.front();
    };
#if defined(KDSPACE_X86_KERNELS)
    if constexpr (std::is_same_v<T, float>) {
      if (wide) {
        for_each_tile(padded, nq, wide_points, wide_queries, [&](std::size_t i, std::size_t j) {
          auto take_here = [&](std::size_t jj, std::size_t ii, float e, float m) { take(j + jj, i + ii, e, m); };
          float_tile_wide(packed.data() + i * d, q_wide.data() + j * d, d, p_norm.data() + i, q_norm.data() + j,
                          limit.data() + j, scale, floor, take_here);
        });
        continue;
      }
      if (avx2) {
        for_each_tile(padded, nq, tile_points, tile_queries, [&](std::size_t i, std::size_t j) {
          auto take_here = [&](std::size_t jj, std::size_t ii, float e, float m) { take(j + jj, i + ii, e, m); };
          float_tile(packed.data() + i * d, qc.data() + j * d, d, p_norm.data() + i, q_norm.data() + j,
                     limit.data() + j, scale, floor, take_here);
        });
        continue;
      }
    }
#endif
    // Portable: the products of the whole block by Eigen, then the same selection.
    dots.resize(query_block * padded);
    for (std::size_t j0 = 0; j0 < nq; j0 += query_block) {
      const std::size_t bq = std::min(query_block, nq - j0);
      product(packed.data(), padded, d, qc.data() + j0 * d, bq, dots.data());
      for (std::size_t j = 0; j < bq; ++j)
        for (std::size_t i = 0; i < bp; ++i) {
          const T sum = p_norm[i] + q_norm[j0 + j];
          take(j0 + j, i, sum - 2 * dots[j * padded + i], scale * sum + floor);
        }
    }
  }
  laps.lap(&ScanProfile::product_s);
  // The exact re-check: every point whose exact distance is within the k-th is a candidate.
  std::vector<Candidate<T>> storage;
  for (std::size_t j = 0; j < nq; ++j) {
    const T* q = queries + j * d;
    KnnResults<T> results(k, std::numeric_limits<T>::infinity(), storage);
    for (const std::uint32_t row : state[j].rows)
      results.offer(internal_distance<L2>(q, rows + static_cast<std::size_t>(row) * d, d), data.order[row]);
    write_answer(results.sorted(), out + j * k);
    if (data.profile) data.profile->candidates += state[j].rows.size();
  }
  laps.lap(&ScanProfile::recheck_s);
}

template <class T, class U>
void scan_rows(const ScanData<T>& data, const U* rows, const T* queries, std::size_t nq, std::size_t k,
               Neighbor<T>* out) {
  const std::size_t d = data.dim;
  // Small integers: exact 16-bit products. Below 2^24 the distances are exact in float (and every
  // extent is below 4096: the 16-bit values and their 32-bit sums cannot overflow).
  Laps laps(data.profile);
  const std::vector<T> offset = small_integer_offsets(data, rows, queries, nq, 16777216.0);
  laps.lap(&ScanProfile::check_s);
  if (!offset.empty()) return scan_small_integers(data, rows, queries, nq, k, offset, out);

  // Could an estimate overflow? The data's part is bounded from the largest centred row norm; the
  // product's entries are then bounded by the norms. A factor 16 of headroom. Queries that are too
  // far from the data for the estimate are answered by a plain exact scan.
  const double limit = static_cast<double>(std::numeric_limits<T>::max()) / 16;
  double data_norm = 0;
  for (std::size_t i = 0; i < data.n; ++i) data_norm = std::max(data_norm, centred_norm_bound(rows + i * d, data.centre, d));
  if (!(data_norm < limit)) {
    for (std::size_t q = 0; q < nq; ++q) exact_scan(data, rows, queries + q * d, k, out + q * k);
    return;
  }
  std::vector<T> kept_queries;
  std::vector<std::size_t> kept_index;
  for (std::size_t q = 0; q < nq; ++q) {
    const T* row = queries + q * d;
    if (centred_norm_bound(row, data.centre, d) < limit) {
      kept_queries.insert(kept_queries.end(), row, row + d);
      kept_index.push_back(q);
    } else {
      exact_scan(data, rows, row, k, out + q * k);  // absurdly large coordinates: no estimate
    }
  }
  laps.lap(&ScanProfile::check_s);
  if (kept_index.size() == nq) return scan_estimated(data, rows, queries, nq, k, out);
  std::vector<Neighbor<T>> answers(kept_index.size() * k);
  scan_estimated(data, rows, kept_queries.data(), kept_index.size(), k, answers.data());
  for (std::size_t i = 0; i < kept_index.size(); ++i)
    std::copy_n(answers.data() + i * k, k, out + kept_index[i] * k);
}

}  // namespace

template <class T>
void blocked_scan_knn_l2(const ScanData<T>& data, const T* queries, std::size_t nq, std::size_t k, Neighbor<T>* out) {
  if (data.bytes) scan_rows(data, data.bytes, queries, nq, k, out);
  else scan_rows(data, data.points, queries, nq, k, out);
}

template void blocked_scan_knn_l2<float>(const ScanData<float>&, const float*, std::size_t, std::size_t,
                                         Neighbor<float>*);
template void blocked_scan_knn_l2<double>(const ScanData<double>&, const double*, std::size_t, std::size_t,
                                          Neighbor<double>*);

}  // namespace kdspace::detail
