// Property tests of PointTree (kdspace/points/point_tree.hpp) against the library's brute force
// (kdspace/points/brute_force.hpp).
//
// Both sides score points with internal_distance() (metric.hpp) in one fixed order, so exact answers
// must agree bit for bit: the same indices, the same distances, in the same order, ties at equal
// distance by ascending index. Approximate answers (eps > 0, max_checks) are held to the guarantees
// the header states instead. Every mismatch is reported with what is needed to reproduce it: data
// shape, seed, dimension, size, split rules, leaf size, query number and kind, k or radius.
//
// The sweeps cover seven data shapes (uniform, Gaussian blobs, duplicate-heavy, integer grid, all
// identical, some coordinates constant, sorted along x), dimensions 1 to 128, every axis rule with
// every position rule at leaf sizes 1, 2, 8, 50 and a depth cap of 3, k = 1, 2, 5, 10, 100 and n,
// float and double, L2, L1 and Linf, Dynamic and compile-time dimensions.
#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <iomanip>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/point_tree.hpp"
#include "catch_support.hpp"
#include "support.hpp"

using kdspace::AxisRule;
using kdspace::BuildParams;
using kdspace::Index;
using kdspace::Neighbor;
using kdspace::PointTree;
using kdspace::PositionRule;
using kdspace::QueryStats;
using kdspace::SearchParams;

namespace {

// ---- data ---------------------------------------------------------------------------------------

using kdspace_test::error_message;
using kdspace_test::make_points;
using kdspace_test::name;
using kdspace_test::Shape;
using kdspace_test::type_name;

std::string describe(const BuildParams& p) {
  std::ostringstream out;
  out << "axis=" << name(p.axis) << " position=" << name(p.position) << " leaf_size=" << p.leaf_size
      << " max_depth=" << p.max_depth;
  return out.str();
}

enum class QueryKind { random, on_point, far };

const char* name(QueryKind k) {
  switch (k) {
    case QueryKind::random:
      return "random";
    case QueryKind::on_point:
      return "on a data point";
    case QueryKind::far:
      return "far outside the data";
  }
  return "?";
}

template <class T>
struct Queries {
  std::vector<T> coords;
  std::vector<QueryKind> kinds;
  std::size_t dim = 0;

