// The demo's ray step: a generated box scene, the three builds, closest-hit tracing of camera and
// random rays on one and all threads, a sample checked against brute force, and a rendered picture.
#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "demo.hpp"
#include "kdspace/io/scene.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/brute_force.hpp"
#include "kdspace/rays/render.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "png_writer.hpp"
#include "progress.hpp"

namespace kdspace::cli::demo {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::uint32_t scene_seed = 20240602;
constexpr std::size_t checked_rays = 300;  // rays of each kind compared with brute force, per build

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// Million rays a second of the best of up to three runs of closest_hit_batch.
double mrays_per_second(const BoxTree& tree, const std::vector<Ray>& rays, unsigned threads) {
  double best = 1e300;
  for (int run = 0; run < 3; ++run) {
    const auto start = Clock::now();
    tree.closest_hit_batch(rays, threads);
    best = std::min(best, seconds_since(start));
    if (best > 0.5) break;
  }
  return static_cast<double>(rays.size()) / best / 1e6;
}

struct BuildChoice {
  const char* name;
  BoxBuildMethod method;
};

}  // namespace

void ray_shooting_step(Context& context) {
  const Settings& s = context.settings;
  const std::size_t n = s.quick ? 10000 : 100000;
  const std::size_t width = s.quick ? 320 : 800, height = s.quick ? 240 : 600;
  const unsigned all = detail::resolve_threads(s.threads);
  const std::string all_label = std::to_string(all) + (all == 1 ? " thread" : " threads");

  Progress progress("demo: ray scene", Progress::Kind::elapsed);
  const std::vector<Box3f> boxes = generate_boxes(n, SceneKind::clustered, scene_seed);
  Box3f scene = boxes.front();  // the bounds of all boxes
  for (const Box3f& b : boxes)
    for (int a = 0; a < 3; ++a) {
      scene.lo[a] = std::min(scene.lo[a], b.lo[a]);
      scene.hi[a] = std::max(scene.hi[a], b.hi[a]);
    }
  if (!s.out_dir.empty()) {  // for trying `kdspace rays` and `kdspace render` on
    io::write_boxes(context.out_path("scene.boxes"), boxes);
    context.wrote(context.out_path("scene.boxes"));
  }
  const Camera camera = fit_camera(scene, static_cast<double>(width) / static_cast<double>(height));
  const std::vector<Ray> camera_rays = primary_rays(camera, width, height);
  const std::vector<Ray> random = random_rays(s.quick ? 20000 : 200000, scene, scene_seed + 1);
  if (!s.out_dir.empty()) {
    io::write_rays(context.out_path("random.rays"), random);
    context.wrote(context.out_path("random.rays"));
  }

  context.report("\n## Ray shooting: " + with_commas(static_cast<double>(n)) +
                 " boxes in Gaussian clusters, closest hit\n\n"
                 "| build | build s | depth | leaves | refs/box | camera Mrays/s (1 thread) | camera Mrays/s (" +
                 all_label + ") | random Mrays/s (1 thread) | random Mrays/s (" + all_label + ") | exact |\n"
                 "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|\n");
  const BuildChoice builds[] = {{"median", BoxBuildMethod::median},
                                {"sah", BoxBuildMethod::sah},
                                {"sah-nlogn", BoxBuildMethod::sah_nlogn}};
  for (const BuildChoice& choice : builds) {
    BoxBuildParams params;
    params.method = choice.method;
    const auto start = Clock::now();
    const BoxTree tree(boxes, params);
    const double build_s = seconds_since(start);

    bool exact = true;
    for (const std::vector<Ray>* rays : {&camera_rays, &random}) {
      const std::size_t stride = std::max<std::size_t>(1, rays->size() / checked_rays);
      for (std::size_t i = 0; i < rays->size(); i += stride) {
        const Ray& ray = (*rays)[i];
        if (!agrees_with_reference(tree.closest_hit(ray), brute_force_closest_hit(boxes, ray), boxes, ray)) {
          exact = false;
          context.fail(std::string("rays, ") + choice.name + " build: ray " + std::to_string(i + 1) +
                       " disagrees with brute force");
          break;
        }
      }
    }
    const auto& st = tree.stats();
    context.report("| " + std::string(choice.name) + " | " + fixed(build_s, 3) + " | " + std::to_string(st.depth) +
                   " | " + with_commas(static_cast<double>(st.leaves)) + " | " + fixed(st.references_per_box, 2) +
                   " | " + fixed(mrays_per_second(tree, camera_rays, 1), 2) + " | " +
                   fixed(mrays_per_second(tree, camera_rays, all), 2) + " | " +
                   fixed(mrays_per_second(tree, random, 1), 2) + " | " + fixed(mrays_per_second(tree, random, all), 2) +
                   " | " + (exact ? "yes" : "NO") + " |\n");
  }
  context.report("\nCamera rays: " + std::to_string(width) + " x " + std::to_string(height) +
                 " pixels from a corner above the scene; random rays: " + with_commas(static_cast<double>(random.size())) +
                 " with origins in the scene's bounds and uniform directions. Exact: " +
                 std::to_string(checked_rays) + " rays of each kind per build against a brute-force slab test in "
                 "double (same box, t within 1e-6 relative).\n");

  RenderParams render;
  render.width = width;
  render.height = height;
  render.threads = s.threads;
  const BoxTree tree(boxes);
  const auto start = Clock::now();
  const Image image = render_image(tree, camera, render);
  const double render_s = seconds_since(start);
  // The picture is written only under --out: nothing lands in the working folder unasked.
  if (s.out_dir.empty()) {
    context.report("Picture: rendered (" + std::to_string(width) + " x " + std::to_string(height) +
                   ", with shadow rays) in " + fixed(render_s, 3) + " s on " + all_label +
                   "; run with --out DIR to write it.\n");
    return;
  }
  const std::string picture = context.out_path("scene.png");
  write_png(picture, image.rgb.data(), image.width, image.height);
  context.wrote(picture);
  context.report("Picture: " + picture + " (" + std::to_string(width) + " x " + std::to_string(height) +
                 ", with shadow rays), rendered in " + fixed(render_s, 3) + " s on " + all_label + ".\n");
}

}  // namespace kdspace::cli::demo
