// Cross-checks of PointTree against FLANN 1.9's exact search on the same data: the single kd-tree
// (flann::KDTreeSingleIndexParams, which is exact with eps 0 whatever `checks` says) and the linear
// scan (flann::LinearIndexParams), both searched with checks = FLANN_CHECKS_UNLIMITED and eps 0.
//
// FLANN adds up a distance in another order than internal_distance(), so distances may differ in the
// last bits and points at (nearly) equal distance may come in another order or, at the k-th place,
// be other points. What is compared:
//   - the distance at every rank, with a relative tolerance (1e-5 for float, 1e-11 for double);
//   - the distance FLANN reports for each of its points, against the distance of that point;
//   - every point FLANN returns is no farther than our k-th distance (plus the tolerance);
//   - the sets of indices strictly inside the k-th distance (less a band twice the tolerance), where
//     the order of summation cannot decide membership.
// Radius search compares the sets of indices, leaving out points within a small band of the radius.
//
// FLANN's L2 functor (flann::L2<T>) works with SQUARED Euclidean distances: its knn distances are
// squared (we take the square root before comparing) and radiusSearch takes a squared radius (we
// pass r * r, as a float: FLANN's radius parameter is a float even for double data). flann::L1<T>
// works with true Manhattan distances. FLANN has no exact L-infinity kd-tree search (its kd-tree
// needs an additive distance), so Linf is checked against the library's brute force only.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <flann/flann.hpp>
#include <iomanip>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/point_tree.hpp"
#include "support.hpp"

using kdspace::AxisRule;
using kdspace::BuildParams;
using kdspace::Index;
using kdspace::Neighbor;
using kdspace::PointTree;
using kdspace::PositionRule;

namespace {

// ---- data (the generators shared with test_point_tree_exact.cpp, in support.hpp; FLANN is fed four shapes)

using kdspace_test::make_points;
using kdspace_test::name;
using kdspace_test::Shape;
using kdspace_test::type_name;

std::string describe(const BuildParams& p) {
  std::ostringstream out;
  out << "axis=" << name(p.axis) << " position=" << name(p.position) << " leaf_size=" << p.leaf_size;
  return out.str();
}

/// Queries cycling through: random in the bounding box grown by 10% (integers for grid data), on a
/// data point, random, on a data point, far outside the data.
template <class T>
std::vector<T> make_queries(Shape shape, const std::vector<T>& pts, std::size_t n, std::size_t dim,
                            std::size_t nq, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<double> lo(dim, std::numeric_limits<double>::infinity()),
      hi(dim, -std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a) {
      lo[a] = std::min(lo[a], static_cast<double>(pts[i * dim + a]));
      hi[a] = std::max(hi[a], static_cast<double>(pts[i * dim + a]));
    }
  std::vector<T> out(nq * dim);
  std::uniform_int_distribution<std::size_t> pick(0, n - 1);
  std::uniform_int_distribution<int> cell(-1, 7);
  for (std::size_t q = 0; q < nq; ++q) {
    T* row = out.data() + q * dim;
    const std::size_t kind = q % 5;
    if (kind == 1 || kind == 3) {
      std::copy_n(pts.data() + pick(rng) * dim, dim, row);
      continue;
    }
    for (std::size_t a = 0; a < dim; ++a) {
      const double span = hi[a] - lo[a];
      double v;
      if (kind == 4)
        v = a % 2 == 0 ? hi[a] + 500 + 100 * unit(rng) : lo[a] - 500 - 100 * unit(rng);
      else if (shape == Shape::grid)
        v = cell(rng);
      else
        v = lo[a] - 0.1 * span - 0.01 + (1.2 * span + 0.02) * unit(rng);
      row[a] = static_cast<T>(v);
    }
  }
  return out;
}

const char* query_kind(std::size_t q) {
  switch (q % 5) {
    case 1:
    case 3:
      return "on a data point";
    case 4:
      return "far outside the data";
    default:
      return "random";
  }
}

std::vector<std::size_t> ks_for(std::size_t n) {
  std::vector<std::size_t> ks;
  for (std::size_t k : {1, 2, 5, 10, 100})
    if (k <= n) ks.push_back(k);
  return ks;
}

/// Every axis rule with every position rule at the given leaf sizes.
std::vector<BuildParams> every_split_rule(std::initializer_list<std::size_t> leaf_sizes) {
  std::vector<BuildParams> out;
  for (AxisRule axis : {AxisRule::cycle, AxisRule::max_spread})
    for (PositionRule position : {PositionRule::median, PositionRule::middle, PositionRule::sliding_midpoint, PositionRule::midpoint})
      for (std::size_t leaf : leaf_sizes) {
        BuildParams p;
        p.axis = axis;
        p.position = position;
        p.leaf_size = leaf;
        out.push_back(p);
      }
  return out;
}

// ---- FLANN ------------------------------------------------------------------------------------------

/// FLANN's functor for a kdspace metric, and how its numbers map to true distances.
template <class Metric, class T>
struct FlannMetric;

template <class T>
struct FlannMetric<kdspace::L2, T> {
  using Distance = flann::L2<T>;
  // flann::L2 reports SQUARED Euclidean distances: the true distance is the square root.
  static double to_distance(double flann_distance) { return std::sqrt(flann_distance); }
  // flann::L2's radiusSearch takes a SQUARED radius, as a float.
  static float radius_argument(T r) {
    return static_cast<float>(static_cast<double>(r) * static_cast<double>(r));
  }
};

template <class T>
struct FlannMetric<kdspace::L1, T> {
  using Distance = flann::L1<T>;
  static double to_distance(double flann_distance) { return flann_distance; }
  static float radius_argument(T r) { return static_cast<float>(r); }
};

template <class Metric, class T>
using FlannIndex = flann::Index<typename FlannMetric<Metric, T>::Distance>;

template <class Metric, class T>
using FlannResult = typename FlannMetric<Metric, T>::Distance::ResultType;

/// FLANN's exact search parameters: no limit on checks, eps 0, sorted results.
flann::SearchParams exact_flann_search() {
  return flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED, 0.0f, true);
}