  std::size_t size() const { return kinds.size(); }
  const T* row(std::size_t q) const { return coords.data() + q * dim; }
};

/// nq queries cycling through: random in the data's bounding box grown by 10% (integers for grid
/// data), exactly on a data point, random, on a data point, far outside the data.
template <class T>
Queries<T> make_queries(Shape shape, const std::vector<T>& pts, std::size_t n, std::size_t dim,
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
  Queries<T> out;
  out.dim = dim;
  out.coords.resize(nq * dim);
  std::uniform_int_distribution<std::size_t> pick(0, n - 1);
  std::uniform_int_distribution<int> cell(-1, 7);
  const QueryKind cycle[] = {QueryKind::random, QueryKind::on_point, QueryKind::random, QueryKind::on_point,
                             QueryKind::far};
  for (std::size_t q = 0; q < nq; ++q) {
    const QueryKind kind = cycle[q % 5];
    out.kinds.push_back(kind);
    T* row = out.coords.data() + q * dim;
    if (kind == QueryKind::on_point) {
      std::copy_n(pts.data() + pick(rng) * dim, dim, row);
      continue;
    }
    for (std::size_t a = 0; a < dim; ++a) {
      const double span = hi[a] - lo[a];
      double v;
      if (kind == QueryKind::far)
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

/// k = 1, 2, 5, 10, 100 where they do not exceed n, and n.
std::vector<std::size_t> ks_for(std::size_t n) {
  std::vector<std::size_t> ks;
  for (std::size_t k : {1, 2, 5, 10, 100})
    if (k < n) ks.push_back(k);
  ks.push_back(n);
  return ks;
}

/// Sizes that keep the sweeps fast: smaller for the high dimensions.
std::size_t size_for(std::size_t dim) {
  return dim <= 4 ? 3000 : dim <= 16 ? 2000 : 1000;
}

/// Every axis rule with every position rule, at leaf sizes 1, 2, 8 and 50, and with max_depth 3
/// (big leaves whatever the leaf size).
std::vector<BuildParams> every_split_rule() {
  std::vector<BuildParams> out;
  for (AxisRule axis : {AxisRule::cycle, AxisRule::max_spread})
    for (PositionRule position :
         {PositionRule::median, PositionRule::middle, PositionRule::sliding_midpoint, PositionRule::midpoint}) {
      for (std::size_t leaf : {1, 2, 8, 50}) {
        BuildParams p;
        p.axis = axis;
        p.position = position;
        p.leaf_size = leaf;
        out.push_back(p);
      }
      BuildParams shallow;
      shallow.axis = axis;
      shallow.position = position;
      shallow.leaf_size = 1;
      shallow.max_depth = 3;
      out.push_back(shallow);
    }
  return out;
}

/// Every axis rule with every position rule at leaf size 8, and with max_depth 3 (leaf size 1).
std::vector<BuildParams> fewer_split_rules() {
  std::vector<BuildParams> out;
  for (const BuildParams& p : every_split_rule())
    if (p.leaf_size == 8 || p.max_depth == 3) out.push_back(p);
  return out;
}

struct Case {
  Shape shape;
  std::size_t n;
  std::size_t dim;
  std::uint32_t seed;
};

template <class T, class Metric>
std::string describe(const Case& c) {
  std::ostringstream out;
  out << "data: " << name(c.shape) << " seed=" << c.seed << " n=" << c.n << " dim=" << c.dim
      << " T=" << type_name<T>() << " metric=" << Metric::name;
  return out.str();
}

template <class T>
std::string describe_query(const Queries<T>& queries, std::size_t q) {
  std::ostringstream out;
  out << "query #" << q << " (" << name(queries.kinds[q]) << ")";
  if (queries.dim <= 8) {
    out << " = (" << std::setprecision(std::numeric_limits<T>::max_digits10);
    for (std::size_t a = 0; a < queries.dim; ++a) out << (a ? ", " : "") << queries.row(q)[a];
    out << ")";
  }
  return out.str();
}

// ---- comparing answers --------------------------------------------------------------------------

template <class T>
std::string show(const Neighbor<T>& nb) {
  std::ostringstream out;
  out << "(index " << nb.index << ", distance " << std::setprecision(std::numeric_limits<T>::max_digits10)
      << nb.distance << ")";
  return out.str();
}

/// Empty when got == want element for element; else what differs first.
template <class T>
std::string first_difference(const std::vector<Neighbor<T>>& got, const std::vector<Neighbor<T>>& want) {
  if (got == want) return {};
  std::ostringstream out;
  if (got.size() != want.size()) out << "got " << got.size() << " results, expected " << want.size() << "; ";
  for (std::size_t i = 0; i < std::min(got.size(), want.size()); ++i)
    if (!(got[i] == want[i])) {
      out << "first difference at rank " << i << ": got " << show(got[i]) << ", expected " << show(want[i]);
      if (i > 0) out << " (rank " << i - 1 << " is " << show(want[i - 1]) << " in both)";
      break;
    }
  if (got.size() == want.size()) {
    auto by_index = [](const Neighbor<T>& a, const Neighbor<T>& b) { return a.index < b.index; };
    auto a = got, b = want;
    std::sort(a.begin(), a.end(), by_index);
    std::sort(b.begin(), b.end(), by_index);
    if (a == b) out << "; the same (index, distance) pairs in another order";
  }
  return out.str();
}

/// Empty when the list is sorted by distance with no index twice. (Equal reported distances are in
/// ascending index order when their internal distances are equal too; for L2 two different squared
/// distances may share a square root and then keep their squared-distance order. The comparison
/// with brute force checks the exact order.)
template <class T>
std::string order_problem(const std::vector<Neighbor<T>>& got) {
  for (std::size_t i = 1; i < got.size(); ++i) {
    const auto &a = got[i - 1], &b = got[i];
    if (!(a.distance <= b.distance))
      return "not in distance order at rank " + std::to_string(i) + ": " + show(a) + " then " + show(b);
  }
  std::vector<Index> ids;
  for (const auto& nb : got) ids.push_back(nb.index);
  std::sort(ids.begin(), ids.end());
  if (std::adjacent_find(ids.begin(), ids.end()) != ids.end()) return "an index is returned twice";
  return {};
}

std::string join(const std::string& a, const std::string& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return a + "; " + b;
}

/// True when got is want with entries of equal distance put in index order, and differs from want:
/// for L2 two different squared distances can round to one Euclidean distance, and then the two
/// sides disagree on the order unless both restore (distance, index) after the square root.
template <class T>
bool differs_only_in_tie_order(const std::vector<Neighbor<T>>& got, const std::vector<Neighbor<T>>& want) {
  if (got == want) return false;
  auto resorted = want;
  std::stable_sort(resorted.begin(), resorted.end(), [](const Neighbor<T>& a, const Neighbor<T>& b) {
    return a.distance < b.distance || (a.distance == b.distance && a.index < b.index);
  });
  return resorted == got;
}

/// Collects failures of one test case: the first few are reported in full, all are counted. A
/// failure that is only a different order of entries at equal Euclidean distance is counted apart
/// (and still fails), so that it cannot hide other failures in the report.
class Mismatches {
 public:
  template <class Where>
  void check(const std::string& problem, Where&& where) {
    check(problem, false, std::forward<Where>(where));
  }
  template <class Where>
  void check(const std::string& problem, bool tie_order_only, Where&& where) {
    ++checked_;
    if (problem.empty()) return;
    if (tie_order_only) {
      if (++tie_order_ <= 2)
        FAIL_CHECK(
            where() << "\n  " << problem
                    << "\n  (only the order of entries at equal Euclidean distance differs: the squared "
                       "distances differ, their square roots do not)");
      return;
    }
    if (++failed_ <= 8) FAIL_CHECK(where() << "\n  " << problem);
  }
  void done() const {
    INFO(failed_ << " of " << checked_ << " comparisons failed (the first 8 are reported above); "
                 << tie_order_
                 << " more differ only in the order of entries at equal Euclidean distance (the first 2 are "
                    "reported above)");
    CHECK(failed_ == 0);
    CHECK(tie_order_ == 0);
    CHECK(checked_ > 0);
  }

 private:
  std::size_t checked_ = 0;
  std::size_t failed_ = 0;
  std::size_t tie_order_ = 0;
};

/// The true distance between q and row p, through the one distance kernel.
template <class Metric, class T>
T true_distance(const T* q, const T* p, std::size_t dim) {
  return Metric::to_distance(kdspace::internal_distance<Metric>(q, p, dim));
}

// ---- the sweeps ---------------------------------------------------------------------------------

/// For every configuration and query: knn(q, k) == brute_force_knn(q, k) for every k in ks_for(n).
template <class T, class Metric, int Dim = kdspace::Dynamic>
void knn_matches_brute_force(const Case& c, const std::vector<BuildParams>& configs, std::size_t nq,
                             Mismatches& bad) {
  const auto pts = make_points<T>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<T>(c.shape, pts, c.n, c.dim, nq, c.seed + 1);
  const auto ks = ks_for(c.n);
  std::vector<std::vector<Neighbor<T>>> want;
  for (std::size_t q = 0; q < queries.size(); ++q)
    for (std::size_t k : ks)
      want.push_back(kdspace::brute_force_knn<Metric>(pts.data(), c.n, c.dim, queries.row(q), k));

  for (const BuildParams& params : configs) {
    const PointTree<T, Dim, Metric> tree(pts.data(), c.n, c.dim, params);
    std::string shape_problem;
    if (tree.size() != c.n || tree.dim() != c.dim) shape_problem = "size() or dim() is wrong";
    if (tree.depth() > params.max_depth)
      shape_problem = "depth " + std::to_string(tree.depth()) + " exceeds max_depth";
    bad.check(shape_problem, [&] { return describe<T, Metric>(c) + " " + describe(params); });
    for (std::size_t q = 0; q < queries.size(); ++q)
      for (std::size_t ki = 0; ki < ks.size(); ++ki) {
        const auto got = tree.knn(queries.row(q), ks[ki]);
        const auto& expected = want[q * ks.size() + ki];
        bad.check(join(first_difference(got, expected), order_problem(got)),
                  differs_only_in_tie_order(got, expected), [&] {
                    return describe<T, Metric>(c) + " " + describe(params) + " " +
                           describe_query(queries, q) + " k=" + std::to_string(ks[ki]);
                  });
      }
  }
}

/// For every configuration and query: radius(q, r) == brute_force_radius(q, r) for radii 0, the
/// distances of the 1st, 5th and n/10-th neighbours, one between two neighbours, the largest
/// distance and one beyond it; and radius(q, r, m) is the first m of the full list.
template <class T, class Metric>
void radius_matches_brute_force(const Case& c, const std::vector<BuildParams>& configs, std::size_t nq,
                                Mismatches& bad) {
  const auto pts = make_points<T>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<T>(c.shape, pts, c.n, c.dim, nq, c.seed + 1);
  std::vector<std::vector<T>> radii(queries.size());
  std::vector<std::vector<std::vector<Neighbor<T>>>> want(queries.size());
  for (std::size_t q = 0; q < queries.size(); ++q) {
    const auto all = kdspace::brute_force_knn<Metric>(pts.data(), c.n, c.dim, queries.row(q), c.n);
    const std::size_t tenth = c.n / 10;
    const T between =
        tenth + 1 < c.n ? (all[tenth].distance + all[tenth + 1].distance) / 2 : all[tenth].distance;
    radii[q] = {T(0),
                all[0].distance,
                all[std::min<std::size_t>(4, c.n - 1)].distance,
                all[tenth].distance,
                between,
                all.back().distance,
                2 * all.back().distance + 1};
    for (T r : radii[q])
      want[q].push_back(kdspace::brute_force_radius<Metric>(pts.data(), c.n, c.dim, queries.row(q), r));
    // The last radius exceeds every distance: it must take in all the points.
    bad.check(want[q].back().size() == c.n ? "" : "brute force misses points inside a radius covering all",
              [&] { return describe<T, Metric>(c) + " " + describe_query(queries, q); });
  }

  for (const BuildParams& params : configs) {
    const PointTree<T, kdspace::Dynamic, Metric> tree(pts.data(), c.n, c.dim, params);
    for (std::size_t q = 0; q < queries.size(); ++q)
      for (std::size_t ri = 0; ri < radii[q].size(); ++ri) {
        const T r = radii[q][ri];
        const auto& expected = want[q][ri];
        auto where = [&] {
          std::ostringstream out;
          out << describe<T, Metric>(c) << " " << describe(params) << " " << describe_query(queries, q)
              << " radius=" << std::setprecision(std::numeric_limits<T>::max_digits10) << r;
          return out.str();
        };
        const auto got = tree.radius(queries.row(q), r);
        bad.check(join(first_difference(got, expected), order_problem(got)),
                  differs_only_in_tie_order(got, expected), where);
        for (std::size_t cap : {std::size_t{0}, std::size_t{1}, expected.size() / 2, expected.size() + 1}) {
          const auto capped = tree.radius(queries.row(q), r, cap);
          const std::vector<Neighbor<T>> prefix(
              expected.begin(),
              expected.begin() + static_cast<std::ptrdiff_t>(std::min(cap, expected.size())));
          bad.check(first_difference(capped, prefix), differs_only_in_tie_order(capped, prefix),
                    [&] { return where() + " max_results=" + std::to_string(cap); });
        }
      }
  }
}

/// Boxes compared with a closed-box filter over all points (indices ascending): boxes around data
/// points, degenerate boxes lo == hi on a data point, boxes with infinite sides, a slab flat on one
/// axis, a box beyond the data and the whole space.
template <class T, int Dim = kdspace::Dynamic>
void box_matches_brute_force(const Case& c, const std::vector<BuildParams>& configs, std::size_t nboxes,
                             Mismatches& bad) {
  const auto pts = make_points<T>(c.shape, c.n, c.dim, c.seed);
  const T inf = std::numeric_limits<T>::infinity();
  std::vector<T> lo_all(c.dim, inf), hi_all(c.dim, -inf);
  for (std::size_t i = 0; i < c.n; ++i)
    for (std::size_t a = 0; a < c.dim; ++a) {
      lo_all[a] = std::min(lo_all[a], pts[i * c.dim + a]);
      hi_all[a] = std::max(hi_all[a], pts[i * c.dim + a]);
    }
  std::mt19937 rng(c.seed + 7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::uniform_int_distribution<std::size_t> pick(0, c.n - 1);
  std::uniform_int_distribution<int> side(0, 2);
  std::vector<std::vector<T>> los, his;
  std::vector<std::string> kinds;
  for (std::size_t b = 0; b < nboxes; ++b) {
    std::vector<T> lo(c.dim), hi(c.dim);
    const T* centre = pts.data() + pick(rng) * c.dim;
    const std::size_t kind = b % 6;
    for (std::size_t a = 0; a < c.dim; ++a) {
      const double span = static_cast<double>(hi_all[a] - lo_all[a]) + 1e-3;
      const T below = static_cast<T>(centre[a] - 0.3 * span * unit(rng));
      const T above = static_cast<T>(centre[a] + 0.3 * span * unit(rng));
      switch (kind) {
        case 0:  // around a data point
          lo[a] = below, hi[a] = above;
          break;
        case 1:  // a single data point
          lo[a] = hi[a] = centre[a];
          break;
        case 2: {  // around a data point, with infinite sides
          const int s = side(rng);
          lo[a] = s == 0 ? -inf : below;
          hi[a] = s == 1 ? inf : above;
          break;
        }
        case 3:  // a slab: flat through a data point on axis 0, unbounded on the others
          lo[a] = a == 0 ? centre[a] : -inf;
          hi[a] = a == 0 ? centre[a] : inf;
          break;
        case 4:  // beyond the data on every axis
          lo[a] = hi_all[a] + 1, hi[a] = hi_all[a] + 2;
          break;
        default:  // the whole space
          lo[a] = -inf, hi[a] = inf;
          break;
      }
    }
    static const char* const names[] = {"around a point", "lo == hi on a point", "infinite sides",
                                        "slab",           "beyond the data",     "whole space"};
    kinds.push_back(names[kind]);
    los.push_back(lo);
    his.push_back(hi);
  }
  std::vector<std::vector<Index>> want(nboxes);
  for (std::size_t b = 0; b < nboxes; ++b)
    for (std::size_t i = 0; i < c.n; ++i) {
      bool inside = true;
      for (std::size_t a = 0; a < c.dim; ++a)
        inside = inside && los[b][a] <= pts[i * c.dim + a] && pts[i * c.dim + a] <= his[b][a];
      if (inside) want[b].push_back(static_cast<Index>(i));
    }

  for (const BuildParams& params : configs) {
    const PointTree<T, Dim> tree(pts.data(), c.n, c.dim, params);
    for (std::size_t b = 0; b < nboxes; ++b) {
      const auto got = tree.box(los[b].data(), his[b].data());
      std::string problem;
      if (got != want[b]) {
        std::ostringstream out;
        out << "got " << got.size() << " indices, expected " << want[b].size();
        for (std::size_t i = 0; i < std::min(got.size(), want[b].size()); ++i)
          if (got[i] != want[b][i]) {
            out << "; first difference at position " << i << ": got " << got[i] << ", expected "
                << want[b][i];
            break;
          }
        problem = out.str();
      }
      bad.check(problem, [&] {
        return describe<T, kdspace::L2>(c) + " " + describe(params) + " box #" + std::to_string(b) + " (" +
               kinds[b] + ")";
      });
    }
  }
}

/// Approximate k-NN: k distinct sorted results at their true distances, the i-th no nearer than the
/// true i-th and at most (1 + eps) times as far.
template <class T, class Metric>
void approximate_within_bound(const Case& c, const std::vector<BuildParams>& configs, std::size_t nq,
                              Mismatches& bad) {
  const auto pts = make_points<T>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<T>(c.shape, pts, c.n, c.dim, nq, c.seed + 1);
  const auto ks = ks_for(c.n);
  std::vector<std::vector<Neighbor<T>>> want;
  for (std::size_t q = 0; q < queries.size(); ++q)
    for (std::size_t k : ks)
      want.push_back(kdspace::brute_force_knn<Metric>(pts.data(), c.n, c.dim, queries.row(q), k));
  // Rounding slack on the bound only: the guarantee itself is not loosened.
  const double slack = 1e-5;
  for (const BuildParams& params : configs) {
    const PointTree<T, kdspace::Dynamic, Metric> tree(pts.data(), c.n, c.dim, params);
    for (double eps : {0.1, 0.5, 2.0}) {
      SearchParams sp;
      sp.eps = eps;
      for (std::size_t q = 0; q < queries.size(); ++q)
        for (std::size_t ki = 0; ki < ks.size(); ++ki) {
          const auto got = tree.knn(queries.row(q), ks[ki], sp);
          const auto& exact = want[q * ks.size() + ki];
          std::ostringstream problem;
          problem << order_problem(got);
          if (got.size() != ks[ki]) problem << " got " << got.size() << " results, expected k";
          for (std::size_t i = 0; i < std::min(got.size(), exact.size()) && problem.str().empty(); ++i) {
            const T real = true_distance<Metric>(queries.row(q), pts.data() + got[i].index * c.dim, c.dim);
            const double bound = (1 + eps) * static_cast<double>(exact[i].distance) * (1 + slack) + 1e-30;
            if (got[i].distance != real)
              problem << "rank " << i << ": " << show(got[i]) << " but that point is at distance " << real;
            else if (got[i].distance < exact[i].distance)
              problem << "rank " << i << ": " << show(got[i]) << " is nearer than the true rank-" << i
                      << " neighbour " << show(exact[i]);
            else if (static_cast<double>(got[i].distance) > bound)
              problem << "rank " << i << ": " << show(got[i]) << " is more than (1 + eps) times the true "
                      << show(exact[i]);
          }
          bad.check(problem.str(), [&] {
            return describe<T, Metric>(c) + " " + describe(params) + " " + describe_query(queries, q) +
                   " k=" + std::to_string(ks[ki]) + " eps=" + std::to_string(eps);
          });
        }
    }
  }
}

const std::vector<Shape> kEveryShape = {Shape::uniform,   Shape::clustered, Shape::duplicates, Shape::grid,
                                        Shape::identical, Shape::flat,      Shape::sorted_x};


/// A minimal matrix: rows(), cols() and (i, j), stored row-major or column-major.
struct TinyMatrix {
  long n, d;
  bool column_major;
  std::vector<double> v;
  long rows() const { return n; }
  long cols() const { return d; }
  double operator()(long i, long j) const {
    return column_major ? v[static_cast<std::size_t>(j * n + i)] : v[static_cast<std::size_t>(i * d + j)];
  }
};

}  // namespace

// ---- exact k-NN: one test case per data shape, every dimension and every split rule --------------

#define KDSPACE_KNN_SWEEP(SHAPE, SEED)                                                                   \
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);                   \
  Mismatches bad;                                                                                        \
  knn_matches_brute_force<float, kdspace::L2>(                                                           \
      {SHAPE, size_for(dim), dim, SEED + static_cast<std::uint32_t>(dim)}, every_split_rule(), 10, bad); \
  bad.done();

TEST_CASE(
    "exact: knn matches brute force bit for bit on uniform data in every dimension with every split rule",
    "[points][exact]"){KDSPACE_KNN_SWEEP(Shape::uniform, 1000)}

TEST_CASE(
    "exact: knn matches brute force bit for bit on clustered data (Gaussian blobs) in every dimension with "
    "every split rule",
    "[points][exact]"){KDSPACE_KNN_SWEEP(Shape::clustered, 2000)}

TEST_CASE(
    "exact: knn matches brute force bit for bit on duplicate-heavy data in every dimension with every split "
    "rule",
    "[points][exact]"){KDSPACE_KNN_SWEEP(Shape::duplicates, 3000)}

TEST_CASE(
    "exact: knn matches brute force bit for bit on integer grid data, ties included, with every split rule",
    "[points][exact]"){KDSPACE_KNN_SWEEP(Shape::grid, 4000)}

TEST_CASE(
    "exact: knn matches brute force bit for bit when some coordinates are constant, with every split rule",
    "[points][exact]"){KDSPACE_KNN_SWEEP(Shape::flat, 5000)}

TEST_CASE("exact: knn matches brute force bit for bit on input sorted along x, with every split rule",
          "[points][exact]"){KDSPACE_KNN_SWEEP(Shape::sorted_x, 6000)}
#undef KDSPACE_KNN_SWEEP

TEST_CASE(
    "exact: knn on all-identical points returns the k smallest indices at one distance, with every split "
    "rule",
    "[points][exact]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  const std::size_t n = GENERATE(as<std::size_t>{}, 2, 17, 500);
  Mismatches bad;
  knn_matches_brute_force<float, kdspace::L2>({Shape::identical, n, dim, 7000}, every_split_rule(), 10, bad);
  knn_matches_brute_force<double, kdspace::L1>({Shape::identical, n, dim, 7001}, fewer_split_rules(), 5, bad);
  bad.done();
}

TEST_CASE(
    "exact: knn matches brute force bit for bit in each dimension from 9 to 24, the descriptors' sizes",
    "[points][exact]") {
  // Descriptor data live here (MFCC 13 and 20, 16-bin histograms): every dimension, so every count of
  // axes after the distance's last block of 8, where the sweeps above reach only 16. With ties
  // (duplicates, grid), all-identical leaves and the first leaf's fill, in float and double.
  const std::size_t dim = GENERATE(range<std::size_t>(9, 25));
  const Shape shape =
      GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid, Shape::identical);
  BuildParams small_leaves;
  small_leaves.leaf_size = 8;
  const std::vector<BuildParams> configs = {BuildParams{}, small_leaves};
  const auto seed = 7200 + static_cast<std::uint32_t>(dim * 8 + static_cast<std::size_t>(shape));
  Mismatches bad;
  knn_matches_brute_force<float, kdspace::L2>({shape, 600, dim, seed}, configs, 12, bad);
  knn_matches_brute_force<double, kdspace::L2>({shape, 300, dim, seed + 1}, configs, 6, bad);
  bad.done();
}

TEST_CASE("exact: a tree of a single point answers knn with that point, with every split rule",
          "[points][exact]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  Mismatches bad;
  knn_matches_brute_force<float, kdspace::L2>({Shape::uniform, 1, dim, 7100}, every_split_rule(), 10, bad);
  knn_matches_brute_force<double, kdspace::Linf>({Shape::uniform, 1, dim, 7101}, every_split_rule(), 5, bad);
  bad.done();
}

TEST_CASE("exact: knn matches brute force bit for bit in double precision and under L1 and Linf",
          "[points][exact]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid);
  const Case c{shape, size_for(dim) / 2, dim, 8000 + static_cast<std::uint32_t>(dim)};
  Mismatches bad;
  SECTION("double, L2") {
    knn_matches_brute_force<double, kdspace::L2>(c, fewer_split_rules(), 6, bad);
  }
  SECTION("float, L1") {
    knn_matches_brute_force<float, kdspace::L1>(c, fewer_split_rules(), 6, bad);
  }
  SECTION("double, L1") {
    knn_matches_brute_force<double, kdspace::L1>(c, fewer_split_rules(), 6, bad);
  }
  SECTION("float, Linf") {
    knn_matches_brute_force<float, kdspace::Linf>(c, fewer_split_rules(), 6, bad);
  }
  SECTION("double, Linf") {
    knn_matches_brute_force<double, kdspace::Linf>(c, fewer_split_rules(), 6, bad);
  }
  bad.done();
}

TEST_CASE("exact: trees with a compile-time dimension answer knn bit for bit like brute force",
          "[points][exact]") {
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid,
                               Shape::identical, Shape::flat, Shape::sorted_x);
  Mismatches bad;
  knn_matches_brute_force<float, kdspace::L2, 3>({shape, 2000, 3, 9000}, every_split_rule(), 10, bad);
  knn_matches_brute_force<double, kdspace::L2, 2>({shape, 2000, 2, 9001}, every_split_rule(), 10, bad);
  knn_matches_brute_force<float, kdspace::L1, 4>({shape, 1000, 4, 9002}, fewer_split_rules(), 10, bad);
  knn_matches_brute_force<double, kdspace::Linf, 1>({shape, 1000, 1, 9003}, fewer_split_rules(), 10, bad);
  // Float L2 from 8 axes on: the SSE2 leaf distance of a compile-time dimension (fixed_distance.hpp).
  knn_matches_brute_force<float, kdspace::L2, 13>({shape, 1000, 13, 9004}, fewer_split_rules(), 10, bad);
  knn_matches_brute_force<float, kdspace::L2, 20>({shape, 600, 20, 9005}, fewer_split_rules(), 10, bad);
  knn_matches_brute_force<float, kdspace::L2, 128>({shape, 300, 128, 9006}, fewer_split_rules(), 10, bad);
  bad.done();
}

TEST_CASE("exact: a Dynamic tree and a compile-time-dimension tree on the same points give identical answers",
          "[points][exact]") {
  const auto pts = make_points<float>(Shape::clustered, 3000, 3, 9100);
  const auto queries = make_queries<float>(Shape::clustered, pts, 3000, 3, 50, 9101);
  for (const BuildParams& params : every_split_rule()) {
    const PointTree<float> dynamic_tree(pts.data(), 3000, 3, params);
    const PointTree<float, 3> fixed_tree(pts.data(), 3000, 3, params);
    CAPTURE(describe(params));
    REQUIRE(dynamic_tree.node_count() == fixed_tree.node_count());
    for (std::size_t q = 0; q < queries.size(); ++q) {
      CAPTURE(q);
      REQUIRE(dynamic_tree.knn(queries.row(q), 10) == fixed_tree.knn(queries.row(q), 10));
      REQUIRE(dynamic_tree.radius(queries.row(q), 0.5f) == fixed_tree.radius(queries.row(q), 0.5f));
    }
  }
}

namespace {

/// Pairs of 2-D float points p0 (index 0), p1 (index 1) whose squared distances from the origin
/// differ (p1's is smaller) while their Euclidean distances, after the square root, are equal.
/// p1 is put on (almost) the circle through p0 and nudged by ulps until that happens.
std::vector<std::vector<float>> sqrt_tie_pairs(std::size_t wanted, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(0.2f, 1.0f);
  const float q[2] = {0, 0};
  std::vector<std::vector<float>> out;
  for (int trial = 0; trial < 100000 && out.size() < wanted; ++trial) {
    std::vector<float> p = {coord(rng), coord(rng), coord(rng), 0};
    const float d0 = kdspace::internal_distance<kdspace::L2>(q, p.data(), 2);
    const float rest = d0 - p[2] * p[2];
    if (rest <= 0) continue;
    const float y = std::sqrt(rest);
    for (int steps = -4; steps <= 4; ++steps) {
      float nudged = y;
      for (int s = 0; s < std::abs(steps); ++s) nudged = std::nextafter(nudged, steps < 0 ? 0.f : 2.f);
      p[3] = nudged;
      const float d1 = kdspace::internal_distance<kdspace::L2>(q, p.data() + 2, 2);
      if (d1 < d0 && std::sqrt(d0) == std::sqrt(d1)) {
        out.push_back(p);
        break;
      }
    }
  }
  return out;
}

std::string describe_pair(const std::vector<float>& p) {
  const float q[2] = {0, 0};
  std::ostringstream out;
  out << std::setprecision(9) << "p0 = (" << p[0] << ", " << p[1] << "), p1 = (" << p[2] << ", " << p[3]
      << "), q = (0, 0); squared distances " << std::hexfloat
      << kdspace::internal_distance<kdspace::L2>(q, p.data(), 2) << " > "
      << kdspace::internal_distance<kdspace::L2>(q, p.data() + 2, 2) << ", square roots equal";
  return out.str();
}

}  // namespace

// Results are ordered by the internal distance (squared for L2), ties by index; the distances
// returned are Euclidean. Two different squared distances can round to one Euclidean distance (sqrt
// halves the number of representable values); such a pair is not a tie, and keeps its squared order.
TEST_CASE(
    "exact: knn and radius agree with brute force when two squared distances round to one Euclidean "
    "distance",
    "[points][exact]") {
  const auto pairs = sqrt_tie_pairs(5, 9200);
  REQUIRE(pairs.size() == 5);
  const float q[2] = {0, 0};
  for (const auto& p : pairs) {
    INFO(describe_pair(p));
    const PointTree<float> tree(p.data(), 2, 2);
    const auto got = tree.knn(q, 2);
    const auto want = kdspace::brute_force_knn<kdspace::L2>(p.data(), 2, 2, q, std::size_t{2});
    const auto got_r = tree.radius(q, 2.f);
    const auto want_r = kdspace::brute_force_radius<kdspace::L2>(p.data(), 2, 2, q, 2.f);
    INFO("tree knn " << show(got[0]) << " " << show(got[1]) << "; brute force " << show(want[0]) << " "
                     << show(want[1]));
    CHECK(order_problem(got).empty());
    CHECK(first_difference(got, want).empty());
    CHECK(first_difference(got_r, want_r).empty());
  }
}

TEST_CASE(
    "exact: of two points whose squared distances differ but share one square root, the nearer by "
    "squared distance comes first",
    "[points][exact]") {
  const auto pairs = sqrt_tie_pairs(5, 9300);
  REQUIRE(pairs.size() == 5);
  const float q[2] = {0, 0};
  for (const auto& p : pairs) {
    INFO(describe_pair(p));
    const PointTree<float> tree(p.data(), 2, 2);
    // p1 (index 1) has the smaller squared distance, so it is the nearest, although both print alike.
    const auto got = tree.knn(q, 2);
    const auto capped = tree.radius(q, 2.f, 1);
    INFO("knn(q, 2) = " << show(got[0]) << ", " << show(got[1]) << "; radius(q, 2, max_results 1) = "
                        << show(capped[0]));
    CHECK(got[0].index == 1);
    CHECK(got[1].index == 0);
    CHECK(got[0].distance == got[1].distance);
    CHECK(capped[0].index == 1);
  }
}

// The middle rule may leave one side of a node empty. Here the root splits x at 0.5, the right node
// {(1, 0), (0.9, 0.1)} (the last two rows of the leaf order) splits y at the middle of its cell, 0.5,
// and all its points fall below: its upper child is empty and starts one past the last point.
TEST_CASE(
    "exact: the middle rule builds and answers exactly when a node's upper child is empty at the end of the "
    "points",
    "[points][exact]") {
  const float pts[] = {0, 1, 1, 0, 0.9f, 0.1f};
  for (AxisRule axis : {AxisRule::cycle, AxisRule::max_spread}) {
    BuildParams params;
    params.axis = axis;
    params.position = PositionRule::middle;
    params.leaf_size = 1;
    INFO(describe(params));
    const PointTree<float> tree(pts, 3, 2, params);
    const float queries[][2] = {{0, 0}, {1, 1}, {0.95f, 0.05f}, {-3, 7}};
    for (const auto& q : queries) {
      CAPTURE(q[0], q[1]);
      for (std::size_t k : {1, 2, 3}) {
        const auto got = tree.knn(q, k);
        CHECK(first_difference(got, kdspace::brute_force_knn<kdspace::L2>(pts, 3, 2, q, k)) == "");
      }
      CHECK(tree.radius(q, 1.f) == kdspace::brute_force_radius<kdspace::L2>(pts, 3, 2, q, 1.f));
    }
  }
}

// ---- radius ---------------------------------------------------------------------------------------

TEST_CASE(
    "exact: radius search matches brute force bit for bit for every metric, precision and split rule, "
    "radius 0 and caps on the count included",
    "[points][exact]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 32, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid,
                               Shape::identical, Shape::flat, Shape::sorted_x);
  const Case c{shape, 500, dim, 10000 + static_cast<std::uint32_t>(dim)};
  Mismatches bad;
  SECTION("float, L2") {
    radius_matches_brute_force<float, kdspace::L2>(c, fewer_split_rules(), 4, bad);
  }
  SECTION("double, L2") {
    radius_matches_brute_force<double, kdspace::L2>(c, fewer_split_rules(), 4, bad);
  }
  SECTION("float, L1") {
    radius_matches_brute_force<float, kdspace::L1>(c, fewer_split_rules(), 4, bad);
  }
  SECTION("double, Linf") {
    radius_matches_brute_force<double, kdspace::Linf>(c, fewer_split_rules(), 4, bad);
  }
  bad.done();
}

