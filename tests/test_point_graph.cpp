// PointForest's neighbour graph: exact answers with an unlimited budget, exact distances always,
// recall that reaches the top as ef grows, one graph for any thread count and for a seed, tuning
// that picks a search and reaches its target on queries it never saw, and clear errors.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/point_forest.hpp"
#include "support.hpp"
#include "../lib/points/build_distances.hpp"
#include "../lib/points/key_select.hpp"

using kdspace::ForestParams;
using kdspace::ForestSearchParams;
using kdspace::GraphMode;
using kdspace::PointForest;
using kdspace::QueryStats;
using kdspace_test::make_points;
using kdspace_test::make_queries;
using kdspace_test::Shape;

namespace {

ForestParams with_graph(unsigned threads = 1) {
  ForestParams params;
  params.graph = GraphMode::on;
  params.threads = threads;
  return params;
}

ForestSearchParams graph_search(std::size_t ef) { return ForestSearchParams{kdspace::unlimited_checks, 0, ef}; }

/// The first returned distance that is not the true distance to its index (bit for bit), or "".
template <class T>
std::string distance_not_exact(const kdspace::NeighborLists<T>& found, const std::vector<T>& pts, std::size_t dim,
                               const std::vector<T>& queries) {
  for (std::size_t q = 0; q < found.rows(); ++q)
    for (const auto& nb : found.row(q)) {
      const T truth = std::sqrt(kdspace::internal_distance<kdspace::L2>(queries.data() + q * dim,
                                                                         pts.data() + std::size_t{nb.index} * dim, dim));
      if (nb.distance != truth)
        return "query " + std::to_string(q) + " index " + std::to_string(nb.index) + ": " +
               std::to_string(nb.distance) + " instead of " + std::to_string(truth);
    }
  return "";
}

/// Whether each row holds k distinct indices in ascending (squared distance, index) order: the tie
/// rule, decided on the squared distance.
template <class T>
bool well_formed(const kdspace::NeighborLists<T>& found, std::size_t k, const std::vector<T>& pts, std::size_t dim,
                 const std::vector<T>& queries) {
  for (std::size_t q = 0; q < found.rows(); ++q) {
    const auto row = found.row(q);
    if (row.size() != k) return false;
    std::vector<kdspace::Index> ids;
    T previous = 0;
    for (std::size_t i = 0; i < k; ++i) {
      ids.push_back(row[i].index);
      const T squared = kdspace::internal_distance<kdspace::L2>(queries.data() + q * dim,
                                                                 pts.data() + std::size_t{row[i].index} * dim, dim);
      if (i > 0 && (squared < previous || (squared == previous && row[i].index < row[i - 1].index))) return false;
      previous = squared;
    }
    std::sort(ids.begin(), ids.end());
    if (std::adjacent_find(ids.begin(), ids.end()) != ids.end()) return false;
  }
  return true;
}

/// nq queries like the data: points of it, moved by a hundredth of the data's spread along each axis.
std::vector<float> near_the_data(const std::vector<float>& pts, std::size_t n, std::size_t dim, std::size_t nq,
                                 std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> move(0.f, 1.f);
  std::vector<float> lo(pts.begin(), pts.begin() + static_cast<std::ptrdiff_t>(dim)), hi = lo;
  for (std::size_t i = 0; i < n * dim; ++i) lo[i % dim] = std::min(lo[i % dim], pts[i]), hi[i % dim] = std::max(hi[i % dim], pts[i]);
  std::vector<float> q(nq * dim);
  for (std::size_t j = 0; j < nq; ++j) {
    const std::size_t on = std::uniform_int_distribution<std::size_t>(0, n - 1)(rng);
    for (std::size_t a = 0; a < dim; ++a) q[j * dim + a] = pts[on * dim + a] + 0.01f * (hi[a] - lo[a]) * move(rng);
  }
  return q;
}

}  // namespace

