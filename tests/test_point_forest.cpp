// PointForest: exact with an unlimited budget, recall that never falls as the budget grows, the
// same answers on any thread count and for a given seed, tuning that reaches its target on queries
// it never saw, and clear errors for bad parameters.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/point_forest.hpp"
#include "support.hpp"

using kdspace::ForestParams;
using kdspace::ForestSearchParams;
using kdspace::PointForest;
using kdspace::QueryStats;
using kdspace_test::make_points;
using kdspace_test::make_queries;
using kdspace_test::Shape;

namespace {

/// The first query whose forest answer differs from brute_force_knn, or "".
template <class T>
std::string forest_differs(const PointForest<T>& forest, const std::vector<T>& pts, std::size_t n,
                                     std::size_t dim, const std::vector<T>& queries, std::size_t k,
                                     const ForestSearchParams& search, unsigned threads) {
  const std::size_t nq = queries.size() / dim;
  const auto batch = forest.knn_batch(queries.data(), nq, k, search, threads);
  return kdspace_test::differs_from_brute_force(batch, pts, n, dim, queries, k);
}

ForestSearchParams unlimited(std::size_t trees = 0) {
  return ForestSearchParams{kdspace::unlimited_checks, trees};
}

}  // namespace

TEST_CASE("forest: with an unlimited budget the answers are exact, bit for bit, on every shape",
          "[points][forest][exact]") {
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical,
                               Shape::flat, Shape::sorted_x);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 3, 17, 64, 128);
  const std::size_t n = GENERATE(as<std::size_t>{}, 1, 9, 1200);
  const bool pca = GENERATE(true, false);
  const std::uint32_t seed = 300 + static_cast<std::uint32_t>(dim * 13 + n);
  const auto pts = make_points<float>(shape, n, dim, seed);
  const auto queries = make_queries(pts, n, dim, 60, seed + 1);
  ForestParams params;
  params.pca = pca;
  params.trees = 3;
  const PointForest<float> forest(pts.data(), n, dim, params);
  for (std::size_t k : {1, 2, 5, 10, 100}) {
    if (k > n) continue;
    INFO(kdspace_test::name(shape) << " n=" << n << " dim=" << dim << " k=" << k << " pca=" << pca);
    CHECK(forest_differs(forest, pts, n, dim, queries, k, unlimited(), 2) == "");
  }
  // One tree alone is exact too, and so is double precision.
  CHECK(forest_differs(forest, pts, n, dim, queries, std::min<std::size_t>(n, 4), unlimited(1), 1) == "");
  const auto pts_d = make_points<double>(shape, n, dim, seed);
  const auto queries_d = make_queries(pts_d, n, dim, 30, seed + 2);
  const PointForest<double> forest_d(pts_d.data(), n, dim, params);
  CHECK(forest_differs(forest_d, pts_d, n, dim, queries_d, std::min<std::size_t>(n, 10), unlimited(), 1) == "");
}

TEST_CASE("forest: exact at awkward scales, where the pruning margin for the projection's rounding matters",
          "[points][forest][exact]") {
  struct Scale {
    double factor, offset;
  };
  const Scale scale = GENERATE(Scale{1, 1e4}, Scale{1e-3, 1e3}, Scale{1e-30, 0}, Scale{1e18, 0}, Scale{1, -3e5});
  const std::size_t dim = GENERATE(as<std::size_t>{}, 2, 40, 128);
  const std::size_t n = 1000;
  auto pts = make_points<float>(Shape::clustered, n, dim, 41);
  for (auto& v : pts) v = static_cast<float>(scale.offset + scale.factor * static_cast<double>(v));
  const auto queries = make_queries(pts, n, dim, 50, 42);
  const PointForest<float> forest(pts.data(), n, dim);
  INFO("scale " << scale.factor << " offset " << scale.offset << " dim " << dim);
  for (std::size_t k : {1, 10}) CHECK(forest_differs(forest, pts, n, dim, queries, k, unlimited(), 1) == "");
}

