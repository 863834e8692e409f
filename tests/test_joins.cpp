// Dual-tree joins: k-NN joins, self-joins, pairs within r, distances within r and pair counts are
// checked bit for bit against brute force (and against the single-tree queries), in ordinary space
// and on a torus, on uniform, clustered, duplicate-heavy, gridded, identical and flat data.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/joins/joins.hpp"
#include "kdspace/joins/periodic_tree.hpp"
#include "support.hpp"

namespace {

using kdspace::IndexPair;
using kdspace::JoinParams;
using kdspace::Neighbor;
using kdspace::PointTree;
using kdspace_test::make_points;
using kdspace_test::Shape;

/// The periods of a torus (+inf: not periodic) and the points moved into [0, L) on periodic axes.
template <class T>
struct Torus {
  std::vector<double> boxsize;  // as given to the joins
  std::vector<T> period;        // L, or +inf

  Torus(std::vector<double> sizes, std::size_t dim) : boxsize(std::move(sizes)) {
    for (std::size_t a = 0; a < dim; ++a) {
      const double L = boxsize.empty() ? 0 : boxsize[boxsize.size() == 1 ? 0 : a];
      period.push_back(L > 0 ? static_cast<T>(L) : std::numeric_limits<T>::infinity());
    }
  }
  bool periodic() const { return !boxsize.empty(); }

  void wrap(std::vector<T>& points) const {
    const std::size_t dim = period.size();
    for (std::size_t i = 0; i < points.size(); ++i) {
      const T L = period[i % dim];
      if (std::isinf(L)) continue;
      T v = points[i] - std::floor(points[i] / L) * L;
      if (!(v >= 0 && v < L)) v = 0;
      points[i] = v;
    }
  }

  /// The reference distance: per axis min(|d|, L - |d|) (|d| where not periodic), combined in the
  /// documented order of internal_distance.
  template <class Metric>
  T distance(const T* a, const T* b) const {
    return kdspace::combine_axes<Metric, T>(period.size(), [&](std::size_t i) {
      const T d = std::abs(a[i] - b[i]);
      return Metric::term(std::isinf(period[i]) ? d : std::min(d, period[i] - d));
    });
  }
};

template <class T>
struct Candidate {
  T dist;
  std::uint32_t index;
  bool operator<(const Candidate& o) const { return dist < o.dist || (dist == o.dist && index < o.index); }
};

/// Every internal distance between the rows of a and b, computed once per case: row i of a against
/// all of b.
template <class T>
struct DistanceTable {
  std::size_t rows, cols;
  std::vector<T> dist;

  template <class Metric>
  static DistanceTable make(const Torus<T>& space, const std::vector<T>& a, const std::vector<T>& b) {
    const std::size_t dim = space.period.size();
    DistanceTable t{a.size() / dim, b.size() / dim, {}};
    t.dist.resize(t.rows * t.cols);
    for (std::size_t i = 0; i < t.rows; ++i)
      for (std::size_t j = 0; j < t.cols; ++j) t.dist[i * t.cols + j] = space.template distance<Metric>(&a[i * dim], &b[j * dim]);
    return t;
  }
  T at(std::size_t i, std::size_t j) const { return dist[i * cols + j]; }
};

/// Brute force: for each row, the k first columns in (distance, index) order; with self, a row
/// skips its own column.
template <class Metric, class T>
std::vector<std::vector<Neighbor<T>>> brute_knn(const DistanceTable<T>& table, std::size_t k, bool self) {
  std::vector<std::vector<Neighbor<T>>> out(table.rows);
  std::vector<Candidate<T>> all;
  for (std::size_t i = 0; i < table.rows; ++i) {
    all.clear();
    for (std::size_t j = 0; j < table.cols; ++j)
      if (!self || j != i) all.push_back({table.at(i, j), static_cast<std::uint32_t>(j)});
    std::partial_sort(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(k), all.end());
    for (std::size_t r = 0; r < k; ++r) out[i].push_back({all[r].index, Metric::to_distance(all[r].dist)});
  }
  return out;
}

/// Brute force: the pairs within r (closed), (a, b) sorted; self: a < b.
template <class Metric, class T>
std::vector<kdspace::PairDistance<T>> brute_pairs(const DistanceTable<T>& table, bool self, T r) {
  const T limit = Metric::to_internal(r);
  std::vector<kdspace::PairDistance<T>> out;
  for (std::size_t i = 0; i < table.rows; ++i)
    for (std::size_t j = self ? i + 1 : 0; j < table.cols; ++j)
      if (table.at(i, j) <= limit)
        out.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j), Metric::to_distance(table.at(i, j))});
  return out;
}

