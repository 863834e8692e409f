// Ray traversal of the BoxTree: Havran's recursive near/far algorithm (TA^B_rec in his thesis
// "Heuristic Ray Shooting Algorithms", 2000), written with an explicit stack of (node, t_entry, t_exit).
//
// A node is entered with the interval [t_entry, t_exit] over which the ray lies in its cell. The ray
// crosses the split plane at t_split; the child on the side the ray comes from (the near child) is
// visited first, over [t_entry, t_split], and the far child afterwards, over [t_split, t_exit], only
// when the ray reaches it inside the cell. A box may be referenced by several leaves and its hit may
// lie beyond the leaf being tested, so the search goes on while a pending node could still hold a
// hit no farther than the best one (t_entry <= best t; equality matters for the tie rule). The
// descent from a node to a leaf, without a branch on the ray, is in descent.hpp.
//
// Robustness and precision:
//   - whether and where a box is hit is decided in double, from the float data:
//     t = (face - origin) * (1 / direction) (detail::clip_to_box);
//   - the traversal runs in float (TraversalRay<float>) when the scene and the ray keep every ray
//     parameter inside the float range, else in double; in float, each leaf's boxes pass a
//     float filter first, four (block_candidates) or with AVX2 eight boxes at a time
//     (block_pair_candidates), and only the boxes it lets through get the
//     double test. Every float parameter is widened by far more than its rounding (traversal_ray.hpp),
//     so the float traversal visits every cell and lets through every box that a double traversal
//     would: the answers are the double traversal's;
//   - a zero direction component (+0 or -0) has the reciprocal +-inf: the split parameter is then
//     +-inf (the ray stays on one side of the plane) or NaN (it lies in the plane, and visits both
//     children over the same interval), which the comparisons below handle without a case of their
//     own;
//   - every comparison of a split parameter with the cell's interval widens the interval, so a hit at
//     the boundary between two cells is seen from both.
//
// Batches trace four, or with AVX2 eight, coherent rays at a time (trace_packet.cpp), the same way.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "descent.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/rays/detail/slab.hpp"
#include "trace_stream.hpp"
#include "traversal_ray.hpp"
#include "walk.hpp"