TEST_CASE("exact: the radius is a true distance, and a point exactly at distance r is inside",
          "[points][exact]") {
  // Every coordinate and distance here is exact in binary: (1, 0) at 1, (3, 4) at 5 (L2), 7 (L1),
  // 4 (Linf) from the origin; (13, 24) at 5 from (10, 20); (1, 1, 1, 1) at 2 from the 4-D origin.
  const double pts2[] = {1, 0, 3, 4, 13, 24, 0.5, 0.5, -6, 0};
  SECTION("float, L2") {
    std::vector<float> p(std::begin(pts2), std::end(pts2));
    const PointTree<float> tree(p.data(), 5, 2);
    const float origin[2] = {0, 0}, q2[2] = {10, 20};
    const auto r1 = tree.radius(origin, 1.f);
    REQUIRE(r1.size() == 2);  // (0.5, 0.5) at 0.707 and (1, 0) at 1
    CHECK(r1[1].index == 0);
    CHECK(r1[1].distance == 1.f);
    const auto r5 = tree.radius(origin, 5.f);
    REQUIRE(r5.size() == 3);
    CHECK(r5[2].index == 1);
    CHECK(r5[2].distance == 5.f);
    CHECK(tree.radius(origin, std::nextafter(5.f, 0.f)).size() == 2);
    const auto around = tree.radius(q2, 5.f);
    REQUIRE(around.size() == 1);
    CHECK(around[0].index == 2);
    CHECK(around[0].distance == 5.f);
    // Not the squared radius: radius 6 reaches (-6, 0) at 6, which a squared comparison (36) would too,
    // but radius 2 must not reach (3, 4) at 5 (its squared distance 25 > 4 > 2).
    CHECK(tree.radius(origin, 6.f).size() == 4);
    CHECK(tree.radius(origin, 2.f).size() == 2);
    CHECK(tree.radius(origin, 25.f).size() == 4);  // 25 is a distance, not a squared one: (13, 24) is at 27.3
  }
  SECTION("double, L2, compile-time dimension") {
    const PointTree<double, 2> tree(pts2, 5, 2);
    const double origin[2] = {0, 0};
    const auto r5 = tree.radius(origin, 5.0);
    REQUIRE(r5.size() == 3);
    CHECK(r5[2].index == 1);
    CHECK(r5[2].distance == 5.0);
    CHECK(tree.radius(origin, 1.0).size() == 2);
  }
  SECTION("float, L1") {
    std::vector<float> p(std::begin(pts2), std::end(pts2));
    const PointTree<float, kdspace::Dynamic, kdspace::L1> tree(p.data(), 5, 2);
    const float origin[2] = {0, 0};
    const auto r7 = tree.radius(origin, 7.f);
    REQUIRE(r7.size() == 4);  // (0.5, 0.5) at 1, (1, 0) at 1, (-6, 0) at 6, (3, 4) at 7
    CHECK(r7[3].index == 1);
    CHECK(r7[3].distance == 7.f);
    CHECK(tree.radius(origin, std::nextafter(7.f, 0.f)).size() == 3);
  }
  SECTION("double, Linf") {
    const PointTree<double, kdspace::Dynamic, kdspace::Linf> tree(pts2, 5, 2);
    const double origin[2] = {0, 0};
    const auto r4 = tree.radius(origin, 4.0);
    REQUIRE(r4.size() == 3);  // (0.5, 0.5) at 0.5, (1, 0) at 1, (3, 4) at 4
    CHECK(r4[2].index == 1);
    CHECK(r4[2].distance == 4.0);
  }
  SECTION("float, L2, 4-D") {
    const float p4[] = {1, 1, 1, 1, 0, 0, 0, 3};
    const PointTree<float> tree(p4, 2, 4);
    const float origin[4] = {0, 0, 0, 0};
    const auto r2 = tree.radius(origin, 2.f);
    REQUIRE(r2.size() == 1);
    CHECK(r2[0].index == 0);
    CHECK(r2[0].distance == 2.f);
  }
}

