// The `kdspace-mpi` command: `mpirun -np P kdspace-mpi knn|radius ...` takes the options of
// `kdspace knn|radius` (lib/cli/search_job.hpp) and writes the same bytes, from a DistributedTree.
//
// Each rank reads its own part of the base and of the query file, the tree spreads the points by
// region, each rank answers the queries of its part, and all ranks write their rows of the result
// files together. Messages: rank 0 prints them; an error of one rank reaches all (see comm.hpp),
// so every rank exits with the same code: 0, 2 (usage), or 1 (bad data, I/O, out of memory).
#include <mpi.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "../comm.hpp"
#include "guard.hpp"
#include "json.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/mpi/distributed_tree.hpp"
#include "kdspace/mpi/read_part.hpp"
#include "kdspace/version.hpp"
#include "options.hpp"
#include "search_job.hpp"
#include "write_rows.hpp"

namespace kdspace::mpi::cli {
namespace {

using kdspace::cli::JsonObject;
using kdspace::cli::Mode;
using kdspace::cli::SearchCommand;
using kdspace::cli::SearchJob;
using kdspace::cli::UsageError;

const char* const usage =
    R"(usage: mpirun -np P kdspace-mpi knn|radius [options]     'kdspace-mpi knn --help' describes one

mpirun -np P kdspace-mpi knn    --base FILE --query FILE -k K --out IDS.ivecs [--distances D.fvecs] [build options] [--threads T] [--stats]
mpirun -np P kdspace-mpi radius --base FILE --query FILE -r R --out IDS.ivecs [--distances D.fvecs] [--max-results M] [build options] [--threads T] [--stats]
kdspace-mpi --version | --help

Exact k-NN and radius search over P MPI ranks, with the options, files and output of 'kdspace knn' and
'kdspace radius': the same bytes whatever P. Each rank reads its own part of the base and query files
(the binary formats by seeking to its rows; .csv by its share of the bytes), the points go to the rank
that owns their region of space, and each rank builds a kd-tree over its region.
Not available here: --eps, --recall, --forest, --checks, --graph, --ef, --degree (approximate search;
use kdspace).
--threads T: threads a rank, default 1 (one rank a core); 0 = all hardware threads.
--stats (rank 0): one JSON object with kdspace's keys (points and nodes summed over ranks, depth the
  deepest rank's tree) and ranks, read_s, rounds, ranks_per_query, messages, bytes,
  messages_per_query, bytes_per_query (the query phase, between ranks), build_messages, build_bytes,
  points_per_rank_min, points_per_rank_max.
Exit codes: 0 success, 2 usage error, 1 bad data or I/O error (the same on every rank); messages on
  stderr (from rank 0) as  kdspace: error: rank R of P: FILE: row N: what is wrong
)";

const SearchCommand mpi_command{
    "kdspace-mpi", "not available in kdspace-mpi: it searches exactly (use kdspace for approximate search)",
    "not available in kdspace-mpi (use kdspace for --self and --boxsize)", 1,
    "threads a rank for its build and its searches; default 1 (one rank a core); 0 = all hardware threads",
    "not available in kdspace-mpi: every rank builds the tree of its own part of the base"};

double seconds_since(double start) {
  return MPI_Wtime() - start;
}

// The longest time any rank took, on every rank.
double slowest(const detail::Comm& comm, double seconds) {
  MPI_Allreduce(MPI_IN_PLACE, &seconds, 1, MPI_DOUBLE, MPI_MAX, comm.get());
  return seconds;
}

template <class T, class Metric>
int run_search(const SearchJob& job, const detail::Comm& comm) {
  MPI_Barrier(comm.get());
  double start = MPI_Wtime();
  FilePart<T> base = read_part<T>(comm.get(), job.base);
  FilePart<T> queries = read_part<T>(comm.get(), job.query);
  const double read_s = slowest(comm, seconds_since(start));
  // Checks that every rank makes alike, with kdspace's messages.
  if (queries.cols != base.cols)
    throw Error(job.query + ": dimension " + std::to_string(queries.cols) + " does not match the base (" +
                job.base + ": dimension " + std::to_string(base.cols) + ")");
  if (job.mode == Mode::knn && job.k > base.total_rows)
    throw Error("k = " + std::to_string(job.k) + " exceeds the number of base points (" + job.base + " has " +
                std::to_string(base.total_rows) + ")");

  DistributedParams params;
  params.build = job.build;
  MPI_Barrier(comm.get());
  start = MPI_Wtime();
  const DistributedTree<T, Metric> tree(comm.get(), base.points.data.data(), base.points.rows, base.cols,
                                        params);
  const double build_s = slowest(comm, seconds_since(start));
  base.points = {};  // the tree holds its own copy

  DistributedStats stats;
  MPI_Barrier(comm.get());
  start = MPI_Wtime();
  const NeighborLists<T> found =
      job.mode == Mode::knn
          ? tree.knn_batch(queries.points.data.data(), queries.points.rows, job.k, job.threads, &stats)
          : tree.radius_batch(queries.points.data.data(), queries.points.rows,
                              kdspace::cli::narrow<T>(job.radius), job.max_results, job.threads, &stats);
  const double query_s = slowest(comm, seconds_since(start));

  {
    // This rank's rows of each file, as the bytes kdspace writes.
    std::vector<unsigned char> id_bytes, distance_bytes;
    comm.phase([&] {
      const kdspace::cli::ResultRows rows = kdspace::cli::result_rows(found, !job.distances.empty());
      id_bytes = io::ivecs_bytes(job.out, rows.ids);
      if (!job.distances.empty()) distance_bytes = io::fvecs_bytes(job.distances, rows.distances);
    });
    SharedOutput ids(comm, job.out, id_bytes);
    if (job.distances.empty()) {
      ids.commit();
    } else {
      SharedOutput distances(comm, job.distances, distance_bytes);
      ids.commit();
      distances.commit();
    }
  }

  if (!job.stats) return 0;
  // Sums over ranks (rank 0 prints them).
  std::vector<std::uint64_t> figures = {
      stats.search.nodes_visited, stats.search.points_visited, stats.ranks_asked,
      stats.traffic.messages,     stats.traffic.bytes,         tree.build_traffic().messages,
      tree.build_traffic().bytes, tree.local_leaves(),         tree.local_nodes(),
      tree.local_index_bytes(),   found.neighbors.size()};
  MPI_Allreduce(MPI_IN_PLACE, figures.data(), static_cast<int>(figures.size()), MPI_UINT64_T, MPI_SUM,
                comm.get());
  std::uint64_t extremes[3] = {tree.local_depth(), tree.local_size(), ~std::uint64_t{tree.local_size()}};
  MPI_Allreduce(MPI_IN_PLACE, extremes, 3, MPI_UINT64_T, MPI_MAX, comm.get());
  const std::uint64_t total_queries = queries.total_rows;
  if (comm.rank() != 0) return 0;
  const double nq = static_cast<double>(total_queries);
  auto per_query = [&](std::uint64_t v) { return total_queries > 0 ? static_cast<double>(v) / nq : 0.0; };
  JsonObject json;
  json.add("command", job.mode == Mode::knn ? "knn" : "radius")
      .add("ranks", std::uint64_t(comm.size()))
      .add("points", std::uint64_t{tree.size()})
      .add("dim", std::uint64_t{tree.dim()})
      .add("queries", total_queries);
  if (job.mode == Mode::knn) {
    json.add("k", std::uint64_t{job.k});
  } else {
    json.add("radius", job.radius).add("results", figures[10]);
    if (job.max_results != std::numeric_limits<std::size_t>::max())
      json.add("max_results", std::uint64_t{job.max_results});
  }
  json.add("metric", Metric::name)
      .add("scalar", sizeof(T) == sizeof(double) ? "double" : "float")
      .add("threads", job.threads)
      .add("read_s", read_s)
      .add("build_s", build_s)
      .add("query_s", query_s)
      .add("queries_per_s", query_s > 0 ? nq / query_s : std::numeric_limits<double>::infinity())
      .add("depth", extremes[0])
      .add("leaves", figures[7])
      .add("nodes", figures[8])
      .add("index_bytes", figures[9])
      .add("nodes_visited_per_query", per_query(figures[0]))
      .add("points_visited_per_query", per_query(figures[1]))
      .add("rounds", stats.rounds)
      .add("ranks_per_query", per_query(figures[2]))
      .add("messages", figures[3])
      .add("bytes", figures[4])
      .add("messages_per_query", per_query(figures[3]))
      .add("bytes_per_query", per_query(figures[4]))
      .add("build_messages", figures[5])
      .add("build_bytes", figures[6])
      .add("points_per_rank_min", ~extremes[2])
      .add("points_per_rank_max", extremes[1]);
  std::printf("%s\n", json.str().c_str());
  return 0;
}

template <class T>
struct Type {
  using type = T;
};

int run_search_command(Mode mode, const std::vector<std::string>& args, const detail::Comm& comm) {
  if (kdspace::cli::wants_help(args)) {
    if (comm.rank() == 0) std::fputs(kdspace::cli::search_usage(mode, mpi_command).c_str(), stdout);
    return 0;
  }
  const SearchJob job = kdspace::cli::parse_job(mode, args, mpi_command);
  io::format_from_path(job.base);  // an unknown extension fails now, not after reading
  io::format_from_path(job.query);
  auto with_metric = [&](auto scalar) {
    using T = typename decltype(scalar)::type;
    if (job.metric == "l1") return run_search<T, L1>(job, comm);
    if (job.metric == "linf") return run_search<T, Linf>(job, comm);
    return run_search<T, L2>(job, comm);
  };
  // stores_double reads a .npy header: a file every rank can open, or an error every rank sees.
  bool wide = false;
  comm.phase([&] { wide = io::stores_double(job.base); });
  return wide ? with_metric(Type<double>{}) : with_metric(Type<float>{});
}

// Runs the command on every rank. Errors every rank sees alike (usage, and those the ranks agreed
// on) are printed once, by rank 0.
int run(const std::vector<std::string>& words, const detail::Comm& comm) {
  auto say = [&](const std::string& what) {
    if (comm.rank() == 0) kdspace::cli::print_error(what);
  };
  if (words.empty()) {
    if (comm.rank() == 0) std::fputs(usage, stderr);
    return 2;
  }
  const std::string& command = words[0];
  const std::vector<std::string> args(words.begin() + 1, words.end());
  if (command == "--help" || command == "-h" || command == "help") {
    if (comm.rank() == 0) std::fputs(usage, stdout);
    return 0;
  }
  if (command == "--version") {
    if (comm.rank() == 0) std::printf("kdspace-mpi %s\n", kdspace::version);
    return 0;
  }
  if (command != "knn" && command != "radius") {
    say("unknown command '" + command + "' (kdspace-mpi runs knn and radius)");
    if (comm.rank() == 0) std::fputs("run 'kdspace-mpi --help'\n", stderr);
    return 2;
  }
  try {
    return run_search_command(command == "knn" ? Mode::knn : Mode::radius, args, comm);
  } catch (const UsageError& e) {
    say(e.what());
    if (comm.rank() == 0) std::fprintf(stderr, "run 'kdspace-mpi %s --help'\n", command.c_str());
    return 2;
  } catch (const Error& e) {
    say(e.what());
    return 1;
  }
}

}  // namespace
}  // namespace kdspace::mpi::cli

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int code = 1;
  {
    const kdspace::mpi::detail::Comm comm(MPI_COMM_WORLD);
    const std::vector<std::string> words(argv + (argc > 0 ? 1 : 0), argv + argc);
    try {
      code = kdspace::mpi::cli::run(words, comm);
    } catch (...) {
      // Not agreed with the other ranks (a bug, or memory running out outside a phase): they may be
      // waiting for this one, so the job ends here, all ranks with it.
      std::fprintf(stderr, "kdspace: error: rank %d of %d: %s\n", comm.rank(), comm.size(),
                   kdspace::mpi::detail::Comm::describe(std::current_exception()).c_str());
      MPI_Abort(MPI_COMM_WORLD, 1);
    }
    if (comm.rank() == 0 && (std::fflush(stdout) != 0 || std::ferror(stdout))) {
      kdspace::cli::print_error("cannot write to standard output");
      if (code == 0) code = 1;
    }
  }
  MPI_Finalize();
  return code;
}
