// The `kdspace` command: picks the subcommand and hands it the rest of the words.
#include <cstdio>
#include <string>
#include <vector>

#include "commands.hpp"
#include "guard.hpp"
#include "kdspace/version.hpp"

namespace {

const char* const usage =
    R"(usage: kdspace COMMAND [options]        'kdspace COMMAND --help' describes one command

kdspace knn    --base FILE --query FILE -k K  --out IDS.ivecs [--distances D.fvecs] [build options] [--eps E] [--threads T] [--stats]
kdspace radius --base FILE --query FILE -r R  --out IDS.ivecs [--distances D.fvecs] [--max-results M] [build options] [--threads T] [--stats]
kdspace index  --base FILE --out INDEX.kdx [build options | --forest T [--checks C] | --recall R [-k K]] [--stats]
kdspace index  --update INDEX.kdx [--add FILE] [--remove IDS.ivecs] [--out NEW.kdx] [--stats]
kdspace knn|radius --index INDEX.kdx --query FILE ...   answers from a saved index (memory-mapped)
kdspace rays   --boxes FILE --rays FILE --out HITS.bin [--build median|sah|sah-nlogn] [--threads T] [--stats]
kdspace render --boxes FILE --out IMAGE.png [--width W] [--height H]
kdspace pairs  --base A [--with B] -r R --out PAIRS.pairs [--metric M] [--boxsize L1,L2,...] [--threads T] [--stats]
kdspace count  --base A [--with B] -r R1,R2,... [--metric M] [--boxsize L1,L2,...]   (JSON: radii, counts)
kdspace overlaps --boxes A.boxes [--with B.boxes] --out PAIRS.pairs [--build binned|sah-nlogn|sah|median] [--threads T] [--stats]
kdspace demo   [--out DIR] [--threads T] [--quick]
               runs the whole library on built-in generated data, checks it, prints a table
kdspace --version | --help
build options: --axis cycle|spread  --position midpoint|median|middle|sliding  --leaf N  --max-depth D  --metric l2|l1|linf
               (defaults: spread, midpoint, 24, 64, l2)
approximate:   --eps E (exact tree, (1+E) bound)  |  --forest T --checks C (randomized forest)  |  --recall R (tune the forest, then search)
               (--forest and --recall: l2 only; distances returned are exact; see 'kdspace knn --help')

Files: .fvecs .ivecs .bvecs (ANN benchmark convention), .csv (optional header line), .npy (2-D float32/float64),
  chosen by the extension. A .csv or float64 .npy base is searched in double precision, any other base in
  float. The queries must have the dimension of the base.
Results: IDS.ivecs holds one row per query: 0-based indices of base points, nearest first, equal distances
  by smaller index; D.fvecs the true distances (Euclidean for l2, not squared). Radius rows differ in length.
-k K: a whole number >= 1 (-k 0 is a usage error, exit 2); K above the number of base points is an error
  (exit 1), never silently shortened.
-r R: a finite number >= 0 in the data's units (not squared); a negative or NaN radius is a usage error.
  --max-results M keeps only the M nearest within R.
--threads T: 0 (the default) uses all hardware threads, for the build and for the queries; the check of a
  loaded index runs on as many as pay for their start (about the square root of the MiB it reads).
--stats: one JSON object on stdout: build_s, query_s, queries_per_s, threads, depth, leaves,
  nodes_visited_per_query, points_visited_per_query, points, dim, queries, k or radius, metric, index_bytes.
  Times are wall seconds of that phase alone, without file I/O.
Long reads and builds show progress on stderr when it is a terminal.
Exit codes: 0 success, 2 usage error, 1 bad data or I/O error; messages on stderr as
  kdspace: error: FILE: row R: what is wrong
)";

/// Runs a subcommand; -1 when there is none of that name.
int dispatch(const std::string& command, const std::vector<std::string>& args) {
  if (command == "knn") return run_knn_command(args);
  if (command == "radius") return run_radius_command(args);
  if (command == "demo") return run_demo_command(args);
  if (command == "rays") return run_rays_command(args);
  if (command == "render") return run_render_command(args);
  if (command == "pairs") return run_pairs_command(args);
  if (command == "count") return run_count_command(args);
  if (command == "index") return run_index_command(args);
  if (command == "overlaps") return run_overlaps_command(args);
  return -1;
}

int unknown_command(const std::string& command) {
  kdspace::cli::print_error("unknown command '" + command + "'");
  std::fputs("run 'kdspace --help'\n", stderr);
  return 2;
}

/// A command's exit code, made 1 if what it printed on stdout could not all be written.
int with_stdout_checked(int code) {
  if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
    kdspace::cli::print_error("cannot write to standard output");
    return code == 0 ? 1 : code;
  }
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> words(argv + (argc > 0 ? 1 : 0), argv + argc);
  if (words.empty()) {
    std::fputs(usage, stderr);
    return 2;
  }
  const std::string& command = words[0];
  const std::vector<std::string> args(words.begin() + 1, words.end());

  if (command == "--help" || command == "-h" || command == "help") {
    if (command == "help" && !args.empty()) {  // "kdspace help knn" = "kdspace knn --help"
      const int code = dispatch(args[0], {"--help"});
      return code < 0 ? unknown_command(args[0]) : with_stdout_checked(code);
    }
    std::fputs(usage, stdout);
    return with_stdout_checked(0);
  }
  if (command == "--version") {
    std::printf("kdspace %s\n", kdspace::version);
    return with_stdout_checked(0);
  }
  const int code = dispatch(command, args);
  return code < 0 ? unknown_command(command) : with_stdout_checked(code);
}