TEST_CASE("forest: every distance returned is exact, and the k-th never grows as the budget grows",
          "[points][forest]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 16, 96);
  const std::size_t n = 3000, k = 10;
  const auto pts = make_points<float>(Shape::clustered, n, dim, 61);
  const auto queries = make_queries(pts, n, dim, 100, 62);
  const PointForest<float> forest(pts.data(), n, dim, ForestParams{});
  const auto exact = forest.knn_exact_batch(queries.data(), 100, k, 1);
  double previous_recall = 0;
  std::vector<float> previous(100 * k, std::numeric_limits<float>::infinity());
  for (std::size_t checks = 1; checks <= 2 * n; checks *= 2) {
    const auto found = forest.knn_batch(queries.data(), 100, k, ForestSearchParams{checks, 0}, 2);
    for (std::size_t q = 0; q < 100; ++q) {
      for (std::size_t i = 0; i < k; ++i) {
        const auto& nb = found.row(q)[i];
        // The distance is the true one for that index.
        const float true_distance = std::sqrt(kdspace::internal_distance<kdspace::L2>(
            queries.data() + q * dim, pts.data() + std::size_t{nb.index} * dim, dim));
        CHECK(nb.distance == true_distance);
        CHECK(nb.distance <= previous[q * k + i]);
        previous[q * k + i] = nb.distance;
      }
    }
    const double recall = kdspace::recall_at_k(found, exact);
    INFO("checks " << checks << " recall " << recall);
    CHECK(recall >= previous_recall);
    previous_recall = recall;
  }
  CHECK(previous_recall == 1.0);  // 2n checks cover every point
}

TEST_CASE("forest: the best-bin-first search finds far more neighbours than its budget would at random",
          "[points][forest]") {
  // Not a speed claim: a sanity check that the priority search works as a search. Scoring 1000 of
  // the 20000 points at random would find 5% of the true neighbours; the search must find several
  // times that even on these isotropic blobs (intrinsic dimension 64, the hard case).
  const std::size_t dim = 64, n = 20000, k = 10, nq = 200;
  const auto pts = make_points<float>(Shape::clustered, n, dim, 71);
  const auto queries = make_queries(pts, n, dim, nq, 72);
  const PointForest<float> forest(pts.data(), n, dim, ForestParams{});
  const auto exact = forest.knn_exact_batch(queries.data(), nq, k, 2);
  const double at_1000 = kdspace::recall_at_k(forest.knn_batch(queries.data(), nq, k, {1000, 0}, 2), exact);
  const double at_4000 = kdspace::recall_at_k(forest.knn_batch(queries.data(), nq, k, {4000, 0}, 2), exact);
  INFO("recall@10 at 1000 checks " << at_1000 << ", at 4000 " << at_4000);
  CHECK(at_1000 > 0.25);
  CHECK(at_4000 > at_1000);
}

TEST_CASE("forest: the same answers on any thread count, single or batched", "[points][forest][threads]") {
  const std::size_t dim = 48, n = 5000, nq = 257, k = 7;
  const auto pts = make_points<float>(Shape::clustered, n, dim, 81);
  const auto queries = make_queries(pts, n, dim, nq, 82);
  ForestParams params;
  params.threads = 3;
  const PointForest<float> forest(pts.data(), n, dim, params);
  const ForestSearchParams search{200, 0};
  QueryStats one_stats;
  const auto one = forest.knn_batch(queries.data(), nq, k, search, 1, &one_stats);
  for (unsigned threads : {2u, 3u, 8u}) {
    QueryStats stats;
    CHECK(forest.knn_batch(queries.data(), nq, k, search, threads, &stats).neighbors == one.neighbors);
    CHECK(stats.points_visited == one_stats.points_visited);
  }
  for (std::size_t q = 0; q < nq; q += 16) {
    const auto single = forest.knn(queries.data() + q * dim, k, search);
    for (std::size_t i = 0; i < k; ++i) CHECK(single[i] == one.row(q)[i]);
  }
  // The build does not depend on its thread count.
  params.threads = 1;
  const PointForest<float> serial(pts.data(), n, dim, params);
  for (std::size_t t = 0; t < forest.tree_count(); ++t) {
    const auto& a = forest.nodes(t);
    const auto& b = serial.nodes(t);
    REQUIRE(a.size() == b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      CHECK(a[i].info == b[i].info);
      CHECK(a[i].link == b[i].link);
      CHECK(a[i].left_max == b[i].left_max);
    }
  }
}

TEST_CASE("forest: a seed gives one forest; another seed another", "[points][forest]") {
  const std::size_t dim = 32, n = 4000;
  const auto pts = make_points<float>(Shape::uniform, n, dim, 91);
  const auto queries = make_queries(pts, n, dim, 50, 92);
  ForestParams params;
  params.seed = 5;
  const PointForest<float> a(pts.data(), n, dim, params), b(pts.data(), n, dim, params);
  params.seed = 6;
  const PointForest<float> c(pts.data(), n, dim, params);
  const ForestSearchParams search{64, 0};
  CHECK(a.knn_batch(queries.data(), 50, 5, search, 1).neighbors == b.knn_batch(queries.data(), 50, 5, search, 1).neighbors);
  bool any_axis_differs = false;
  for (std::size_t t = 0; t < a.tree_count(); ++t)
    for (std::size_t i = 0; i < std::min(a.nodes(t).size(), c.nodes(t).size()); ++i)
      any_axis_differs = any_axis_differs || a.nodes(t)[i].info != c.nodes(t)[i].info;
  CHECK(any_axis_differs);
}