template <class T>
std::vector<IndexPair> indices_of(const std::vector<kdspace::PairDistance<T>>& pairs) {
  std::vector<IndexPair> out;
  for (const auto& p : pairs) out.push_back({p.a, p.b});
  return out;
}

template <class T>
std::string first_row_difference(const kdspace::NeighborLists<T>& got, const std::vector<std::vector<Neighbor<T>>>& want) {
  if (got.rows() != want.size()) return "row count " + std::to_string(got.rows()) + " vs " + std::to_string(want.size());
  for (std::size_t q = 0; q < want.size(); ++q) {
    const auto row = got.row(q);
    if (row.size() != want[q].size()) return "row " + std::to_string(q) + ": " + std::to_string(row.size()) + " results, expected " + std::to_string(want[q].size());
    for (std::size_t i = 0; i < row.size(); ++i)
      if (!(row[i] == want[q][i]))
        return "row " + std::to_string(q) + " rank " + std::to_string(i) + ": index " + std::to_string(row[i].index) +
               " at " + std::to_string(row[i].distance) + ", brute force index " + std::to_string(want[q][i].index) +
               " at " + std::to_string(want[q][i].distance);
  }
  return "";
}

/// A few radii: 0, and exactly at some pair distances (the internal distance decides) and one step
/// either side of them.
template <class Metric, class T>
std::vector<T> probing_radii(const Torus<T>& space, const std::vector<T>& points, std::uint32_t seed) {
  const std::size_t dim = space.period.size(), n = points.size() / dim;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<std::size_t> pick(0, n - 1);
  std::vector<T> radii{T(0)};
  for (int i = 0; i < 2; ++i) {
    // The true distance of a pair whose internal distance round-trips through it.
    const T d = Metric::to_distance(space.template distance<Metric>(&points[pick(rng) * dim], &points[pick(rng) * dim]));
    radii.push_back(d);
    radii.push_back(std::nextafter(d, T(0)));
    radii.push_back(std::nextafter(d, std::numeric_limits<T>::infinity()));
  }
  return radii;
}

struct Case {
  Shape shape;
  std::size_t n;
  std::size_t dim;
};

const Case cases[] = {
    {Shape::uniform, 400, 1},    {Shape::uniform, 500, 3},    {Shape::clustered, 500, 3},  {Shape::duplicates, 400, 2},
    {Shape::grid, 400, 3},       {Shape::identical, 200, 4},  {Shape::flat, 400, 5},       {Shape::uniform, 300, 9},
    {Shape::clustered, 300, 17}, {Shape::grid, 200, 64},      {Shape::sorted_x, 300, 2},   {Shape::uniform, 1, 3},
};

template <class T>
std::vector<double> boxsize_for(Shape shape, std::size_t dim, bool periodic) {
  if (!periodic) return {};
  if (shape == Shape::grid) return {5.0};  // integer points mod 5: many pairs at exactly L / 2
  std::vector<double> sizes(dim, 1.5);
  if (dim > 1) sizes[dim / 2] = 0;  // one axis not periodic
  return sizes;
}

