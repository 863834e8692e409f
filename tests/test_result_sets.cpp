// The k-NN result sets (detail/result_sets.hpp) keep the same candidates in the same order: the first
// k in (distance, index) order among those within the limit. Each is checked against the heap
// (KnnResults) offer by offer: the same answer to each offer, the same bound after it, the same list
// at the end; on streams with many ties, infinite distances and a finite limit.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "kdspace/points/detail/result_sets.hpp"

using kdspace::detail::Candidate;
using kdspace::detail::KnnResults;

namespace {

/// Offers `stream` to `results` and to a heap of the same k and limit; the first difference, or "".
template <class Results>
std::string differs_from_heap(Results& results, std::size_t k, float limit,
                              const std::vector<Candidate<float>>& stream) {
  std::vector<Candidate<float>> heap_storage;
  KnnResults<float> heap(k, limit, heap_storage);
  for (std::size_t i = 0; i < stream.size(); ++i) {
    const bool kept = results.offer(stream[i].dist, stream[i].index);
    const bool heap_kept = heap.offer(stream[i].dist, stream[i].index);
    if (kept != heap_kept || results.bound() != heap.bound() || results.full() != heap.full())
      return "offer " + std::to_string(i) + " (" + std::to_string(stream[i].dist) + ", " +
             std::to_string(stream[i].index) + "): kept " + std::to_string(kept) + " bound " +
             std::to_string(results.bound()) + ", heap: kept " + std::to_string(heap_kept) + " bound " +
             std::to_string(heap.bound());
  }
  const auto& got = results.sorted();
  const auto& want = heap.sorted();
  if (got.size() != want.size())
    return "sizes " + std::to_string(got.size()) + " and " + std::to_string(want.size());
  for (std::size_t j = 0; j < got.size(); ++j)
    if (got[j].dist != want[j].dist || got[j].index != want[j].index)
      return "rank " + std::to_string(j) + ": (" + std::to_string(got[j].dist) + ", " +
             std::to_string(got[j].index) + ") where the heap has (" + std::to_string(want[j].dist) + ", " +
             std::to_string(want[j].index) + ")";
  return "";
}

/// `length` candidates with distinct indices in random order (some near 2^32) and distances drawn
/// from `values` distinct values (few values: many ties), a share of them infinite.
std::vector<Candidate<float>> make_stream(std::size_t length, int values, std::mt19937& rng) {
  std::vector<std::uint32_t> indices(length);
  std::iota(indices.begin(), indices.end(), 0u);
  for (std::size_t i = 0; i < length; i += 7) indices[i] = UINT32_MAX - static_cast<std::uint32_t>(i);
  std::shuffle(indices.begin(), indices.end(), rng);
  std::uniform_int_distribution<int> value(0, values);
  std::vector<Candidate<float>> stream(length);
  for (std::size_t i = 0; i < length; ++i) {
    const int v = value(rng);
    stream[i] = {v == values ? std::numeric_limits<float>::infinity() : static_cast<float>(v) * 0.25f,
                 indices[i]};
  }
  return stream;
}

// Calls f(k, values, limit) for every k in [min_k, max_k], streams of 1, 3, 20 and 1000 distinct
// values (few values: many ties), and no limit or a limit of 2.
template <class F>
void for_each_setting(std::size_t min_k, std::size_t max_k, F f) {
  for (std::size_t k = min_k; k <= max_k; ++k)
    for (int values : {1, 3, 20, 1000})
      for (float limit : {std::numeric_limits<float>::infinity(), 2.0f}) f(k, values, limit);
}

}  // namespace

TEST_CASE(
    "result sets: SortedKnnResults keeps the heap's candidates, offer by offer, ties and infinities included",
    "[points][result_sets]") {
  std::mt19937 rng(11);
  for_each_setting(
      1, kdspace::detail::SortedKnnResults<float>::small_k, [&](std::size_t k, int values, float limit) {
        for (std::size_t length : {std::size_t{0}, k - 1, k, 3 * k + 5}) {
          const auto stream = make_stream(length, values, rng);
          std::vector<Candidate<float>> storage;
          kdspace::detail::SortedKnnResults<float> results(k, limit, storage);
          INFO("k " << k << ", " << values << " values, limit " << limit << ", " << length << " offers");
          CHECK(differs_from_heap(results, k, limit, stream) == "");
        }
      });
}

