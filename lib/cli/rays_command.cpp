// The commands `kdspace rays` and `kdspace render` (see /DESIGN.md, "The command kdspace").
#include <chrono>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "box_inputs.hpp"
#include "commands.hpp"
#include "guard.hpp"
#include "json.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/scene.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/render.hpp"
#include "options.hpp"
#include "png_writer.hpp"
#include "progress.hpp"

using namespace kdspace;
using namespace kdspace::cli;

namespace {

using Clock = std::chrono::steady_clock;

const char* const rays_usage =
    R"(usage: kdspace rays --boxes FILE --rays FILE --out HITS [--build median|sah|sah-nlogn]
                    [--threads T] [--any-hit] [--stats]
Traces every ray of the .rays file through the boxes of the .boxes file and writes, for each ray, the
index of the first box it hits (-1 for none) and the ray parameter t of the hit (+inf for none).
  --boxes FILE    uint64 N, then N x 6 float32: min x y z, max x y z
  --rays FILE     uint64 M, then M x 6 float32: origin x y z, direction x y z (any non-zero length)
  --out HITS      uint64 M, then M x (int32 box, float32 t)
  --build B       sah-nlogn (default; Wald & Havran's O(N log N) SAH build), sah (the same tree,
                  O(N log^2 N)), median (axis cycling, plane at the middle of the cell)
  --threads T     threads for the build and the tracing; 0 (default) = all hardware threads
  --any-hit       some box hit by each ray (the first found), not the closest
  --stats         one JSON object on stdout: build_s, trace_s, mrays_per_s, threads, depth, leaves,
                  nodes_visited_per_ray, boxes_tested_per_ray, ...
A ray hits a closed, solid box; a ray starting inside a box hits it at t = 0; equal t goes to the
smaller box index.
Exit codes: 0 success, 2 usage error, 1 bad data or I/O error.
)";

const char* const render_usage =
    R"(usage: kdspace render --boxes FILE --out IMAGE.png [--width W] [--height H]
                      [--build median|sah|sah-nlogn] [--threads T] [--no-shadows] [--stats]
Draws the boxes seen from a diagonal direction, each in its own colour, shaded by the face hit and
a light above the camera, with shadows; the camera is fitted to the scene.
  --width W, --height H   image size in pixels, 1 to 32768 (default 800 x 600)
  --threads T             0 (default) = all hardware threads
  --stats                 one JSON object on stdout: build_s, render_s, ...
Exit codes: 0 success, 2 usage error, 1 bad data or I/O error.
)";

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