// ---- box ------------------------------------------------------------------------------------------

TEST_CASE(
    "exact: box search returns exactly the points in the closed box, degenerate and infinite boxes included",
    "[points][exact]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 4, 8, 16, 32, 64, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid,
                               Shape::identical, Shape::flat, Shape::sorted_x);
  Mismatches bad;
  const Case c{shape, std::min<std::size_t>(size_for(dim), 1000), dim,
               11000 + static_cast<std::uint32_t>(dim)};
  box_matches_brute_force<float>(c, every_split_rule(), 24, bad);
  box_matches_brute_force<double>(c, fewer_split_rules(), 12, bad);
  if (dim == 3) box_matches_brute_force<float, 3>(c, fewer_split_rules(), 12, bad);
  bad.done();
}

// ---- approximate search ---------------------------------------------------------------------------

TEST_CASE(
    "exact: approximate knn with eps 0.1, 0.5 and 2 stays within (1 + eps) of the true distance at every "
    "rank",
    "[points][exact][approximate]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 2, 3, 8, 32, 128);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::grid);
  const Case c{shape, std::min<std::size_t>(size_for(dim), 1000), dim,
               12000 + static_cast<std::uint32_t>(dim)};
  Mismatches bad;
  SECTION("float, L2") {
    approximate_within_bound<float, kdspace::L2>(c, fewer_split_rules(), 5, bad);
  }
  SECTION("double, L1") {
    approximate_within_bound<double, kdspace::L1>(c, fewer_split_rules(), 5, bad);
  }
  SECTION("float, Linf") {
    approximate_within_bound<float, kdspace::Linf>(c, fewer_split_rules(), 5, bad);
  }
  bad.done();
}

