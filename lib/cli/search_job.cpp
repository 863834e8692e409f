#include "search_job.hpp"

#include <string>

#include "build_options.hpp"
#include "kdspace/points/point_forest.hpp"
#include "options.hpp"

namespace kdspace::cli {
namespace {

const char* const knn_about = R"(Finds the K nearest base points of every query point.

  -k K                 a whole number >= 1; -k 0 is a usage error (exit 2), K above the number of
                       base points an error (exit 1), never silently shortened
)";

const char* const self_usage =
    R"(  --self               instead of --query: for each base point its K nearest other points (a point
                       at the same place is another point), K <= points - 1; a dual-tree self-join
)";

const char* const boxsize_usage =
    R"(  --boxsize L1,L2,...  periodic boundaries: the box size of each axis (one value: every axis);
                       along a periodic axis the distance is min(|d|, L - |d|); base and queries
                       must lie in [0, L) there; 0 leaves an axis not periodic (SciPy's boxsize)
)";

const char* const approximate_usage =
    R"(  --eps E              approximate, on the exact tree: the i-th result within (1+E) of the true
                       i-th (default 0: exact)
approximate search for high dimensions (l2 only; the distances returned are always exact; a .bvecs
base is kept as bytes, a quarter of the memory):
  --recall R           the index chooses: it builds randomized kd-trees and, from dimension 8 on, a
                       neighbour graph over the points, then finds the fastest search that reaches a
                       mean recall@K of R (0 < R <= 1) on a sample of the queries (up to 200 choose
                       the setting, 200 others check it), and searches all queries with it;
                       with --forest T: the trees only (T of them); with --graph: the graph only
  --forest T           T randomized kd-trees (1..1024) searched together, best bin first
  --checks C           with --forest: points scored per query (default 256); more is slower and
                       finds more of the true neighbours; with the --index of a forest, instead of
                       the setting stored in it
  --graph              the neighbour graph, searched best first from the leaf of a kd-tree
  --ef E               with --graph: the best E points found are kept while searching (default
                       64, at least K); more is slower and finds more of the true neighbours;
                       with the --index of a forest with a graph, instead of the setting stored in it
  --degree D           with --graph or --recall: neighbours a point keeps in the graph (2..1024,
                       default 32)
                       With --recall, --forest or --graph, --stats adds method (graph or forest),
                       ef or trees and checks, graph_build_s, tune_s, and the recall measured on
                       up to 200 of the queries against exact answers.
)";

const char* const radius_about =
    R"(Finds every base point within distance R of each query point (closed ball).

  -r R                 a finite number >= 0 in the data's units (not squared); negative or NaN is a
                       usage error (exit 2); the rows of IDS differ in length
  --max-results M      keep only the M nearest within R (M >= 1)
)";

const char* const files_usage = R"(  --base FILE          the points searched
  --query FILE         the query points, of the same dimension
                       Files: .fvecs .ivecs .bvecs .csv (optional header line) .npy, chosen by extension.
                       A .csv or float64 .npy base is searched in double precision, any other in float.
  --out IDS.ivecs      one row per query: 0-based indices of base points, nearest first, equal
                       distances by smaller index
  --distances D.fvecs  the true distances of those points (Euclidean for l2, not squared)
)";

const char* const index_usage =
    R"(  --index INDEX.kdx    or a saved index of them (kdspace index), memory-mapped: the same answers as
                       building it in the run (ids after updates: those kdspace index gave); its
                       build options and metric are those it was saved with
  --verify safety|full how much of a point tree index is checked before it is searched: safety
                       (default) its checksums and what keeps the search in bounds; full also every
                       point against its cell and the order (for files another program wrote)
)";

const char* const stats_usage =
    R"(  --stats              one JSON object on stdout: build_s, query_s, queries_per_s, threads, depth,
                       leaves, nodes_visited_per_query, points_visited_per_query, points, dim,
                       queries, k or radius, metric, index_bytes (times without file I/O)
)";

const char* const index_stats_usage =
    R"(                       with --index, load_s (mapping and checking the index, until it answers)
                       and build_s 0; for a point tree under --verify safety, verified_s too:
                       when the file's checksums, taken beside the queries, were all verified
                       (no answer is written before)
)";

std::vector<OptionSpec> option_specs(Mode mode, const SearchCommand& command) {
  std::vector<OptionSpec> specs = {{"--base"},        {"--index", true, command.index_refused_because},
                                   {"--verify", true, command.index_refused_because},
                                   {"--query"},       {"--out"},
                                   {"--distances"},   {"--threads"},
                                   {"--stats", false}};
  for (const OptionSpec& build : build_option_specs()) specs.push_back(build);
  specs.push_back({"--boxsize", true, command.joins_refused_because});
  if (mode == Mode::knn) {
    specs.push_back({"--self", false, command.joins_refused_because});
    specs.push_back({"-k"});
    for (const char* approximate : {"--eps", "--recall", "--forest", "--checks", "--ef", "--degree"})
      specs.push_back({approximate, true, command.approximate_refused_because});
    specs.push_back({"--graph", false, command.approximate_refused_because});
  } else {
    specs.push_back({"-r"});
    specs.push_back({"--max-results"});
  }
  return specs;
}

