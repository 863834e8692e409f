// `kdspace pairs` and `kdspace count`: the pairs of points within a distance, written to a .pairs
// file, and the number of pairs within each of many radii, printed as JSON. Both read one point set
// (pairs within it, each once) or two (--with: pairs across them), build a PointTree over each and
// run a dual-tree join (kdspace/joins/joins.hpp), in ordinary space or on a torus (--boxsize).
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "guard.hpp"
#include "json.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/pairs.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/joins/joins.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/point_tree.hpp"
#include "options.hpp"
#include "progress.hpp"

namespace kdspace::cli {
namespace {

using Clock = std::chrono::steady_clock;

enum class JoinMode { pairs, count };

const char* const pairs_usage =
    R"(usage: kdspace pairs --base A [--with B] -r R --out PAIRS.pairs [--metric l2|l1|linf]
                     [--boxsize L1,L2,...] [--threads T] [--stats]
Finds every pair of points within distance R (closed: a pair at exactly R is in).

  -r R                 a finite number >= 0 in the data's units (not squared)
  --out PAIRS.pairs    uint64 M (little-endian), then M pairs of uint32 (a, b), sorted by (a, b);
                       without --with: pairs of distinct points of A, a < b, each once;
                       with --with: a indexes A and b indexes B. Written to a temporary file and
                       renamed, so it is never left half-written.
  --distances D.npy    also the distance of each pair, in the same order (M x 1, float64 for a
                       double-precision input, else float32): a sparse distance matrix
)";

const char* const count_usage =
    R"(usage: kdspace count --base A [--with B] -r R1,R2,... [--metric l2|l1|linf]
                     [--boxsize L1,L2,...] [--threads T] [--stats]
Counts the pairs of points within each radius, in one pass, and prints one JSON object:
  {"radii": [R1, R2, ...], "counts": [C1, C2, ...]}
where Cj is the number of pairs (a, b) at distance <= Rj (without --with: unordered pairs of distinct
points of A; with --with: a from A, b from B). Radii in any order, as given.

  -r R1,R2,...         finite numbers >= 0, comma-separated, in the data's units (not squared)
  --stats              adds the figures of the run to the same JSON object
)";

const char* const shared_usage = R"(  --base A             the points; .fvecs .ivecs .bvecs .csv (optional header line) .npy, by extension.
                       A .csv or float64 .npy file is read in double precision, any other in float
                       (in double when either file is double).
  --with B             a second point set of the same dimension: pairs across A and B
  --metric l2|l1|linf  (default l2)
  --boxsize L1,L2,...  periodic boundaries: the box size of each axis (one value: every axis); the
                       distance along a periodic axis is min(|d|, L - |d|); points must lie in
                       [0, L) there; 0 leaves an axis not periodic (as SciPy's cKDTree boxsize)
  --threads T          0 (default) = all hardware threads; the output is the same on any number
  --stats              one JSON object on stdout: build_s, query_s, queries_per_s, threads, depth,
                       leaves, nodes_visited_per_query (node pairs per point of A),
                       points_visited_per_query (distances per point of A), ... (times without I/O)
Exit codes: 0 success, 2 usage error, 1 bad data or I/O error.
)";

struct JoinJob {
  JoinMode mode = JoinMode::pairs;
  std::string base, with, out, distances, metric = "l2";
  double radius = 0;
  std::vector<double> radii, boxsize;
  unsigned threads = 0;
  bool stats = false;
};

JoinJob parse_job(JoinMode mode, const std::vector<std::string>& args) {
  std::vector<OptionSpec> specs = {{"--base"},    {"--with"},    {"-r"},           {"--metric"},
                                   {"--boxsize"}, {"--threads"}, {"--stats", false}};
  if (mode == JoinMode::pairs) {
    specs.push_back({"--out"});
    specs.push_back({"--distances"});
  }
  const Options o(args, specs);
  JoinJob job;
  job.mode = mode;
  job.base = o.required("--base");
  job.with = o.text("--with");
  if (!o.has("-r")) throw UsageError("missing option -r");
  const double inf = std::numeric_limits<double>::infinity();
  if (mode == JoinMode::pairs) {
    job.radius = o.number("-r", 0, 0, inf);
    job.out = o.required("--out");
    require_extension("--out", job.out, ".pairs");
    job.distances = o.text("--distances");
    if (!job.distances.empty()) require_extension("--distances", job.distances, ".npy");
  } else {
    job.radii = o.numbers("-r", 0, inf);
  }
  job.metric = o.choice("--metric", "l2", {"l2", "l1", "linf"});
  job.boxsize = o.numbers("--boxsize", 0, inf);
  job.threads = static_cast<unsigned>(o.count("--threads", 0, 0, 4096));
  job.stats = o.has("--stats");
  return job;
}

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