TEST_CASE(
    "exact: knn with a small max_checks still returns k sorted distinct neighbours at their true distances",
    "[points][exact][approximate]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 2, 3, 8, 32);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates);
  const Case c{shape, 2000, dim, 13000 + static_cast<std::uint32_t>(dim)};
  const auto pts = make_points<float>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<float>(c.shape, pts, c.n, c.dim, 10, c.seed + 1);
  Mismatches bad;
  for (const BuildParams& params : fewer_split_rules()) {
    const PointTree<float> tree(pts.data(), c.n, c.dim, params);
    for (std::size_t max_checks : {1, 3, 20}) {
      SearchParams sp;
      sp.max_checks = max_checks;
      for (std::size_t q = 0; q < queries.size(); ++q)
        for (std::size_t k : {1, 5, 10, 100}) {
          const auto got = tree.knn(queries.row(q), k, sp);
          std::string problem = order_problem(got);
          if (got.size() != k) problem = join(problem, "got " + std::to_string(got.size()) + " results");
          for (const auto& nb : got)
            if (nb.index >= c.n || nb.distance != true_distance<kdspace::L2>(
                                                      queries.row(q), pts.data() + nb.index * c.dim, c.dim)) {
              problem = join(problem, show(nb) + " is not a point at its true distance");
              break;
            }
          bad.check(problem, [&] {
            return describe<float, kdspace::L2>(c) + " " + describe(params) + " " +
                   describe_query(queries, q) + " k=" + std::to_string(k) +
                   " max_checks=" + std::to_string(max_checks);
          });
        }
    }
  }
  bad.done();
}

