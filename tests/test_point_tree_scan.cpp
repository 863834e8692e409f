// The blocked scan (BatchMethod::scan, and the automatic switch to it): its answers must be those of
// brute_force_knn bit for bit, on every data shape, in float and double, at every scale of the
// coordinates (where the rounding bound of the matrix-product estimate is put to the test).
#include <catch2/catch.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/point_tree.hpp"
#include "support.hpp"

using kdspace::BatchMethod;
using kdspace::Neighbor;
using kdspace::PointTree;
using kdspace::QueryStats;
using kdspace::SearchParams;
using kdspace_test::make_points;
using kdspace_test::make_queries;
using kdspace_test::Shape;

namespace {

/// Compares knn_batch(scan) with brute_force_knn for every query; returns the first difference.
template <class T, class Metric>
std::string scan_differs(const std::vector<T>& pts, std::size_t n, std::size_t dim, const std::vector<T>& queries,
                         std::size_t k, unsigned threads, BatchMethod method = BatchMethod::scan) {
  const PointTree<T, kdspace::Dynamic, Metric> tree(pts.data(), n, dim);
  SearchParams sp;
  sp.batch_method = method;
  const std::size_t nq = queries.size() / dim;
  const auto batch = tree.knn_batch(queries.data(), nq, k, sp, threads);
  return kdspace_test::differs_from_brute_force<Metric>(batch, pts, n, dim, queries, k);
}

}  // namespace

TEST_CASE("scan: knn_batch by the blocked scan equals brute force bit for bit on every shape, dimension and k",
          "[points][exact][scan]") {
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical,
                               Shape::flat, Shape::sorted_x);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 3, 8, 17, 64, 128);
  const std::size_t n = GENERATE(as<std::size_t>{}, 1, 7, 1500);
  const std::uint32_t seed = 900 + static_cast<std::uint32_t>(dim * 7 + n);
  const auto pts = make_points<float>(shape, n, dim, seed);
  const auto queries = make_queries(pts, n, dim, 150, seed + 1);
  for (std::size_t k : {1, 2, 5, 10, 100}) {
    if (k > n) continue;
    INFO(kdspace_test::name(shape) << " n=" << n << " dim=" << dim << " k=" << k << " float");
    CHECK(scan_differs<float, kdspace::L2>(pts, n, dim, queries, k, 2) == "");
  }
  const auto pts_d = make_points<double>(shape, n, dim, seed);
  const auto queries_d = make_queries(pts_d, n, dim, 80, seed + 2);
  INFO(kdspace_test::name(shape) << " n=" << n << " dim=" << dim << " k=" << std::min<std::size_t>(n, 10)
                                 << " double");
  CHECK(scan_differs<double, kdspace::L2>(pts_d, n, dim, queries_d, std::min<std::size_t>(n, 10), 1) == "");
}

TEST_CASE("scan: exact at every scale: far from the origin, tiny, huge and mixed coordinates",
          "[points][exact][scan]") {
  // Offsets make the norms large against the distances (the estimate's rounding bound is then wide);
  // tiny coordinates reach the subnormal range; huge ones would overflow the estimate and must take
  // the plain exact scan.
  struct Scale {
    double factor, offset;
  };
  const Scale scale = GENERATE(Scale{1, 1e4}, Scale{1e-3, 1e3}, Scale{1e-30, 0}, Scale{1e-42, 0}, Scale{1e18, 0},
                               Scale{1e18, 1e19}, Scale{1, -3e5});
  const std::size_t dim = GENERATE(as<std::size_t>{}, 2, 32, 128);
  const std::size_t n = 1200;
  auto pts = make_points<float>(Shape::clustered, n, dim, 77);
  for (auto& v : pts) v = static_cast<float>(scale.offset + scale.factor * static_cast<double>(v));
  const auto queries = make_queries(pts, n, dim, 100, 78);
  INFO("scale " << scale.factor << " offset " << scale.offset << " dim " << dim);
  for (std::size_t k : {1, 10, 50}) CHECK(scan_differs<float, kdspace::L2>(pts, n, dim, queries, k, 2) == "");
}