TEST_CASE("graph: with an unlimited budget the answers are exact, bit for bit, on every shape",
          "[points][graph][exact]") {
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical,
                               Shape::flat);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 2, 8, 33, 128);
  const std::size_t n = GENERATE(as<std::size_t>{}, 1, 9, 1500);
  const std::uint32_t seed = 500 + static_cast<std::uint32_t>(dim * 7 + n);
  const auto pts = make_points<float>(shape, n, dim, seed);
  const auto queries = make_queries(pts, n, dim, 40, seed + 1);
  const PointForest<float> forest(pts.data(), n, dim, with_graph(2));
  REQUIRE(forest.has_graph());
  for (std::size_t k : {1, 5, 10}) {
    if (k > n) continue;
    INFO(kdspace_test::name(shape) << " n=" << n << " dim=" << dim << " k=" << k);
    const auto unlimited = forest.knn_batch(queries.data(), 40, k, graph_search(kdspace::unlimited_checks), 2);
    CHECK(kdspace_test::differs_from_brute_force(unlimited, pts, n, dim, queries, k) == "");
    const auto as_many_as_points = forest.knn_batch(queries.data(), 40, k, graph_search(n), 1);
    CHECK(as_many_as_points.neighbors == unlimited.neighbors);
    // Any budget: k well-ordered, distinct answers at their true distances.
    const auto small = forest.knn_batch(queries.data(), 40, k, graph_search(1), 1);
    CHECK(well_formed(small, k, pts, dim, queries));
    CHECK(distance_not_exact(small, pts, dim, queries) == "");
  }
}

TEST_CASE("graph: every distance is exact, and recall reaches the top as ef grows", "[points][graph]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 16, 96);
  const std::size_t n = 4000, k = 10, nq = 150;
  const auto pts = make_points<float>(Shape::clustered, n, dim, 601);
  const auto queries = near_the_data(pts, n, dim, nq, 602);
  const PointForest<float> forest(pts.data(), n, dim, with_graph());
  const auto exact = forest.knn_exact_batch(queries.data(), nq, k, 1);
  double first = -1, last = -1;
  for (std::size_t ef : {10, 20, 40, 80, 160, 320}) {
    QueryStats stats;
    const auto found = forest.knn_batch(queries.data(), nq, k, graph_search(ef), 2, &stats);
    CHECK(distance_not_exact(found, pts, dim, queries) == "");
    CHECK(well_formed(found, k, pts, dim, queries));
    const double recall = kdspace::recall_at_k(found, exact);
    INFO("dim " << dim << " ef " << ef << " recall " << recall << ", points scored a query "
                << static_cast<double>(stats.points_visited) / nq);
    CHECK(stats.queries == nq);
    if (ef <= 40) CHECK(stats.points_visited < nq * n / 4);  // a search, not a scan
    if (first < 0) first = recall;
    last = recall;
  }
  // The blobs are isotropic Gaussians: at 96-D their points are all about as far from each other,
  // the hardest case for a graph (and for a tree).
  CHECK(first > 0.5);
  CHECK(last >= (dim < 64 ? 0.99 : 0.9));
  CHECK(last >= first);
}

TEST_CASE("graph: queries far from the data still get better answers as ef grows, up to the exact ones",
          "[points][graph]") {
  // Six separate blobs and queries anywhere in their bounding box or far outside it: the graph is
  // joined into one piece, so a larger pool reaches further, and ef = n is exact.
  const std::size_t dim = 16, n = 4000, k = 10, nq = 150;
  const auto pts = make_points<float>(Shape::clustered, n, dim, 603);
  const auto queries = make_queries(pts, n, dim, nq, 604);
  const PointForest<float> forest(pts.data(), n, dim, with_graph());
  const auto exact = forest.knn_exact_batch(queries.data(), nq, k, 1);
  double previous = 0;
  for (std::size_t ef : {10, 100, 1000, 4000}) {
    const auto found = forest.knn_batch(queries.data(), nq, k, graph_search(ef), 1);
    CHECK(distance_not_exact(found, pts, dim, queries) == "");
    const double recall = kdspace::recall_at_k(found, exact);
    INFO("ef " << ef << " recall " << recall);
    CHECK(recall >= previous - 0.01);
    previous = recall;
  }
  CHECK(previous == 1.0);
}

