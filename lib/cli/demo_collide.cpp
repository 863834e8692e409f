// The demo's collision step: all overlapping pairs of a generated scene with two builds, boxes moving
// for many frames (MovingScene), overlap queries and first contacts, each checked against brute
// force; and, under --out, a picture of the last frame with the colliding boxes in red.
#include <algorithm>
#include <array>
#include <chrono>
#include <string>
#include <vector>

#include "demo.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/brute_force.hpp"
#include "kdspace/collide/contact.hpp"
#include "kdspace/collide/motion_gen.hpp"
#include "kdspace/collide/moving_scene.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/rays/render.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "png_writer.hpp"
#include "progress.hpp"

namespace kdspace::cli::demo {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::uint32_t scene_seed = 20240716;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct MotionChoice {
  const char* name;
  MotionKind kind;
  double moving_share;
};

/// Overlap queries and first contacts of a few boxes of the scene, against brute force.
bool queries_exact(Context& context, const BoxTree& tree, const std::vector<Box3f>& boxes) {
  const std::size_t stride = std::max<std::size_t>(1, boxes.size() / 200);
  for (std::size_t i = 0; i < boxes.size(); i += stride) {
    if (overlapping(tree, boxes[i]) != brute_force_overlapping(boxes, boxes[i])) {
      context.fail("collisions: overlap query of box " + std::to_string(i + 1) +
                   " disagrees with brute force");
      return false;
    }
    const Vec3f motion{0.05f, -0.02f, 0.01f * static_cast<float>(i % 5)};
    const Contact got = first_contact(tree, boxes[i], motion);
    const Contact want = brute_force_first_contact(boxes, boxes[i], motion);
    if (got.box != want.box || got.t != want.t) {
      context.fail("collisions: first contact of box " + std::to_string(i + 1) +
                   " disagrees with brute force");
      return false;
    }
  }
  return true;
}

/// The scene of the moving boxes: the uniform scene with every box shrunk to half its size about its
/// centre, so that a box touches others now and then rather than always.
std::vector<Box3f> sparse_boxes(std::size_t n) {
  std::vector<Box3f> boxes = generate_boxes(n, SceneKind::uniform, scene_seed + 1);
  for (Box3f& b : boxes)
    for (int a = 0; a < 3; ++a) {
      const float centre = 0.5f * b.lo[a] + 0.5f * b.hi[a], quarter = 0.25f * (b.hi[a] - b.lo[a]);
      b.lo[a] = centre - quarter;
      b.hi[a] = std::max(b.lo[a], centre + quarter);
    }
  return boxes;
}

}  // namespace