template <class Metric, class T>
std::unique_ptr<FlannIndex<Metric, T>> build_flann(std::vector<T>& pts, std::size_t n, std::size_t dim,
                                                   const flann::IndexParams& params) {
  const flann::Matrix<T> data(pts.data(), n, dim);
  auto index = std::make_unique<FlannIndex<Metric, T>>(data, params);
  index->buildIndex();
  return index;
}

/// FLANN's k nearest of every query: indices and true distances, row q at [q * k, q * k + k).
template <class Metric, class T>
struct FlannKnn {
  std::size_t k = 0;
  std::vector<std::size_t> indices;
  std::vector<double> distances;
};

template <class Metric, class T>
FlannKnn<Metric, T> flann_knn(const FlannIndex<Metric, T>& index, std::vector<T>& queries, std::size_t nq,
                              std::size_t dim, std::size_t k) {
  FlannKnn<Metric, T> out;
  out.k = k;
  out.indices.assign(nq * k, 0);
  std::vector<FlannResult<Metric, T>> raw(nq * k);
  flann::Matrix<T> qm(queries.data(), nq, dim);
  flann::Matrix<std::size_t> im(out.indices.data(), nq, k);
  flann::Matrix<FlannResult<Metric, T>> dm(raw.data(), nq, k);
  index.knnSearch(qm, im, dm, k, exact_flann_search());
  for (auto d : raw) out.distances.push_back(FlannMetric<Metric, T>::to_distance(static_cast<double>(d)));
  return out;
}

template <class T>
double tolerance() {
  return sizeof(T) == sizeof(float) ? 1e-5 : 1e-11;
}

bool close(double a, double b, double tol) {
  return std::abs(a - b) <= tol * std::max(1.0, std::abs(b));
}

template <class Metric, class T>
double true_distance(const T* q, const T* p, std::size_t dim) {
  return static_cast<double>(Metric::to_distance(kdspace::internal_distance<Metric>(q, p, dim)));
}