TEST_CASE("exact: knn with max_checks at least n is exact", "[points][exact][approximate]") {
  const Case c{Shape::clustered, 2000, 8, 13500};
  const auto pts = make_points<float>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<float>(c.shape, pts, c.n, c.dim, 10, c.seed + 1);
  Mismatches bad;
  for (const BuildParams& params : fewer_split_rules()) {
    const PointTree<float> tree(pts.data(), c.n, c.dim, params);
    SearchParams sp;
    sp.max_checks = c.n;
    for (std::size_t q = 0; q < queries.size(); ++q)
      for (std::size_t k : {1, 10, 100}) {
        const auto want = kdspace::brute_force_knn<kdspace::L2>(pts.data(), c.n, c.dim, queries.row(q), k);
        const auto got = tree.knn(queries.row(q), k, sp);
        bad.check(first_difference(got, want), differs_only_in_tie_order(got, want), [&] {
          return describe<float, kdspace::L2>(c) + " " + describe(params) + " " + describe_query(queries, q) +
                 " k=" + std::to_string(k);
        });
      }
  }
  bad.done();
}

// ---- batches --------------------------------------------------------------------------------------

namespace {

template <class T>
std::vector<Neighbor<T>> row_of(const kdspace::NeighborLists<T>& lists, std::size_t q) {
  const auto row = lists.row(q);
  return std::vector<Neighbor<T>>(row.begin(), row.end());
}

bool same_stats(const QueryStats& a, const QueryStats& b) {
  return a.queries == b.queries && a.nodes_visited == b.nodes_visited && a.points_visited == b.points_visited;
}

std::string show(const QueryStats& s) {
  return "{queries " + std::to_string(s.queries) + ", nodes " + std::to_string(s.nodes_visited) +
         ", points " + std::to_string(s.points_visited) + "}";
}

const char* name(kdspace::BatchMethod m) {
  switch (m) {
    case kdspace::BatchMethod::automatic:
      return "automatic";
    case kdspace::BatchMethod::tree:
      return "tree";
    case kdspace::BatchMethod::scan:
      return "scan";
  }
  return "?";
}

/// knn_batch(params) on `threads` threads == knn(params) query by query: the rows for every batch
/// method, and the summed stats where the batch uses the tree as knn does (method tree).
template <class T>
void batch_knn_matches_single(const PointTree<T>& tree, const Queries<T>& queries, std::size_t k,
                              SearchParams sp, const std::string& context, Mismatches& bad) {
  std::vector<std::vector<Neighbor<T>>> single;
  QueryStats single_stats;
  for (std::size_t q = 0; q < queries.size(); ++q)
    single.push_back(tree.knn(queries.row(q), k, sp, &single_stats));
  for (const auto method : {kdspace::BatchMethod::tree, kdspace::BatchMethod::automatic, kdspace::BatchMethod::scan})
  for (unsigned threads : {1u, 2u, 4u}) {
    sp.batch_method = method;
    QueryStats batch_stats;
    const auto batch = tree.knn_batch(queries.coords.data(), queries.size(), k, sp, threads, &batch_stats);
    auto where = [&] {
      return context + " k=" + std::to_string(k) + " eps=" + std::to_string(sp.eps) +
             " max_checks=" + std::to_string(sp.max_checks) + " threads=" + std::to_string(threads) +
             " batch_method=" + name(method);
    };
    bad.check(batch.rows() == queries.size() ? "" : "wrong number of rows", where);
    if (batch.rows() != queries.size()) continue;
    for (std::size_t q = 0; q < queries.size(); ++q)
      bad.check(first_difference(row_of(batch, q), single[q]), [&] {
        return where() + " " + describe_query(queries, q) + " (expected: the single-query answer)";
      });
    if (method == kdspace::BatchMethod::tree)
      bad.check(same_stats(batch_stats, single_stats)
                    ? ""
                    : "batch stats " + show(batch_stats) + " differ from the summed single-query stats " +
                          show(single_stats),
                where);
  }
}

}  // namespace

