// `kdspace knn` and `kdspace radius`: read a base and a query file, build a PointTree (or load a
// saved index), search, write the ids (and distances) of the results. Both commands share one
// implementation; they differ only in their options (search_job.hpp, shared with kdspace-mpi) and
// in the batch query they run.
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "commands.hpp"
#include "guard.hpp"
#include "json.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/point_forest.hpp"
#include "kdspace/points/point_tree.hpp"
#include "join_search.hpp"
#include "options.hpp"
#include "progress.hpp"
#include "search_job.hpp"
#include "tree_dimension.hpp"

namespace kdspace::cli {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

template <class T>
io::Matrix<T> read_with_progress(const std::string& path) {
  Progress progress("reading " + path);
  return io::read_points<T>(path, progress.callback());
}

bool starts_with(const std::string& s, const std::string& prefix) {
  return s.compare(0, prefix.size(), prefix) == 0;
}

// An index speaks of "row R" of its input; that input is the base file.
Error in_base_file(const Error& e, const SearchJob& job) {
  const std::string what = e.what();
  return Error(starts_with(what, job.base + ":") ? what : job.base + ": " + what);
}

// "query row R: ..." from an index becomes "QUERYFILE: row R: ...".
Error in_query_file(const Error& e, const SearchJob& job) {
  const std::string what = e.what();
  const std::string prefix = "query row ";
  return Error(starts_with(what, prefix) ? job.query + ": row " + what.substr(prefix.size()) : what);
}

/// The base and query files, read and checked against each other (and k against the base). The base
/// may be read as bytes (B = std::uint8_t: a .bvecs base for the forest, a quarter of the memory).
template <class T, class B = T>
struct Inputs {
  io::Matrix<B> base;
  io::Matrix<T> queries;
};

// With --boxsize: the box size, and the points of `file` inside the box (the message names the row).
template <class T>
void check_in_box(const io::Matrix<T>& points, const std::string& file, const SearchJob& job) {
  if (job.boxsize.empty()) return;
  if constexpr (std::is_floating_point_v<T>) {
    try {
      const std::vector<T> period = detail::periods_from_boxsize<T>(job.boxsize, points.cols);
      detail::check_in_box(points.data.data(), points.rows, points.cols, period);
    } catch (const Error& e) {
      throw Error(file + ": " + e.what());
    }
  }
}

template <class T, class B = T>
Inputs<T, B> read_inputs(const SearchJob& job) {
  Inputs<T, B> in{read_with_progress<B>(job.base), {}};
  if (job.self) {
    if (job.k > in.base.rows - 1)
      throw Error("k = " + std::to_string(job.k) + " exceeds the number of other points (" + job.base + " has " +
                  std::to_string(in.base.rows) + " points)");
    check_in_box(in.base, job.base, job);
    return in;
  }
  in.queries = read_with_progress<T>(job.query);
  if (in.queries.cols != in.base.cols)
    throw Error(job.query + ": dimension " + std::to_string(in.queries.cols) + " does not match the base (" +
                job.base + ": dimension " + std::to_string(in.base.cols) + ")");
  if (job.mode == Mode::knn && job.k > in.base.rows)
    throw Error("k = " + std::to_string(job.k) + " exceeds the number of base points (" + job.base + " has " +
                std::to_string(in.base.rows) + ")");
  check_in_box(in.base, job.base, job);
  check_in_box(in.queries, job.query, job);
  return in;
}

// The trees a dual-tree join takes: PointTrees of the metrics it has rules for (not Minkowski of
// another order, which only a loaded index brings here; not a DynamicPointTree).
template <class Tree>
struct has_joins : std::false_type {};
template <class T, int Dim, class Metric>
struct has_joins<PointTree<T, Dim, Metric>> : std::bool_constant<!std::is_same_v<Metric, Minkowski>> {};

// The joins of a compile-time-dimension tree are compiled in the library for L2 only
// (KDSPACE_JOIN_INSTANCES in kdspace/joins/joins.hpp); run_search sends a join under L1 or Linf to
// the run-time-dimension tree, so that the command does not compile the joins again.
template <class Tree>
inline constexpr bool joins_compiled_for = false;
template <class T, int Dim, class Metric>
inline constexpr bool joins_compiled_for<PointTree<T, Dim, Metric>> =
    has_joins<PointTree<T, Dim, Metric>>::value && (Dim == Dynamic || std::is_same_v<Metric, L2>);

template <class Tree>
inline constexpr bool dim_known_at_compile_time = false;
template <class T, int Dim, class Metric>
inline constexpr bool dim_known_at_compile_time<PointTree<T, Dim, Metric>> = Dim != Dynamic;

template <class T, int Dim, class Metric>
PointTree<T, Dim, Metric> build_tree(const io::Matrix<T>& base, const SearchJob& job) {
  try {
    return PointTree<T, Dim, Metric>(base.data.data(), base.rows, base.cols, job.build);
  } catch (const Error& e) {
    throw in_base_file(e, job);
  }
}

// Whether the job asks for a dual-tree join (join_search.hpp): --self and --boxsize, which a single
// tree does not answer.
bool wants_join(const SearchJob& job) { return job.self || !job.boxsize.empty(); }

// Whether the batch goes through a dual-tree join: asked for, and a tree that has them.
template <class Tree>
bool by_join(const SearchJob& job) {
  return has_joins<Tree>::value && wants_join(job);
}

// Tree: a PointTree or a DynamicPointTree (the same queries).
template <class T, class Tree>
NeighborLists<T> search(const Tree& tree, const io::Matrix<T>& queries, const SearchJob& job, QueryStats& stats) {
  if (by_join<Tree>(job)) {
    if constexpr (joins_compiled_for<Tree>) {
      JoinRequest request;
      request.knn = job.mode == Mode::knn;
      request.k = job.k;
      request.radius = job.radius;
      request.max_results = job.max_results == std::numeric_limits<std::size_t>::max() ? 0 : job.max_results;
      request.self = job.self;
      request.boxsize = job.boxsize;
      request.threads = job.threads;
      return search_by_join(tree, queries, request, stats);
    } else {
      throw std::logic_error("a join reached a tree whose joins are not compiled (see run_search)");
    }
  }
  try {
    if (job.mode == Mode::knn) {
      SearchParams params;
      params.eps = job.eps;
      return tree.knn_batch(queries.data.data(), queries.rows, job.k, params, job.threads, &stats);
    }
    return tree.radius_batch(queries.data.data(), queries.rows, narrow<T>(job.radius), job.max_results,
                             job.threads, &stats);
  } catch (const Error& e) {
    throw in_query_file(e, job);
  }
}

/// How the index searched came to be: built in the run (build_s), or loaded (load_s: until it answers
/// queries). A loaded index may leave the file's checksums `pending`, waited for before any answer is
/// written; verified_s then says when they were all verified.
struct Origin {
  double build_s = 0;
  double load_s = -1;  // < 0: not loaded
  io::PendingChecksums* pending = nullptr;
  Clock::time_point load_start{};
  double verified_s = -1;  // < 0: nothing was pending