TEST_CASE("graph: rows far from the rest do not cost the other points their graph", "[points][graph]") {
  // The build scores rows on a grid of 16-bit integers; a grid scaled to the widest axis's whole
  // range would put every point but the outlier on a few cells, and ties broken by row would make
  // the graph arbitrary. The same points with and without the outliers must reach the same recall.
  const std::size_t dim = 16, n = 4000, k = 10, nq = 150, ef = 20;
  const auto pts = make_points<float>(Shape::uniform, n, dim, 611);
  const auto queries = near_the_data(pts, n, dim, nq, 612);
  // One outlier (the grid's scale then comes from the axes' robust ranges), or 2% of the rows
  // far out (no robust range leaves them out: the build scores the float rows themselves).
  const std::size_t outliers = GENERATE(as<std::size_t>{}, 1, 80);
  auto with_outlier = pts;
  for (std::size_t o = 0; o < outliers; ++o)
    for (std::size_t a = 0; a < dim; ++a) with_outlier.push_back(a == 0 ? 1e4f + static_cast<float>(o) : 0.f);
  const auto recall_of = [&](const auto& data, const auto& at) {
    using T = typename std::decay_t<decltype(data)>::value_type;
    const PointForest<T> forest(data.data(), data.size() / dim, dim, with_graph());
    const auto exact = forest.knn_exact_batch(at.data(), nq, k, 1);
    const auto found = forest.knn_batch(at.data(), nq, k, graph_search(ef), 1);
    CHECK(distance_not_exact(found, data, dim, at) == "");
    return kdspace::recall_at_k(found, exact);
  };
  // Double rows take the same grid, or the queries' exact kernel where float rows take theirs.
  const double without = recall_of(pts, queries), with = recall_of(with_outlier, queries);
  const double with_doubles = recall_of(std::vector<double>(with_outlier.begin(), with_outlier.end()),
                                        std::vector<double>(queries.begin(), queries.end()));
  INFO("recall at ef " << ef << ": " << without << " without the outliers, " << with << " with " << outliers
                       << " (doubles " << with_doubles << ")");
  CHECK(without > 0.8);
  CHECK(with >= without - 0.02);
  CHECK(with_doubles >= without - 0.02);
}

TEST_CASE("graph: one graph and the same answers on any thread count", "[points][graph][threads]") {
  const std::size_t dim = 40, n = 6000, nq = 200, k = 10;
  const auto pts = make_points<float>(Shape::clustered, n, dim, 611);
  const auto queries = make_queries(pts, n, dim, nq, 612);
  const PointForest<float> serial(pts.data(), n, dim, with_graph(1));
  const PointForest<float> threaded(pts.data(), n, dim, with_graph(3));
  REQUIRE(serial.graph().degree == threaded.graph().degree);
  CHECK(serial.graph().links == threaded.graph().links);
  for (std::size_t ef : {10, 64}) {
    QueryStats one_stats;
    const auto one = serial.knn_batch(queries.data(), nq, k, graph_search(ef), 1, &one_stats);
    for (unsigned threads : {2u, 8u}) {
      QueryStats stats;
      CHECK(threaded.knn_batch(queries.data(), nq, k, graph_search(ef), threads, &stats).neighbors == one.neighbors);
      CHECK(stats.points_visited == one_stats.points_visited);
    }
    for (std::size_t q = 0; q < nq; q += 25) {
      const auto single = threaded.knn(queries.data() + q * dim, k, graph_search(ef));
      for (std::size_t i = 0; i < k; ++i) CHECK(single[i] == one.row(q)[i]);
    }
  }
}