/// Empty when our k-NN of q and FLANN's agree as described at the top of the file.
template <class Metric, class T>
std::string compare_knn(const std::vector<Neighbor<T>>& ours, const std::size_t* their_index,
                        const double* their_distance, std::size_t k, const T* q, const std::vector<T>& pts,
                        std::size_t n, std::size_t dim) {
  const double tol = tolerance<T>();
  std::ostringstream out;
  out << std::setprecision(std::numeric_limits<T>::max_digits10);
  if (ours.size() != k) {
    out << "kdspace returned " << ours.size() << " neighbours for k = " << k;
    return out.str();
  }
  for (std::size_t i = 0; i < k; ++i) {
    if (their_index[i] >= n) {
      out << "FLANN rank " << i << ": index " << their_index[i] << " out of range";
      return out.str();
    }
    if (!close(static_cast<double>(ours[i].distance), their_distance[i], tol)) {
      out << "rank " << i << ": kdspace (index " << ours[i].index << ", distance " << ours[i].distance
          << "), FLANN (index " << their_index[i] << ", distance " << their_distance[i] << ")";
      return out.str();
    }
    const double actual = true_distance<Metric>(q, pts.data() + their_index[i] * dim, dim);
    if (!close(their_distance[i], actual, tol)) {
      out << "FLANN rank " << i << ": index " << their_index[i] << " reported at " << their_distance[i]
          << " but lies at " << actual;
      return out.str();
    }
  }
  const double kth = static_cast<double>(ours.back().distance);
  const double band = 2 * tol * std::max(1.0, kth);
  std::set<std::size_t> ours_inside, theirs_inside, theirs_all;
  for (const auto& nb : ours)
    if (static_cast<double>(nb.distance) < kth - band) ours_inside.insert(nb.index);
  for (std::size_t i = 0; i < k; ++i) {
    theirs_all.insert(their_index[i]);
    const double actual = true_distance<Metric>(q, pts.data() + their_index[i] * dim, dim);
    if (actual > kth + band) {
      out << "FLANN returns index " << their_index[i] << " at " << actual << ", beyond the k-th distance "
          << kth;
      return out.str();
    }
    if (actual < kth - band) theirs_inside.insert(their_index[i]);
  }
  if (theirs_all.size() != k) return "FLANN returns an index twice";
  if (ours_inside != theirs_inside) {
    std::vector<std::size_t> only_ours, only_theirs;
    std::set_difference(ours_inside.begin(), ours_inside.end(), theirs_inside.begin(), theirs_inside.end(),
                        std::back_inserter(only_ours));
    std::set_difference(theirs_inside.begin(), theirs_inside.end(), ours_inside.begin(), ours_inside.end(),
                        std::back_inserter(only_theirs));
    out << "the neighbours strictly inside the k-th distance " << kth << " differ: " << only_ours.size()
        << " only in kdspace"
        << (only_ours.empty() ? "" : " (e.g. index " + std::to_string(only_ours[0]) + ")") << ", "
        << only_theirs.size() << " only in FLANN"
        << (only_theirs.empty() ? "" : " (e.g. index " + std::to_string(only_theirs[0]) + ")");
    // Which side is right: the library's brute force, bit-exact with kdspace's distance kernel.
    const auto bf = kdspace::brute_force_knn<Metric>(pts.data(), n, dim, q, k);
    out << "; brute force k-th distance " << bf.back().distance;
    return out.str();
  }
  return {};
}

/// Collects failures: the first 8 are reported in full, all are counted.
class Mismatches {
 public:
  template <class Where>
  void check(const std::string& problem, Where&& where) {
    ++checked_;
    if (problem.empty()) return;
    if (++failed_ <= 8) FAIL_CHECK(where() << "\n  " << problem);
  }
  void done() const {
    INFO(failed_ << " of " << checked_ << " comparisons failed (the first 8 are reported above)");
    CHECK(failed_ == 0);
    CHECK(checked_ > 0);
  }

 private:
  std::size_t checked_ = 0;
  std::size_t failed_ = 0;
};

struct Case {
  Shape shape;
  std::size_t n;
  std::size_t dim;
  std::uint32_t seed;
};

