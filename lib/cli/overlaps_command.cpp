// The command `kdspace overlaps` (see /DESIGN.md, "The command kdspace").
#include <chrono>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "box_inputs.hpp"
#include "commands.hpp"
#include "guard.hpp"
#include "json.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/io/pairs.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "options.hpp"
#include "progress.hpp"

using namespace kdspace;
using namespace kdspace::cli;

namespace {

using Clock = std::chrono::steady_clock;

const char* const overlaps_usage =
    R"(usage: kdspace overlaps --boxes A.boxes [--with B.boxes] --out PAIRS.pairs
                        [--build binned|sah-nlogn|sah|median] [--threads T] [--stats]
Finds every pair of overlapping boxes: within A (a < b), or between A and B (a in A, b in B). Boxes
are closed: boxes that share only a face, an edge or a corner overlap.
  --boxes A       uint64 N, then N x 6 float32: min x y z, max x y z
  --with B        a second set of boxes in the same format
  --out PAIRS     uint64 M, then M x (uint32 a, uint32 b), sorted by (a, b), each pair once; written
                  to a temporary file and renamed when complete
  --build B       binned (default: the cheapest build, made for this), sah-nlogn, sah, median
  --threads T     threads for the pair search; 0 (default) = all hardware threads
  --stats         one JSON object on stdout: build_s, query_s, pairs, threads, depth, leaves, ...
A set of 0 boxes (a file whose count is 0) is valid and gives no pairs; an empty file (0 bytes), a
truncated file, a box with min > max or a coordinate that is not finite are errors naming the file
and the box. The pairs are held in memory before writing: 8 bytes each.
Exit codes: 0 success, 2 usage error, 1 bad data or I/O error.
)";

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

int overlaps_command(const std::vector<std::string>& args) {
  if (wants_help(args)) {
    std::fputs(overlaps_usage, stdout);
    return 0;
  }
  const Options o(args, {{"--boxes"}, {"--with"}, {"--out"}, {"--build"}, {"--threads"}, {"--stats", false}});
  const std::string boxes_path = o.required("--boxes");
  const std::string with_path = o.text("--with");
  const std::string out_path = o.required("--out");
  const std::string build = o.choice("--build", "binned", {"binned", "sah-nlogn", "sah", "median"});
  const auto threads = static_cast<unsigned>(o.count("--threads", 0, 0, 4096));
  check_output_folder(out_path);

  const std::vector<Box3f> boxes = read_boxes_with_progress(boxes_path);
  const bool two_sets = o.has("--with");
  std::vector<Box3f> other;
  if (two_sets) other = read_boxes_with_progress(with_path);

  BoxBuildParams params;
  params.method = build_method(build);
  params.threads = threads;
  double build_s = 0;
  const BoxTree tree = build_with_progress(boxes, params, build_s);
  double other_build_s = 0;
  const BoxTree other_tree = build_with_progress(other, params, other_build_s);
  build_s += other_build_s;

  CollideStats stats;
  std::vector<IndexPair> pairs;
  const Clock::time_point start = Clock::now();
  {
    Progress progress("finding pairs", Progress::Kind::elapsed);
    pairs = two_sets ? overlapping_pairs(tree, other_tree, threads, &stats)
                     : overlapping_pairs(tree, threads, &stats);
  }
  const double query_s = seconds_since(start);

  io::write_pairs(out_path, pairs);

  if (o.has("--stats")) {
    const BoxTreeStats& s = tree.stats();
    JsonObject json;
    json.add("command", "overlaps").add("boxes", std::uint64_t{boxes.size()});
    if (two_sets) json.add("with_boxes", std::uint64_t{other.size()});
    json.add("build", build)
        .add("threads", detail::resolve_threads(threads))
        .add("build_s", build_s)
        .add("query_s", query_s)
        .add("pairs", std::uint64_t{pairs.size()})
        .add("depth", std::uint64_t{s.depth})
        .add("leaves", std::uint64_t{s.leaves})
        .add("references_per_box", s.references_per_box);
    if (two_sets)
      json.add("with_depth", std::uint64_t{other_tree.stats().depth})
          .add("with_leaves", std::uint64_t{other_tree.stats().leaves});
    json.add("boxes_tested", stats.boxes_tested);
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

}  // namespace

int run_overlaps_command(const std::vector<std::string>& args) {
  return run_guarded("overlaps", [&] { return overlaps_command(args); });
}