TEST_CASE("graph: a seed gives one graph; byte rows give the graph of their values", "[points][graph]") {
  const std::size_t dim = 64, n = 3000;
  std::mt19937 rng(621);
  std::uniform_int_distribution<int> level(0, 255);
  std::vector<float> pts(n * dim);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a) pts[i * dim + a] = static_cast<float>((level(rng) + 8 * (i % 7) * (a % 5)) % 256);
  ForestParams params = with_graph();
  params.seed = 3;
  const PointForest<float> a(pts.data(), n, dim, params), b(pts.data(), n, dim, params);
  CHECK(a.graph().links == b.graph().links);
  // Kept as bytes, the build scores the bytes; as floats, their 16-bit grid, whose power-of-two scale
  // keeps integer values exact: every distance times the same power of four, so the same order.
  ForestParams wide = params;
  wide.compact = false;
  const PointForest<float> floats(pts.data(), n, dim, wide);
  REQUIRE(a.compact());
  REQUIRE_FALSE(floats.compact());
  CHECK(a.graph().links == floats.graph().links);
  const auto queries = make_queries(pts, n, dim, 50, 622);
  CHECK(a.knn_batch(queries.data(), 50, 10, graph_search(20), 1).neighbors ==
        floats.knn_batch(queries.data(), 50, 10, graph_search(20), 1).neighbors);
  params.seed = 4;
  const PointForest<float> c(pts.data(), n, dim, params);
  CHECK(a.graph().links != c.graph().links);
}

TEST_CASE("graph: the build's pool follows the intrinsic dimension of the data", "[points][graph]") {
  // graph_build_ef = 0 (the default) gives twice the estimated intrinsic dimension, within 16..24:
  // 16 for points on a plane, whatever the dimension of the space they are in, and 24 for points
  // spread in all 64 dimensions.
  auto same_graph = [](const std::vector<float>& pts, std::size_t n, std::size_t dim, std::size_t pool) {
    const PointForest<float> automatic(pts.data(), n, dim, with_graph());
    ForestParams explicit_pool = with_graph();
    explicit_pool.graph_build_ef = pool;
    const PointForest<float> fixed(pts.data(), n, dim, explicit_pool);
    return automatic.graph().links == fixed.graph().links;
  };
  const std::size_t n = 3000, dim = 16;
  std::mt19937 rng(681);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  std::vector<float> directions(2 * dim), plane(n * dim);
  for (float& d : directions) d = unit(rng) - 0.5f;
  for (std::size_t i = 0; i < n; ++i) {
    const float u = unit(rng), v = unit(rng);
    for (std::size_t a = 0; a < dim; ++a) plane[i * dim + a] = u * directions[a] + v * directions[dim + a];
  }
  CHECK(same_graph(plane, n, dim, 16));
  CHECK_FALSE(same_graph(plane, n, dim, 24));
  const auto spread = make_points<float>(Shape::uniform, n, 64, 682);
  CHECK(same_graph(spread, n, 64, 24));
  CHECK_FALSE(same_graph(spread, n, 64, 16));
}

TEST_CASE("graph: degenerate data: identical points, duplicates, one or two points, k = n", "[points][graph]") {
  for (Shape shape : {Shape::identical, Shape::duplicates, Shape::flat, Shape::grid}) {
    const std::size_t n = 700, dim = 12;
    const auto pts = make_points<float>(shape, n, dim, 631);
    const auto queries = make_queries(pts, n, dim, 30, 632);
    const PointForest<float> forest(pts.data(), n, dim, with_graph());
    for (std::size_t k : {std::size_t{1}, std::size_t{10}, n}) {
      INFO(kdspace_test::name(shape) << " k " << k);
      const auto found = forest.knn_batch(queries.data(), 30, k, graph_search(16), 1);
      CHECK(well_formed(found, k, pts, dim, queries));
      CHECK(distance_not_exact(found, pts, dim, queries) == "");
    }
  }
  const std::vector<float> one(16, 1.f);
  const PointForest<float> single(one.data(), 1, 16, with_graph());
  const auto r = single.knn(one.data(), 1, graph_search(10));
  REQUIRE(r.size() == 1);
  CHECK(r[0].index == 0);
  CHECK(r[0].distance == 0.f);
  std::vector<float> two(32, 0.f);
  two[16] = 3.f, two[17] = 4.f;
  const PointForest<float> pair(two.data(), 2, 16, with_graph());
  const auto both = pair.knn(two.data() + 16, 2, graph_search(1));
  REQUIRE(both.size() == 2);
  CHECK(both[0].index == 1);
  CHECK(both[1].distance == 5.f);
}