/// Runs every join on one case and checks it against brute force.
template <class T, class Metric, int Dim = kdspace::Dynamic>
void check_case(const Case& c, bool periodic, std::uint32_t seed) {
  CAPTURE(kdspace_test::name(c.shape), c.n, c.dim, periodic, Metric::name, kdspace_test::type_name<T>());
  const Torus<T> space(boxsize_for<T>(c.shape, c.dim, periodic), c.dim);
  std::vector<T> points = make_points<T>(c.shape, c.n, c.dim, seed);
  std::vector<T> others = make_points<T>(c.shape == Shape::identical ? Shape::uniform : c.shape, c.n / 2 + 1, c.dim, seed + 1);
  space.wrap(points);
  space.wrap(others);
  const std::size_t n = c.n, m = others.size() / c.dim;
  kdspace::BuildParams build;
  build.leaf_size = 1 + seed % 12;  // small leaves: deep trees, many node pairs
  const PointTree<T, Dim, Metric> tree(points.data(), n, c.dim, build);
  const PointTree<T, Dim, Metric> other_tree(others.data(), m, c.dim, build);
  JoinParams params;
  params.threads = 1;
  params.boxsize = space.boxsize;

  const auto self_table = DistanceTable<T>::template make<Metric>(space, points, points);
  const auto cross_table = DistanceTable<T>::template make<Metric>(space, others, points);
  const auto pair_table = DistanceTable<T>::template make<Metric>(space, points, others);
  for (std::size_t k : {std::size_t{1}, std::size_t{4}, n - 1}) {
    if (k == 0 || k > n - 1) continue;
    CAPTURE(k);
    REQUIRE(first_row_difference(kdspace::self_knn_join(tree, k, params), brute_knn<Metric>(self_table, k, true)) == "");
  }
  for (std::size_t k : {std::size_t{1}, std::size_t{3}, n}) {
    if (k > n) continue;
    CAPTURE(k);
    REQUIRE(first_row_difference(kdspace::knn_join(other_tree, tree, k, params), brute_knn<Metric>(cross_table, k, false)) ==
            "");
  }
  for (const T r : probing_radii<Metric>(space, points, seed)) {
    CAPTURE(r);
    const auto self_want = brute_pairs<Metric>(self_table, true, r);
    const auto cross_want = brute_pairs<Metric>(pair_table, false, r);
    REQUIRE(kdspace::distances_within(tree, r, params) == self_want);
    REQUIRE(kdspace::distances_within(tree, other_tree, r, params) == cross_want);
    REQUIRE(kdspace::pairs_within(tree, r, params) == indices_of(self_want));
    REQUIRE(kdspace::pairs_within(tree, other_tree, r, params) == indices_of(cross_want));
  }
  // Counts at all probing radii in one call, in scrambled order, against the brute-force pair lists.
  std::vector<T> radii = probing_radii<Metric>(space, points, seed + 7);
  radii.push_back(std::numeric_limits<T>::infinity());
  std::reverse(radii.begin(), radii.end());
  std::swap(radii[1], radii[4]);
  const auto self_counts = kdspace::count_pairs(tree, radii, params);
  const auto cross_counts = kdspace::count_pairs(tree, other_tree, radii, params);
  std::vector<double> weights(n), other_weights(m);
  for (std::size_t i = 0; i < n; ++i) weights[i] = static_cast<double>(i % 5) - 1;
  for (std::size_t i = 0; i < m; ++i) other_weights[i] = static_cast<double>(i % 3) + 0.5;
  const auto self_sums = kdspace::count_weighted_pairs(tree, radii, weights.data(), params);
  const auto cross_sums = kdspace::count_weighted_pairs(tree, other_tree, radii, weights.data(), other_weights.data(), params);
  for (std::size_t j = 0; j < radii.size(); ++j) {
    CAPTURE(radii[j]);
    const auto self_want = brute_pairs<Metric>(self_table, true, radii[j]);
    const auto cross_want = brute_pairs<Metric>(pair_table, false, radii[j]);
    REQUIRE(self_counts[j] == self_want.size());
    REQUIRE(cross_counts[j] == cross_want.size());
    double self_sum = 0, cross_sum = 0;  // small integers and halves: exact in any order
    for (const auto& p : self_want) self_sum += weights[p.a] * weights[p.b];
    for (const auto& p : cross_want) cross_sum += weights[p.a] * other_weights[p.b];
    REQUIRE(self_sums[j] == self_sum);
    REQUIRE(cross_sums[j] == cross_sum);
  }
}

}  // namespace

TEST_CASE("joins: every join equals brute force bit for bit in ordinary space", "[joins][exact]") {
  std::uint32_t seed = 1;
  for (const Case& c : cases) {
    check_case<float, kdspace::L2>(c, false, seed++);
    check_case<double, kdspace::L2>(c, false, seed++);
  }
}

TEST_CASE("joins: every join equals brute force bit for bit on a torus", "[joins][exact][periodic]") {
  std::uint32_t seed = 100;
  for (const Case& c : cases) {
    check_case<float, kdspace::L2>(c, true, seed++);
    check_case<double, kdspace::L2>(c, true, seed++);
  }
}

// The joins on the fixed 3-D trees of the benchmarks, whose leaves of up to 64 points span several
// blocks of 8, on every shape. Where the processor has AVX2 the base cases run in their AVX2
// compilation (avx2_dispatch.hpp); the ctest entry `baseline_without_avx2_joins` runs these cases
// again with KDSPACE_NO_AVX2 set, so both compilations are checked.
TEST_CASE("joins: the base cases on 3-D trees equal brute force", "[joins][exact][periodic]") {
  CAPTURE(kdspace::detail::avx2_dispatch());
  std::uint32_t seed = 400;
  for (const Shape shape : {Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical,
                            Shape::flat, Shape::sorted_x}) {
    const Case c{shape, 400, 3};
    for (const bool periodic : {false, true}) {
      check_case<float, kdspace::L2, 3>(c, periodic, seed++);
      check_case<double, kdspace::L2, 3>(c, periodic, seed++);
    }
  }
}