TEST_CASE("exact: knn_batch and radius_batch on 1, 2 and 4 threads give the single-query answers and stats",
          "[points][exact][threads]") {
  const std::size_t dim = GENERATE(as<std::size_t>{}, 3, 16);
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates);
  const Case c{shape, 3000, dim, 14000 + static_cast<std::uint32_t>(dim)};
  const auto pts = make_points<float>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<float>(c.shape, pts, c.n, c.dim, 300, c.seed + 1);
  BuildParams params;
  params.position = PositionRule::sliding_midpoint;
  params.leaf_size = 4;
  const PointTree<float> tree(pts.data(), c.n, c.dim, params);
  const std::string context = describe<float, kdspace::L2>(c) + " " + describe(params);
  Mismatches bad;
  for (std::size_t k : {1, 10, 100}) {
    batch_knn_matches_single(tree, queries, k, SearchParams{}, context, bad);
    SearchParams approximate;
    approximate.eps = 0.5;
    batch_knn_matches_single(tree, queries, k, approximate, context, bad);
  }
  for (float r : {0.f, 0.3f, 2.f}) {
    for (std::size_t cap : {std::size_t{5}, std::numeric_limits<std::size_t>::max()}) {
      std::vector<std::vector<Neighbor<float>>> single;
      QueryStats single_stats;
      for (std::size_t q = 0; q < queries.size(); ++q)
        single.push_back(tree.radius(queries.row(q), r, cap, &single_stats));
      for (unsigned threads : {1u, 2u, 4u}) {
        QueryStats batch_stats;
        const auto batch =
            tree.radius_batch(queries.coords.data(), queries.size(), r, cap, threads, &batch_stats);
        auto where = [&] {
          return context + " radius=" + std::to_string(r) + " max_results=" + std::to_string(cap) +
                 " threads=" + std::to_string(threads);
        };
        REQUIRE(batch.rows() == queries.size());
        for (std::size_t q = 0; q < queries.size(); ++q)
          bad.check(first_difference(row_of(batch, q), single[q]),
                    [&] { return where() + " " + describe_query(queries, q); });
        bad.check(same_stats(batch_stats, single_stats)
                      ? ""
                      : "batch stats " + show(batch_stats) + " != " + show(single_stats),
                  where);
      }
    }
  }
  bad.done();
}

TEST_CASE("exact: knn_batch beyond 8-D, its queries reordered by leaf, gives the single-query answers",
          "[points][exact][threads]") {
  // Beyond 8-D (where batches are not put in Z-order) a batch of 256 queries or more visits them in
  // the order of the leaves their descents reach, whatever the tree's size.
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::flat);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 9, 13, 20);
  const Case c{shape, 3000, dim, 14700 + static_cast<std::uint32_t>(dim)};
  const auto pts = make_points<float>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<float>(c.shape, pts, c.n, c.dim, 300, c.seed + 1);
  const PointTree<float> tree(pts.data(), c.n, c.dim);
  Mismatches bad;
  for (std::size_t k : {1, 10})
    batch_knn_matches_single(tree, queries, k, SearchParams{}, describe<float, kdspace::L2>(c), bad);
  bad.done();
}

TEST_CASE("exact: knn_batch with max_checks answers each query as knn with the same max_checks does",
          "[points][exact][threads][approximate]") {
  const Case c{Shape::uniform, 3000, 3, 14500};
  const auto pts = make_points<float>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<float>(c.shape, pts, c.n, c.dim, 300, c.seed + 1);
  BuildParams params;
  params.leaf_size = 4;
  const PointTree<float> tree(pts.data(), c.n, c.dim, params);
  Mismatches bad;
  SearchParams sp;
  sp.max_checks = 50;
  batch_knn_matches_single(tree, queries, 5, sp, describe<float, kdspace::L2>(c) + " " + describe(params),
                           bad);
  bad.done();
}

// ---- statistics -----------------------------------------------------------------------------------

TEST_CASE("exact: query statistics are positive and bounded by the tree's nodes and points",
          "[points][exact]") {
  const Shape shape = GENERATE(Shape::uniform, Shape::clustered, Shape::duplicates, Shape::identical);
  const std::size_t dim = GENERATE(as<std::size_t>{}, 1, 3, 16);
  const Case c{shape, 2000, dim, 15000 + static_cast<std::uint32_t>(dim)};
  const auto pts = make_points<float>(c.shape, c.n, c.dim, c.seed);
  const auto queries = make_queries<float>(c.shape, pts, c.n, c.dim, 20, c.seed + 1);
  for (const BuildParams& params : fewer_split_rules()) {
    const PointTree<float> tree(pts.data(), c.n, c.dim, params);
    INFO((describe<float, kdspace::L2>(c)) << " " << describe(params) << " node_count=" << tree.node_count());
    REQUIRE(tree.node_count() >= 1);
    REQUIRE(tree.leaf_count() >= 1);
    REQUIRE(tree.leaf_count() <= tree.node_count());
    QueryStats knn_stats, radius_stats, box_stats;
    for (std::size_t q = 0; q < queries.size(); ++q) {
      QueryStats one;
      tree.knn(queries.row(q), 10, {}, &one);
      INFO(describe_query(queries, q) << " knn stats " << show(one));
      CHECK(one.queries == 1);
      CHECK(one.nodes_visited >= 1);
      CHECK(one.points_visited >= 1);
      CHECK(one.nodes_visited <= tree.node_count());
      CHECK(one.points_visited <= c.n);
      knn_stats += one;
      tree.radius(queries.row(q), 0.5f, std::numeric_limits<std::size_t>::max(), &radius_stats);
      const auto lo = std::vector<float>(queries.row(q), queries.row(q) + c.dim);
      auto hi = lo;
      for (auto& v : hi) v += 0.5f;
      tree.box(lo.data(), hi.data(), &box_stats);
    }
    const std::uint64_t nq = queries.size();
    INFO("knn " << show(knn_stats) << " radius " << show(radius_stats) << " box " << show(box_stats));
    CHECK(knn_stats.queries == nq);
    CHECK(knn_stats.nodes_visited >= nq);
    CHECK(knn_stats.nodes_visited <= tree.node_count() * nq);
    CHECK(knn_stats.points_visited >= nq);
    CHECK(knn_stats.points_visited <= c.n * nq);
    CHECK(radius_stats.queries == nq);
    CHECK(radius_stats.nodes_visited <= tree.node_count() * nq);
    CHECK(radius_stats.points_visited <= c.n * nq);
    CHECK(box_stats.queries == nq);
    CHECK(box_stats.nodes_visited >= nq);
    CHECK(box_stats.nodes_visited <= tree.node_count() * nq);
    CHECK(box_stats.points_visited <= c.n * nq);
  }
}

// ---- many identical points ------------------------------------------------------------------------

TEST_CASE("exact: a million identical 3-D points build quickly and answer knn with indices 0 .. k-1",
          "[points][exact]") {
  const std::size_t n = 1000000;
  const float p[3] = {0.25f, -1.5f, 3.0f};
  std::vector<float> pts(n * 3);
  for (std::size_t i = 0; i < n; ++i) std::copy_n(p, 3, pts.data() + i * 3);
  const auto start = std::chrono::steady_clock::now();
  const PointTree<float, 3> tree(pts.data(), n, 3);
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  INFO("build took " << build_s << " s; nodes " << tree.node_count() << ", depth " << tree.depth());
  CHECK(build_s < 5.0);
  CHECK(tree.size() == n);
  const float queries[3][3] = {{0.25f, -1.5f, 3.0f}, {1.25f, -1.5f, 3.0f}, {-100.f, 40.f, 7.f}};
  for (const auto& q : queries) {
    const float d = true_distance<kdspace::L2>(q, p, 3);
    for (std::size_t k : {1, 10, 1000}) {
      CAPTURE(q[0], q[1], q[2], k);
      QueryStats stats;
      const auto got = tree.knn(q, k, {}, &stats);
      REQUIRE(got.size() == k);
      for (std::size_t i = 0; i < k; ++i) {
        CAPTURE(i);
        REQUIRE(got[i].index == i);
        REQUIRE(got[i].distance == d);
      }
      CHECK(stats.points_visited < 100);  // one distance serves a whole run of identical points
    }
    const auto capped = tree.radius(q, d, 10);
    REQUIRE(capped.size() == 10);
    CHECK(capped.back().index == 9);
  }
  const float lo[3] = {0.25f, -1.5f, 3.0f};
  const auto inside = tree.box(lo, lo);
  REQUIRE(inside.size() == n);
  CHECK(inside.front() == 0);
  CHECK(inside.back() == n - 1);
  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  INFO("build and queries took " << total_s << " s");
  CHECK(total_s < 10.0);
}

// ---- bad input ------------------------------------------------------------------------------------