TEST_CASE("graph: tuning picks a search and reaches the target on queries it never saw", "[points][graph]") {
  const std::size_t dim = 40, n = 20000, k = 10, nq = 500;
  const auto drawn = make_points<float>(Shape::clustered, n + nq + 200, dim, 641);
  const std::vector<float> pts(drawn.begin(), drawn.begin() + static_cast<std::ptrdiff_t>(n * dim));
  const std::vector<float> queries(drawn.begin() + static_cast<std::ptrdiff_t>(n * dim),
                                   drawn.begin() + static_cast<std::ptrdiff_t>((n + nq) * dim));
  const std::vector<float> tuning_queries(drawn.end() - static_cast<std::ptrdiff_t>(200 * dim), drawn.end());
  const PointForest<float> forest(pts.data(), n, dim, with_graph(2));
  const auto exact = forest.knn_exact_batch(queries.data(), nq, k, 2);
  for (double target : {0.9, 0.99}) {
    struct Choice {
      bool graph, trees;
    };
    for (Choice choice : {Choice{true, true}, Choice{true, false}, Choice{false, true}}) {
      kdspace::TuneParams tp;
      tp.graph = choice.graph;
      tp.trees = choice.trees;
      const kdspace::ForestTuning tuned = forest.tune(target, k, tuning_queries.data(), 200, tp);
      INFO("target " << target << " graph " << choice.graph << " trees " << choice.trees << ": ef " << tuned.ef
                     << ", trees " << tuned.trees << ", checks " << tuned.checks << "; tuning recall "
                     << tuned.tuning_recall << ", validation " << tuned.validation_recall);
      if (!choice.trees) CHECK(tuned.ef > 0);
      if (!choice.graph) CHECK(tuned.ef == 0);
      if (tuned.ef == 0) CHECK(tuned.trees >= 1);
      CHECK(tuned.validation_recall >= target);
      const double recall = kdspace::recall_at_k(forest.knn_batch(queries.data(), nq, k, tuned.search(), 2), exact);
      INFO("recall on fresh queries " << recall);
      CHECK(recall >= target - 0.02);
    }
  }
}

TEST_CASE("graph: GraphMode::automatic builds the graph from graph_min_dim on", "[points][graph]") {
  for (std::size_t dim : {kdspace::graph_min_dim - 1, kdspace::graph_min_dim}) {
    const auto pts = make_points<float>(Shape::uniform, 500, dim, 651);
    const PointForest<float> forest(pts.data(), 500, dim);
    CHECK(forest.has_graph() == (dim >= kdspace::graph_min_dim));
    ForestParams off;
    off.graph = GraphMode::off;
    CHECK_FALSE(PointForest<float>(pts.data(), 500, dim, off).has_graph());
    CHECK(PointForest<float>(pts.data(), 500, dim, with_graph()).has_graph());
  }
}

TEST_CASE("graph: bad parameters get clear errors", "[points][graph][errors]") {
  const auto pts = make_points<float>(Shape::uniform, 100, 8, 661);
  auto build = [&](auto change) {
    ForestParams p = with_graph();
    change(p);
    PointForest<float> f(pts.data(), 100, 8, p);
  };
  CHECK_THROWS_WITH(build([](ForestParams& p) { p.graph_degree = 1; }), Catch::Contains("graph_degree must be in 2..1024"));
  CHECK_THROWS_WITH(build([](ForestParams& p) { p.graph_degree = 1025; }), Catch::Contains("graph_degree"));
  for (double alpha : {0.9, 17.0, std::numeric_limits<double>::quiet_NaN()})
    CHECK_THROWS_WITH(build([alpha](ForestParams& p) { p.graph_alpha = alpha; }), Catch::Contains("graph_alpha"));
  ForestParams off;
  off.graph = GraphMode::off;
  const PointForest<float> no_graph(pts.data(), 100, 8, off);
  CHECK_THROWS_WITH(no_graph.knn(pts.data(), 3, graph_search(10)), Catch::Contains("has none"));
  const PointForest<float> forest(pts.data(), 100, 8, with_graph());
  CHECK_THROWS_WITH(forest.knn(pts.data(), 0, graph_search(10)), Catch::Contains("k must be at least 1"));
}