// In its own leaf a point of a self-join is offered first the points within the k-th distance of
// the point before it, then the others: k from 2 to past a leaf, leaves of the join's size, of 49 to
// 64 points (a tree leaf of 60: the high bits of the leaf's masks) and of more than 64 points (the
// block-by-block path), ties of distance (duplicates, grids, identical); float and double.
template <class T>
void check_self_knn_nearer_first(std::uint32_t seed) {
  for (const Shape shape :
       {Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical, Shape::flat}) {
    for (const std::size_t leaf_size : {std::size_t{24}, std::size_t{60}, std::size_t{100}}) {
      const std::size_t n = 600, dim = 3;
      CAPTURE(kdspace_test::name(shape), leaf_size, kdspace_test::type_name<T>());
      const Torus<T> space({}, dim);
      const std::vector<T> points = make_points<T>(shape, n, dim, seed++);
      kdspace::BuildParams build;
      build.leaf_size = leaf_size;
      const PointTree<T, 3> tree(points.data(), n, dim, build);
      const auto table = DistanceTable<T>::template make<kdspace::L2>(space, points, points);
      JoinParams params;
      params.threads = 1;
      for (const std::size_t k : {2, 5, 10, 16, 33, 70}) {
        CAPTURE(k);
        REQUIRE(first_row_difference(kdspace::self_knn_join(tree, k, params),
                                     brute_knn<kdspace::L2>(table, k, true)) == "");
      }
    }
  }
}

TEST_CASE("joins: self-join k-NN on 3-D trees equals brute force for many k and leaf sizes",
          "[joins][exact]") {
  check_self_knn_nearer_first<double>(500);
  check_self_knn_nearer_first<float>(600);
}

// A few thousand points: the found pairs go to buckets of several first indices each, and the runs
// of one point's pairs are put in order by insertion (a few pairs) or by std::sort (duplicates, all
// identical); radii exactly at nearest-neighbour distances and one step either side.
template <class T>
void check_pairs_in_order(Shape shape, bool periodic, std::uint32_t seed) {
  const std::size_t n = 2100, dim = 3;
  CAPTURE(kdspace_test::name(shape), periodic, kdspace_test::type_name<T>());
  const Torus<T> space(boxsize_for<T>(shape, dim, periodic), dim);
  std::vector<T> points = make_points<T>(shape, n, dim, seed);
  space.wrap(points);
  const PointTree<T> tree(points.data(), n, dim);
  const auto table = DistanceTable<T>::template make<kdspace::L2>(space, points, points);
  std::vector<T> radii;
  for (std::size_t i : {std::size_t{0}, n / 2, n - 1}) {
    T nearest = std::numeric_limits<T>::infinity();
    for (std::size_t j = 0; j < n; ++j)
      if (j != i) nearest = std::min(nearest, table.at(i, j));
    const T d = kdspace::L2::to_distance(nearest);
    radii.insert(radii.end(), {d, std::nextafter(d, T(0)), std::nextafter(d, std::numeric_limits<T>::infinity())});
  }
  std::sort(radii.begin(), radii.end());
  radii.erase(std::unique(radii.begin(), radii.end()), radii.end());
  for (unsigned threads : {1u, 3u}) {
    JoinParams params;
    params.threads = threads;
    params.boxsize = space.boxsize;
    for (const T r : radii) {
      CAPTURE(threads, r);
      const auto want = brute_pairs<kdspace::L2>(table, true, r);
      REQUIRE(kdspace::distances_within(tree, r, params) == want);
      REQUIRE(kdspace::pairs_within(tree, r, params) == indices_of(want));
    }
  }
}

TEST_CASE("joins: pairs of a few thousand points come in order, at and around exact distances", "[joins][exact]") {
  std::uint32_t seed = 700;
  for (const Shape shape : {Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical,
                            Shape::sorted_x}) {
    check_pairs_in_order<float>(shape, false, seed++);
    check_pairs_in_order<double>(shape, false, seed++);
    check_pairs_in_order<double>(shape, true, seed++);
  }
}

TEST_CASE("joins: a self range join over leaves of exactly 64 points equals brute force", "[joins][exact]") {
  // range joins use 64-point leaves: the last point of a full leaf starts its own-leaf mask at 64
  for (const std::size_t n : {std::size_t{64}, std::size_t{128}, std::size_t{200}}) {
    CAPTURE(n);
    const std::size_t dim = 3;
    const Torus<float> space(boxsize_for<float>(Shape::uniform, dim, false), dim);
    const std::vector<float> points = make_points<float>(Shape::uniform, n, dim, 900 + static_cast<std::uint32_t>(n));
    const PointTree<float> tree(points.data(), n, dim);
    const auto table = DistanceTable<float>::template make<kdspace::L2>(space, points, points);
    for (const float r : {0.0f, 0.25f, 10.0f}) {
      CAPTURE(r);
      const auto want = brute_pairs<kdspace::L2>(table, true, r);
      REQUIRE(kdspace::distances_within(tree, r, JoinParams{}) == want);
      REQUIRE(kdspace::pairs_within(tree, r, JoinParams{}) == indices_of(want));
    }
  }
}

