// `kdspace index`: builds an index of a base file and saves it (kdspace knn|radius --index answer from
// it), or updates a saved point tree: adds points, removes points by id, saves it again.
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <unordered_set>
#include <vector>

#include "build_options.hpp"
#include "commands.hpp"
#include "guard.hpp"
#include "json.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "options.hpp"
#include "progress.hpp"

namespace kdspace::cli {
namespace {

using Clock = std::chrono::steady_clock;

const char* const index_usage =
    R"(usage: kdspace index --base FILE --out INDEX.kdx [build options] [--threads T] [--stats]
       kdspace index --base FILE --out INDEX.kdx --forest T [--checks C] [--leaf N] [--threads T] [--stats]
       kdspace index --base FILE --out INDEX.kdx --recall R [-k K] [--forest T] [--leaf N] [--threads T] [--stats]
       kdspace index --update INDEX.kdx [--add FILE] [--remove IDS.ivecs] [--out NEW.kdx] [--stats]
Builds an index of the base points and saves it; 'kdspace knn|radius --index INDEX.kdx' answers from
it (memory-mapped) as from the same index built in the run. Saving is atomic: a crash or a full disk
leaves an old INDEX.kdx as it was.

  --base FILE          the points (.fvecs .ivecs .bvecs .csv .npy); a .csv or float64 .npy base is
                       indexed in double precision, any other in float
  --out INDEX.kdx      where to save the index
  --forest T           a randomized kd-forest of T trees (approximate k-NN, l2) instead of the exact
                       tree; --checks C is stored as the budget to search it with (default 256)
  --recall R           an approximate index tuned for a mean recall@K of R (0 < R <= 1, -k K,
                       default 10) on base points used as queries (each left out of its own
                       answers): 8 randomized kd-trees and, from dimension 8 on, a neighbour graph,
                       and the fastest search found (the graph's ef or the trees' checks) is stored;
                       with --forest T: T trees only, no graph
  --update INDEX.kdx   removes the points whose ids IDS.ivecs lists (every value of every row), then
                       adds the points of FILE, which get the ids next_id, next_id + 1, ... in row
                       order (--stats gives first_id); saves over INDEX.kdx unless --out is given.
                       A tree index becomes an updatable one, which answers exactly as a tree built
                       over the points it holds, under their ids (a point keeps its id until removed)
  --threads T          threads for the build; 0 (default) = all hardware threads
  --stats              one JSON object on stdout: build_s (or load_s and update_s), save_s,
                       file_bytes, points, dim, and the index's shape
)";

struct IndexJob {
  std::string base, out, update, add, remove;
  BuildParams build;
  std::string metric = "l2";
  std::size_t forest_trees = 0;  // 0: the exact tree
  bool graph = false;            // the forest may build its neighbour graph (--recall without --forest)
  std::size_t checks = 256;
  double recall = 0;
  std::size_t k = 10;
  unsigned threads = 0;
  bool stats = false;
};

IndexJob parse_job(const std::vector<std::string>& args) {
  std::vector<OptionSpec> specs = {{"--base"},   {"--out"},     {"--update"},      {"--add"},
                                   {"--remove"}, {"--forest"},  {"--checks"},      {"--recall"},
                                   {"-k"},       {"--threads"}, {"--stats", false}};
  for (const OptionSpec& build : build_option_specs()) specs.push_back(build);
  const Options o(args, specs);
  IndexJob job;
  job.threads = static_cast<unsigned>(o.count("--threads", 0, 0, 4096));
  job.stats = o.has("--stats");
  if (o.has("--update")) {
    job.update = o.required("--update");
    job.out = o.text("--out", job.update);
    job.add = o.text("--add");
    job.remove = o.text("--remove");
    if (o.has("--base")) throw UsageError("--base and --update exclude each other");
    if (job.add.empty() && job.remove.empty())
      throw UsageError("--update needs --add FILE or --remove IDS.ivecs");
    if (!job.remove.empty()) require_extension("--remove", job.remove, ".ivecs");
    for (const char* building : {"--forest", "--checks", "--recall", "-k"})
      if (o.has(building))
        throw UsageError(std::string(building) + " applies when building, not to --update");
    const std::string build_option = first_build_option(o);
    if (!build_option.empty())
      throw UsageError(build_option + " applies when building; " + job.update +
                       " keeps the options it was built with");
    return job;
  }
  if (o.has("--add") || o.has("--remove")) throw UsageError("--add and --remove go with --update");
  job.base = o.required("--base");
  job.out = o.required("--out");
  job.build = parse_build_params(o);
  job.build.threads = job.threads;
  job.metric = parse_metric(o);
  if (o.has("--forest") || o.has("--recall")) {
    job.forest_trees = o.count("--forest", 8, 1, 1024);
    job.graph = !o.has("--forest");
    if (job.metric != "l2") throw UsageError("--forest and --recall index with --metric l2 only");
    for (const char* exact_only : {"--axis", "--position", "--max-depth"})
      if (o.has(exact_only))
        throw UsageError(std::string(exact_only) + " applies to the exact tree, not to a forest");
    job.build.leaf_size =
        o.count("--leaf", ForestParams{}.leaf_size, 1, std::numeric_limits<std::size_t>::max());
    if (o.has("--recall")) {
      if (o.has("--checks"))
        throw UsageError("--checks and --recall exclude each other: --recall chooses the checks");
      job.recall = o.number("--recall", 0.0, 0.0, 1.0);
      if (!(job.recall > 0)) throw UsageError("--recall must be in (0, 1], got " + o.text("--recall"));
      job.k = o.count("-k", 10, 1, std::numeric_limits<std::size_t>::max());
    } else if (o.has("-k")) {
      throw UsageError("-k goes with --recall");
    }
    job.checks = o.count("--checks", 256, 1, std::numeric_limits<std::size_t>::max());
  } else {
    for (const char* forest_only : {"--checks", "--recall", "-k"})
      if (o.has(forest_only)) throw UsageError(std::string(forest_only) + " goes with --forest or --recall");
  }
  return job;
}

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::uint64_t file_bytes(const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  return ec ? 0 : static_cast<std::uint64_t>(size);
}

template <class T>
io::Matrix<T> read_with_progress(const std::string& path) {
  Progress progress("reading " + path);
  return io::read_points<T>(path, progress.callback());
}

// An index speaks of "row R" of its input; that input is `path`.
Error in_file(const Error& e, const std::string& path) {
  const std::string what = e.what();
  return Error(what.rfind(path + ":", 0) == 0 ? what : path + ": " + what);
}

// Times a save, with progress.
template <class Index>
double save(const std::string& path, const Index& index) {
  Progress progress("saving " + path, Progress::Kind::elapsed);
  const Clock::time_point start = Clock::now();
  io::save(path, index);
  return seconds_since(start);
}

// ---- building ---------------------------------------------------------------------------------------

template <class T, class Metric>
int build_tree_index(const IndexJob& job) {
  io::Matrix<T> base = read_with_progress<T>(job.base);
  Progress progress("building the tree", Progress::Kind::elapsed);
  Clock::time_point start = Clock::now();
  std::unique_ptr<PointTree<T, Dynamic, Metric>> tree;
  try {
    tree = std::make_unique<PointTree<T, Dynamic, Metric>>(base.data.data(), base.rows, base.cols, job.build);
  } catch (const Error& e) {
    throw in_file(e, job.base);
  }
  const double build_s = seconds_since(start);
  progress.finish();
  base = {};
  const double save_s = save(job.out, *tree);
  if (job.stats) {
    JsonObject json;
    json.add("command", "index")
        .add("kind", "point tree")
        .add("points", std::uint64_t{tree->size()})
        .add("dim", std::uint64_t{tree->dim()})
        .add("metric", Metric::name)
        .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
        .add("threads", detail::resolve_threads(job.threads))
        .add("build_s", build_s)
        .add("save_s", save_s)
        .add("file_bytes", file_bytes(job.out))
        .add("depth", std::uint64_t{tree->depth()})
        .add("leaves", std::uint64_t{tree->leaf_count()})
        .add("nodes", std::uint64_t{tree->node_count()})
        .add("index_bytes", std::uint64_t{tree->index_bytes()});
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

// B: the type the base is read as (T, or std::uint8_t for a .bvecs base: kept as bytes).
template <class T, class B = T>
int build_forest_index(const IndexJob& job) {
  io::Matrix<B> base = read_with_progress<B>(job.base);
  ForestParams params;
  params.trees = job.forest_trees;
  params.leaf_size = job.build.leaf_size;
  params.threads = job.threads;
  params.graph = job.graph ? GraphMode::automatic : GraphMode::off;
  Progress progress("building the forest", Progress::Kind::elapsed);
  const Clock::time_point start = Clock::now();
  std::unique_ptr<PointForest<T>> forest;
  try {
    forest = std::make_unique<PointForest<T>>(base.data.data(), base.rows, base.cols, params);
  } catch (const Error& e) {
    throw in_file(e, job.base);
  }
  const double build_s = seconds_since(start);
  progress.finish();
  base = {};
  ForestSearchParams search{job.checks, 0, 0};
  ForestTuning tuning;
  if (job.recall > 0) {
    Progress tune_progress("tuning the forest", Progress::Kind::elapsed);
    TuneParams tune_params;
    tune_params.threads = job.threads;
    try {
      tuning = forest->tune(job.recall, job.k, tune_params);
    } catch (const Error& e) {
      throw in_file(e, job.base);
    }
    search = tuning.search();
  }
  Progress save_progress("saving " + job.out, Progress::Kind::elapsed);
  const Clock::time_point save_start = Clock::now();
  io::save(job.out, *forest, &search);
  const double save_s = seconds_since(save_start);
  save_progress.finish();
  if (job.stats) {
    JsonObject json;
    json.add("command", "index")
        .add("kind", "point forest")
        .add("points", std::uint64_t{forest->size()})
        .add("dim", std::uint64_t{forest->dim()})
        .add("metric", "l2")
        .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
        .add("stored_as", forest->compact() ? "bytes" : (sizeof(T) == sizeof(double) ? "double" : "float"))
        .add("threads", detail::resolve_threads(job.threads))
        .add("trees_built", std::uint64_t{forest->tree_count()})
        .add("method", search.ef > 0 ? "graph" : "forest");
    if (forest->has_graph())
      json.add("graph_degree", std::uint64_t{forest->graph_degree()}).add("graph_build_s", forest->graph_build_seconds());
    if (search.ef > 0)
      json.add("ef", std::uint64_t{search.ef});
    else
      json.add("trees", std::uint64_t{search.trees == 0 ? forest->tree_count() : search.trees})
          .add("checks", std::uint64_t{search.checks});
    json.add("build_s", build_s);
    if (job.recall > 0)
      json.add("target_recall", job.recall)
          .add("k", std::uint64_t{job.k})
          .add("tune_s", tuning.seconds)
          .add("tuning_recall", tuning.tuning_recall)
          .add("validation_recall", tuning.validation_recall);
    json.add("save_s", save_s)
        .add("file_bytes", file_bytes(job.out))
        .add("depth", std::uint64_t{forest->depth()})
        .add("leaves", std::uint64_t{forest->leaf_count()})
        .add("nodes", std::uint64_t{forest->node_count()})
        .add("index_bytes", std::uint64_t{forest->index_bytes()});
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

int build_index(const IndexJob& job) {
  io::format_from_path(job.base);  // an unknown extension fails before anything is read
  const bool wide = io::stores_double(job.base);
  if (job.forest_trees > 0) {
    if (wide) return build_forest_index<double>(job);
    if (io::format_from_path(job.base) == io::Format::bvecs)
      return build_forest_index<float, std::uint8_t>(job);
    return build_forest_index<float>(job);
  }
  if (job.metric == "l1") return wide ? build_tree_index<double, L1>(job) : build_tree_index<float, L1>(job);
  if (job.metric == "linf")
    return wide ? build_tree_index<double, Linf>(job) : build_tree_index<float, Linf>(job);
  return wide ? build_tree_index<double, L2>(job) : build_tree_index<float, L2>(job);
}

// ---- updating ---------------------------------------------------------------------------------------

// The ids IDS.ivecs lists, each held by the index and listed once ("IDS.ivecs: row 2: ...").
template <class Tree>
std::vector<Index> ids_to_remove(const IndexJob& job, const Tree& tree) {
  const io::RaggedRows<std::int32_t> rows = io::read_ivecs_rows(job.remove);
  std::vector<Index> ids;
  std::unordered_set<Index> listed;
  for (std::size_t r = 0; r < rows.rows(); ++r)
    for (std::size_t i = rows.offsets[r]; i < rows.offsets[r + 1]; ++i) {
      const std::string where = job.remove + ": row " + std::to_string(r + 1) + ": ";
      const std::int32_t v = rows.values[i];
      if (v < 0) throw Error(where + "id " + std::to_string(v) + " is negative");
      const auto id = static_cast<Index>(v);
      if (!tree.contains(id))
        throw Error(where + "id " + std::to_string(id) + " is not in " + job.update +
                    " (never given, or removed)");
      if (!listed.insert(id).second) throw Error(where + "id " + std::to_string(id) + " is listed twice");
      ids.push_back(id);
    }
  return ids;
}

template <class T, class Metric>
int update_index(const IndexJob& job, const std::shared_ptr<const io::IndexFile>& file,
                 Clock::time_point start) {
  Progress progress("loading " + job.update, Progress::Kind::elapsed);
  auto tree = io::load_with_checksums(
      file, [](const auto& f) { return io::load_dynamic_point_tree<T, Dynamic, Metric>(f); });
  const double load_s = seconds_since(start);
  progress.finish();

  const std::vector<Index> gone = job.remove.empty() ? std::vector<Index>{} : ids_to_remove(job, tree);
  io::Matrix<T> added;
  if (!job.add.empty()) {
    added = read_with_progress<T>(job.add);
    if (added.cols != tree.dim())
      throw Error(job.add + ": dimension " + std::to_string(added.cols) + " does not match the index (" +
                  job.update + ": dimension " + std::to_string(tree.dim()) + ")");
  }
  Progress update_progress("updating the index", Progress::Kind::elapsed);
  const Clock::time_point update_start = Clock::now();
  tree.remove(gone.data(), gone.size());
  Index first_id = 0;
  try {
    first_id = tree.insert(added.data.data(), added.rows);
  } catch (const Error& e) {
    throw in_file(e, job.add);
  }
  const double update_s = seconds_since(update_start);
  update_progress.finish();
  const double save_s = save(job.out, tree);
  if (job.stats) {
    JsonObject json;
    json.add("command", "index")
        .add("kind", "updatable point tree")
        .add("points", std::uint64_t{tree.size()})
        .add("dim", std::uint64_t{tree.dim()})
        .add("metric", Metric::name)
        .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
        .add("removed", std::uint64_t{gone.size()})
        .add("added", std::uint64_t{added.rows})
        .add("first_id", std::uint64_t{first_id})
        .add("next_id", std::uint64_t{tree.next_id()})
        .add("parts", std::uint64_t{tree.part_count()})
        .add("removed_pending", std::uint64_t{tree.removed_count()})
        .add("load_s", load_s)
        .add("update_s", update_s)
        .add("save_s", save_s)
        .add("file_bytes", file_bytes(job.out));
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

int update(const IndexJob& job) {
  if (!job.add.empty()) io::format_from_path(job.add);
  const Clock::time_point start = Clock::now();
  const auto file = io::IndexFile::open(job.update, io::LoadMode::map, io::Checksums::deferred);
  const io::IndexInfo& info = file->info();
  if (info.kind != io::IndexKind::point_tree && info.kind != io::IndexKind::dynamic_point_tree)
    throw Error(job.update + ": holds a " + io::name_of(info.kind) + "; only point trees take updates");
  const bool wide = info.scalar == io::ScalarType::float64;
  switch (info.metric) {
    case io::MetricId::l1:
      return wide ? update_index<double, L1>(job, file, start) : update_index<float, L1>(job, file, start);
    case io::MetricId::linf:
      return wide ? update_index<double, Linf>(job, file, start)
                  : update_index<float, Linf>(job, file, start);
    case io::MetricId::minkowski:
      return wide ? update_index<double, Minkowski>(job, file, start)
                  : update_index<float, Minkowski>(job, file, start);
    default:
      return wide ? update_index<double, L2>(job, file, start) : update_index<float, L2>(job, file, start);
  }
}

}  // namespace
}  // namespace kdspace::cli

int run_index_command(const std::vector<std::string>& args) {
  using namespace kdspace::cli;
  return run_guarded("index", [&] {
    if (wants_help(args)) {
      std::fputs(index_usage, stdout);
      std::fputs(build_options_usage, stdout);
      std::fputs("Exit codes: 0 success, 2 usage error, 1 bad data or I/O error.\n", stdout);
      return 0;
    }
    const IndexJob job = parse_job(args);
    return job.update.empty() ? build_index(job) : update(job);
  });
}