TEST_CASE("exact: bad input throws kdspace::Error with a message naming the problem",
          "[points][exact][errors]") {
  using Catch::Matchers::Contains;
  const auto pts = make_points<float>(Shape::uniform, 10, 3, 16000);
  const PointTree<float> tree(pts.data(), 10, 3);
  const float q[3] = {0, 0, 0};
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();

  SECTION("no points") {
    CHECK_THAT(error_message([&] { PointTree<float>(pts.data(), 0, 3); }), Contains("no points"));
  }
  SECTION("dimension 0") {
    CHECK_THAT(error_message([&] { PointTree<float>(pts.data(), 10, 0); }), Contains("dimension 0"));
  }
  SECTION("a NaN coordinate names the row and the coordinate") {
    auto bad = pts;
    bad[2 * 3 + 1] = nan;  // third row, second coordinate
    const std::string what = error_message([&] { PointTree<float>(bad.data(), 10, 3); });
    CHECK_THAT(what, Contains("row 3") && Contains("coordinate 2") && Contains("not finite"));
    CHECK_THAT(error_message([&] {
                 PointTree<double, kdspace::Dynamic, kdspace::L1>(
                     std::vector<double>(bad.begin(), bad.end()).data(), 10, 3);
               }),
               Contains("row 3") && Contains("coordinate 2"));
  }
  SECTION("an infinite coordinate names the row and the coordinate") {
    auto bad = pts;
    bad[2 * 3 + 0] = -inf;
    CHECK_THAT(error_message([&] { PointTree<float>(bad.data(), 10, 3); }),
               Contains("row 3") && Contains("coordinate 1") && Contains("inf"));
  }
  SECTION("k = 0 and k > n") {
    CHECK_THAT(error_message([&] { tree.knn(q, 0); }), Contains("k") && Contains("at least 1"));
    CHECK_THAT(error_message([&] { tree.knn(q, 11); }), Contains("11") && Contains("10"));
    CHECK_THAT(error_message([&] { tree.knn_batch(q, 1, 0); }), Contains("k"));
    CHECK_THAT(error_message([&] { tree.knn_batch(q, 1, 11); }), Contains("11") && Contains("10"));
  }
  SECTION("a negative or NaN radius") {
    CHECK_THAT(error_message([&] { tree.radius(q, -1.f); }), Contains("radius") && Contains("-1"));
    CHECK_THAT(error_message([&] { tree.radius(q, nan); }), Contains("radius") && Contains("nan"));
    CHECK_THAT(error_message([&] { tree.radius_batch(q, 1, -0.5f); }), Contains("radius"));
  }
  SECTION("a NaN or infinite query coordinate") {
    const float bad_q[3] = {0, nan, 0};
    CHECK_THAT(error_message([&] { tree.knn(bad_q, 1); }), Contains("query") && Contains("coordinate 2"));
    CHECK_THAT(error_message([&] { tree.radius(bad_q, 1.f); }),
               Contains("query") && Contains("coordinate 2"));
    const float inf_q[3] = {0, 0, inf};
    CHECK_THAT(error_message([&] { tree.knn(inf_q, 1); }),
               Contains("coordinate 3") && Contains("not finite"));
    const float two[6] = {0, 0, 0, 0, nan, 0};
    CHECK_THAT(error_message([&] { tree.knn_batch(two, 2, 1); }),
               Contains("query row 2") && Contains("coordinate 2"));
    CHECK_THAT(error_message([&] { tree.radius_batch(two, 2, 1.f); }), Contains("query row 2"));
    CHECK_THAT(error_message([&] { tree.box(bad_q, q); }), Contains("box") && Contains("coordinate 2"));
  }
  SECTION("a box with lo > hi") {
    const float lo[3] = {0, 2, 0}, hi[3] = {1, 1, 1};
    CHECK_THAT(error_message([&] { tree.box(lo, hi); }),
               Contains("box") && Contains("coordinate 2") && Contains("2.0") && Contains("1.0"));
  }
  SECTION("eps < 0, NaN eps and max_checks = 0") {
    SearchParams negative;
    negative.eps = -0.1;
    CHECK_THAT(error_message([&] { tree.knn(q, 1, negative); }), Contains("eps"));
    SearchParams not_a_number;
    not_a_number.eps = std::numeric_limits<double>::quiet_NaN();
    CHECK_THAT(error_message([&] { tree.knn(q, 1, not_a_number); }), Contains("eps"));
    SearchParams no_checks;
    no_checks.max_checks = 0;
    CHECK_THAT(error_message([&] { tree.knn(q, 1, no_checks); }), Contains("max_checks"));
    CHECK_THAT(error_message([&] { tree.knn_batch(q, 1, 1, no_checks); }), Contains("max_checks"));
  }
  SECTION("leaf_size = 0 and max_depth beyond 256") {
    BuildParams no_leaf;
    no_leaf.leaf_size = 0;
    CHECK_THAT(error_message([&] { PointTree<float>(pts.data(), 10, 3, no_leaf); }), Contains("leaf_size"));
    BuildParams too_deep;
    too_deep.max_depth = 300;
    CHECK_THAT(error_message([&] { PointTree<float>(pts.data(), 10, 3, too_deep); }), Contains("max_depth"));
  }
  SECTION("a fixed-dimension tree given points of another dimension") {
    CHECK_THAT(error_message([&] { PointTree<float, 3>(pts.data(), 15, 2); }),
               Contains("dimension 2") && Contains("3"));
    CHECK_THAT(error_message([&] { PointTree<double, 2>(std::vector<double>(30, 1.0).data(), 10, 3); }),
               Contains("dimension 3") && Contains("2"));
  }
  SECTION("the matrix constructor checks like the pointer constructor") {
    TinyMatrix m{4, 3, false, std::vector<double>(12, 1.0)};
    m.v[2 * 3 + 1] = std::numeric_limits<double>::quiet_NaN();
    CHECK_THAT(error_message([&] { PointTree<float>{m}; }), Contains("row 3") && Contains("coordinate 2"));
    const TinyMatrix empty{0, 3, false, {}};
    CHECK_THAT(error_message([&] { PointTree<float>{empty}; }), Contains("no points"));
    const TinyMatrix wrong{2, 4, false, std::vector<double>(8, 0.0)};
    CHECK_THAT(error_message([&] { PointTree<float, 3>{wrong}; }), Contains("dimension 4"));
  }
  SECTION("brute force rejects k out of range too") {
    CHECK_THAT(
        error_message([&] { kdspace::brute_force_knn<kdspace::L2>(pts.data(), 10, 3, q, std::size_t{0}); }),
        Contains("k"));
  }
  SECTION("every failure is a kdspace::Error") {
    CHECK_THROWS_AS(tree.knn(q, 0), kdspace::Error);
    CHECK_THROWS_AS(tree.radius(q, -1.f), kdspace::Error);
    CHECK_THROWS_AS(PointTree<float>(pts.data(), 0, 3), kdspace::Error);
  }
}

// ---- the matrix constructor -----------------------------------------------------------------------

TEST_CASE(
    "exact: the matrix constructor builds the tree the row-pointer constructor builds, in either storage "
    "order",
    "[points][exact]") {
  const std::size_t n = 500, dim = 5;
  const auto pts = make_points<double>(Shape::clustered, n, dim, 17000);
  TinyMatrix row_major{static_cast<long>(n), static_cast<long>(dim), false, pts};
  TinyMatrix col_major{static_cast<long>(n), static_cast<long>(dim), true, std::vector<double>(n * dim)};
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a) col_major.v[a * n + i] = pts[i * dim + a];
  std::vector<float> as_float(pts.begin(), pts.end());
  const auto queries = make_queries<float>(Shape::clustered, as_float, n, dim, 20, 17001);
  const PointTree<float> from_rows(as_float.data(), n, dim);
  for (const TinyMatrix* m : {&row_major, &col_major}) {
    INFO((m->column_major ? "column-major" : "row-major"));
    const PointTree<float> from_matrix(*m);
    REQUIRE(from_matrix.size() == n);
    REQUIRE(from_matrix.dim() == dim);
    REQUIRE(from_matrix.node_count() == from_rows.node_count());
    for (std::size_t q = 0; q < queries.size(); ++q) {
      CAPTURE(q);
      CHECK(from_matrix.knn(queries.row(q), 7) == from_rows.knn(queries.row(q), 7));
    }
  }
  const PointTree<double> from_double_matrix(row_major);
  const std::vector<double> q0(queries.row(0), queries.row(0) + dim);
  CHECK(from_double_matrix.knn(q0.data(), 5) ==
        kdspace::brute_force_knn<kdspace::L2>(pts.data(), n, dim, q0.data(), std::size_t{5}));
}