TEST_CASE("joins: runs of pairs are placed in order by rank, ties of distance and long runs included",
          "[joins][exact]") {
  using kdspace::detail::FoundPair;
  std::mt19937 rng(41);
  for (std::size_t m = 0; m <= 40; ++m) {
    for (int trial = 0; trial < 20; ++trial) {
      // Distinct second indices (a point's pairs), distances drawn from few values so that many tie.
      std::vector<std::uint32_t> b(200);
      std::iota(b.begin(), b.end(), 0u);
      std::shuffle(b.begin(), b.end(), rng);
      std::vector<FoundPair<double>> run;
      for (std::size_t j = 0; j < m; ++j) run.push_back({7, b[j], static_cast<double>(rng() % 4)});
      const auto check = [&](auto less) {
        std::vector<FoundPair<double>> want = run, got(m, FoundPair<double>{0, 0, 0.0});
        std::sort(want.begin(), want.end(), less);
        kdspace::detail::place_run(run.data(), m, got.data(), less);
        for (std::size_t j = 0; j < m; ++j) {
          CAPTURE(m, trial, j);
          REQUIRE(got[j].b == want[j].b);
          REQUIRE(got[j].dist == want[j].dist);
        }
      };
      check(kdspace::detail::BySecondIndex{});
      check(kdspace::detail::NearestFirst{});
    }
  }
}

TEST_CASE("joins: a k-NN table keeps the first k offers in (distance, index) order, ties and partial rows included",
          "[joins][exact]") {
  using kdspace::detail::Candidate;
  using kdspace::detail::KnnTable;
  std::mt19937 rng(43);
  const double inf = std::numeric_limits<double>::infinity();
  for (std::size_t k = 1; k <= 40; ++k) {  // sorted rows up to 32, heaps beyond
    for (int trial = 0; trial < 10; ++trial) {
      // Seven rows offered interleaved (largest_kth takes four rows at a time), distances from few
      // values so that many tie on distance; at the end the rows move to the places of a shuffle.
      const std::size_t rows = 7, offers = k + rng() % 50;
      std::vector<Neighbor<double>> result(rows * k, KnnTable<double>::placeholder());
      KnnTable<double> table(result.data(), rows, k);
      std::vector<std::vector<Candidate<double>>> offered(rows);
      std::vector<std::uint32_t> index(300);
      std::iota(index.begin(), index.end(), 0u);
      std::shuffle(index.begin(), index.end(), rng);
      for (std::size_t j = 0; j < offers * rows; ++j) {
        const std::size_t row = j % rows;
        const Candidate<double> c{static_cast<double>(rng() % 6), index[j % index.size()]};
        if (std::any_of(offered[row].begin(), offered[row].end(), [&](const auto& o) { return o.index == c.index; }))
          continue;  // a join offers a point to a row once
        offered[row].push_back(c);
        table.offer(row, c.dist, c.index);
        std::vector<Candidate<double>> want = offered[row];
        std::sort(want.begin(), want.end(), kdspace::detail::ComesBefore{});
        CAPTURE(k, trial, j, row);
        REQUIRE(table.kth(row) == (want.size() < k ? inf : want[k - 1].dist));
      }
      double largest = 0;
      for (std::size_t row = 0; row < rows; ++row) {
        largest = std::max(largest, table.kth(row));
        REQUIRE(table.largest_kth(0, row + 1) == largest);
      }
      std::vector<std::uint32_t> result_row(rows);
      std::iota(result_row.begin(), result_row.end(), 0u);
      std::shuffle(result_row.begin(), result_row.end(), rng);
      table.finish<kdspace::L2>(result_row.data());  // rows in order, true distances, moved
      for (std::size_t row = 0; row < rows; ++row) {
        std::vector<Candidate<double>> want = offered[row];
        std::sort(want.begin(), want.end(), kdspace::detail::ComesBefore{});
        want.resize(k, Candidate<double>{inf, std::numeric_limits<std::uint32_t>::max()});
        const Neighbor<double>* got = result.data() + result_row[row] * k;
        for (std::size_t i = 0; i < k; ++i) {
          CAPTURE(k, trial, row, i);
          REQUIRE(got[i].index == want[i].index);
          REQUIRE(got[i].distance == std::sqrt(want[i].dist));
        }
      }
    }
  }
}

