// rays_walk: one batch of random rays through one scene's BoxTree, for instruction counts
// (valgrind --tool=callgrind --branch-sim=yes --toggle-collect='*trace_batch*').
//
//   rays_walk MESH_FILE|uniform|clustered [--boxes N] [--rays M] [--primary WxH] [--any-hit] [--reps R]
//             [--voxels R] [--ki K] [--bonus B]
//
// Builds the default tree (with --ki / --bonus: that K_i / empty-space bonus) over a mesh's triangle
// boxes (bench/real_data/mesh_io.hpp formats), its surface voxels on a grid of R cells along its
// longest side (--voxels R, as kdspace-rays-bench) or N generated boxes (default 1e5), makes M
// random rays (default 1e5; kdspace::random_rays, seed 2, as kdspace-rays-bench) and traces them R
// times (default 1) with closest_hit_batch (or any_hit_batch) on one thread. With --primary, the camera rays of a WxH image instead
// (kdspace::fit_camera, as kdspace-rays-bench; traced in packets). Prints the hits, the nodes and boxes per
// ray, and the trace's CPU time per ray.
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "rays_scenes.hpp"

using namespace kdspace;

namespace {

double cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: rays_walk MESH_FILE|uniform|clustered [--boxes N] [--rays M] [--primary WxH] "
                 "[--any-hit] [--reps R] [--voxels R] [--ki K] [--bonus B]\n");
    return 2;
  }
  const std::string scene = argv[1];
  std::size_t n = 100000, m = 100000, reps = 1;
  bool any = false;
  BoxBuildParams params;
  std::size_t voxels = 0;
  std::size_t width = 0, height = 0;
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--boxes" && i + 1 < argc)
      n = std::strtoull(argv[++i], nullptr, 10);
    else if (arg == "--rays" && i + 1 < argc)
      m = std::strtoull(argv[++i], nullptr, 10);
    else if (arg == "--reps" && i + 1 < argc)
      reps = std::strtoull(argv[++i], nullptr, 10);
    else if (arg == "--primary" && i + 1 < argc &&
             std::sscanf(argv[i + 1], "%zux%zu", &width, &height) == 2 && width > 0 && height > 0)
      ++i;
    else if (arg == "--any-hit")
      any = true;
    else if (arg == "--voxels" && i + 1 < argc)
      voxels = std::strtoull(argv[++i], nullptr, 10);
    else if (arg == "--ki" && i + 1 < argc)
      params.K_i = std::strtof(argv[++i], nullptr);
    else if (arg == "--bonus" && i + 1 < argc)
      params.empty_bonus = std::strtof(argv[++i], nullptr);
    else {
      std::fprintf(stderr, "rays_walk: unknown argument %s\n", arg.c_str());
      return 2;
    }
  }
  std::vector<Box3f> boxes;
  if (scene == "uniform")
    boxes = generate_boxes(n, SceneKind::uniform, 1);
  else if (scene == "clustered")
    boxes = generate_boxes(n, SceneKind::clustered, 1);
  else if (voxels > 0)
    boxes = bench::surface_voxels(bench::read_mesh(scene), voxels);
  else
    boxes = bench::triangle_boxes(bench::read_mesh(scene));
  const BoxTree tree(boxes, params);
  const std::vector<Ray> rays =
      width > 0
          ? primary_rays(fit_camera(tree.bounds(), static_cast<double>(width) / static_cast<double>(height)),
                         width, height)
          : random_rays(m, tree.bounds(), 2);
  m = rays.size();
  double best = 1e300;
  std::size_t hit_count = 0;
  RayStats stats;
  for (std::size_t rep = 0; rep < reps; ++rep) {
    RayStats local;
    const double start = cpu_seconds();
    const std::vector<Hit> hits =
        any ? tree.any_hit_batch(rays, 1, &local) : tree.closest_hit_batch(rays, 1, &local);
    best = std::min(best, cpu_seconds() - start);
    hit_count = 0;
    for (const Hit& h : hits) hit_count += h.hit() ? 1 : 0;
    stats = local;
  }
  std::printf(
      "%zu boxes, %zu rays, %zu hit; %.2f nodes, %.2f boxes a ray; best %.1f ns a ray; SAH cost %.1f\n", boxes.size(),
      rays.size(), hit_count, static_cast<double>(stats.nodes_visited) / static_cast<double>(m),
      static_cast<double>(stats.boxes_tested) / static_cast<double>(m), 1e9 * best / static_cast<double>(m), tree.stats().sah_cost);
  return 0;
}