// --recall, --forest, --checks, --graph, --ef, --degree: which approximate search, and the rules
// that keep them apart.
void parse_approximate_options(const Options& o, SearchJob& job) {
  const bool forest = o.has("--forest"), graph = o.has("--graph"), tune = o.has("--recall");
  if (!forest && !graph && !tune) {
    if (o.has("--checks")) throw UsageError("--checks needs --forest");
    if (o.has("--ef")) throw UsageError("--ef needs --graph");
    if (o.has("--degree")) throw UsageError("--degree needs --graph or --recall");
    return;
  }
  if (o.has("--eps"))
    throw UsageError("--eps applies to the exact tree; it cannot be combined with --recall, --forest or --graph");
  if (forest && graph) throw UsageError("--forest and --graph exclude each other: one searches the trees, the other the graph");
  if (tune)
    for (const char* option : {"--checks", "--ef"})
      if (o.has(option)) throw UsageError(std::string(option) + " and --recall exclude each other: --recall chooses it");
  if (o.has("--checks") && !forest) throw UsageError("--checks needs --forest");
  if (o.has("--ef") && !graph) throw UsageError("--ef needs --graph");
  if (o.has("--degree") && forest) throw UsageError("--degree applies to the graph, not to --forest");
  job.use_trees = forest || !graph;
  job.use_graph = graph || !forest;
  job.forest_trees = o.count("--forest", graph ? ForestParams{}.trees : 8, 1, 1024);
  job.degree = o.count("--degree", ForestParams{}.graph_degree, 2, 1024);
  if (tune) {
    job.recall = o.number("--recall", 0.0, 0.0, 1.0);
    if (!(job.recall > 0)) throw UsageError("--recall must be in (0, 1], got " + o.text("--recall"));
  } else {
    job.checks = o.count("--checks", 256, 1, std::numeric_limits<std::size_t>::max());
    job.ef = o.count("--ef", 64, 1, std::numeric_limits<std::size_t>::max());
  }
}

}  // namespace

std::string search_usage(Mode mode, const SearchCommand& command) {
  const bool approximate = command.approximate_refused_because.empty();
  const bool joins = command.joins_refused_because.empty();
  const std::string indent(command.program.size() + (mode == Mode::knn ? 12 : 15), ' ');
  const std::string queries = mode == Mode::knn && joins ? "(--query FILE | --self)" : "--query FILE";
  std::string text =
      "usage: " + command.program +
      (mode == Mode::knn ? " knn --base FILE " + queries + " -k K" : " radius --base FILE --query FILE -r R") +
      " --out IDS.ivecs [--distances D.fvecs]\n" + indent;
  if (mode == Mode::radius) text += "[--max-results M] ";
  if (joins) text += "[--boxsize L1,L2,...] ";
  text += "[build options]";
  if (mode == Mode::knn && approximate)
    text += " [--eps E | --recall R | --forest T [--checks C] |\n" + indent + " --graph [--ef E] [--degree D]]\n" + indent;
  else
    text += " ";
  text += "[--threads T] [--stats]\n";
  const bool index = command.index_refused_because.empty();
  if (index)
    text += "       " + command.program +
            (mode == Mode::knn
                 ? " knn --index INDEX.kdx --query FILE -k K --out IDS.ivecs [--eps E | --checks C] ...\n"
                 : " radius --index INDEX.kdx --query FILE -r R --out IDS.ivecs ...\n");
  if (mode == Mode::knn) {
    text += knn_about;
    if (joins) text += self_usage;
    if (approximate) text += approximate_usage;
  } else {
    text += radius_about;
  }
  text += files_usage;
  if (joins) text += boxsize_usage;
  if (index) text += index_usage;
  text += "  --threads T          " + command.threads_help + "\n";
  text += stats_usage;
  if (index) text += index_stats_usage;
  text += build_options_usage;
  text += "Exit codes: 0 success, 2 usage error, 1 bad data or I/O error.\n";
  return text;
}