  // Throws the pending checksums' Error, if any: then no answer is written.
  void wait_for_checksums() {
    if (!pending || !pending->started()) return;
    pending->wait();
    verified_s = std::chrono::duration<double>(pending->done_at() - load_start).count();
  }
  void add_to(JsonObject& json) const {
    json.add("build_s", build_s);
    if (load_s >= 0) json.add("load_s", load_s);
    if (verified_s >= 0) json.add("verified_s", verified_s);
  }
};

// Searches a built or loaded tree, writes the results, prints --stats.
template <class T, class Metric, class Tree>
int search_tree(const SearchJob& job, const Tree& tree, const io::Matrix<T>& queries, Origin origin) {
  QueryStats stats;
  Progress search_progress("searching", Progress::Kind::elapsed);
  const Clock::time_point start = Clock::now();
  const NeighborLists<T> found = search(tree, queries, job, stats);
  const double query_s = seconds_since(start);
  search_progress.finish();

  origin.wait_for_checksums();
  write_results(found, job);

  if (job.stats) {
    const double nq = static_cast<double>(found.rows());
    JsonObject json;
    json.add("command", job.mode == Mode::knn ? "knn" : "radius")
        .add("points", std::uint64_t{tree.size()})
        .add("dim", std::uint64_t{tree.dim()})
        .add("dim_known_at", dim_known_at_compile_time<Tree> ? "compile time" : "run time")
        .add("queries", std::uint64_t{found.rows()});
    json.add("method", by_join<Tree>(job) ? "dual-tree join" : "tree");
    if (job.self) json.add("self", "yes");
    if (!job.boxsize.empty()) json.add("boxsize", job.boxsize);
    if (job.mode == Mode::knn) {
      json.add("k", std::uint64_t{job.k}).add("eps", job.eps);
    } else {
      json.add("radius", job.radius).add("results", std::uint64_t{found.neighbors.size()});
      if (job.max_results != std::numeric_limits<std::size_t>::max())
        json.add("max_results", std::uint64_t{job.max_results});
    }
    json.add("metric", Metric::name)
        .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
        .add("threads", detail::resolve_threads(job.threads));
    origin.add_to(json);
    json.add("query_s", query_s)
        .add("queries_per_s", query_s > 0 ? nq / query_s : std::numeric_limits<double>::infinity())
        .add("depth", std::uint64_t{tree.depth()})
        .add("leaves", std::uint64_t{tree.leaf_count()})
        .add("nodes", std::uint64_t{tree.node_count()})
        .add("index_bytes", std::uint64_t{tree.index_bytes()})
        .add("nodes_visited_per_query", static_cast<double>(stats.nodes_visited) / nq)
        .add("points_visited_per_query", static_cast<double>(stats.points_visited) / nq);
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}


// Build, search, write; Dim: the tree's dimension (tree_dimension.hpp), as a constant or Dynamic.
template <class T, int Dim, class Metric>
int build_and_search(const SearchJob& job, Inputs<T>& in) {
  io::Matrix<T>& base = in.base;
  Progress build_progress("building the tree", Progress::Kind::elapsed);
  const Clock::time_point start = Clock::now();
  const PointTree<T, Dim, Metric> tree = build_tree<T, Dim, Metric>(base, job);
  Origin origin;
  origin.build_s = seconds_since(start);
  build_progress.finish();
  base = {};  // the tree holds its own copy
  return search_tree<T, Metric>(job, tree, in.queries, origin);
}

template <class T, class Metric>
int run_search(const SearchJob& job) {
  Inputs<T> in = read_inputs<T>(job);
  if constexpr (!std::is_same_v<Metric, L2>)  // a join under L1 or Linf: see joins_compiled_for
    if (wants_join(job)) return build_and_search<T, Dynamic, Metric>(job, in);
  return with_tree_dimension(in.base.cols, [&](auto dim) {
    return build_and_search<T, decltype(dim)::value, Metric>(job, in);
  });
}

// Searches a built or loaded forest, writes the results, prints --stats (with the recall measured
// on a sample of the queries).
template <class T>
int search_forest(const SearchJob& job, const PointForest<T>& forest, const io::Matrix<T>& queries,
                  const ForestSearchParams& search_params, const Origin& origin, const ForestTuning* tuning) {
  QueryStats stats;
  Progress search_progress("searching", Progress::Kind::elapsed);
  Clock::time_point start = Clock::now();
  NeighborLists<T> found;
  try {
    found = forest.knn_batch(queries.data.data(), queries.rows, job.k, search_params, job.threads, &stats);
  } catch (const Error& e) {
    throw in_query_file(e, job);
  }
  const double query_s = seconds_since(start);
  search_progress.finish();

  write_results(found, job);

  if (job.stats) {
    // Recall on up to 200 evenly spaced queries, against exact answers (not part of query_s).
    const std::size_t sample = std::min<std::size_t>(queries.rows, 200);
    start = Clock::now();
    std::vector<T> picked(sample * queries.cols);
    NeighborLists<T> picked_found;
    picked_found.offsets.resize(sample + 1);
    for (std::size_t i = 0; i < sample; ++i) {
      const std::size_t q = i * queries.rows / sample;
      std::copy(queries.data.begin() + static_cast<std::ptrdiff_t>(q * queries.cols),
                queries.data.begin() + static_cast<std::ptrdiff_t>((q + 1) * queries.cols),
                picked.begin() + static_cast<std::ptrdiff_t>(i * queries.cols));
      for (const auto& nb : found.row(q)) picked_found.neighbors.push_back(nb);
      picked_found.offsets[i + 1] = picked_found.neighbors.size();
    }
    const NeighborLists<T> exact = forest.knn_exact_batch(picked.data(), sample, job.k, job.threads);
    const double recall = recall_at_k(picked_found, exact);
    const double recall_check_s = seconds_since(start);

    const double nq = static_cast<double>(queries.rows);
    JsonObject json;
    const bool graph_search = search_params.ef > 0;
    json.add("command", "knn")
        .add("method", graph_search ? "graph" : "forest")
        .add("points", std::uint64_t{forest.size()})
        .add("dim", std::uint64_t{forest.dim()})
        .add("queries", std::uint64_t{queries.rows})
        .add("k", std::uint64_t{job.k})
        .add("metric", "l2")
        .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
        .add("threads", detail::resolve_threads(job.threads))
        .add("trees_built", std::uint64_t{forest.tree_count()})
        .add("projected_dims", std::uint64_t{forest.projected_dims()})
        .add("stored_as", forest.compact() ? "bytes" : (sizeof(T) == sizeof(double) ? "double" : "float"));
    if (forest.has_graph())
      json.add("graph_degree", std::uint64_t{forest.graph_degree()}).add("graph_build_s", forest.graph_build_seconds());
    if (graph_search) {
      json.add("ef", std::uint64_t{search_params.ef});
    } else {
      json.add("trees", std::uint64_t{search_params.trees == 0 ? forest.tree_count() : search_params.trees})
          .add("checks", std::uint64_t{search_params.checks});
    }
    origin.add_to(json);
    if (tuning) {
      json.add("target_recall", job.recall)
          .add("tune_s", tuning->seconds)
          .add("tuning_recall", tuning->tuning_recall)
          .add("validation_recall", tuning->validation_recall)
          .add("settings_tried", std::uint64_t{tuning->settings_tried});
    }
    json.add("query_s", query_s)
        .add("queries_per_s", query_s > 0 ? nq / query_s : std::numeric_limits<double>::infinity())
        .add("recall", recall)
        .add("recall_queries", std::uint64_t{sample})
        .add("recall_check_s", recall_check_s)
        .add("depth", std::uint64_t{forest.depth()})
        .add("leaves", std::uint64_t{forest.leaf_count()})
        .add("nodes", std::uint64_t{forest.node_count()})
        .add("index_bytes", std::uint64_t{forest.index_bytes()})
        .add("nodes_visited_per_query", static_cast<double>(stats.nodes_visited) / nq)
        .add("points_visited_per_query", static_cast<double>(stats.points_visited) / nq);
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

// The forest's counterpart of run_search: build (and tune), search, write, and measure the recall on
// a sample of the queries. B: the type the base is read as (T, or std::uint8_t for a .bvecs base).
template <class T, class B = T>
int run_forest_search(const SearchJob& job) {
  Inputs<T, B> in = read_inputs<T, B>(job);
  io::Matrix<B>& base = in.base;
  const io::Matrix<T>& queries = in.queries;

  ForestParams params;
  params.trees = job.forest_trees;
  params.leaf_size = job.build.leaf_size;
  params.threads = job.threads;
  params.graph = !job.use_graph ? GraphMode::off : job.use_trees ? GraphMode::automatic : GraphMode::on;
  params.graph_degree = job.degree;
  Progress build_progress("building the index", Progress::Kind::elapsed);
  Clock::time_point start = Clock::now();
  std::unique_ptr<PointForest<T>> forest;
  try {
    forest = std::make_unique<PointForest<T>>(base.data.data(), base.rows, base.cols, params);
  } catch (const Error& e) {
    throw in_base_file(e, job);
  }
  Origin origin;
  origin.build_s = seconds_since(start);
  build_progress.finish();
  base = {};

  ForestSearchParams search_params = job.use_trees ? ForestSearchParams{job.checks, 0, 0}
                                                   : ForestSearchParams{unlimited_checks, 0, job.ef};
  ForestTuning tuning;
  if (job.recall > 0) {
    Progress tune_progress("tuning the search", Progress::Kind::elapsed);
    TuneParams tune_params;
    tune_params.threads = job.threads;
    tune_params.graph = job.use_graph;
    tune_params.trees = job.use_trees;
    try {
      tuning = forest->tune(job.recall, job.k, queries.data.data(), queries.rows, tune_params);
    } catch (const Error& e) {
      throw in_query_file(e, job);
    }
    tune_progress.finish();
    search_params = tuning.search();
  }

  return search_forest(job, *forest, queries, search_params, origin, job.recall > 0 ? &tuning : nullptr);
}

// ---- answering from a saved index -------------------------------------------------------------------

// The queries, checked against the index's dimension and size.
template <class T>
io::Matrix<T> read_queries_for_index(const SearchJob& job, std::size_t dim, std::size_t points) {
  io::Matrix<T> queries = read_with_progress<T>(job.query);
  if (queries.cols != dim)
    throw Error(job.query + ": dimension " + std::to_string(queries.cols) + " does not match the index (" + job.index +
                ": dimension " + std::to_string(dim) + ")");
  if (job.mode == Mode::knn && job.k > points)
    throw Error("k = " + std::to_string(job.k) + " exceeds the number of indexed points (" + job.index + " holds " +
                std::to_string(points) + ")");
  return queries;
}

// How a load shows progress: with a ticker (a thread of its own) only for a file of 64 MiB or more,
// which a disk of 100 MB/s could take a second to bring in; a smaller file's load would pay the
// thread's start (tens of microseconds) inside load_s and never show anything.
Progress::Kind load_progress(const io::IndexFile& file) {
  constexpr std::uint64_t ticker_bytes = std::uint64_t{64} << 20;
  return file.info().file_bytes >= ticker_bytes ? Progress::Kind::elapsed : Progress::Kind::fraction;
}

// Loads the tree of `file` (a PointTree or a DynamicPointTree) and searches it.
template <class T, class Metric>
int search_tree_index(const SearchJob& job, const std::shared_ptr<const io::IndexFile>& file,
                      Clock::time_point start) {
  if (job.checks > 0 || job.ef > 0)
    throw UsageError(std::string(job.checks > 0 ? "--checks" : "--ef") + " applies to forests; " + job.index +
                     " holds a point tree");
  io::PendingChecksums pending;
  auto load_and_search = [&](auto load) {
    Progress progress("loading " + job.index, load_progress(*file));
    const auto tree = load();
    Origin origin;
    origin.load_s = seconds_since(start);
    origin.pending = &pending;
    origin.load_start = start;
    progress.finish();
    const io::Matrix<T> queries = read_queries_for_index<T>(job, tree.dim(), tree.size());
    return search_tree<T, Metric>(job, tree, queries, origin);
  };
  if (file->info().kind == io::IndexKind::point_tree)
    return load_and_search(
        [&] { return io::load_point_tree_deferred<T, Dynamic, Metric>(file, job.verify, job.threads, &pending); });
  return load_and_search([&] {
    return io::load_with_checksums(
        file, [](const auto& f) { return io::load_dynamic_point_tree<T, Dynamic, Metric>(f); });
  });
}

template <class T>
int search_forest_index(const SearchJob& job, const std::shared_ptr<const io::IndexFile>& file,
                        Clock::time_point start) {
  if (job.mode != Mode::knn) throw Error(job.index + ": holds a point forest, which answers knn only");
  if (job.eps > 0) throw UsageError("--eps applies to trees; " + job.index + " holds a point forest (use --checks)");
  Progress progress("loading " + job.index, load_progress(*file));
  ForestSearchParams stored;
  const PointForest<T> forest =
      io::load_with_checksums(file, [&](const auto& f) { return io::load_point_forest<T>(f, &stored); });
  Origin origin;
  origin.load_s = seconds_since(start);
  progress.finish();
  ForestSearchParams search = stored.checks > 0 || stored.ef > 0 ? stored : ForestSearchParams{};
  if (job.checks > 0) search = ForestSearchParams{job.checks, 0, 0};
  if (job.ef > 0) {
    if (!forest.has_graph()) throw UsageError("--ef searches a neighbour graph; " + job.index + " holds none (use --checks)");
    search = ForestSearchParams{unlimited_checks, 0, job.ef};
  }
  const io::Matrix<T> queries = read_queries_for_index<T>(job, forest.dim(), forest.size());
  return search_forest(job, forest, queries, search, origin, nullptr);
}

int search_index(const SearchJob& job) {
  const Clock::time_point start = Clock::now();
  const auto file = io::IndexFile::open(job.index, io::LoadMode::map, io::Checksums::deferred);
  io::format_from_path(job.query);  // an unknown extension fails before the index is checked
  const io::IndexInfo& info = file->info();
  const bool wide = info.scalar == io::ScalarType::float64;
  switch (info.kind) {
    case io::IndexKind::point_tree:
    case io::IndexKind::dynamic_point_tree:
      switch (info.metric) {
        case io::MetricId::l1:
          return wide ? search_tree_index<double, L1>(job, file, start) : search_tree_index<float, L1>(job, file, start);
        case io::MetricId::linf:
          return wide ? search_tree_index<double, Linf>(job, file, start)
                      : search_tree_index<float, Linf>(job, file, start);
        case io::MetricId::minkowski:
          return wide ? search_tree_index<double, Minkowski>(job, file, start)
                      : search_tree_index<float, Minkowski>(job, file, start);
        default:
          return wide ? search_tree_index<double, L2>(job, file, start) : search_tree_index<float, L2>(job, file, start);
      }
    case io::IndexKind::point_forest:
      return wide ? search_forest_index<double>(job, file, start) : search_forest_index<float>(job, file, start);
    default:
      throw Error(job.index + ": holds a " + io::name_of(info.kind) + ", not an index of points");
  }
}

template <class T>
struct Type {
  using type = T;
};

/// Calls f(Type<Scalar>, Type<Metric>) for the scalar the base file holds and the chosen metric.
template <class F>
int with_tree_type(const SearchJob& job, F&& f) {
  auto with_metric = [&](auto scalar) {
    if (job.metric == "l1") return f(scalar, Type<L1>{});
    if (job.metric == "linf") return f(scalar, Type<Linf>{});
    return f(scalar, Type<L2>{});
  };
  return io::stores_double(job.base) ? with_metric(Type<double>{}) : with_metric(Type<float>{});
}

int run_search_command(Mode mode, const std::vector<std::string>& args) {
  const char* name = mode == Mode::knn ? "knn" : "radius";
  return run_guarded(name, [&] {
    if (wants_help(args)) {
      std::fputs(search_usage(mode).c_str(), stdout);
      return 0;
    }
    const SearchJob job = parse_job(mode, args);
    if (!job.index.empty()) return search_index(job);
    // An unknown extension fails now, not after reading the base.
    io::format_from_path(job.base);
    if (!job.self) io::format_from_path(job.query);
    if (job.forest_trees > 0) {
      if (io::stores_double(job.base)) return run_forest_search<double>(job);
      if (io::format_from_path(job.base) == io::Format::bvecs) return run_forest_search<float, std::uint8_t>(job);
      return run_forest_search<float>(job);
    }
    return with_tree_type(job, [&](auto scalar, auto metric) {
      return run_search<typename decltype(scalar)::type, typename decltype(metric)::type>(job);
    });
  });
}

}  // namespace
}  // namespace kdspace::cli

int run_knn_command(const std::vector<std::string>& args) {
  return kdspace::cli::run_search_command(kdspace::cli::Mode::knn, args);
}

int run_radius_command(const std::vector<std::string>& args) {
  return kdspace::cli::run_search_command(kdspace::cli::Mode::radius, args);
}