TEST_CASE("joins: smaller_index picks the smaller of two indices", "[joins]") {
  using kdspace::detail::smaller_index;
  const std::uint32_t top = std::numeric_limits<std::uint32_t>::max();
  const std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs{
      {0, 0}, {0, 1}, {1, 0}, {5, 5}, {top, 0}, {0, top}, {top - 1, top}, {top, top}, {123456, 654321}};
  for (const auto& [a, b] : pairs) {
    CAPTURE(a, b);
    REQUIRE(smaller_index(a, b) == std::min(a, b));
  }
}

TEST_CASE("joins: L1 and Linf joins equal brute force flat and periodic", "[joins][exact][periodic]") {
  std::uint32_t seed = 200;
  for (const Case& c : {cases[1], cases[3], cases[4], cases[8]}) {
    for (bool periodic : {false, true}) {
      check_case<float, kdspace::L1>(c, periodic, seed++);
      check_case<double, kdspace::Linf>(c, periodic, seed++);
    }
  }
}

// Radii at the very bounds the count rule compares with: the lower and upper bounds of pairs of the
// join's cells (the bulk count of a pair of cells whose bounds fall within one bin, and the bin
// boundaries of the leaves' block counts), one step either side, and many radii at once; with
// duplicates and grids (many equal distances), weights, and on a torus.
template <class T, class Metric>
void check_counts_at_cell_bounds(const Case& c, bool periodic, std::uint32_t seed, kdspace::JoinStats& stats) {
  CAPTURE(kdspace_test::name(c.shape), c.n, c.dim, periodic, Metric::name, kdspace_test::type_name<T>());
  const Torus<T> space(boxsize_for<T>(c.shape, c.dim, periodic), c.dim);
  std::vector<T> points = make_points<T>(c.shape, c.n, c.dim, seed);
  space.wrap(points);
  kdspace::BuildParams build;
  build.leaf_size = 1 + seed % 5;
  const PointTree<T, kdspace::Dynamic, Metric> tree(points.data(), c.n, c.dim, build);
  JoinParams params;
  params.threads = 1;
  params.boxsize = space.boxsize;

  const kdspace::detail::BoundedTree<T, kdspace::Dynamic> cells(tree, kdspace::detail::count_leaf_points);
  const auto bounds = [&](const auto& torus) {
    std::vector<T> radii;
    const auto nodes = static_cast<std::uint32_t>(std::min<std::size_t>(cells.node_count(), 24));
    for (std::uint32_t q = 0; q < nodes; ++q)
      for (std::uint32_t r = q; r < nodes; r += 3) {
        if (cells.node(q).count() == 0 || cells.node(r).count() == 0) continue;
        for (const T b : {torus.lower(cells.lo(q), cells.hi(q), cells.lo(r), cells.hi(r), c.dim),
                          torus.upper(cells.lo(q), cells.hi(q), cells.lo(r), cells.hi(r), c.dim)}) {
          const T d = Metric::to_distance(b);
          for (const T x : {d, std::nextafter(d, T(0)), std::nextafter(d, std::numeric_limits<T>::infinity())})
            if (std::isfinite(x)) radii.push_back(x);
        }
      }
    return radii;
  };
  const std::vector<T> radii = space.periodic()
                                   ? bounds(kdspace::detail::TorusSpace<Metric, T>{{space.period.data()}})
                                   : bounds(kdspace::detail::FlatSpace<Metric>{});
  REQUIRE(!radii.empty());
  std::vector<double> weights(c.n);
  for (std::size_t i = 0; i < c.n; ++i) weights[i] = static_cast<double>(i % 4) - 0.5;
  const auto counts = kdspace::count_pairs(tree, radii, params, &stats);
  const auto sums = kdspace::count_weighted_pairs(tree, radii, weights.data(), params);
  const auto table = DistanceTable<T>::template make<Metric>(space, points, points);
  for (std::size_t j = 0; j < radii.size(); ++j) {
    CAPTURE(radii[j]);
    const auto want = brute_pairs<Metric>(table, true, radii[j]);
    REQUIRE(counts[j] == want.size());
    double sum = 0;  // quarters: exact in any order
    for (const auto& p : want) sum += weights[p.a] * weights[p.b];
    REQUIRE(sums[j] == sum);
  }
}

