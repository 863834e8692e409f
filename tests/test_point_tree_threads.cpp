// Threads change nothing but speed: builds and batch queries on several threads give the answers of
// one thread. Tagged [threads]; CI runs these under ThreadSanitizer too.
#include <catch2/catch.hpp>

#include <random>
#include <vector>

#include "kdspace/kdspace.hpp"

namespace {

std::vector<float> random_points(std::size_t n, std::size_t dim, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> uniform(-1.f, 1.f);
  std::vector<float> points(n * dim);
  for (auto& v : points) v = uniform(rng);
  return points;
}

template <class Tree>
void require_same_tree(const Tree& a, const Tree& b) {
  REQUIRE(a.node_count() == b.node_count());
  REQUIRE(a.depth() == b.depth());
  for (std::size_t i = 0; i < a.node_count(); ++i) {
    CAPTURE(i);
    REQUIRE(a.nodes()[i].info == b.nodes()[i].info);
    REQUIRE(a.nodes()[i].link == b.nodes()[i].link);
    REQUIRE(a.nodes()[i].left_max == b.nodes()[i].left_max);
    REQUIRE(a.nodes()[i].right_min == b.nodes()[i].right_min);
  }
}

}  // namespace

TEST_CASE("a build on several threads makes the same tree as on one", "[threads]") {
  const std::size_t dim = GENERATE(2, 7);
  const auto position = GENERATE(kdspace::PositionRule::median, kdspace::PositionRule::middle,
                                 kdspace::PositionRule::sliding_midpoint, kdspace::PositionRule::midpoint);
  const auto points = random_points(20000, dim, 11);
  kdspace::BuildParams params;
  params.position = position;
  params.threads = 1;
  const kdspace::PointTree<float> serial(points.data(), 20000, dim, params);
  for (unsigned threads : {2u, 3u, 4u, 0u}) {
    CAPTURE(dim, threads);
    params.threads = threads;
    const kdspace::PointTree<float> parallel(points.data(), 20000, dim, params);
    require_same_tree(serial, parallel);
    const float query[7] = {0.1f, -0.2f, 0.3f, 0.f, 0.5f, -0.6f, 0.7f};
    REQUIRE(serial.knn(query, 10) == parallel.knn(query, 10));
  }
}

TEST_CASE("batch k-NN and radius answers on 1, 2 and 4 threads are identical", "[threads]") {
  const std::size_t dim = 5, n = 5000, nq = 700;
  const auto points = random_points(n, dim, 3);
  const auto queries = random_points(nq, dim, 4);
  const kdspace::PointTree<float> tree(points.data(), n, dim);
  kdspace::QueryStats one_stats;
  const auto knn_one = tree.knn_batch(queries.data(), nq, 7, {}, 1, &one_stats);
  const auto radius_one = tree.radius_batch(queries.data(), nq, 0.4f, SIZE_MAX, 1);
  for (unsigned threads : {2u, 4u}) {
    CAPTURE(threads);
    kdspace::QueryStats stats;
    const auto knn_many = tree.knn_batch(queries.data(), nq, 7, {}, threads, &stats);
    REQUIRE(knn_many.offsets == knn_one.offsets);
    REQUIRE(knn_many.neighbors == knn_one.neighbors);
    REQUIRE(stats.queries == one_stats.queries);
    REQUIRE(stats.points_visited == one_stats.points_visited);
    const auto radius_many = tree.radius_batch(queries.data(), nq, 0.4f, SIZE_MAX, threads);
    REQUIRE(radius_many.offsets == radius_one.offsets);
    REQUIRE(radius_many.neighbors == radius_one.neighbors);
  }
  for (std::size_t q = 0; q < nq; q += 50) {
    const auto single = tree.knn(queries.data() + q * dim, 7);
    REQUIRE(std::vector<kdspace::Neighbor<float>>(knn_one.row(q).begin(), knn_one.row(q).end()) == single);
  }
}