bool starts_with(const std::string& s, const std::string& prefix) { return s.compare(0, prefix.size(), prefix) == 0; }

// A message about "row R" of a point set, in the file it came from.
Error in_file(const Error& e, const std::string& path) {
  const std::string what = e.what();
  return Error(starts_with(what, path + ":") ? what : path + ": " + what);
}

// Writes a file under a temporary name next to `path`, then renames it over `path`, so that it is
// never seen half-written.
template <class Write>
void write_then_rename(const std::string& path, Write&& write) {
  const std::size_t dot = path.find_last_of('.');  // the writer picks the format by the extension
  const std::string temp = path + ".tmp." + std::to_string(::getpid()) + (dot == std::string::npos ? "" : path.substr(dot));
  try {
    write(temp);
  } catch (...) {
    std::remove(temp.c_str());
    throw;
  }
  if (std::rename(temp.c_str(), path.c_str()) != 0) {
    const int error = errno;
    std::remove(temp.c_str());
    throw Error(path + ": cannot replace the file: " + std::strerror(error));
  }
}

// A radius as the points' type; beyond float's range it becomes +inf (every pair), never undefined.
template <class T>
T as_scalar(double r) {
  return r > static_cast<double>(std::numeric_limits<T>::max()) ? std::numeric_limits<T>::infinity() : static_cast<T>(r);
}

template <class T, class Metric>
PointTree<T, Dynamic, Metric> build(const io::Matrix<T>& points, const std::string& path, unsigned threads) {
  BuildParams params;
  params.threads = threads;
  try {
    return PointTree<T, Dynamic, Metric>(points.data.data(), points.rows, points.cols, params);
  } catch (const Error& e) {
    throw in_file(e, path);
  }
}

template <class T>
io::Matrix<T> read(const std::string& path) {
  Progress progress("reading " + path);
  return io::read_points<T>(path, progress.callback());
}