SearchJob parse_job(Mode mode, const std::vector<std::string>& args, const SearchCommand& command) {
  const Options o(args, option_specs(mode, command));
  constexpr std::size_t no_limit = std::numeric_limits<std::size_t>::max();
  SearchJob job;
  job.mode = mode;
  job.self = o.has("--self");
  if (o.has("--index")) {
    job.index = o.required("--index");
    if (o.has("--verify")) {
      const std::string verify = o.required("--verify");
      if (verify != "safety" && verify != "full")
        throw UsageError("--verify " + verify + ": expected safety or full");
      job.verify = verify == "full" ? Verify::full : Verify::safety;
    }
    job.checks = 0;  // the setting stored in a forest index, unless --checks or --ef says otherwise
    job.ef = 0;
    if (o.has("--base")) throw UsageError("--base and --index exclude each other");
    for (const char* join : {"--self", "--boxsize"})
      if (o.has(join)) throw UsageError(std::string(join) + " applies to a base built in the run, not to --index");
    std::string built = first_build_option(o);
    for (const char* option : {"--forest", "--recall", "--graph", "--degree"})
      if (built.empty() && o.has(option)) built = option;
    if (!built.empty()) throw UsageError(built + " applies when building; " + job.index + " was built with its own");
  } else {
    if (o.has("--verify")) throw UsageError("--verify applies to --index");
    job.base = o.required("--base");
  }
  if (job.self && o.has("--query"))
    throw UsageError("--self and --query exclude each other: --self searches the base for its own points");
  if (!job.self) job.query = o.required("--query");
  job.boxsize = o.numbers("--boxsize", 0, std::numeric_limits<double>::infinity());
  if (mode == Mode::knn) {
    if (!o.has("-k")) throw UsageError("missing option -k");
    job.k = o.count("-k", 0, 1, no_limit);
    job.eps = o.number("--eps", 0.0, 0.0, std::numeric_limits<double>::infinity());
    if (!job.index.empty()) {
      if (o.has("--eps") && (o.has("--checks") || o.has("--ef")))
        throw UsageError("--eps applies to trees, --checks and --ef to forests: not both");
      if (o.has("--checks") && o.has("--ef"))
        throw UsageError("--checks searches a forest's trees, --ef its graph: not both");
      job.checks = o.count("--checks", 0, 1, no_limit);
      job.ef = o.count("--ef", 0, 1, no_limit);
    } else {
      parse_approximate_options(o, job);
    }
  } else {
    if (!o.has("-r")) throw UsageError("missing option -r");
    job.radius = o.number("-r", 0.0, 0.0, std::numeric_limits<double>::infinity());
    job.max_results = o.count("--max-results", no_limit, 1, no_limit);
  }
  job.out = o.required("--out");
  require_extension("--out", job.out, ".ivecs");
  job.distances = o.text("--distances");
  if (!job.distances.empty()) require_extension("--distances", job.distances, ".fvecs");

  job.build = parse_build_params(o);
  job.metric = parse_metric(o);
  if (job.forest_trees > 0) {
    if (job.metric != "l2") throw UsageError("--recall, --forest and --graph search with --metric l2 only");
    for (const char* exact_only : {"--axis", "--position", "--max-depth"})
      if (o.has(exact_only))
        throw UsageError(std::string(exact_only) + " applies to the exact tree, not to --recall, --forest or --graph");
    job.build.leaf_size = o.count("--leaf", ForestParams{}.leaf_size, 1, no_limit);
  }
  if (job.self || !job.boxsize.empty()) {
    const std::string joined = job.self ? "--self" : "--boxsize";
    if (job.forest_trees > 0) throw UsageError(joined + " applies to the exact tree, not to --forest or --recall");
    if (job.eps > 0) throw UsageError(joined + " searches exactly; it cannot be combined with --eps");
  }
  job.threads = static_cast<unsigned>(o.count("--threads", command.default_threads, 0, 4096));
  job.build.threads = job.threads;
  job.stats = o.has("--stats");
  return job;
}

template <class T>
ResultRows result_rows(const NeighborLists<T>& found, bool with_distances) {
  ResultRows rows;
  rows.ids.offsets = found.offsets;
  rows.ids.values.reserve(found.neighbors.size());
  for (const Neighbor<T>& nb : found.neighbors)
    rows.ids.values.push_back(static_cast<std::int32_t>(nb.index));
  if (!with_distances) return rows;
  rows.distances.offsets = found.offsets;
  rows.distances.values.reserve(found.neighbors.size());
  for (const Neighbor<T>& nb : found.neighbors) rows.distances.values.push_back(narrow<float>(nb.distance));
  return rows;
}

template <class T>
void write_results(const NeighborLists<T>& found, const SearchJob& job) {
  const ResultRows rows = result_rows(found, !job.distances.empty());
  io::write_ivecs(job.out, rows.ids);
  if (!job.distances.empty()) io::write_fvecs(job.distances, rows.distances);
}

template ResultRows result_rows<float>(const NeighborLists<float>&, bool);
template ResultRows result_rows<double>(const NeighborLists<double>&, bool);
template void write_results<float>(const NeighborLists<float>&, const SearchJob&);
template void write_results<double>(const NeighborLists<double>&, const SearchJob&);

}  // namespace kdspace::cli