template <class Metric, class T>
std::string describe(const Case& c) {
  std::ostringstream out;
  out << "data: " << name(c.shape) << " seed=" << c.seed << " n=" << c.n << " dim=" << c.dim
      << " T=" << type_name<T>() << " metric=" << Metric::name;
  return out.str();
}

/// For every configuration, query and k: kdspace's knn against FLANN's kd-tree (leaf 10) and, for
/// n <= 2000, FLANN's linear scan.
template <class Metric, class T>
void knn_agrees_with_flann(const Case& c, const std::vector<BuildParams>& configs, std::size_t nq,
                           Mismatches& bad) {
  auto pts = make_points<T>(c.shape, c.n, c.dim, c.seed);
  auto queries = make_queries<T>(c.shape, pts, c.n, c.dim, nq, c.seed + 1);
  const auto ks = ks_for(c.n);
  struct Reference {
    const char* name;
    std::vector<FlannKnn<Metric, T>> per_k;
  };
  std::vector<Reference> references;
  {
    auto tree = build_flann<Metric, T>(pts, c.n, c.dim, flann::KDTreeSingleIndexParams(10));
    Reference r{"FLANN KDTreeSingleIndex(10)", {}};
    for (std::size_t k : ks) r.per_k.push_back(flann_knn<Metric, T>(*tree, queries, nq, c.dim, k));
    references.push_back(std::move(r));
  }
  if (c.n <= 2000) {
    auto linear = build_flann<Metric, T>(pts, c.n, c.dim, flann::LinearIndexParams());
    Reference r{"FLANN LinearIndex", {}};
    for (std::size_t k : ks) r.per_k.push_back(flann_knn<Metric, T>(*linear, queries, nq, c.dim, k));
    references.push_back(std::move(r));
  }
  for (const BuildParams& params : configs) {
    const PointTree<T, kdspace::Dynamic, Metric> tree(pts.data(), c.n, c.dim, params);
    for (std::size_t q = 0; q < nq; ++q)
      for (std::size_t ki = 0; ki < ks.size(); ++ki) {
        const std::size_t k = ks[ki];
        const T* query = queries.data() + q * c.dim;
        const auto ours = tree.knn(query, k);
        for (const Reference& ref : references) {
          const auto& theirs = ref.per_k[ki];
          bad.check(compare_knn<Metric>(ours, theirs.indices.data() + q * k, theirs.distances.data() + q * k,
                                        k, query, pts, c.n, c.dim),
                    [&] {
                      return describe<Metric, T>(c) + " " + describe(params) + " against " + ref.name +
                             " query #" + std::to_string(q) + " (" + query_kind(q) +
                             ") k=" + std::to_string(k);
                    });
        }
      }
  }
}