TEST_CASE("forest: tuning reaches the target recall on queries it never saw", "[points][forest]") {
  const std::size_t dim = 40, n = 20000, k = 10, nq = 500;
  // One draw: the first n points are the data, the last nq the fresh queries (same blobs, new points).
  const auto drawn = make_points<float>(Shape::clustered, n + nq, dim, 101);
  const std::vector<float> pts(drawn.begin(), drawn.begin() + static_cast<std::ptrdiff_t>(n * dim));
  const std::vector<float> queries(drawn.begin() + static_cast<std::ptrdiff_t>(n * dim), drawn.end());
  ForestParams params;
  params.trees = 8;
  params.threads = 2;
  params.graph = kdspace::GraphMode::off;  // the trees' tuning (test_point_graph.cpp tunes with the graph)
  const PointForest<float> forest(pts.data(), n, dim, params);
  // Tuned on base points (left out of their own answers), and on 200 fresh queries of the kind.
  const auto other = make_points<float>(Shape::clustered, n + nq + 200, dim, 101);
  const std::vector<float> tuning_queries(other.end() - static_cast<std::ptrdiff_t>(200 * dim), other.end());
  for (double target : {0.8, 0.95})
  for (bool on_queries : {false, true}) {
    const kdspace::ForestTuning tuned =
        on_queries ? forest.tune(target, k, tuning_queries.data(), 200) : forest.tune(target, k);
    INFO("tuned on " << (on_queries ? "fresh queries" : "base points"));
    INFO("target " << target << ": trees " << tuned.trees << " checks " << tuned.checks << " tuning recall "
                   << tuned.tuning_recall << " validation recall " << tuned.validation_recall << " in "
                   << tuned.seconds << " s, " << tuned.settings_tried << " settings");
    CHECK(tuned.trees >= 1);
    CHECK(tuned.trees <= 8);
    CHECK(tuned.tuning_recall >= target);
    CHECK(tuned.validation_recall >= target);
    CHECK(tuned.checks < n);  // far from exhaustive on clustered data
    // Fresh queries from the same distribution, not in the data: within sampling error of the
    // target (500 queries: the standard error of a mean recall near 0.9 is about 0.01).
    const auto exact = forest.knn_exact_batch(queries.data(), nq, k, 2);
    const auto found = forest.knn_batch(queries.data(), nq, k, tuned.search(), 2);
    const double recall = kdspace::recall_at_k(found, exact);
    INFO("recall on fresh queries " << recall);
    CHECK(recall >= target - 0.03);
  }
}