void collision_step(Context& context) {
  const Settings& s = context.settings;
  const unsigned all = detail::resolve_threads(s.threads);
  const std::string all_label = std::to_string(all) + (all == 1 ? " thread" : " threads");
  Progress progress("demo: collisions", Progress::Kind::elapsed);

  // ---- all pairs of a static scene ----
  const std::size_t n = s.quick ? 10000 : 100000;
  const std::vector<Box3f> boxes = generate_boxes(n, SceneKind::clustered, scene_seed);
  const std::vector<IndexPair> expected = brute_force_pairs(boxes);
  context.report("\n## Collisions: all overlapping pairs of " + with_commas(static_cast<double>(n)) +
                 " boxes in Gaussian clusters\n\n"
                 "| build | build s | pairs s (1 thread) | pairs s (" +
                 all_label + ") | pairs | exact |\n|---|---:|---:|---:|---:|---|\n");
  for (const BoxBuildMethod method : {BoxBuildMethod::binned, BoxBuildMethod::sah_nlogn}) {
    BoxBuildParams params;
    params.method = method;
    auto start = Clock::now();
    const BoxTree tree(boxes, params);
    const double build_s = seconds_since(start);
    start = Clock::now();
    const std::vector<IndexPair> one = overlapping_pairs(tree, 1);
    const double one_s = seconds_since(start);
    start = Clock::now();
    const std::vector<IndexPair> many = overlapping_pairs(tree, all);
    const double many_s = seconds_since(start);
    const char* name = method == BoxBuildMethod::binned ? "binned" : "sah-nlogn";
    bool exact = one == expected && many == expected;
    if (!exact) context.fail(std::string("collisions, ") + name + " build: pairs differ from brute force");
    exact = queries_exact(context, tree, boxes) && exact;
    context.report("| " + std::string(name) + " | " + fixed(build_s, 3) + " | " + fixed(one_s, 3) + " | " +
                   fixed(many_s, 3) + " | " + with_commas(static_cast<double>(one.size())) + " | " +
                   (exact ? "yes" : "NO") + " |\n");
  }
  context.report(
      "\nExact: the pairs equal a brute-force sweep along x; 200 overlap queries and first contacts "
      "equal testing every box.\n");

  // ---- moving boxes ----
  const std::size_t m = s.quick ? 2000 : 20000;
  const int frames = s.quick ? 20 : 60;
  const MotionChoice motions[] = {{"Brownian, all move", MotionKind::brownian, 1.0},
                                  {"free fall, all move", MotionKind::free_fall, 1.0},
                                  {"Brownian, 10% move", MotionKind::brownian, 0.1}};
  context.report(
      "\n## Collisions of " + with_commas(static_cast<double>(m)) +
      " moving boxes (half the mean spacing), " + std::to_string(frames) + " frames (MovingScene, " +
      all_label +
      ")\n\n| motion | ms a frame | pairs a frame | rebuilds | exact |\n|---|---:|---:|---:|---|\n");
  std::vector<Box3f> last_frame;
  std::vector<IndexPair> last_pairs;
  for (const MotionChoice& motion : motions) {
    MotionSimulation simulation(sparse_boxes(m), motion.kind, motion.moving_share, scene_seed + 2);
    MovingSceneParams params;
    params.threads = s.threads;
    MovingScene scene(params);
    double seconds = 0;
    std::size_t pairs = 0, rebuilds = 0;
    bool exact = true;
    for (int frame = 0; frame < frames; ++frame) {
      const std::vector<Box3f>& now = frame == 0 ? simulation.boxes() : simulation.step();
      const auto start = Clock::now();
      const std::vector<IndexPair>& found = scene.step(now);
      seconds += seconds_since(start);
      pairs += found.size();
      rebuilds += scene.last_frame().rebuilt ? 1 : 0;
      if ((frame % 10 == 9 || frame + 1 == frames) && exact && found != brute_force_pairs(now)) {
        exact = false;
        context.fail(std::string("collisions, ") + motion.name + ": frame " + std::to_string(frame + 1) +
                     " differs from brute force");
      }
    }
    context.report("| " + std::string(motion.name) + " | " + fixed(1000 * seconds / frames, 2) + " | " +
                   with_commas(static_cast<double>(pairs) / frames) + " | " + std::to_string(rebuilds) +
                   " | " + (exact ? "yes" : "NO") + " |\n");
    if (motion.kind == MotionKind::free_fall && motion.moving_share == 1.0) {
      last_frame = simulation.boxes();
      last_pairs = scene.pairs();
    }
  }
  context.report(
      "\nThe tree is refitted each frame (planes kept, boxes sent down again) and rebuilt when its "
      "leaves have come to cost 1.5 times the box tests they cost when built; when few boxes move, "
      "only they look for partners. Exact: every tenth frame equals a brute-force sweep.\n");

  // ---- the picture: the last frame of the free fall, colliding boxes in red ----
  if (s.out_dir.empty()) {
    context.report("(Run with --out DIR for a picture of the last frame.)\n");
    return;
  }
  std::vector<char> colliding(last_frame.size(), 0);
  for (const IndexPair& p : last_pairs) colliding[p.a] = colliding[p.b] = 1;
  RenderParams render;
  render.width = s.quick ? 320 : 800;
  render.height = s.quick ? 240 : 600;
  render.threads = s.threads;
  render.box_colours.resize(last_frame.size());
  for (std::size_t i = 0; i < last_frame.size(); ++i)
    render.box_colours[i] =
        colliding[i] ? std::array<float, 3>{0.95f, 0.2f, 0.15f} : std::array<float, 3>{0.55f, 0.7f, 0.9f};
  const BoxTree tree(last_frame);
  const Image image = render_image(tree, render);
  const std::string picture = context.out_path("collisions.png");
  write_png(picture, image.rgb.data(), image.width, image.height);
  context.wrote(picture);
  const auto touching = static_cast<double>(std::count(colliding.begin(), colliding.end(), 1));
  context.report("Picture: " + picture + ": the last frame of the free fall, the " + with_commas(touching) +
                 " boxes that overlap another in red.\n");
}

}  // namespace kdspace::cli::demo
