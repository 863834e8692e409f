// The options of `kdspace knn` and `kdspace radius`, and how their results are written. One piece
// shared by the commands that take them: `kdspace` (knn_command.cpp) and `kdspace-mpi` (lib/mpi/cli/),
// so that both accept the same words, check them the same way and write the same bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/io/vectors.hpp"
#include "kdspace/points/neighbor.hpp"
#include "kdspace/points/params.hpp"
#include "kdspace/points/point_forest.hpp"

namespace kdspace::cli {

enum class Mode { knn, radius };

/// What differs between the commands that share these options.
struct SearchCommand {
  std::string program = "kdspace";  ///< as the usage line and the --help hint name it
  /// When set, --eps, --recall, --forest, --checks, --graph, --ef and --degree are refused with this
  /// reason (exact search only).
  std::string approximate_refused_because = {};
  /// When set, --self and --boxsize (searches by the dual-tree joins) are refused with this reason.
  std::string joins_refused_because = {};
  unsigned default_threads = 0;  ///< --threads when absent; 0 = all hardware threads
  /// The --threads line of the usage text, with the default.
  std::string threads_help = "threads for the build and the queries; 0 (default) = all hardware threads";
  /// When set, --index (answer from a saved index) is refused with this reason.
  std::string index_refused_because = {};
};

struct SearchJob {
  Mode mode = Mode::knn;
  std::string base, query, out, distances;
  std::string index;  ///< a saved index answers instead of a tree built over base (then empty)
  Verify verify = Verify::safety;  ///< --verify: how much of a point tree index its load checks
  BuildParams build;
  std::string metric = "l2";
  std::size_t k = 0;
  double radius = 0;
  std::size_t max_results = std::numeric_limits<std::size_t>::max();
  double eps = 0;
  std::size_t forest_trees = 0;  // 0: the exact tree; else the trees built for the approximate index
  std::size_t checks = 256;  // with --index: 0 = the setting stored in a forest index
  bool use_graph = false;  // the graph is searched (with ef) or, with --recall, may be chosen
  bool use_trees = false;  // the trees are searched (with checks) or, with --recall, may be chosen
  std::size_t ef = 64;       // with --index: 0 = the setting stored in a forest index
  std::size_t degree = ForestParams{}.graph_degree;
  double recall = 0;  // 0: no tuning
  bool self = false;            // knn: each base point's K nearest other points; no query file
  std::vector<double> boxsize;  // periodic boundaries (empty: none)
  unsigned threads = 0;
  bool stats = false;
};

/// The --help text of `PROGRAM knn` or `PROGRAM radius`.
std::string search_usage(Mode mode, const SearchCommand& command = {});

/// Parses and checks the words after the subcommand. Throws UsageError.
SearchJob parse_job(Mode mode, const std::vector<std::string>& args, const SearchCommand& command = {});

/// A non-negative value as T; beyond float's range it becomes infinity (a plain cast would be
/// undefined behaviour). Used for distances written to .fvecs and for the radius of a float tree.
template <class T, class From>
T narrow(From v) {
  if (sizeof(T) < sizeof(From) && v > static_cast<From>(std::numeric_limits<T>::max()))
    return std::numeric_limits<T>::infinity();
  return static_cast<T>(v);
}

/// The rows of IDS.ivecs and D.fvecs: ids of the neighbours and their distances as float32.
struct ResultRows {
  io::RaggedRows<std::int32_t> ids;
  io::RaggedRows<float> distances;  ///< empty unless asked for
};

template <class T>
ResultRows result_rows(const NeighborLists<T>& found, bool with_distances);

/// Writes --out (and --distances when given).
template <class T>
void write_results(const NeighborLists<T>& found, const SearchJob& job);

}  // namespace kdspace::cli