namespace kdspace {

namespace {


using detail::StackEntry;

void check_range(float t_min, float t_max) {
  if (!std::isfinite(t_min)) throw Error("t_min must be finite, got " + std::to_string(t_min));
  if (std::isnan(t_max)) throw Error("t_max must not be NaN");
  if (t_min > t_max)
    throw Error("t_min " + std::to_string(t_min) + " exceeds t_max " + std::to_string(t_max));
}

/// True when ray_problem(ray) is "" (finite, non-zero direction), without making a string: the
/// batches check every ray, and for cheap rays the message-building check costs a noticeable share.
inline bool usable(const Ray& ray) {
  float sum = 0;
  for (int a = 0; a < 3; ++a)
    sum += 0.0f * ray.origin[a] + 0.0f * ray.direction[a];  // NaN if any is not finite
  const bool zero = ray.direction[0] == 0 && ray.direction[1] == 0 && ray.direction[2] == 0;
  return sum == 0 && !zero;
}

/// What the check of a batch found: the position of its first ray that is not usable() (n when
/// all are), and whether every ray has every origin component within +-2^62 and every direction
/// component of magnitude at least 2^-64: then a ray's detail::packet_key is just its signs.
struct BatchCheck {
  std::size_t first_unusable;
  bool all_in_packet_range;
};

/// check_batch one block of rays at a time, in the baseline instruction set.
BatchCheck check_batch_scalar(const Ray* rays, std::size_t n) {
  using detail::power_of_two_bits;
  constexpr std::size_t block = 64;
  constexpr std::uint32_t exponent = 0x7f800000u, magnitude = 0x7fffffffu;
  std::uint32_t bits[block * 6];
  std::uint32_t out_of_range = 0;
  for (std::size_t begin = 0; begin < n; begin += block) {
    const std::size_t count = std::min(block, n - begin);
    std::memcpy(bits, rays + begin, count * sizeof(Ray));
    std::uint32_t bad = 0;
    for (std::size_t w = 0; w < 6 * count; ++w) {
      bad |= static_cast<std::uint32_t>((bits[w] & exponent) == exponent);  // +-inf or NaN
      out_of_range |= static_cast<std::uint32_t>((bits[w] & magnitude) > power_of_two_bits(62));
    }
    for (std::size_t r = 0; r < count; ++r) {
      const std::uint32_t* direction = bits + 6 * r + 3;
      bad |= static_cast<std::uint32_t>(((direction[0] | direction[1] | direction[2]) & magnitude) == 0);
      for (int a = 0; a < 3; ++a)
        out_of_range |= static_cast<std::uint32_t>((direction[a] & magnitude) < power_of_two_bits(-64));
    }
    if (bad != 0)
      for (std::size_t r = begin; r < begin + count; ++r)
        if (!usable(rays[r])) return BatchCheck{r, false};
  }
  return BatchCheck{n, out_of_range == 0};
}

#if defined(KDSPACE_AVX2_DISPATCH)
/// check_batch's tests on rays[0 .. 8 k) (the largest such k), eight rays (48 words, six registers)
/// at a time: `bad` when some ray is not usable (then check_batch looks for it), `out_of_range` as
/// in check_batch. Returns the rays it looked at.
__attribute__((target("avx2"))) std::size_t check_batch_avx(const Ray* rays, std::size_t n, bool& bad,
                                                            bool& out_of_range) {
  using detail::power_of_two_bits;
  const __m256i exponent = _mm256_set1_epi32(0x7f800000), magnitude = _mm256_set1_epi32(0x7fffffff);
  const __m256i above = _mm256_set1_epi32(static_cast<int>(power_of_two_bits(62)));
  const __m256i below = _mm256_set1_epi32(static_cast<int>(power_of_two_bits(-64)));
  // Word w of a block is a direction component when w % 6 is 3, 4 or 5; the pattern repeats every
  // three registers.
  __m256i is_direction[3];
  for (int j = 0; j < 3; ++j) {
    alignas(32) std::int32_t lanes[8];
    for (int l = 0; l < 8; ++l) lanes[l] = (8 * j + l) % 6 >= 3 ? -1 : 0;
    is_direction[j] = _mm256_load_si256(reinterpret_cast<const __m256i*>(lanes));
  }
  // Bit 6 r + 3 of a block's 48-bit mask of zero words: ray r's first direction component.
  constexpr std::uint64_t first_direction = 0x208208208208ull;
  __m256i not_finite = _mm256_setzero_si256(), range = _mm256_setzero_si256();
  std::uint64_t zero_direction = 0;
  std::size_t done = 0;
  for (; done + 8 <= n; done += 8) {
    const auto* words = reinterpret_cast<const __m256i*>(rays + done);
    std::uint64_t zero = 0;
    for (int j = 0; j < 6; ++j) {
      const __m256i w = _mm256_loadu_si256(words + j);
      const __m256i m = _mm256_and_si256(w, magnitude);
      not_finite = _mm256_or_si256(not_finite, _mm256_cmpeq_epi32(_mm256_and_si256(w, exponent), exponent));
      // Magnitudes are below 2^31, so signed comparisons order them.
      range = _mm256_or_si256(range, _mm256_cmpgt_epi32(m, above));
      range = _mm256_or_si256(range, _mm256_and_si256(is_direction[j % 3], _mm256_cmpgt_epi32(below, m)));
      const auto z = static_cast<std::uint32_t>(
          _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(m, _mm256_setzero_si256()))));
      zero |= static_cast<std::uint64_t>(z) << (8 * j);
    }
    zero_direction |= zero & zero >> 1 & zero >> 2 & first_direction;
  }
  bad = !_mm256_testz_si256(not_finite, not_finite) || zero_direction != 0;
  out_of_range = !_mm256_testz_si256(range, range);
  return done;
}
#endif