TEST_CASE("forest: bad parameters and inputs get clear errors", "[points][forest][errors]") {
  const auto pts = make_points<float>(Shape::uniform, 100, 8, 111);
  auto build = [&](ForestParams p) { PointForest<float> f(pts.data(), 100, 8, p); };
  auto with = [](auto change) {
    ForestParams p;
    change(p);
    return p;
  };
  CHECK_THROWS_WITH(build(with([](ForestParams& p) { p.trees = 0; })), Catch::Contains("trees must be at least 1"));
  CHECK_THROWS_WITH(build(with([](ForestParams& p) { p.leaf_size = 0; })), Catch::Contains("leaf_size"));
  CHECK_THROWS_WITH(build(with([](ForestParams& p) { p.projected_dims = 65; })), Catch::Contains("projected_dims"));
  CHECK_THROWS_WITH(build(with([](ForestParams& p) { p.candidate_axes = 0; })), Catch::Contains("candidate_axes"));
  for (double share : {0.0, -0.1, 1.5, std::numeric_limits<double>::quiet_NaN()})
    CHECK_THROWS_WITH(build(with([share](ForestParams& p) { p.variance_share = share; })), Catch::Contains("variance_share"));
  CHECK_THROWS_WITH(PointForest<float>(pts.data(), 0, 8), Catch::Contains("empty"));
  CHECK_THROWS_WITH(PointForest<float>(pts.data(), 100, 0), Catch::Contains("dimension 0"));
  auto bad = pts;
  bad[5 * 8 + 2] = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH(PointForest<float>(bad.data(), 100, 8), Catch::Contains("row 6: coordinate 3 is not finite"));
  const std::vector<std::uint8_t> byte_rows(800, 7);
  CHECK_THROWS_WITH(PointForest<float>(byte_rows.data(), 0, 8), Catch::Contains("empty"));
  CHECK_THROWS_WITH(PointForest<double>(byte_rows.data(), 100, 0), Catch::Contains("dimension 0"));
  CHECK_THROWS_WITH(PointForest<float>(static_cast<const std::uint8_t*>(nullptr), 100, 8), Catch::Contains("null pointer"));
  CHECK_THROWS_WITH(PointForest<float>(byte_rows.data(), 100, 8, with([](ForestParams& p) { p.trees = 0; })),
                    Catch::Contains("trees must be at least 1"));

  const PointForest<float> forest(pts.data(), 100, 8);
  CHECK_THROWS_WITH(forest.knn(pts.data(), 0), Catch::Contains("k must be at least 1"));
  CHECK_THROWS_WITH(forest.knn(pts.data(), 101), Catch::Contains("exceeds the number of points"));
  CHECK_THROWS_WITH(forest.knn(pts.data(), 3, {0, 0}), Catch::Contains("checks must be at least 1"));
  std::vector<float> q(2 * 8, 0.5f);
  q[8 + 7] = std::numeric_limits<float>::infinity();
  CHECK_THROWS_WITH(forest.knn_batch(q.data(), 2, 3), Catch::Contains("query row 2: coordinate 8 is not finite"));
  for (double recall : {0.0, -0.5, 1.01, std::numeric_limits<double>::quiet_NaN()})
    CHECK_THROWS_WITH(forest.tune(recall, 5), Catch::Contains("recall must be in (0, 1]"));
  CHECK_THROWS_WITH(forest.tune(0.9, 100), Catch::Contains("needs at least 101 points"));
  CHECK_THROWS_WITH(forest.tune(0.9, 101, q.data(), 1), Catch::Contains("needs at least 101"));
  CHECK_THROWS_WITH(forest.tune(0.9, 5, q.data(), 2), Catch::Contains("query row 2: coordinate 8 is not finite"));
  CHECK_THROWS_WITH(forest.tune(0.9, 5, q.data(), 0), Catch::Contains("no queries"));
}

TEST_CASE("forest: tiny data: one point, two points, k = n", "[points][forest]") {
  const std::vector<float> one = {1.f, 2.f, 3.f};
  const PointForest<float> single(one.data(), 1, 3);
  const auto r = single.knn(one.data(), 1, {1, 0});
  REQUIRE(r.size() == 1);
  CHECK(r[0].index == 0);
  CHECK(r[0].distance == 0.f);
  const std::vector<float> two = {0.f, 0.f, 3.f, 4.f};
  const PointForest<float> pair(two.data(), 2, 2);
  const std::vector<float> q = {3.f, 4.f};
  const auto both = pair.knn(q.data(), 2, {1, 0});
  REQUIRE(both.size() == 2);
  CHECK(both[0].index == 1);
  CHECK(both[1].distance == 5.f);
  const auto tuned = pair.tune(1.0, 1);
  CHECK(tuned.validation_recall == 1.0);
}

TEST_CASE("forest: the automatic projected dimension follows the spread of the variance",
          "[points][forest]") {
  const std::size_t n = 3000, dim = 100;
  // Isotropic: 90% of the variance needs about 90 directions, so the cap of 64 applies.
  const auto isotropic = make_points<float>(Shape::uniform, n, dim, 41);
  CHECK(PointForest<float>(isotropic.data(), n, dim).projected_dims() == 64);
  // Variance in 5 directions (plus a trace elsewhere): the floor of 24 applies.
  std::vector<float> thin(n * dim);
  const auto few = make_points<float>(Shape::uniform, n, 5, 42);
  const auto trace = make_points<float>(Shape::uniform, n, dim, 43);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a) thin[i * dim + a] = 1e-3f * trace[i * dim + a] + (a % 20 == 0 ? few[i * 5 + a / 20] : 0.f);
  const PointForest<float> thin_forest(thin.data(), n, dim);
  CHECK(thin_forest.projected_dims() == 24);
  // Asked for: as given; fewer dimensions than the floor: all of them; no PCA: the dimension.
  ForestParams asked;
  asked.projected_dims = 10;
  CHECK(PointForest<float>(isotropic.data(), n, dim, asked).projected_dims() == 10);
  CHECK(PointForest<float>(few.data(), n, 5).projected_dims() == 5);
  ForestParams no_pca;
  no_pca.pca = false;
  CHECK(PointForest<float>(isotropic.data(), n, dim, no_pca).projected_dims() == dim);
  // Between the two: variance spread evenly over 40 directions keeps about 36 of them.
  std::vector<float> forty(n * dim, 0.f);
  const auto spread = make_points<float>(Shape::uniform, n, 40, 44);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < 40; ++a) forty[i * dim + a * 2] = spread[i * 40 + a];
  const std::size_t kept = PointForest<float>(forty.data(), n, dim).projected_dims();
  CHECK(kept >= 33);
  CHECK(kept <= 39);
  // The answers stay exact with an unlimited budget whatever the dimension kept.
  const auto queries = make_queries(forty, n, dim, 20, 45);
  CHECK(forest_differs(PointForest<float>(forty.data(), n, dim), forty, n, dim, queries, 10, unlimited(), 1) == "");
}

