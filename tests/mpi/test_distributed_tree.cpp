// DistributedTree under mpirun -np 1..4: the answers of every rank equal, bit for bit, those of one
// PointTree over all the points, and an error on one rank reaches every rank.
//
// Every rank makes the same data (same seeds), keeps its own rows and queries, and checks its own
// answers. Only CHECK is used, never REQUIRE: a rank that stopped a test early would leave the
// others waiting in the next collective call.
#include <mpi.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "../support.hpp"
#include "kdspace/mpi/distributed_tree.hpp"

namespace {

using kdspace::L1;
using kdspace::L2;
using kdspace::Linf;
using kdspace::NeighborLists;
using kdspace::PointTree;
using kdspace::mpi::DistributedParams;
using kdspace::mpi::DistributedStats;
using kdspace::mpi::DistributedTree;
using kdspace_test::Shape;

int rank() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}

int ranks() {
  int p = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &p);
  return p;
}

/// The rows [first, last) of n a rank holds. Uneven on purpose: rank 0 gets a small share, the
/// last rank none when there are three ranks or more (a rank may bring no points at all).
std::pair<std::size_t, std::size_t> uneven_share(std::size_t n, int r, int p) {
  const int holders = p >= 3 ? p - 1 : p;
  if (r >= holders) return {n, n};
  auto start = [&](int i) {
    return i == 0 ? std::size_t{0}
                  : n / 7 +
                        (n - n / 7) * static_cast<std::size_t>(i - 1) / static_cast<std::size_t>(holders - 1);
  };
  if (holders == 1) return {0, n};
  return {start(r), r + 1 == holders ? n : start(r + 1)};
}

/// Even shares: rows [first, last) of n for this rank.
std::pair<std::size_t, std::size_t> even_share(std::size_t n, int r, int p) {
  return {n * static_cast<std::size_t>(r) / static_cast<std::size_t>(p),
          n * static_cast<std::size_t>(r + 1) / static_cast<std::size_t>(p)};
}

/// The first row where this rank's answers differ from the reference's rows [first, ...), or "".
template <class T>
std::string first_difference(const NeighborLists<T>& got, const NeighborLists<T>& expected,
                             std::size_t first) {
  for (std::size_t q = 0; q < got.rows(); ++q) {
    const auto a = got.row(q), b = expected.row(first + q);
    if (a.size() != b.size())
      return "query " + std::to_string(first + q) + ": " + std::to_string(a.size()) + " results, expected " +
             std::to_string(b.size());
    for (std::size_t i = 0; i < a.size(); ++i)
      if (!(a[i] == b[i]))
        return "query " + std::to_string(first + q) + " result " + std::to_string(i) + ": index " +
               std::to_string(a[i].index) + ", expected " + std::to_string(b[i].index);
  }
  return got.rows() == 0 || first + got.rows() <= expected.rows() ? "" : "too many rows";
}

struct Case {
  Shape shape;
  std::size_t n, dim;
  std::uint32_t seed;
};

// Builds a DistributedTree over the rows this rank holds and checks k-NN for several k and a radius
// search (with and without max_results) against one PointTree over all points.
template <class T, class Metric>
void check_case(const Case& c, const DistributedParams& params) {
  const int r = rank(), p = ranks();
  const std::vector<T> pts = kdspace_test::make_points<T>(c.shape, c.n, c.dim, c.seed);
  const std::size_t nq = 97;
  const std::vector<T> queries = kdspace_test::make_queries(pts, c.n, c.dim, nq, c.seed + 1);
  const auto [p0, p1] = uneven_share(c.n, r, p);
  const auto [q0, q1] = even_share(nq, r, p);
  const PointTree<T, kdspace::Dynamic, Metric> reference(pts.data(), c.n, c.dim);
  const DistributedTree<T, Metric> tree(MPI_COMM_WORLD, pts.data() + p0 * c.dim, p1 - p0, c.dim, params);
  CHECK(tree.size() == c.n);
  const T* mine = queries.data() + q0 * c.dim;
  INFO(kdspace_test::name(c.shape) << ", n " << c.n << ", dim " << c.dim << ", " << Metric::name << ", "
                                   << kdspace_test::type_name<T>() << ", rank " << r << " of " << p);
  for (const std::size_t k : {std::size_t{1}, std::size_t{7}, std::size_t{40}, c.n}) {
    if (k > c.n) continue;
    INFO("k = " << k);
    DistributedStats stats;
    const NeighborLists<T> got = tree.knn_batch(mine, q1 - q0, k, 1, &stats);
    const NeighborLists<T> expected = reference.knn_batch(queries.data(), nq, k, kdspace::SearchParams{}, 1);
    CHECK(first_difference(got, expected, q0) == "");
    CHECK(stats.queries == q1 - q0);
  }
  // A radius holding a few dozen points around a typical query: the distance to the 30th neighbour
  // of query 0.
  const auto probe = reference.knn(queries.data(), std::min<std::size_t>(30, c.n));
  const T radius = probe.back().distance;
  for (const std::size_t max_results : {std::numeric_limits<std::size_t>::max(), std::size_t{5}}) {
    INFO("radius " << radius << ", max_results " << max_results);
    const NeighborLists<T> got = tree.radius_batch(mine, q1 - q0, radius, max_results, 2);
    const NeighborLists<T> expected = reference.radius_batch(queries.data(), nq, radius, max_results, 1);
    CHECK(first_difference(got, expected, q0) == "");
  }
}