/// A batch checks every ray before it traces any. Bit operations over blocks of rays, without a
/// branch a ray, make that cheap beside a camera ray's packet traversal (where the checks with
/// branches cost a sixth of its instructions: callgrind).
BatchCheck check_batch(const Ray* rays, std::size_t n) {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (detail::avx2_dispatch()) {
    bool bad = false, out_of_range = false;
    const std::size_t done = check_batch_avx(rays, n, bad, out_of_range);
    if (bad) {
      for (std::size_t r = 0; r < done; ++r)
        if (!usable(rays[r])) return BatchCheck{r, false};
    }
    const BatchCheck rest = check_batch_scalar(rays + done, n - done);
    if (rest.first_unusable < n - done) return BatchCheck{done + rest.first_unusable, false};
    return BatchCheck{n, !out_of_range && rest.all_in_packet_range};
  }
#endif
  return check_batch_scalar(rays, n);
}

/// detail::packet_key of a ray whose components are all in the packet range (BatchCheck): its signs.
inline std::uint32_t sign_key(const Ray& ray) {
  std::uint32_t direction[3];
  std::memcpy(direction, ray.direction.data(), sizeof direction);
  return direction[0] >> 31 | (direction[1] >> 31) << 1 | (direction[2] >> 31) << 2;
}

/// The most rays a batch's worker takes at a time when the rays that form no packet go in streams:
/// a stream gains from more rays (more of them share each node), until their state (some 50 bytes
/// a ray) leaves the cache.
constexpr std::size_t max_stream_chunk = 65536;

void check_ray(const Ray& ray) {
  if (usable(ray)) return;
  const std::string problem = ray_problem(ray);
  if (!problem.empty()) throw Error("ray: " + problem);
}

}  // namespace

template <class Real, bool AnyHit, bool Wide>
Hit BoxTree::trace(const Ray& ray, float t_min, float t_max, RayStats& stats) const {
  ++stats.rays;
  if (boxes_.empty()) return Hit{};
  const detail::TraversalRay<Real> r(ray);
  Real t_entry = static_cast<Real>(t_min), t_exit = static_cast<Real>(t_max);
  if (!detail::clip_widened(bounds_, r, t_entry, t_exit)) return Hit{};
  detail::DescentRayOf<Real> descent{};
#if defined(KDSPACE_AVX2_DISPATCH)
  if constexpr (Wide) descent = detail::descent_ray(r);
#endif
  detail::BestHit<Real> best(t_max);
  detail::walk<Real, AnyHit, Wide>(detail::view_of(*this), ray, r, descent, StackEntry<Real>{0, t_entry, t_exit},
                                   t_min, best, stats);
  return best.hit();
}

template <bool AnyHit>
Hit BoxTree::trace_in_float(const Ray& ray, float t_min, float t_max, RayStats& stats) const {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (detail::avx2_dispatch()) return trace_wide<AnyHit>(ray, t_min, t_max, stats);
#endif
  return trace<float, AnyHit>(ray, t_min, t_max, stats);
}

template <bool AnyHit>
Hit BoxTree::trace_any_precision(const Ray& ray, float t_min, float t_max, RayStats& stats) const {
  if (float_range_ && detail::fits_float_traversal(ray, float_trace_limit))
    return trace_in_float<AnyHit>(ray, t_min, t_max, stats);
  return trace<double, AnyHit>(ray, t_min, t_max, stats);
}

#if defined(KDSPACE_AVX2_DISPATCH)
// The float traversal compiled for AVX2, its leaves tested eight boxes at a time: `flatten` inlines
// the traversal here, where the eight-box filter (an AVX2 function) can be inlined in turn.
template <bool AnyHit>
__attribute__((target("avx2"), flatten)) Hit BoxTree::trace_wide(const Ray& ray, float t_min, float t_max,
                                                                 RayStats& stats) const {
  return trace<float, AnyHit, true>(ray, t_min, t_max, stats);
}
#endif

Hit BoxTree::closest_hit(const Ray& ray, float t_min, float t_max, RayStats* stats) const {
  check_ray(ray);
  check_range(t_min, t_max);
  RayStats local;
  const Hit h = trace_any_precision<false>(ray, t_min, t_max, local);
  if (stats) *stats += local;
  return h;
}

Hit BoxTree::any_hit(const Ray& ray, float t_min, float t_max, RayStats* stats) const {
  check_ray(ray);
  check_range(t_min, t_max);
  RayStats local;
  const Hit h = trace_any_precision<true>(ray, t_min, t_max, local);
  if (stats) *stats += local;
  return h;
}