TEST_CASE("forest: byte-valued points are kept as bytes, with the same answers bit for bit",
          "[points][forest][exact]") {
  const std::size_t n = 2500, dim = GENERATE(as<std::size_t>{}, 5, 64, 128);
  std::mt19937 rng(static_cast<std::uint32_t>(dim));
  std::uniform_int_distribution<int> level(0, 255), cluster(0, 9);
  std::vector<float> centres(10 * dim);
  for (float& c : centres) c = static_cast<float>(level(rng));
  std::vector<float> pts(n * dim);
  std::normal_distribution<float> noise(0.f, 12.f);
  for (std::size_t i = 0; i < n; ++i) {
    const int c = cluster(rng);
    for (std::size_t a = 0; a < dim; ++a)
      pts[i * dim + a] = std::clamp(std::round(centres[c * dim + a] + noise(rng)), 0.f, 255.f);
  }
  // Queries: some byte-valued, some not (the points' storage is what matters).
  auto queries = make_queries(pts, n, dim, 40, 77);
  for (std::size_t i = 0; i < 20 * dim; ++i) queries[i] = std::round(queries[i]);
  ForestParams wide;
  wide.compact = false;
  const PointForest<float> bytes(pts.data(), n, dim), floats(pts.data(), n, dim, wide);
  REQUIRE(bytes.compact());
  REQUIRE_FALSE(floats.compact());
  CHECK(bytes.memory_bytes() + 3 * n * dim == floats.memory_bytes());
  const std::size_t nq = queries.size() / dim;
  for (std::size_t k : {1, 10, 50}) {
    INFO("dim " << dim << ", k " << k);
    CHECK(forest_differs(bytes, pts, n, dim, queries, k, unlimited(), 2) == "");
    for (std::size_t checks : {16, 200}) {
      CHECK(bytes.knn_batch(queries.data(), nq, k, {checks, 0}, 1).neighbors ==
            floats.knn_batch(queries.data(), nq, k, {checks, 0}, 1).neighbors);
    }
  }
  // Built from byte rows, the forest is the same, kept as bytes or widened.
  const std::vector<std::uint8_t> byte_rows(pts.begin(), pts.end());
  const PointForest<float> from_bytes(byte_rows.data(), n, dim);
  const PointForest<float> from_bytes_widened(byte_rows.data(), n, dim, wide);
  CHECK(from_bytes.compact());
  CHECK_FALSE(from_bytes_widened.compact());
  CHECK(from_bytes.memory_bytes() == bytes.memory_bytes());
  CHECK(from_bytes.projected_dims() == bytes.projected_dims());
  for (std::size_t checks : {std::size_t{16}, std::size_t{200}, kdspace::unlimited_checks}) {
    INFO("dim " << dim << ", from byte rows, checks " << checks);
    const auto want = bytes.knn_batch(queries.data(), nq, 10, {checks, 0}, 1);
    for (const PointForest<float>* f : {&from_bytes, &from_bytes_widened})
      CHECK(f->knn_batch(queries.data(), nq, 10, {checks, 0}, 2).neighbors == want.neighbors);
  }
  // The exact answers for tuning come from the bytes as well.
  const auto exact = bytes.knn_exact_batch(queries.data(), nq, 10, 1);
  CHECK(kdspace_test::differs_from_brute_force(exact, pts, n, dim, queries, 10) == "");
  // Doubles too; and one coordinate off the byte grid keeps the points as they are.
  const std::vector<double> as_double(pts.begin(), pts.end());
  const PointForest<double> double_bytes(as_double.data(), n, dim);
  CHECK(double_bytes.compact());
  auto off_grid = pts;
  off_grid[dim + 1] = 0.5f;
  CHECK_FALSE(PointForest<float>(off_grid.data(), n, dim).compact());
  off_grid[dim + 1] = 256.f;
  CHECK_FALSE(PointForest<float>(off_grid.data(), n, dim).compact());
  off_grid[dim + 1] = -1.f;
  CHECK_FALSE(PointForest<float>(off_grid.data(), n, dim).compact());
}