template <class T, class Metric>
void check_shapes(const DistributedParams& params) {
  const Case cases[] = {
      {Shape::uniform, 1500, 3, 11},  {Shape::clustered, 1200, 5, 12}, {Shape::duplicates, 900, 2, 13},
      {Shape::grid, 1000, 3, 14},     {Shape::identical, 300, 4, 15},  {Shape::flat, 800, 9, 16},
      {Shape::sorted_x, 1000, 2, 17}, {Shape::uniform, 1, 3, 18},      {Shape::uniform, 3, 2, 19},
  };
  for (const Case& c : cases) check_case<T, Metric>(c, params);
}

// Small samples and rounds: the regions are uneven and share their boundaries with many points of
// the grid and duplicate data; queries take several rounds.
DistributedParams small_params() {
  DistributedParams params;
  params.sample_per_rank = 5;
  params.queries_per_round = 13;
  params.build.leaf_size = 4;
  return params;
}

}  // namespace

TEST_CASE("mpi: knn and radius equal one PointTree bit for bit on every data shape (float, l2)", "[mpi]") {
  check_shapes<float, L2>(small_params());
  check_shapes<float, L2>(DistributedParams{});
}

TEST_CASE("mpi: knn and radius equal one PointTree bit for bit under l1 and linf and in double", "[mpi]") {
  check_shapes<float, L1>(small_params());
  check_shapes<float, Linf>(small_params());
  check_shapes<double, L2>(small_params());
  check_shapes<double, Linf>(DistributedParams{});
}

TEST_CASE("mpi: the answers do not depend on how the points were spread over the ranks at the start",
          "[mpi]") {
  // All points on the last rank: the redistribution moves them all.
  const int r = rank(), p = ranks();
  const std::size_t n = 1000, dim = 3, nq = 50;
  const auto pts = kdspace_test::make_points<float>(Shape::clustered, n, dim, 21);
  const auto queries = kdspace_test::make_queries(pts, n, dim, nq, 22);
  const bool holder = r == p - 1;
  const DistributedTree<float> tree(MPI_COMM_WORLD, pts.data(), holder ? n : 0, dim, small_params());
  const PointTree<float> reference(pts.data(), n, dim);
  const auto [q0, q1] = even_share(nq, r, p);
  const auto got = tree.knn_batch(queries.data() + q0 * dim, q1 - q0, 10);
  CHECK(first_difference(got, reference.knn_batch(queries.data(), nq, 10), q0) == "");
  if (p > 1) CHECK(tree.local_size() < n);
}

TEST_CASE("mpi: a bad point on one rank makes every rank throw the same error, naming that rank", "[mpi]") {
  const int r = rank(), p = ranks();
  std::vector<float> pts = kdspace_test::make_points<float>(Shape::uniform, 40, 2, 31);
  const int bad_rank = p - 1;
  if (r == bad_rank) pts[2 * 3 + 1] = std::numeric_limits<float>::quiet_NaN();  // its point 4
  std::string message;
  try {
    const DistributedTree<float> tree(MPI_COMM_WORLD, pts.data(), pts.size() / 2, 2);
  } catch (const kdspace::Error& e) {
    message = e.what();
  }
  CHECK(message == "rank " + std::to_string(bad_rank) + " of " + std::to_string(p) +
                       ": point 4 of this rank: coordinate 2 is not finite (nan)");
}

TEST_CASE("mpi: k above the number of points and ranks of different dimensions are errors on every rank",
          "[mpi]") {
  const int r = rank(), p = ranks();
  const auto pts = kdspace_test::make_points<float>(Shape::uniform, 20, 3, 41);
  const DistributedTree<float> tree(MPI_COMM_WORLD, pts.data() + static_cast<std::size_t>(r) * 3, 1, 3);
  std::string message;
  try {
    tree.knn_batch(pts.data(), 2, static_cast<std::size_t>(p) + 1);
  } catch (const kdspace::Error& e) {
    message = e.what();
  }
  CHECK(message.find("exceeds the number of points (" + std::to_string(p) + ")") != std::string::npos);

  if (p > 1) {
    message.clear();
    try {
      const DistributedTree<float> mixed(MPI_COMM_WORLD, pts.data(), 2, r == 1 ? 2 : 3);
    } catch (const kdspace::Error& e) {
      message = e.what();
    }
    CHECK(message == "the ranks disagree on the dimension of the points: from 2 to 3");
  }
}
