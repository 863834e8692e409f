// The point-search step of `kdspace demo`: three generated data sets (uniform 3-D, clustered 16-D,
// clustered 128-D), a PointTree on each, exact 10-NN and radius batches timed on one thread and on
// all, and the answers of a sample of queries compared bit for bit with brute force.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "demo.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/point_tree.hpp"
#include "progress.hpp"

namespace kdspace::cli::demo {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::uint64_t seed = 20240601;
constexpr std::size_t k = 10;
constexpr std::size_t checked_queries = 200;  // queries compared with brute force, per data set

/// splitmix64 and hand-made distributions, so that the data are the same with every compiler and
/// standard library (std::normal_distribution is not specified bit for bit).
class Random {
 public:
  explicit Random(std::uint64_t s) : state_(s) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1).
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  /// Standard normal (Box-Muller).
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double u1 = 1.0 - uniform(), u2 = uniform();  // u1 in (0, 1]
    const double radius = std::sqrt(-2.0 * std::log(u1)), angle = 6.283185307179586 * u2;
    spare_ = radius * std::sin(angle);
    has_spare_ = true;
    return radius * std::cos(angle);
  }
  std::size_t below(std::size_t n) { return static_cast<std::size_t>(uniform() * static_cast<double>(n)); }

 private:
  std::uint64_t state_;
  double spare_ = 0;
  bool has_spare_ = false;
};

struct Recipe {
  const char* name;   ///< file names: NAME_base.fvecs, NAME_query.fvecs
  const char* title;  ///< in the table
  std::size_t n, dim, queries;
  std::size_t blobs;  ///< 0: uniform in the unit cube; else Gaussian blobs
};

// The full sizes; --quick takes a tenth of n and of the queries.
const Recipe recipes[] = {
    {"uniform-3d", "uniform 3-D", 1000000, 3, 10000, 0},
    {"blobs-16d", "Gaussian blobs 16-D", 100000, 16, 10000, 64},
    {"blobs-128d", "Gaussian blobs 128-D", 20000, 128, 10000, 100},
};

struct DataSet {
  io::Matrix<float> base, queries;
};

io::Matrix<float> make_matrix(std::size_t rows, std::size_t cols) {
  io::Matrix<float> m;
  m.rows = rows;
  m.cols = cols;
  m.data.resize(rows * cols);
  return m;
}

// Blobs: centres uniform in [0, 100)^dim, each with its own spread (sigma 1..5); a point is a
// random centre plus Gaussian noise. Base and queries come from the same blobs.
DataSet generate(const Recipe& r, std::size_t n, std::size_t nq, std::uint64_t set_seed) {
  DataSet d{make_matrix(n, r.dim), make_matrix(nq, r.dim)};
  Random shape(set_seed);
  std::vector<double> centres(r.blobs * r.dim), sigmas(r.blobs);
  for (double& c : centres) c = 100.0 * shape.uniform();
  for (double& s : sigmas) s = 1.0 + 4.0 * shape.uniform();
  auto fill = [&](io::Matrix<float>& m, std::uint64_t stream) {
    Random rng(set_seed * 1000003u + stream);
    for (std::size_t i = 0; i < m.rows; ++i) {
      float* row = m.row(i);
      if (r.blobs == 0) {
        for (std::size_t a = 0; a < r.dim; ++a) row[a] = static_cast<float>(rng.uniform());
      } else {
        const std::size_t b = rng.below(r.blobs);
        for (std::size_t a = 0; a < r.dim; ++a)
          row[a] = static_cast<float>(centres[b * r.dim + a] + sigmas[b] * rng.normal());
      }
    }
  };
  fill(d.base, 1);
  fill(d.queries, 2);
  return d;
}

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// Queries a second of the batch `run`, the best of a few runs (up to 5, while they take under
/// 0.3 s together), so that short batches are not measured by their first, cold run alone.
template <class Run>
double queries_per_second(std::size_t queries, Run&& run) {
  double best = std::numeric_limits<double>::infinity(), total = 0;
  for (int i = 0; i < 5 && total < 0.3; ++i) {
    const auto start = Clock::now();
    run();
    const double t = seconds_since(start);
    best = std::min(best, t);
    total += t;
  }
  return static_cast<double>(queries) / best;
}


// Whether a row of the tree equals the brute-force answer, value for value: same indices, same
// distances, same order.
template <class Row>
bool row_equals(const Row& row, const std::vector<Neighbor<float>>& expected) {
  return row.size() == expected.size() && std::equal(row.begin(), row.end(), expected.begin());
}

struct Result {
  double build_s = 0, knn_one_qps = 0, knn_all_qps = 0, radius_qps = 0, radius = 0, mean_radius_hits = 0;
  bool exact = true;
};