/// For every configuration, query and radius: the indices kdspace finds within r and those FLANN's
/// radiusSearch finds agree, except for points within a small band around r. Radii: the distances of
/// the 1st, 10th and (n/20)-th neighbours, and between two neighbours.
template <class Metric, class T>
void radius_agrees_with_flann(const Case& c, const std::vector<BuildParams>& configs, std::size_t nq,
                              Mismatches& bad) {
  auto pts = make_points<T>(c.shape, c.n, c.dim, c.seed);
  auto queries = make_queries<T>(c.shape, pts, c.n, c.dim, nq, c.seed + 1);
  auto flann_tree = build_flann<Metric, T>(pts, c.n, c.dim, flann::KDTreeSingleIndexParams(10));
  // FLANN's float radius rounds r * r: a relative band of 1e-6 covers it besides the summation order.
  const double tol = std::max(tolerance<T>(), 1e-6);
  std::vector<std::unique_ptr<PointTree<T, kdspace::Dynamic, Metric>>> trees;
  for (const BuildParams& params : configs)
    trees.push_back(std::make_unique<PointTree<T, kdspace::Dynamic, Metric>>(pts.data(), c.n, c.dim, params));
  for (std::size_t q = 0; q < nq; ++q) {
    T* query = queries.data() + q * c.dim;
    const auto sorted = trees.front()->knn(query, c.n);
    const std::size_t last = c.n - 1;
    const std::vector<T> radii = {
        sorted[0].distance, sorted[std::min<std::size_t>(9, last)].distance, sorted[c.n / 20].distance,
        (sorted[c.n / 2].distance + sorted[std::min(c.n / 2 + 1, last)].distance) / 2};
    for (T r : radii) {
      std::vector<std::vector<std::size_t>> their_indices;
      std::vector<std::vector<FlannResult<Metric, T>>> their_distances;
      flann::Matrix<T> qm(query, 1, c.dim);
      flann_tree->radiusSearch(qm, their_indices, their_distances, FlannMetric<Metric, T>::radius_argument(r),
                               exact_flann_search());
      const double band = tol * std::max(1.0, static_cast<double>(r));
      auto clear_of_boundary = [&](std::size_t i) {
        return std::abs(true_distance<Metric>(query, pts.data() + i * c.dim, c.dim) -
                        static_cast<double>(r)) > band;
      };
      std::set<std::size_t> theirs;
      std::string problem;
      for (std::size_t i : their_indices[0]) {
        if (i >= c.n) {
          problem = "FLANN returns index " + std::to_string(i) + ", out of range";
          break;
        }
        if (true_distance<Metric>(query, pts.data() + i * c.dim, c.dim) > static_cast<double>(r) + band)
          problem = "FLANN returns index " + std::to_string(i) + " outside the radius";
        if (clear_of_boundary(i)) theirs.insert(i);
      }
      for (std::size_t t = 0; t < trees.size(); ++t) {
        const auto ours_list = trees[t]->radius(query, r);
        std::set<std::size_t> ours;
        for (const auto& nb : ours_list)
          if (clear_of_boundary(nb.index)) ours.insert(nb.index);
        std::string mismatch = problem;
        if (mismatch.empty() && ours != theirs)
          mismatch = "away from the boundary kdspace finds " + std::to_string(ours.size()) +
                     " points, FLANN " + std::to_string(theirs.size()) + " (of " +
                     std::to_string(their_indices[0].size()) + " in all)";
        bad.check(mismatch, [&] {
          std::ostringstream out;
          out << describe<Metric, T>(c) << " " << describe(configs[t]) << " query #" << q << " ("
              << query_kind(q) << ") radius=" << std::setprecision(std::numeric_limits<T>::max_digits10) << r;
          return out.str();
        });
      }
    }
  }
}

}  // namespace

// ---- k-NN ----------------------------------------------------------------------------------------

TEST_CASE(
    "flann: L2 knn agrees with FLANN's exact kd-tree and linear scan on uniform, clustered, duplicate-heavy "
    "and gridded data in every dimension with every split rule",
    "[points][flann]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid);
  const auto configs = every_split_rule({1, 16});
  Mismatches bad;
  for (std::size_t n : {1, 2, 17, 1000}) {
    const Case c{shape, n, dim, 20000 + static_cast<std::uint32_t>(dim * 10 + n)};
    knn_agrees_with_flann<kdspace::L2, float>(c, configs, 10, bad);
    knn_agrees_with_flann<kdspace::L2, double>(c, configs, 5, bad);
  }
  bad.done();
}

TEST_CASE(
    "flann: L1 knn agrees with FLANN's exact L1 kd-tree and linear scan in every dimension with every split "
    "rule",
    "[points][flann]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid);
  const auto configs = every_split_rule({8});
  Mismatches bad;
  for (std::size_t n : {3, 1000}) {
    const Case c{shape, n, dim, 21000 + static_cast<std::uint32_t>(dim * 10 + n)};
    knn_agrees_with_flann<kdspace::L1, float>(c, configs, 10, bad);
    knn_agrees_with_flann<kdspace::L1, double>(c, configs, 5, bad);
  }
  bad.done();
}

TEST_CASE("flann: knn on 100000 points in 2, 3 and 4 dimensions agrees with FLANN's exact kd-tree",
          "[points][flann]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 2, 3, 4);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates);
  Mismatches bad;
  const Case c{shape, 100000, dim, 22000 + static_cast<std::uint32_t>(dim)};
  knn_agrees_with_flann<kdspace::L2, float>(c, every_split_rule({16}), 40, bad);
  if (dim == 3) knn_agrees_with_flann<kdspace::L2, double>(c, every_split_rule({4}), 20, bad);
  bad.done();
}