TEST_CASE("scan: forced scan under L1 and Linf equals brute force", "[points][exact][scan]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 3, 40);
  const auto pts = make_points<float>(Shape::grid, 900, dim, 55);
  const auto queries = make_queries(pts, 900, dim, 90, 56);
  CHECK(scan_differs<float, kdspace::L1>(pts, 900, dim, queries, 7, 2) == "");
  CHECK(scan_differs<float, kdspace::Linf>(pts, 900, dim, queries, 7, 2) == "");
}

TEST_CASE("scan: the automatic choice scans uniform 128-D data and keeps the tree on 3-D data",
          "[points][exact][scan]") {
  // In 128 dimensions an exact tree query scores nearly every point; in 3 it scores a few dozen.
  auto points_scored = [](std::size_t dim, std::size_t nq) {
    const std::size_t n = 4000;
    const auto pts = make_points<float>(Shape::uniform, n, dim, 31);
    const auto queries = make_queries(pts, n, dim, nq, 32);
    const PointTree<float> tree(pts.data(), n, dim);
    QueryStats stats;
    const auto automatic = tree.knn_batch(queries.data(), nq, 10, {}, 2, &stats);
    SearchParams by_tree;
    by_tree.batch_method = BatchMethod::tree;
    const auto reference = tree.knn_batch(queries.data(), nq, 10, by_tree, 1);
    CHECK(automatic.neighbors == reference.neighbors);
    CHECK(stats.queries == nq);
    return static_cast<double>(stats.points_visited) / static_cast<double>(nq * n);
  };
  // The first 16 queries go to the tree; the rest score all points.
  CHECK(points_scored(128, 200) > 0.95);
  CHECK(points_scored(3, 200) < 0.05);
  // A batch too small to probe stays on the tree, and is exact all the same.
  CHECK(points_scored(128, 20) > 0.0);
}

TEST_CASE("scan: results do not depend on the thread count", "[points][exact][scan][threads]") {
  const auto pts = make_points<float>(Shape::clustered, 2000, 96, 5);
  const auto queries = make_queries(pts, 2000, 96, 333, 6);
  const PointTree<float> tree(pts.data(), 2000, 96);
  SearchParams sp;
  sp.batch_method = BatchMethod::scan;
  const auto one = tree.knn_batch(queries.data(), 333, 10, sp, 1);
  for (unsigned threads : {2u, 3u, 8u}) CHECK(tree.knn_batch(queries.data(), 333, 10, sp, threads).neighbors == one.neighbors);
}

TEST_CASE("scan: small-integer data (the 16-bit integer path) equals brute force bit for bit",
          "[points][exact][scan]") {
  // Byte values, values far from the origin with small extents, negative values, many exact ties
  // (values in 0..3); then data just outside the path (extents too wide, queries between integers),
  // which the estimated scan answers.
  struct Case {
    const char* name;
    double offset;
    int levels;             // coordinates are offset + an integer in [0, levels)
    bool fractional_queries;
  };
  const Case c = GENERATE(Case{"bytes", 0, 256, false}, Case{"far from the origin", 1e6, 200, false},
                          Case{"negative", -300, 256, false}, Case{"ties", 0, 4, false},
                          Case{"extents too wide", 0, 3000, false}, Case{"queries between integers", 0, 256, true});
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 3, 17, 128, 129);
  const std::size_t n = 1300;
  std::mt19937 rng(4242 + static_cast<std::uint32_t>(dim));
  std::uniform_int_distribution<int> level(0, c.levels - 1);
  auto draw = [&](std::size_t count, bool fractional) {
    std::vector<double> v(count * dim);
    for (auto& x : v) x = c.offset + level(rng) + (fractional ? 0.5 : 0.0);
    return v;
  };
  const std::vector<double> base = draw(n, false), queries = draw(90, c.fractional_queries);
  const std::vector<float> base_f(base.begin(), base.end()), queries_f(queries.begin(), queries.end());
  for (std::size_t k : {1, 10, 64}) {
    INFO(c.name << " dim=" << dim << " k=" << k);
    CHECK(scan_differs<float, kdspace::L2>(base_f, n, dim, queries_f, k, 2) == "");
    CHECK(scan_differs<double, kdspace::L2>(base, n, dim, queries, k, 1) == "");
  }
}