TEST_CASE(
    "result sets: NearestResults keeps the heap's candidate for k = 1, offer by offer, ties and infinities "
    "included",
    "[points][result_sets]") {
  std::mt19937 rng(14);
  for_each_setting(1, 1, [&](std::size_t k, int values, float limit) {
    for (std::size_t length :
         {std::size_t{0}, std::size_t{1}, std::size_t{2}, std::size_t{30}, std::size_t{1000}}) {
      const auto stream = make_stream(length, values, rng);
      std::vector<Candidate<float>> storage;
      kdspace::detail::NearestResults<float> results(limit, storage);
      INFO(values << " values, limit " << limit << ", " << length << " offers");
      CHECK(differs_from_heap(results, k, limit, stream) == "");
    }
  });
}

#if defined(__SSE2__)
TEST_CASE(
    "result sets: ChunkedKnnResults keeps the heap's candidates, offer by offer, ties and infinities "
    "included",
    "[points][result_sets]") {
  using kdspace::detail::ChunkedKnnResults;
  std::mt19937 rng(12);
  for_each_setting(
      ChunkedKnnResults::min_k, ChunkedKnnResults::max_k, [&](std::size_t k, int values, float limit) {
        for (std::size_t length : {std::size_t{0}, k - 1, k, 3 * k + 5, 200 * k}) {
          const auto stream = make_stream(length, values, rng);
          std::vector<Candidate<float>> storage;
          ChunkedKnnResults results(k, limit, storage);
          INFO("k " << k << ", " << values << " values, limit " << limit << ", " << length << " offers");
          CHECK(differs_from_heap(results, k, limit, stream) == "");
        }
      });
}

TEST_CASE(
    "result sets: ChunkedKnnResults filled with a first leaf at once, then offered the rest, keeps the "
    "heap's candidates",
    "[points][result_sets]") {
  using kdspace::detail::ChunkedKnnResults;
  std::mt19937 rng(13);
  for_each_setting(
      ChunkedKnnResults::min_k, ChunkedKnnResults::max_k, [&](std::size_t k, int values, float limit) {
        for (std::size_t m :
             {std::size_t{1}, k - 1, k, k + 1, std::size_t{24}, ChunkedKnnResults::max_fill}) {
          const auto stream = make_stream(m + 3 * k, values, rng);
          std::vector<float> dist(m);
          std::vector<std::uint32_t> index(m);
          for (std::size_t i = 0; i < m; ++i) dist[i] = stream[i].dist, index[i] = stream[i].index;
          std::vector<Candidate<float>> storage;
          ChunkedKnnResults results(k, limit, storage);
          results.fill(dist.data(), index.data(), m);
          // The heap is offered the whole stream; the set, the part after the fill.
          std::vector<Candidate<float>> heap_storage;
          KnnResults<float> heap(k, limit, heap_storage);
          for (std::size_t i = 0; i < m; ++i) heap.offer(stream[i].dist, stream[i].index);
          INFO("k " << k << ", " << values << " values, limit " << limit << ", " << m << " filled");
          CHECK(results.bound() == heap.bound());
          CHECK(results.full() == heap.full());
          const std::vector<Candidate<float>> rest(stream.begin() + static_cast<long>(m), stream.end());
          // After the fill the set answers every further offer as a heap holding the same kept does.
          const std::vector<Candidate<float>> kept_by_heap(heap.sorted());
          std::vector<Candidate<float>> continued_storage;
          KnnResults<float> continued(k, limit, continued_storage);
          for (const auto& c : kept_by_heap) continued.offer(c.dist, c.index);
          for (std::size_t i = 0; i < rest.size(); ++i) {
            const bool kept = results.offer(rest[i].dist, rest[i].index);
            const bool heap_kept = continued.offer(rest[i].dist, rest[i].index);
            CHECK(kept == heap_kept);
            CHECK(results.bound() == continued.bound());
          }
          const auto& got = results.sorted();
          const auto& want = continued.sorted();
          REQUIRE(got.size() == want.size());
          for (std::size_t j = 0; j < got.size(); ++j) {
            CHECK(got[j].dist == want[j].dist);
            CHECK(got[j].index == want[j].index);
          }
        }
      });
}
#endif