template <bool AnyHit>
std::vector<Hit> BoxTree::trace_batch(const Ray* rays, std::size_t n, RayRange range, unsigned threads,
                                      RayStats* stats) const {
  if (n > 0 && rays == nullptr) throw Error("rays: null pointer");
  check_range(range.t_min, range.t_max);
  const BatchCheck checked = check_batch(rays, n);
  for (std::size_t i = checked.first_unusable; i < n; ++i) {
    if (usable(rays[i])) continue;
    const std::string problem = ray_problem(rays[i]);
    if (!problem.empty()) throw Error("ray " + std::to_string(i + 1) + ": " + problem);
  }
  std::vector<Hit> hits(n);  // all Hit{}: trace_stream leaves a ray that misses the scene so
  const unsigned workers = detail::resolve_threads(threads);
  std::vector<RayStats> per_worker(workers);
#if defined(__SSE2__)
  const bool packets = float_range_ && !boxes_.empty();  // trace_packet's conditions on the tree
#else
  const bool packets = false;
#endif
  const bool wide_packets = packets && detail::avx2_dispatch();
  // Every ray in the packet range fits the float traversal: the rays traced one by one then skip
  // fits_float_traversal's per-ray checks (its branches were 5% of a random ray's instructions).
  const bool all_float = float_range_ && checked.all_in_packet_range;
  const auto trace_one = [&](const Ray& ray, RayStats& local) {
    return all_float ? trace_in_float<AnyHit>(ray, range.t_min, range.t_max, local)
                     : trace_any_precision<AnyHit>(ray, range.t_min, range.t_max, local);
  };
  // Rays that form no packet go through the tree in streams, one a direction octant
  // (trace_stream.cpp), where the tree holds boxes in the float range and every ray fits the float
  // traversal; a stream wants many rays, so the workers then take larger chunks.
  const bool streams = packets && checked.all_in_packet_range;
  // With several workers, at least four chunks each, so that they finish together; a multiple of 8,
  // so that the packets are those of the whole batch.
  const std::size_t chunk =
      !streams ? 256
      : workers == 1
          ? max_stream_chunk
          : std::clamp<std::size_t>((n / (4 * workers) + 7) / 8 * 8, 256, max_stream_chunk);
  std::vector<detail::StreamScratch> scratch(streams ? workers : 0);
  // Traces rays[begin, end) on `worker`'s behalf, adding to `local`.
  const auto trace_range = [&](std::size_t begin, std::size_t end, RayStats& local) {
    const auto trace_four = [&](std::size_t first, bool together) {
      if (together) {
        trace_packet<AnyHit>(rays + first, 4, range, hits.data() + first, local);
      } else {
        for (std::size_t k = first; k < first + 4; ++k) hits[k] = trace_one(rays[k], local);
      }
    };
    // Eight (with AVX2) or four consecutive rays that run the same way (equal detail::packet_key:
    // coherent rays, a camera's neighbouring pixels) go through the tree together; the others one
    // by one. All give the same hits and statistics.
    const auto packet_key = [&checked](const Ray& ray) {
      return checked.all_in_packet_range ? sign_key(ray) : detail::packet_key(ray);
    };
    std::size_t i = begin;
    std::uint32_t key[8];
    // 0 when rays[first .. first + 4) can form a packet: their keys are equal and below 8.
    const auto misfit_four = [&key](int first) {
      std::uint32_t differ = key[first] >> 3;
      for (int l = first + 1; l < first + 4; ++l) differ |= key[l] ^ key[first];
      return differ;
    };
    for (; i + 8 <= end; i += 8) {
      for (int l = 0; l < 8; ++l) key[l] = packet_key(rays[i + static_cast<std::size_t>(l)]);
      const bool first = packets && misfit_four(0) == 0, second = packets && misfit_four(4) == 0;
      if (wide_packets && first && second && key[0] == key[4]) {
        trace_packet<AnyHit>(rays + i, 8, range, hits.data() + i, local);
      } else {
        trace_four(i, first);
        trace_four(i + 4, second);
      }
    }
    if (i + 4 <= end) {
      for (int l = 0; l < 4; ++l) key[l] = packet_key(rays[i + static_cast<std::size_t>(l)]);
      trace_four(i, packets && misfit_four(0) == 0);
      i += 4;
    }
    for (; i < end; ++i) hits[i] = trace_one(rays[i], local);
  };
  // The same with streams: the rays of a packet as above, every other ray into its octant's stream.
  const auto stream_range = [&](std::size_t begin, std::size_t end, unsigned worker, RayStats& local) {
    detail::StreamScratch& s = scratch[worker];
    const std::size_t count = end - begin;
    if (s.keys.size() < count) {
      s.keys.resize(count);
      s.ids.resize(count);
    }
    // A ray's key: its direction's signs, or 8 once it has gone in a packet.
    std::uint32_t* key = s.keys.data();
    for (std::size_t k = 0; k < count; ++k) key[k] = sign_key(rays[begin + k]);
    const auto alike_four = [&](std::size_t first) {
      const std::uint32_t* k = key + (first - begin);
      return ((k[0] ^ k[1]) | (k[0] ^ k[2]) | (k[0] ^ k[3])) == 0;
    };
    // Mostly coherent rays (a camera's) trace their few odd rays one by one as they come, beside the
    // packets that walked the same cells just before: a stream would meet them cold.
    std::size_t alike = 0;
    for (std::size_t first = begin; first + 4 <= end; first += 4) alike += alike_four(first) ? 4 : 0;
    const bool coherent = 2 * alike >= count;
    const auto packet = [&](std::size_t first, int width) {
      trace_packet<AnyHit>(rays + first, width, range, hits.data() + first, local);
      for (int l = 0; l < width; ++l) key[first - begin + static_cast<std::size_t>(l)] = 8;
    };
    const auto odd = [&](std::size_t first, std::size_t last) {  // rays that form no packet
      if (!coherent) return;  // they go in the streams
      for (std::size_t k = first; k < last; ++k) {
        hits[k] = trace_one(rays[k], local);
        key[k - begin] = 8;
      }
    };
    std::size_t i = begin;
    for (; i + 8 <= end; i += 8) {
      const bool first = alike_four(i), second = alike_four(i + 4);
      if (wide_packets && first && second && key[i - begin] == key[i + 4 - begin]) {
        packet(i, 8);
        continue;
      }
      if (first) packet(i, 4); else odd(i, i + 4);
      if (second) packet(i + 4, 4); else odd(i + 4, i + 8);
    }
    if (i + 4 <= end && alike_four(i)) {
      packet(i, 4);
      i += 4;
    }
    odd(i, end);
    if (coherent) return;
    // The other rays by octant (a counting sort over the keys 0 .. 8: ascending within an octant,
    // the rays already traced last), one stream an octant.
    std::array<std::size_t, 11> start{};
    for (std::size_t k = 0; k < count; ++k) ++start[key[k] + 2];
    for (std::size_t o = 2; o < start.size(); ++o) start[o] += start[o - 1];
    std::uint32_t* ids = s.ids.data();
    for (std::size_t k = 0; k < count; ++k) ids[start[key[k] + 1]++] = static_cast<std::uint32_t>(begin + k);
    for (std::size_t o = 0; o < 8; ++o)
      if (start[o + 1] > start[o])
        detail::trace_stream<AnyHit>(*this, rays, ids + start[o], start[o + 1] - start[o], range, hits.data(), local,
                                     s);
  };
  detail::parallel_for(n, workers, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
    RayStats local;
    // One worker is handed the whole batch: it too goes chunk by chunk, so that a stream's rays stay
    // in the cache.
    for (std::size_t first = begin; first < end; first += chunk) {
      if (streams)
        stream_range(first, std::min(end, first + chunk), worker, local);
      else
        trace_range(first, std::min(end, first + chunk), local);
    }
    per_worker[worker] += local;
  });
  if (stats)
    for (const RayStats& s : per_worker) *stats += s;
  return hits;
}

std::vector<Hit> BoxTree::closest_hit_batch(const Ray* rays, std::size_t n, RayRange range, unsigned threads,
                                            RayStats* stats) const {
  return trace_batch<false>(rays, n, range, threads, stats);
}

std::vector<Hit> BoxTree::any_hit_batch(const Ray* rays, std::size_t n, RayRange range, unsigned threads,
                                        RayStats* stats) const {
  return trace_batch<true>(rays, n, range, threads, stats);
}

}  // namespace kdspace