Result run_data_set(Context& context, const Recipe& r, std::uint64_t set_seed) {
  const Settings& s = context.settings;
  const std::size_t n = s.quick ? r.n / 10 : r.n, nq = s.quick ? r.queries / 10 : r.queries;
  Progress progress(std::string("demo: ") + r.title, Progress::Kind::elapsed);
  const DataSet d = generate(r, n, nq, set_seed);
  if (!s.out_dir.empty()) {
    for (const auto& [suffix, m] :
         {std::pair{"_base.fvecs", &d.base}, std::pair{"_query.fvecs", &d.queries}}) {
      const std::string path = context.out_path(std::string(r.name) + suffix);
      io::write_points(path, *m);
      context.wrote(path);
    }
  }
  const float* q = d.queries.data.data();
  Result out;

  auto start = Clock::now();
  const PointTree<float> tree(d.base.data.data(), n, r.dim, BuildParams{});
  out.build_s = seconds_since(start);

  NeighborLists<float> one, all, within;
  out.knn_one_qps = queries_per_second(nq, [&] { one = tree.knn_batch(q, nq, k, {}, 1); });
  out.knn_all_qps = queries_per_second(nq, [&] { all = tree.knn_batch(q, nq, k, {}, s.threads); });

  // The radius: the median distance of the k-th neighbour, so that a typical query finds about k.
  std::vector<float> kth(nq);
  for (std::size_t i = 0; i < nq; ++i) kth[i] = all.row(i)[k - 1].distance;
  std::nth_element(kth.begin(), kth.begin() + static_cast<std::ptrdiff_t>(nq / 2), kth.end());
  const float radius = kth[nq / 2];
  out.radius_qps = queries_per_second(nq, [&] {
    within = tree.radius_batch(q, nq, radius, std::numeric_limits<std::size_t>::max(), s.threads);
  });
  out.radius = radius;
  out.mean_radius_hits = static_cast<double>(within.neighbors.size()) / static_cast<double>(nq);

  // Checks: one thread = all threads for every query; a sample equals brute force bit for bit.
  if (one.offsets != all.offsets || !(one.neighbors == all.neighbors)) {
    out.exact = false;
    context.fail(std::string(r.title) + ": k-NN on one thread differs from k-NN on all threads");
  }
  const std::size_t sample = std::min(checked_queries, nq);
  std::vector<char> knn_ok(sample, 0), radius_ok(sample, 0);
  detail::parallel_for(sample, s.threads, 4, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t j = begin; j < end; ++j) {
      const std::size_t qi = j * nq / sample;
      const float* query = q + qi * r.dim;
      knn_ok[j] = row_equals(all.row(qi), brute_force_knn<L2>(d.base.data.data(), n, r.dim, query, k));
      radius_ok[j] =
          row_equals(within.row(qi), brute_force_radius<L2>(d.base.data.data(), n, r.dim, query, radius));
    }
  });
  for (std::size_t j = 0; j < sample; ++j) {
    const std::string where = std::string(r.title) + ": query " + std::to_string(j * nq / sample + 1) + ": ";
    if (!knn_ok[j]) context.fail(where + "10-NN differs from brute_force_knn");
    if (!radius_ok[j]) context.fail(where + "radius search differs from brute_force_radius");
    out.exact = out.exact && knn_ok[j] && radius_ok[j];
  }
  return out;
}

}  // namespace

void point_search_step(Context& context) {
  const Settings& s = context.settings;
  const unsigned threads = detail::resolve_threads(s.threads);
  const std::string all_label = s.threads == 0 ? "all threads" : std::to_string(threads) + " threads";
  context.report(
      "## Exact search with PointTree\n\n| dataset | n | dim | build s | knn q/s (1 thread) | knn q/s (" +
      all_label + ") | radius q/s | exact |\n|---|---:|---:|---:|---:|---:|---:|:---:|\n");
  std::string notes;
  std::size_t queries = 0;
  for (std::size_t i = 0; i < std::size(recipes); ++i) {
    const Recipe& r = recipes[i];
    const Result res = run_data_set(context, r, seed + i);
    const std::size_t n = s.quick ? r.n / 10 : r.n;
    queries = s.quick ? r.queries / 10 : r.queries;
    context.report("| " + std::string(r.title) + " | " + with_commas(static_cast<double>(n)) + " | " +
                   std::to_string(r.dim) + " | " + fixed(res.build_s, 3) + " | " +
                   with_commas(res.knn_one_qps) + " | " + with_commas(res.knn_all_qps) + " | " +
                   with_commas(res.radius_qps) + " | " + (res.exact ? "yes" : "no") + " |\n");
    notes += "- " + std::string(r.title) + ": radius " + fixed(res.radius, 4) + ", " +
             fixed(res.mean_radius_hits, 1) + " points a query on average\n";
  }
  const std::string n_queries = std::to_string(queries);
  context.report("\n" + n_queries + " queries a data set, from the distribution of its base; k = " +
                 std::to_string(k) + "; seed " + std::to_string(seed) +
                 (s.threads == 0 ? "; all threads = " + std::to_string(threads) : std::string()) + ".\n");
  context.report("Build: default BuildParams (one thread). Radius search on " + all_label +
                 ", the radius being the median distance of the 10th neighbour:\n" + notes);
  context.report("Exact: for " + std::to_string(checked_queries) +
                 " queries a data set, k-NN and radius results equal brute_force_knn and brute_force_radius "
                 "bit for bit (indices and distances, in the contract's order: distance (squared for L2), then index); "
                 "k-NN on one thread equals k-NN on " +
                 all_label + " for every query.\n\n");
}

}  // namespace kdspace::cli::demo