namespace {

/// The scan itself (detail::blocked_scan_knn_l2, rows in the caller's order) with at most the given
/// kernel, on float rows or on the same values as bytes; the first difference from brute force.
std::string kernel_differs(const std::vector<float>& pts, std::size_t n, std::size_t dim, const std::vector<float>& queries,
                           std::size_t k, kdspace::detail::ScanKernel widest, bool as_bytes) {
  std::vector<std::uint32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::uint32_t>(i);
  std::vector<float> centre(dim, 0.f);
  for (std::size_t a = 0; a < dim; ++a) centre[a] = pts[a];  // any point near the data will do
  const std::vector<std::uint8_t> bytes = as_bytes ? std::vector<std::uint8_t>(pts.begin(), pts.end())
                                                   : std::vector<std::uint8_t>();
  kdspace::detail::ScanData<float> data{as_bytes ? nullptr : pts.data(), order.data(), n, dim, centre.data(),
                                        as_bytes ? bytes.data() : nullptr};
  data.widest = widest;
  const std::size_t nq = queries.size() / dim;
  kdspace::NeighborLists<float> lists;
  lists.neighbors.resize(nq * k);
  for (std::size_t q = 1; q <= nq; ++q) lists.offsets.push_back(q * k);
  kdspace::detail::blocked_scan_knn_l2(data, queries.data(), nq, k, lists.neighbors.data());
  return kdspace_test::differs_from_brute_force<kdspace::L2>(lists, pts, n, dim, queries, k);
}

}  // namespace

TEST_CASE("scan: every product kernel (AVX-512, AVX2, portable) equals brute force bit for bit",
          "[points][exact][scan]") {
  // Each kernel the processor has is forced in turn (wider ones fall back when it lacks them). Sizes
  // leave partial tiles of points (n not a multiple of 32, more than one block of 1024) and of
  // queries (37: not a multiple of 6 or 12). Data: float estimates (clustered, far from the origin:
  // large norms and a wide bound, duplicates and all-identical points: ties broken by index) and
  // small integers (byte values, with many ties; as float rows and as byte rows).
  using kdspace::detail::ScanKernel;
  const ScanKernel kernel = GENERATE(ScanKernel::avx512, ScanKernel::avx2, ScanKernel::portable);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 5, 128);
  const std::size_t n = 2071, nq = 37;
  struct Case {
    const char* name;
    Shape shape;
    double offset;
    int levels;  // > 0: coordinates are integers in [0, levels) instead of the shape
  };
  const Case c = GENERATE(Case{"clustered", Shape::clustered, 0, 0}, Case{"large norms", Shape::clustered, 3e4, 0},
                          Case{"duplicates", Shape::duplicates, 0, 0}, Case{"identical", Shape::identical, 0, 0},
                          Case{"bytes", Shape::uniform, 0, 256}, Case{"byte ties", Shape::uniform, 0, 3});
  std::vector<float> pts = make_points<float>(c.shape, n, dim, 321 + static_cast<std::uint32_t>(dim));
  std::vector<float> queries = make_queries(pts, n, dim, nq, 322);
  if (c.levels > 0) {
    std::mt19937 rng(323);
    std::uniform_int_distribution<int> level(0, c.levels - 1);
    for (auto& v : pts) v = static_cast<float>(level(rng));
    for (auto& v : queries) v = static_cast<float>(level(rng));
  }
  for (auto& v : pts) v += static_cast<float>(c.offset);
  for (auto& v : queries) v += static_cast<float>(c.offset);
  for (std::size_t k : {std::size_t{1}, std::size_t{10}, std::size_t{97}, n}) {
    INFO(c.name << " kernel " << static_cast<int>(kernel) << " dim " << dim << " k " << k);
    CHECK(kernel_differs(pts, n, dim, queries, k, kernel, false) == "");
    if (c.levels > 0) CHECK(kernel_differs(pts, n, dim, queries, k, kernel, true) == "");
  }
}

TEST_CASE("scan: k above the number of points is an error, k equal to it is answered", "[points][exact][scan]") {
  const auto pts = make_points<float>(Shape::uniform, 40, 64, 9);
  const auto queries = make_queries(pts, 40, 64, 30, 10);
  const PointTree<float> tree(pts.data(), 40, 64);
  SearchParams sp;
  sp.batch_method = BatchMethod::scan;
  CHECK_THROWS_AS(tree.knn_batch(queries.data(), 30, 41, sp, 1), kdspace::Error);
  CHECK(scan_differs<float, kdspace::L2>(pts, 40, 64, queries, 40, 1) == "");
}