TEST_CASE("joins: counts at radii equal to the cells' distance bounds equal brute force", "[joins][exact][periodic]") {
  kdspace::JoinStats stats;
  std::uint32_t seed = 300;
  for (const Case& c : {cases[1], cases[2], cases[3], cases[4], cases[5]}) {
    for (bool periodic : {false, true}) {
      check_counts_at_cell_bounds<double, kdspace::L2>(c, periodic, seed++, stats);
      check_counts_at_cell_bounds<float, kdspace::L1>(c, periodic, seed++, stats);
      check_counts_at_cell_bounds<double, kdspace::Linf>(c, periodic, seed++, stats);
    }
  }
  REQUIRE(stats.bulk_pairs > 0);  // pairs of cells were counted whole
}

TEST_CASE("joins: PeriodicTree answers single and batch queries like brute force on the torus", "[joins][exact][periodic]") {
  using kdspace::L2;
  for (const Case& c : {cases[1], cases[3], cases[4], cases[6], cases[8], cases[11]}) {
    for (bool doubles : {false, true}) {
      CAPTURE(kdspace_test::name(c.shape), c.n, c.dim, doubles);
      auto run = [&](auto zero) {
        using T = decltype(zero);
        const Torus<T> space(boxsize_for<T>(c.shape, c.dim, true), c.dim);
        std::vector<T> points = make_points<T>(c.shape, c.n, c.dim, 31);
        std::vector<T> queries = make_points<T>(Shape::uniform, 40, c.dim, 32);
        space.wrap(points);
        space.wrap(queries);
        const PointTree<T> tree(points.data(), c.n, c.dim);
        const kdspace::PeriodicTree<T> torus(tree, space.boxsize);
        const auto table = DistanceTable<T>::template make<L2>(space, queries, points);
        const std::size_t k = std::min<std::size_t>(5, c.n);
        const auto want = brute_knn<L2>(table, k, false);
        const T r = L2::to_distance(table.at(0, c.n / 2));  // exactly some pair's distance
        const auto batch = torus.knn_batch(queries.data(), 40, k, 1);
        const auto radius_batch = torus.radius_batch(queries.data(), 40, r, 1);
        REQUIRE(first_row_difference(batch, want) == "");
        for (std::size_t q = 0; q < 40; ++q) {
          REQUIRE(torus.knn(&queries[q * c.dim], k) == want[q]);
          // (distance, index) order, decided on the internal distance as everywhere.
          std::vector<Candidate<T>> near;
          for (std::size_t j = 0; j < c.n; ++j)
            if (table.at(q, j) <= L2::to_internal(r)) near.push_back({table.at(q, j), static_cast<std::uint32_t>(j)});
          std::sort(near.begin(), near.end());
          std::vector<Neighbor<T>> within;
          for (const auto& nb : near) within.push_back({nb.index, L2::to_distance(nb.dist)});
          REQUIRE(torus.radius(&queries[q * c.dim], r) == within);
          REQUIRE(std::vector<Neighbor<T>>(radius_batch.row(q).begin(), radius_batch.row(q).end()) == within);
        }
      };
      if (doubles) run(0.0);
      else run(0.0f);
    }
  }
}

TEST_CASE("joins: a PeriodicTree box wraps around periodic axes", "[joins][periodic]") {
  // 2-D grid of integer points in [0, 10) x [0, 10), periodic along x only.
  std::vector<float> points;
  for (int x = 0; x < 10; ++x)
    for (int y = 0; y < 10; ++y) points.insert(points.end(), {float(x), float(y)});
  const PointTree<float> tree(points.data(), 100, 2);
  const kdspace::PeriodicTree<float> torus(tree, {10.0, 0.0});
  auto brute = [&](const float* lo, const float* hi) {
    std::vector<kdspace::Index> out;
    for (kdspace::Index i = 0; i < 100; ++i) {
      const float x = points[i * 2], y = points[i * 2 + 1];
      const bool in_x = lo[0] <= hi[0] ? (lo[0] <= x && x <= hi[0]) : (x >= lo[0] || x <= hi[0]);
      if (in_x && lo[1] <= y && y <= hi[1]) out.push_back(i);
    }
    return out;
  };
  const float boxes[][4] = {{8, 1, 2, 3}, {2, 1, 8, 3}, {9.5f, 0, 0.5f, 9}, {0, 0, 10, 9}, {3, 4, 3, 4}, {7, 5, 7, 4.5f}};
  for (const auto& b : boxes) {
    const float lo[2] = {b[0], b[1]}, hi[2] = {b[2], b[3]};
    CAPTURE(lo[0], lo[1], hi[0], hi[1]);
    if (lo[1] > hi[1]) {
      REQUIRE_THROWS_WITH(torus.box(lo, hi), Catch::Contains("not periodic"));
      continue;
    }
    REQUIRE(torus.box(lo, hi) == brute(lo, hi));
  }
  const std::vector<kdspace::Index> wrapped = [&] {
    const float lo[2] = {8, 1}, hi[2] = {2, 3};
    return torus.box(lo, hi);
  }();
  REQUIRE(wrapped.size() == 5 * 3);  // x in {8, 9, 0, 1, 2}, y in {1, 2, 3}
}