TEST_CASE("graph: the branch-free selection and sort of keys agree with std::sort", "[points][graph]") {
  // Distinct keys in random, sorted, reversed and nearly sorted orders, every count from 0 to 140
  // and every number kept: the kept ones are the smallest, and sort_keys sorts.
  std::mt19937_64 rng(771);
  for (std::size_t count = 0; count <= 140; ++count) {
    std::vector<std::uint64_t> keys(count);
    for (std::size_t i = 0; i < count; ++i) keys[i] = (rng() & ~std::uint64_t{0xffffffff}) | i;  // distinct
    std::vector<std::uint64_t> sorted = keys;
    std::sort(sorted.begin(), sorted.end());
    for (int order = 0; order < 4; ++order) {
      std::vector<std::uint64_t> input = order == 0 ? keys : sorted;
      if (order == 2) std::reverse(input.begin(), input.end());
      if (order == 3 && count > 2) std::swap(input[count / 3], input[count - 1]);
      for (std::size_t keep = 0; keep <= count; keep += count > 40 ? 7 : 1) {
        std::vector<std::uint64_t> work = input;
        kdspace::detail::select_smallest(work.data(), count, keep);
        std::sort(work.begin(), work.begin() + static_cast<std::ptrdiff_t>(keep));
        REQUIRE(std::equal(work.begin(), work.begin() + static_cast<std::ptrdiff_t>(keep), sorted.begin()));
      }
      std::vector<std::uint64_t> work = input;
      kdspace::detail::sort_keys(work.data(), count);
      REQUIRE(work == sorted);
    }
  }
}

TEMPLATE_TEST_CASE("graph: the build's 16-bit grid keeps rows that differ apart, or is not used", "[points][graph]",
                   float, double) {
  // Rows that differ must not share a grid row: when no finite scale can keep them apart (every
  // robust range 0 though some axis varies, a range that overflows, or one too small for the
  // grid), quantize_rows returns nothing and the build scores the rows themselves.
  const std::size_t dim = 16;
  auto keeps_apart = [&](const std::vector<TestType>& rows) {
    const std::size_t n = rows.size() / dim;
    const auto grid = kdspace::detail::quantize_rows(rows.data(), n, dim);
    if (!grid) return true;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j) {
        const bool rows_differ = !std::equal(rows.begin() + static_cast<std::ptrdiff_t>(i * dim),
                                             rows.begin() + static_cast<std::ptrdiff_t>((i + 1) * dim),
                                             rows.begin() + static_cast<std::ptrdiff_t>(j * dim));
        const bool grid_differs = !std::equal(grid->begin() + static_cast<std::ptrdiff_t>(i * dim),
                                              grid->begin() + static_cast<std::ptrdiff_t>((i + 1) * dim),
                                              grid->begin() + static_cast<std::ptrdiff_t>(j * dim));
        if (rows_differ && !grid_differs) return false;
      }
    return true;
  };
  // Nearly all rows copies of one: 9,995 at the origin, 5 elsewhere (the sample's 0.1% tails
  // never reach them, so every robust range is 0).
  std::vector<TestType> copies(10000 * dim, TestType(0));
  for (std::size_t i = 0; i < 5; ++i) copies[(2000 * i + 7) * dim + i] = static_cast<TestType>(i + 1);
  CHECK(keeps_apart(copies));
  // Each axis non-zero in one row of 2,000.
  std::vector<TestType> sparse(2000 * dim, TestType(0));
  for (std::size_t r = 0; r < 2000; r += 125) sparse[r * dim + (r / 125) % dim] = TestType(1);
  CHECK(keeps_apart(sparse));
  // A range wider than the largest finite value, and one narrower than the grid can scale.
  for (const TestType half : {std::numeric_limits<TestType>::max(), std::numeric_limits<TestType>::denorm_min()}) {
    std::vector<TestType> wide(64 * dim);
    for (std::size_t i = 0; i < wide.size(); ++i) wide[i] = (i / dim) % 2 ? half : -half;
    CHECK(keeps_apart(wide));
  }
  // All rows the same: any grid keeps nothing apart that differs.
  CHECK(keeps_apart(std::vector<TestType>(100 * dim, TestType(3))));
}
