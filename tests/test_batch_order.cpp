// The order in which a batch visits its queries (detail/morton_order.hpp): a permutation of the
// batch in Z-order of the queries' cells, and batches answered in that order give the brute-force
// answers bit for bit, on every data shape, in 1 to 8 dimensions (and beyond, where the order is
// another), for many k.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "kdspace/points/detail/morton_order.hpp"
#include "kdspace/points/point_tree.hpp"
#include "support.hpp"

using kdspace::PointTree;
using kdspace::SearchParams;
using kdspace::detail::morton_order;
using kdspace_test::make_points;
using kdspace_test::make_queries;
using kdspace_test::Shape;

namespace {

/// The Z-order key of a row, bit by bit (the plain definition, independent of the table look-ups):
/// the cell of each axis in a grid of 2^bits cells over [lo, hi], its bits interleaved, axis 0 lowest.
std::uint64_t reference_key(const float* x, std::size_t dim, const float* lo, const float* hi,
                            std::size_t bits) {
  std::uint64_t key = 0;
  for (std::size_t a = 0; a < dim; ++a) {
    const double cells = static_cast<double>(std::uint64_t{1} << bits);
    const double extent = static_cast<double>(hi[a]) - static_cast<double>(lo[a]);
    double t = extent > 0 ? (static_cast<double>(x[a]) - static_cast<double>(lo[a])) * (cells / extent) : 0;
    t = std::min(cells - 1, std::max(0.0, t));
    const auto cell = static_cast<std::uint64_t>(t);
    for (std::size_t b = 0; b < bits; ++b) key |= ((cell >> b) & 1u) << (b * dim + a);
  }
  return key;
}

}  // namespace

TEST_CASE("morton_order is a permutation of the rows, in ascending Z-order key, stable within a cell",
          "[points][batch_order]") {
  for (std::size_t dim = 1; dim <= kdspace::detail::morton_max_dim; ++dim)
    for (const Shape shape :
         {Shape::uniform, Shape::clustered, Shape::duplicates, Shape::identical, Shape::grid}) {
      CAPTURE(dim, kdspace_test::name(shape));
      const std::size_t n = 700, first = 37, last = 650;
      const auto rows = make_points<float>(shape, n, dim, 900 + static_cast<std::uint32_t>(dim));
      // A box smaller than the rows' own, so that some rows lie outside it.
      std::vector<float> lo(dim), hi(dim);
      for (std::size_t a = 0; a < dim; ++a) {
        lo[a] = rows[a] - 1;
        hi[a] = rows[a] + 1;
      }
      const std::vector<std::size_t> order =
          morton_order(rows.data(), first, last, dim, lo.data(), hi.data());
      REQUIRE(order.size() == last - first);
      std::vector<std::size_t> sorted = order;
      std::sort(sorted.begin(), sorted.end());
      for (std::size_t i = 0; i < sorted.size(); ++i) REQUIRE(sorted[i] == first + i);
      const std::size_t bits = kdspace::detail::morton_bits_per_axis(last - first, dim);
      for (std::size_t i = 1; i < order.size(); ++i) {
        const std::uint64_t before =
            reference_key(rows.data() + order[i - 1] * dim, dim, lo.data(), hi.data(), bits);
        const std::uint64_t after =
            reference_key(rows.data() + order[i] * dim, dim, lo.data(), hi.data(), bits);
        REQUIRE(before <= after);
        if (before == after) REQUIRE(order[i - 1] < order[i]);
      }
    }
}

TEST_CASE("morton_order takes rows at the ends of the float range, a flat box and an empty range",
          "[points][batch_order]") {
  const float big = std::numeric_limits<float>::max();
  const std::vector<float> rows = {-big, big, big, -big, 0, 0, big, big, -big, -big, 1, -1};
  const float lo[2] = {-big, -big}, hi[2] = {big, big};
  auto order = morton_order(rows.data(), 0, 6, 2, lo, hi);
  std::sort(order.begin(), order.end());
  REQUIRE(order == std::vector<std::size_t>{0, 1, 2, 3, 4, 5});
  const float point[2] = {3, 3};  // a box of no extent: every row in one cell, the given order kept
  REQUIRE(morton_order(rows.data(), 0, 6, 2, point, point) == std::vector<std::size_t>{0, 1, 2, 3, 4, 5});
  REQUIRE(morton_order(rows.data(), 4, 4, 2, lo, hi).empty());
  const double huge = std::numeric_limits<double>::max();
  const std::vector<double> wide = {-huge, huge, 0, huge, -huge};
  const double wide_lo = -huge, wide_hi = huge;  // hi - lo overflows a double: one cell
  REQUIRE(morton_order(wide.data(), 0, 5, 1, &wide_lo, &wide_hi) == std::vector<std::size_t>{0, 1, 2, 3, 4});
}

TEST_CASE(
    "exact: knn_batch answered in Z-order matches brute force bit for bit on every shape, 1-9 dimensions",
    "[points][exact][batch_order]") {
  // 300 queries: batches from 256 queries on are reordered (up to 8-D in Z-order, beyond by leaf); a
  // third of the queries are base points (ties), every seventh far outside.
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 5, 8, 9);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid,
                               Shape::identical, Shape::flat, Shape::sorted_x);
  const std::size_t n = 1500;
  const auto seed = 31000 + static_cast<std::uint32_t>(dim * 16 + static_cast<std::size_t>(shape));
  const auto pts = make_points<float>(shape, n, dim, seed);
  const auto queries = make_queries<float>(pts, n, dim, 300, seed + 1);
  const PointTree<float> tree(pts.data(), n, dim);
  CAPTURE(dim, kdspace_test::name(shape));
  for (const std::size_t k : {1, 2, 7, 16, 50}) {
    CAPTURE(k);
    SearchParams by_tree;
    by_tree.batch_method = kdspace::BatchMethod::tree;
    REQUIRE(kdspace_test::differs_from_brute_force(tree.knn_batch(queries.data(), 300, k, by_tree, 1), pts, n,
                                                   dim, queries, k) == "");
  }
  // In double too, on two threads.
  const auto wide = make_points<double>(shape, n, dim, seed);
  const auto wide_queries = make_queries<double>(wide, n, dim, 300, seed + 2);
  const PointTree<double> wide_tree(wide.data(), n, dim);
  REQUIRE(kdspace_test::differs_from_brute_force(wide_tree.knn_batch(wide_queries.data(), 300, 10, {}, 2),
                                                 wide, n, dim, wide_queries, 10) == "");
}
