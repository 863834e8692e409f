// One build, any metric: the Minkowski metric of any order p, a tree copied into another metric,
// scalar type or dimension form, and queries with a caller's result set (query_with).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/kdspace.hpp"
#include "support.hpp"

namespace {

using kdspace::BuildParams;
using kdspace::Dynamic;
using kdspace::Minkowski;
using kdspace::Neighbor;
using kdspace::PointTree;
using kdspace_test::Shape;

const Shape all_shapes[] = {Shape::uniform,   Shape::clustered, Shape::duplicates, Shape::grid,
                            Shape::identical, Shape::flat,      Shape::sorted_x};

std::vector<BuildParams> split_rules() {
  std::vector<BuildParams> rules(3);
  rules[1].position = kdspace::PositionRule::sliding_midpoint;
  rules[2].position = kdspace::PositionRule::middle;
  rules[2].axis = kdspace::AxisRule::cycle;
  for (auto& r : rules) r.leaf_size = 4;
  return rules;
}

/// Counts the points within an internal limit: the smallest result set there is.
template <class T>
struct CountWithin {
  T limit;
  std::size_t count = 0;
  T bound() const { return limit; }
  bool full() const { return false; }
  bool offer(T dist, std::uint32_t) {
    if (!(dist <= limit)) return false;
    ++count;
    return true;
  }
};

template <class T>
std::string describe(Shape shape, std::size_t dim, double p, const BuildParams& rule) {
  return std::string(kdspace_test::type_name<T>()) + " " + kdspace_test::name(shape) + " dim " +
         std::to_string(dim) + " p " + std::to_string(p) + " " + kdspace_test::name(rule.position);
}

/// k-NN (several k) and radius (several radii) of a Minkowski tree equal brute force with the same
/// kernel, bit for bit, on every shape of data.
template <class T>
void minkowski_matches_brute_force(double p) {
  const std::size_t n = 200, nq = 12;
  for (Shape shape : all_shapes)
    for (std::size_t dim : {1, 3, 9}) {
      const auto pts = kdspace_test::make_points<T>(shape, n, dim, 17);
      const auto queries = kdspace_test::make_queries<T>(pts, n, dim, nq, 18);
      const Minkowski metric(p);
      for (const BuildParams& rule : split_rules()) {
        const PointTree<T, Dynamic, Minkowski> tree(pts.data(), n, dim, rule, metric);
        for (std::size_t q = 0; q < nq; ++q) {
          const T* x = queries.data() + q * dim;
          INFO(describe<T>(shape, dim, p, rule) << " query " << q);
          const auto all = kdspace::brute_force_knn(metric, pts.data(), n, dim, x, n);
          for (std::size_t k : {std::size_t{1}, std::size_t{7}, n})
            REQUIRE(tree.knn(x, k) ==
                    std::vector<Neighbor<T>>(all.begin(), all.begin() + static_cast<long>(k)));
          for (T r : {T(0), all[0].distance, all[9].distance, all[n / 2].distance}) {
            REQUIRE(tree.radius(x, r) == kdspace::brute_force_radius(metric, pts.data(), n, dim, x, r));
            CountWithin<T> counter{metric.to_internal(r)};
            tree.query_with(x, counter);
            REQUIRE(counter.count == tree.radius(x, r).size());
          }
        }
      }
    }
}

}  // namespace

TEST_CASE("Minkowski: knn and radius equal brute force bit for bit for p = 1.5, 3 and 7.5",
          "[points][metrics]") {
  for (double p : {1.5, 3.0, 7.5}) {
    minkowski_matches_brute_force<double>(p);
    minkowski_matches_brute_force<float>(p);
  }
}

TEST_CASE("Minkowski: distances are (sum |d_i|^p)^(1/p); p = 1 and p = 2 agree with L1 and L2",
          "[points][metrics]") {
  const double a[3] = {0, 0, 0}, b[3] = {1, 2, 2};
  const Minkowski cube(3);
  CHECK(cube.to_distance(kdspace::internal_distance(cube, a, b, 3)) ==
        Approx(std::cbrt(17.0)).epsilon(1e-15));
  const auto pts = kdspace_test::make_points<double>(Shape::clustered, 500, 4, 3);
  const auto queries = kdspace_test::make_queries<double>(pts, 500, 4, 20, 4);
  const PointTree<double, Dynamic, Minkowski> one(pts.data(), 500, 4, {}, Minkowski(1));
  const PointTree<double, Dynamic, kdspace::L1> l1(pts.data(), 500, 4);
  const PointTree<double, Dynamic, Minkowski> two(pts.data(), 500, 4, {}, Minkowski(2));
  const PointTree<double, Dynamic, kdspace::L2> l2(pts.data(), 500, 4);
  for (std::size_t q = 0; q < 20; ++q) {
    const double* x = queries.data() + q * 4;
    // |d|^1 is exact, so p = 1 is L1 bit for bit; |d|^2 by pow is the correctly rounded square.
    CHECK(one.knn(x, 10) == l1.knn(x, 10));
    const auto got = two.knn(x, 10), want = l2.knn(x, 10);
    for (std::size_t i = 0; i < 10; ++i) {
      CHECK(got[i].index == want[i].index);
      CHECK(got[i].distance == Approx(want[i].distance).epsilon(1e-15));
    }
  }
}