int rays_command(const std::vector<std::string>& args) {
  if (wants_help(args)) {
    std::fputs(rays_usage, stdout);
    return 0;
  }
  const Options o(args, {{"--boxes"},
                         {"--rays"},
                         {"--out"},
                         {"--build"},
                         {"--threads"},
                         {"--any-hit", false},
                         {"--stats", false}});
  const std::string boxes_path = o.required("--boxes");
  const std::string rays_path = o.required("--rays");
  const std::string out_path = o.required("--out");
  const std::string build = o.choice("--build", "sah-nlogn", {"median", "sah", "sah-nlogn"});
  const auto threads = static_cast<unsigned>(o.count("--threads", 0, 0, 4096));
  const bool any_hit = o.has("--any-hit");
  check_output_folder(out_path);

  const std::vector<Box3f> boxes = read_boxes_with_progress(boxes_path);
  std::vector<Ray> rays;
  {
    Progress progress("reading " + rays_path, Progress::Kind::elapsed);
    rays = io::read_rays(rays_path);
  }

  BoxBuildParams params;
  params.method = build_method(build);
  params.threads = threads;
  double build_s = 0;
  const BoxTree tree = build_with_progress(boxes, params, build_s);

  RayStats stats;
  std::vector<Hit> hits;
  Clock::time_point start = Clock::now();
  {
    Progress progress("tracing", Progress::Kind::elapsed);
    hits =
        any_hit ? tree.any_hit_batch(rays, threads, &stats) : tree.closest_hit_batch(rays, threads, &stats);
  }
  const double trace_s = seconds_since(start);

  io::write_hits(out_path, hits);

  if (o.has("--stats")) {
    std::uint64_t hit_count = 0;
    for (const Hit& h : hits) hit_count += h.hit() ? 1 : 0;
    const BoxTreeStats& s = tree.stats();
    JsonObject json;
    json.add("command", "rays")
        .add("boxes", std::uint64_t{boxes.size()})
        .add("rays", std::uint64_t{rays.size()})
        .add("build", build)
        .add("query", any_hit ? "any-hit" : "closest-hit")
        .add("threads", detail::resolve_threads(threads))
        .add("build_s", build_s)
        .add("trace_s", trace_s)
        .add("mrays_per_s", trace_s > 0 ? static_cast<double>(rays.size()) / trace_s / 1e6
                                        : std::numeric_limits<double>::infinity())
        .add("depth", std::uint64_t{s.depth})
        .add("leaves", std::uint64_t{s.leaves})
        .add("nodes", std::uint64_t{s.nodes})
        .add("references_per_box", s.references_per_box)
        .add("sah_cost", s.sah_cost)
        .add("nodes_visited_per_ray", stats.nodes_visited_per_ray())
        .add("boxes_tested_per_ray", stats.boxes_tested_per_ray())
        .add("hits", hit_count);
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

int render_command(const std::vector<std::string>& args) {
  if (wants_help(args)) {
    std::fputs(render_usage, stdout);
    return 0;
  }
  const Options o(args, {{"--boxes"},
                         {"--out"},
                         {"--width"},
                         {"--height"},
                         {"--build"},
                         {"--threads"},
                         {"--no-shadows", false},
                         {"--stats", false}});
  const std::string boxes_path = o.required("--boxes");
  const std::string out_path = o.required("--out");
  RenderParams render;
  render.width = o.count("--width", 800, 1, 32768);
  render.height = o.count("--height", 600, 1, 32768);
  render.shadows = !o.has("--no-shadows");
  render.threads = static_cast<unsigned>(o.count("--threads", 0, 0, 4096));
  const std::string build = o.choice("--build", "sah-nlogn", {"median", "sah", "sah-nlogn"});
  check_output_folder(out_path);

  const std::vector<Box3f> boxes = read_boxes_with_progress(boxes_path);
  if (boxes.empty()) throw Error(boxes_path + ": no boxes to draw");
  BoxBuildParams params;
  params.method = build_method(build);
  params.threads = render.threads;
  double build_s = 0;
  const BoxTree tree = build_with_progress(boxes, params, build_s);

  Image image;
  const Clock::time_point start = Clock::now();
  {
    Progress progress("rendering", Progress::Kind::elapsed);
    image = render_image(tree, render);
  }
  const double render_s = seconds_since(start);
  write_png(out_path, image.rgb.data(), image.width, image.height);

  if (o.has("--stats")) {
    JsonObject json;
    json.add("command", "render")
        .add("boxes", std::uint64_t{boxes.size()})
        .add("build", build)
        .add("threads", detail::resolve_threads(render.threads))
        .add("width", std::uint64_t{image.width})
        .add("height", std::uint64_t{image.height})
        .add("build_s", build_s)
        .add("render_s", render_s)
        .add("depth", std::uint64_t{tree.stats().depth})
        .add("leaves", std::uint64_t{tree.stats().leaves})
        .add("sah_cost", tree.stats().sah_cost);
    std::printf("%s\n", json.str().c_str());
  }
  return 0;
}

}  // namespace

int run_rays_command(const std::vector<std::string>& args) {
  return run_guarded("rays", [&] { return rays_command(args); });
}

int run_render_command(const std::vector<std::string>& args) {
  return run_guarded("render", [&] { return render_command(args); });
}