TEST_CASE("joins: bad input is a clear error", "[joins][errors]") {
  std::vector<float> points{0.5f, 0.5f, 1.5f, 0.25f, 0.1f, 0.9f};
  const PointTree<float> tree(points.data(), 3, 2);
  const std::vector<float> three_d{0.f, 0.f, 0.f};
  const PointTree<float> other(three_d.data(), 1, 3);
  JoinParams params;
  REQUIRE_THROWS_WITH(kdspace::self_knn_join(tree, 3), Catch::Contains("exceeds the number of other points (2)"));
  REQUIRE_THROWS_WITH(kdspace::self_knn_join(tree, 0), Catch::Contains("k must be at least 1"));
  REQUIRE_THROWS_WITH(kdspace::pairs_within(tree, other, 1.f), Catch::Contains("differ in dimension"));
  REQUIRE_THROWS_WITH(kdspace::pairs_within(tree, -1.f), Catch::Contains("radius must be a non-negative number"));
  REQUIRE_THROWS_WITH(kdspace::count_pairs(tree, {0.5f, std::nanf("")}), Catch::Contains("radius must be"));
  REQUIRE_THROWS_WITH(kdspace::count_pairs(tree, std::vector<float>{}), Catch::Contains("no radii"));
  params.boxsize = {1.0};
  REQUIRE_THROWS_WITH(kdspace::pairs_within(tree, 0.1f, params),
                      Catch::Contains("row 2: coordinate 1 = 1.500000 lies outside the periodic box [0, 1.000000)"));
  params.boxsize = {2.0, 2.0, 2.0};
  REQUIRE_THROWS_WITH(kdspace::pairs_within(tree, 0.1f, params), Catch::Contains("boxsize has 3 values"));
  params.boxsize = {2.0, -1.0};
  REQUIRE_THROWS_WITH(kdspace::pairs_within(tree, 0.1f, params), Catch::Contains("boxsize of axis 2 must be"));
  REQUIRE_THROWS_WITH(kdspace::PeriodicTree<float>(tree, {0.0}), Catch::Contains("no axis is periodic"));
  const kdspace::PeriodicTree<float> torus(tree, {2.0});
  const float outside[2] = {0.5f, 2.0f};
  REQUIRE_THROWS_WITH(torus.knn(outside, 1), Catch::Contains("query: coordinate 2 = 2.000000 lies outside"));
  REQUIRE_THROWS_WITH(torus.knn_batch(outside, 1, 1), Catch::Contains("query row 1: coordinate 2"));
  const std::vector<double> bad_weights{1, NAN, 1};
  REQUIRE_THROWS_WITH(kdspace::count_weighted_pairs(tree, {0.5f}, bad_weights.data()),
                      Catch::Contains("weights: row 2: weight is not finite"));
}

TEST_CASE("joins: answers are the same on any number of threads", "[joins][threads]") {
  const std::size_t n = 20000, dim = 3;
  std::vector<float> points = make_points<float>(Shape::clustered, n, dim, 5);
  const Torus<float> space({25.0}, dim);
  space.wrap(points);
  const PointTree<float> tree(points.data(), n, dim);
  for (bool periodic : {false, true}) {
    CAPTURE(periodic);
    JoinParams params;
    params.threads = 1;
    if (periodic) params.boxsize = space.boxsize;
    const std::vector<float> radii{0.001f, 0.01f, 0.05f, 0.3f};
    std::vector<double> weights(n);
    for (std::size_t i = 0; i < n; ++i) weights[i] = 1.0 / static_cast<double>(i + 1);  // sums that round
    const auto knn = kdspace::self_knn_join(tree, 6, params);
    const auto pairs = kdspace::pairs_within(tree, 0.02f, params);
    const auto counts = kdspace::count_pairs(tree, radii, params);
    const auto sums = kdspace::count_weighted_pairs(tree, radii, weights.data(), params);
    for (unsigned threads : {2u, 3u, 0u}) {
      CAPTURE(threads);
      params.threads = threads;
      const auto knn_many = kdspace::self_knn_join(tree, 6, params);
      REQUIRE(knn_many.neighbors == knn.neighbors);
      REQUIRE(kdspace::pairs_within(tree, 0.02f, params) == pairs);
      REQUIRE(kdspace::count_pairs(tree, radii, params) == counts);
      REQUIRE(kdspace::count_weighted_pairs(tree, radii, weights.data(), params) == sums);  // bit for bit
    }
  }
}