TEST_CASE("Minkowski: an order below 1, infinite or NaN is refused", "[points][metrics]") {
  for (double p : {0.5, 0.0, -2.0, std::numeric_limits<double>::infinity(), std::nan("")}) {
    CAPTURE(p);
    REQUIRE_THROWS_AS(Minkowski(p), kdspace::Error);
  }
  REQUIRE_THROWS_WITH(Minkowski(0.5), Catch::Contains("p must be a finite number >= 1"));
}

TEST_CASE("Minkowski: a float term beyond float's range is infinity, never undefined", "[points][metrics]") {
  const Minkowski big(40);
  CHECK(big.term(100.0f) == std::numeric_limits<float>::infinity());
  CHECK(std::isfinite(big.term(100.0)));
  CHECK(big.to_internal(100.0f) == std::numeric_limits<float>::infinity());
}

TEST_CASE("a tree copied into another metric answers as a tree built with that metric", "[points][metrics]") {
  for (Shape shape : all_shapes) {
    const std::size_t n = 400, dim = 3, nq = 20;
    const auto pts = kdspace_test::make_points<double>(shape, n, dim, 5);
    const auto queries = kdspace_test::make_queries<double>(pts, n, dim, nq, 6);
    BuildParams rule;
    rule.leaf_size = 5;
    const PointTree<double, 3, kdspace::L2> built(pts.data(), n, dim, rule);
    const PointTree<double, Dynamic, kdspace::L1> as_l1(built);
    const PointTree<double, Dynamic, kdspace::Linf> as_linf(built);
    const PointTree<double, Dynamic, Minkowski> as_p3(built, Minkowski(3));
    const PointTree<double, Dynamic, kdspace::L1> l1(pts.data(), n, dim, rule);
    const PointTree<double, Dynamic, kdspace::Linf> linf(pts.data(), n, dim, rule);
    const PointTree<double, Dynamic, Minkowski> p3(pts.data(), n, dim, rule, Minkowski(3));
    REQUIRE(as_l1.node_count() == built.node_count());
    REQUIRE(as_p3.depth() == built.depth());
    for (std::size_t q = 0; q < nq; ++q) {
      INFO(kdspace_test::name(shape) << " query " << q);
      const double* x = queries.data() + q * dim;
      REQUIRE(as_l1.knn(x, 9) == l1.knn(x, 9));
      REQUIRE(as_linf.knn(x, 9) == linf.knn(x, 9));
      REQUIRE(as_p3.knn(x, 9) == p3.knn(x, 9));
      REQUIRE(as_p3.radius(x, 0.3) == p3.radius(x, 0.3));
    }
  }
}

TEST_CASE("a float tree widened to double answers as a double tree of the same values", "[points][metrics]") {
  for (Shape shape : all_shapes) {
    const std::size_t n = 400, dim = 5, nq = 20;
    const auto pts = kdspace_test::make_points<float>(shape, n, dim, 9);
    const auto queries = kdspace_test::make_queries<float>(pts, n, dim, nq, 10);
    const std::vector<double> wide(pts.begin(), pts.end()), wide_queries(queries.begin(), queries.end());
    const PointTree<float> narrow(pts.data(), n, dim);
    const PointTree<double, Dynamic, Minkowski> widened(narrow, Minkowski(4.5));
    const PointTree<double, Dynamic, Minkowski> direct(wide.data(), n, dim, {}, Minkowski(4.5));
    for (std::size_t q = 0; q < nq; ++q) {
      INFO(kdspace_test::name(shape) << " query " << q);
      const double* x = wide_queries.data() + q * dim;
      REQUIRE(widened.knn(x, 6) == direct.knn(x, 6));
      REQUIRE(widened.knn(x, 6) == kdspace::brute_force_knn(Minkowski(4.5), wide.data(), n, dim, x, 6));
    }
  }
}

TEST_CASE("a tree copied into a compile-time dimension must have that dimension", "[points][metrics]") {
  const auto pts = kdspace_test::make_points<float>(Shape::uniform, 50, 4, 1);
  const PointTree<float> four(pts.data(), 50, 4);
  REQUIRE_THROWS_WITH((PointTree<float, 3>(four)), Catch::Contains("dimension 4"));
  const auto three_pts = kdspace_test::make_points<float>(Shape::uniform, 50, 3, 1);
  const PointTree<float> three(three_pts.data(), 50, 3);
  const PointTree<float, 3> fixed(three);
  const float q[3] = {0.1f, 0.2f, 0.3f};
  REQUIRE(fixed.knn(q, 5) == three.knn(q, 5));
}

TEST_CASE("query_with checks its query like knn does", "[points][metrics]") {
  const auto pts = kdspace_test::make_points<double>(Shape::uniform, 50, 2, 1);
  const PointTree<double> tree(pts.data(), 50, 2);
  CountWithin<double> counter{1.0};
  const double bad[2] = {0.5, std::nan("")};
  REQUIRE_THROWS_WITH(tree.query_with(bad, counter), Catch::Contains("coordinate 2 is not finite"));
  kdspace::SearchParams negative;
  negative.eps = -1;
  const double good[2] = {0.5, 0.5};
  REQUIRE_THROWS_WITH(tree.query_with(good, counter, negative), Catch::Contains("eps must be"));
}
