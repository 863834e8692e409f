// The 3-D float leaf scan four points a step (detail/leaf_scan3.hpp): every distance the same bits as
// internal_distance<L2>, at every leaf length and so every overlap of the last step; and a scan keeps
// what offering every point of the leaf keeps, whatever the result set (k = 1, the sorted list, the
// chunked list, the heap, a radius), ties and a limit included.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/detail/leaf_scan3.hpp"
#include "kdspace/points/detail/result_sets.hpp"

#if defined(__SSE2__)

namespace {

using kdspace::detail::Candidate;

// count 3-D points whose coordinates span many binary orders (so that any other order of the
// additions would round differently), some equal to the query's, some repeated (ties).
std::vector<float> points_around(const float* q, std::size_t count, std::mt19937& rng) {
  std::uniform_real_distribution<float> mantissa(-1, 1);
  std::uniform_int_distribution<int> exponent(-12, 12), pick(0, 6);
  std::vector<float> rows(3 * count);
  for (std::size_t i = 0; i < count; ++i) {
    const int kind = pick(rng);
    for (std::size_t a = 0; a < 3; ++a) {
      float& v = rows[3 * i + a];
      if (kind == 0 && i > 0)
        v = rows[3 * (i - 1) + a];  // the point before again: a tie
      else if (kind == 1 && a == 1)
        v = q[a];
      else
        v = q[a] + std::ldexp(mantissa(rng), exponent(rng));
    }
  }
  return rows;
}

template <class Results>
std::vector<Candidate<float>> scanned(Results& results, const float* q, const std::vector<float>& rows,
                                      const std::vector<std::uint32_t>& index) {
  kdspace::detail::scan_leaf3_l2(q, rows.data(), index.data(), index.size(), results);
  return results.sorted();
}

template <class Results>
std::vector<Candidate<float>> offered_all(Results& results, const float* q, const std::vector<float>& rows,
                                          const std::vector<std::uint32_t>& index) {
  for (std::size_t i = 0; i < index.size(); ++i)
    results.offer(kdspace::internal_distance<kdspace::L2>(q, rows.data() + 3 * i, 3), index[i]);
  return results.sorted();
}

bool same(const std::vector<Candidate<float>>& a, const std::vector<Candidate<float>>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t j = 0; j < a.size(); ++j)
    if (a[j].dist != b[j].dist || a[j].index != b[j].index) return false;
  return true;
}

}  // namespace

TEST_CASE("leaf scan 3-D: four points a step give internal_distance's bits at every leaf length",
          "[points][exact]") {
  std::mt19937 rng(31);
  for (std::size_t count = 4; count <= 40; ++count)
    for (int trial = 0; trial < 50; ++trial) {
      const float q[3] = {std::ldexp(1.5f, trial % 7 - 3), -0.75f, 1e3f};
      const std::vector<float> rows = points_around(q, count, rng);
      std::vector<float> dist(count);
      kdspace::detail::l2_distances3(q, rows.data(), count, dist.data());
      for (std::size_t i = 0; i < count; ++i) {
        CAPTURE(count, trial, i);
        CHECK(dist[i] == kdspace::internal_distance<kdspace::L2>(q, rows.data() + 3 * i, 3));
      }
    }
}

TEST_CASE("leaf scan 3-D: a leaf scanned four points a step keeps what offering every point keeps",
          "[points][exact][result_sets]") {
  std::mt19937 rng(32);
  for (std::size_t count = 4; count <= 40; ++count)
    for (int trial = 0; trial < 20; ++trial) {
      const float q[3] = {0.5f, std::ldexp(1.0f, trial % 5), -2.0f};
      const std::vector<float> rows = points_around(q, count, rng);
      std::vector<std::uint32_t> index(count);
      std::uniform_int_distribution<std::uint32_t> any_index(0, UINT32_MAX);
      for (auto& i : index) i = any_index(rng);  // leaf order is not index order
      // A limit at a middle distance: some points beyond it, and the set not always full.
      std::vector<float> dist(count);
      kdspace::detail::l2_distances3(q, rows.data(), count, dist.data());
      const float limit = trial % 2 ? std::numeric_limits<float>::infinity() : dist[count / 2];
      CAPTURE(count, trial, limit);
      std::vector<Candidate<float>> s1, s2;
      {
        kdspace::detail::NearestResults<float> a(limit, s1), b(limit, s2);
        CHECK(same(scanned(a, q, rows, index), offered_all(b, q, rows, index)));
      }
      for (std::size_t k : {2, 3, 10}) {
        kdspace::detail::SortedKnnResults<float> a(k, limit, s1), b(k, limit, s2);
        CHECK(same(scanned(a, q, rows, index), offered_all(b, q, rows, index)));
      }
      {
        kdspace::detail::ChunkedKnnResults a(5, limit, s1), b(5, limit, s2);
        CHECK(same(scanned(a, q, rows, index), offered_all(b, q, rows, index)));
      }
      {
        kdspace::detail::KnnResults<float> a(40, limit, s1), b(40, limit, s2);
        CHECK(same(scanned(a, q, rows, index), offered_all(b, q, rows, index)));
      }
      {
        kdspace::detail::RangeResults<float> a(limit, s1), b(limit, s2);
        CHECK(same(scanned(a, q, rows, index), offered_all(b, q, rows, index)));
      }
    }
}

#endif