TEST_CASE("flann: knn on 10000 points in 8 to 128 dimensions agrees with FLANN's exact kd-tree",
          "[points][flann]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 8, 16, 32, 64, 128);
  Mismatches bad;
  const Case c{Shape::clustered, 10000, dim, 22500 + static_cast<std::uint32_t>(dim)};
  BuildParams sliding;
  sliding.position = PositionRule::sliding_midpoint;
  knn_agrees_with_flann<kdspace::L2, float>(c, {BuildParams{}, sliding}, 10, bad);
  bad.done();
}

// ---- radius --------------------------------------------------------------------------------------

TEST_CASE(
    "flann: radius search agrees with FLANN's radiusSearch away from the boundary (L2 with a squared radius, "
    "and L1)",
    "[points][flann]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid);
  const auto configs = every_split_rule({8});
  Mismatches bad;
  const Case c{shape, dim <= 4 ? std::size_t{5000} : std::size_t{1000}, dim,
               23000 + static_cast<std::uint32_t>(dim)};
  radius_agrees_with_flann<kdspace::L2, float>(c, configs, 5, bad);
  radius_agrees_with_flann<kdspace::L2, double>(c, configs, 3, bad);
  radius_agrees_with_flann<kdspace::L1, float>(c, configs, 3, bad);
  bad.done();
}

// ---- Linf (no FLANN counterpart) -------------------------------------------------------------------

// FLANN has no exact L-infinity kd-tree search (its kd-tree accumulates per-axis terms by addition),
// so Linf is checked against the library's brute force, bit for bit, on the same data.
TEST_CASE(
    "flann: Linf knn and radius match brute force bit for bit on the FLANN test data, up to 100000 points",
    "[points][flann]") {
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 8, 32, 128);
  const std::size_t n = dim <= 3 ? 100000 : 2000;
  const auto pts = make_points<float>(shape, n, dim, 24000 + static_cast<std::uint32_t>(dim));
  const auto queries = make_queries<float>(shape, pts, n, dim, 10, 24100 + static_cast<std::uint32_t>(dim));
  const auto ks = ks_for(n);
  std::vector<std::vector<Neighbor<float>>> want_knn, want_radius;
  std::vector<float> radii;
  for (std::size_t q = 0; q < 10; ++q) {
    const float* query = queries.data() + q * dim;
    for (std::size_t k : ks)
      want_knn.push_back(kdspace::brute_force_knn<kdspace::Linf>(pts.data(), n, dim, query, k));
    radii.push_back(want_knn[q * ks.size() + std::min<std::size_t>(3, ks.size() - 1)].back().distance);
    want_radius.push_back(
        kdspace::brute_force_radius<kdspace::Linf>(pts.data(), n, dim, query, radii.back()));
  }
  Mismatches bad;
  for (const BuildParams& params : every_split_rule({16})) {
    const PointTree<float, kdspace::Dynamic, kdspace::Linf> tree(pts.data(), n, dim, params);
    for (std::size_t q = 0; q < 10; ++q) {
      const float* query = queries.data() + q * dim;
      auto where = [&] {
        return std::string("data: ") + name(shape) + " n=" + std::to_string(n) +
               " dim=" + std::to_string(dim) + " " + describe(params) + " query #" + std::to_string(q) +
               " (" + query_kind(q) + ")";
      };
      for (std::size_t ki = 0; ki < ks.size(); ++ki)
        bad.check(
            tree.knn(query, ks[ki]) == want_knn[q * ks.size() + ki] ? "" : "knn differs from brute force",
            [&] { return where() + " k=" + std::to_string(ks[ki]); });
      bad.check(tree.radius(query, radii[q]) == want_radius[q] ? "" : "radius differs from brute force",
                [&] { return where() + " radius=" + std::to_string(radii[q]); });
    }
  }
  bad.done();
}