template <class T, class Metric>
int run_join(const JoinJob& job) {
  const bool two_sets = !job.with.empty();
  io::Matrix<T> a = read<T>(job.base);
  io::Matrix<T> b = two_sets ? read<T>(job.with) : io::Matrix<T>{};
  if (two_sets && b.cols != a.cols)
    throw Error(job.with + ": dimension " + std::to_string(b.cols) + " does not match " + job.base + " (dimension " +
                std::to_string(a.cols) + ")");
  JoinParams params;
  params.threads = job.threads;
  params.boxsize = job.boxsize;
  // The box size is checked before the builds, and the points against it with their file's name.
  const std::vector<T> period = detail::periods_from_boxsize<T>(job.boxsize, a.cols);
  try {
    detail::check_in_box(a.data.data(), a.rows, a.cols, period);
  } catch (const Error& e) {
    throw in_file(e, job.base);
  }
  try {
    detail::check_in_box(b.data.data(), b.rows, b.cols, period);
  } catch (const Error& e) {
    throw in_file(e, job.with);
  }

  Progress build_progress("building the trees", Progress::Kind::elapsed);
  Clock::time_point start = Clock::now();
  const PointTree<T, Dynamic, Metric> tree_a = build<T, Metric>(a, job.base, job.threads);
  std::optional<PointTree<T, Dynamic, Metric>> tree_b;
  if (two_sets) tree_b.emplace(build<T, Metric>(b, job.with, job.threads));
  const double build_s = seconds_since(start);
  build_progress.finish();
  const std::size_t points_a = a.rows, points_b = b.rows;
  a = {};
  b = {};

  JoinStats stats;
  JsonObject json;
  Progress join_progress(job.mode == JoinMode::pairs ? "finding pairs" : "counting pairs", Progress::Kind::elapsed);
  start = Clock::now();
  double query_s = 0;
  if (job.mode == JoinMode::pairs) {
    const T r = as_scalar<T>(job.radius);
    std::vector<IndexPair> pairs;
    io::Matrix<T> distances;
    if (job.distances.empty()) {
      pairs = two_sets ? pairs_within(tree_a, *tree_b, r, params, &stats) : pairs_within(tree_a, r, params, &stats);
    } else {
      const std::vector<PairDistance<T>> entries =
          two_sets ? distances_within(tree_a, *tree_b, r, params, &stats) : distances_within(tree_a, r, params, &stats);
      pairs.reserve(entries.size());
      distances = io::Matrix<T>{entries.size(), 1, {}};
      distances.data.reserve(entries.size());
      for (const auto& e : entries) {
        pairs.push_back({e.a, e.b});
        distances.data.push_back(e.distance);
      }
    }
    query_s = seconds_since(start);
    join_progress.finish();
    if (!job.distances.empty())
      write_then_rename(job.distances, [&](const std::string& temp) { io::write_points(temp, distances); });
    io::write_pairs(job.out, pairs);
    json.add("command", "pairs").add("radius", job.radius).add("pairs", std::uint64_t{pairs.size()});
  } else {
    std::vector<T> radii;
    for (const double r : job.radii) radii.push_back(as_scalar<T>(r));
    const std::vector<std::uint64_t> counts =
        two_sets ? count_pairs(tree_a, *tree_b, radii, params, &stats) : count_pairs(tree_a, radii, params, &stats);
    query_s = seconds_since(start);
    join_progress.finish();
    json.add("radii", job.radii).add("counts", counts);
    if (!job.stats) {
      std::printf("%s\n", json.str().c_str());
      return 0;
    }
    json.add("command", "count");
  }
  if (!job.stats) return 0;
  const double n = static_cast<double>(points_a);
  json.add("points", std::uint64_t{points_a})
      .add("with_points", std::uint64_t{points_b})
      .add("dim", std::uint64_t{tree_a.dim()})
      .add("metric", Metric::name)
      .add("periodic", job.boxsize.empty() ? "no" : "yes")
      .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
      .add("threads", detail::resolve_threads(job.threads))
      .add("build_s", build_s)
      .add("query_s", query_s)
      .add("queries_per_s", query_s > 0 ? n / query_s : std::numeric_limits<double>::infinity())
      .add("depth", std::uint64_t{tree_a.depth()})
      .add("leaves", std::uint64_t{tree_a.leaf_count()})
      .add("node_pairs", stats.node_pairs)
      .add("leaf_pairs", stats.leaf_pairs)
      .add("distances", stats.distances)
      .add("bulk_pairs", stats.bulk_pairs)
      .add("nodes_visited_per_query", static_cast<double>(stats.node_pairs) / n)
      .add("points_visited_per_query", static_cast<double>(stats.distances) / n);
  std::printf("%s\n", json.str().c_str());
  return 0;
}

int run_join_command(JoinMode mode, const std::vector<std::string>& args) {
  const char* name = mode == JoinMode::pairs ? "pairs" : "count";
  return run_guarded(name, [&] {
    if (wants_help(args)) {
      std::fputs(mode == JoinMode::pairs ? pairs_usage : count_usage, stdout);
      std::fputs(shared_usage, stdout);
      return 0;
    }
    const JoinJob job = parse_job(mode, args);
    io::format_from_path(job.base);  // an unknown extension fails before any reading
    if (!job.with.empty()) io::format_from_path(job.with);
    const bool in_double = io::stores_double(job.base) || (!job.with.empty() && io::stores_double(job.with));
    auto with_metric = [&](auto zero) {
      using T = decltype(zero);
      if (job.metric == "l1") return run_join<T, L1>(job);
      if (job.metric == "linf") return run_join<T, Linf>(job);
      return run_join<T, L2>(job);
    };
    return in_double ? with_metric(0.0) : with_metric(0.0f);
  });
}

}  // namespace
}  // namespace kdspace::cli

int run_pairs_command(const std::vector<std::string>& args) {
  return kdspace::cli::run_join_command(kdspace::cli::JoinMode::pairs, args);
}

int run_count_command(const std::vector<std::string>& args) {
  return kdspace::cli::run_join_command(kdspace::cli::JoinMode::count, args);
}
