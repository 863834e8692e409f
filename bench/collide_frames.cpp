// collide_frames: frames of a MovingScene with nothing else in the process, for counting the
// instructions a frame costs under callgrind (a machine shared with other work times frames poorly):
//
//   valgrind --tool=callgrind --callgrind-out-file=/dev/null build/bench/bench/collide_frames 100000 1 10
//   refit brownian
//
// minus the same with 0 frames, divided by the frames, is the cost of one frame.
//
// usage: collide_frames BOXES SHARE FRAMES refit|refit-all|rebuild|rebuild-median brownian|free-fall
//   BOXES   the uniform scene (generate_boxes, seed 7) with its boxes shrunk to half their size, as in
//           kdspace-collide-bench's moving scenes
//   SHARE   the share of the boxes that move (0 to 1)
//   refit           MovingScene defaults: refit, pairs updated for the moved boxes when few moved
//   refit-all       refit, all pairs found every frame
//   rebuild         a new binned tree every frame, all pairs
//   rebuild-median  a new median tree every frame, all pairs
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "kdspace/collide/motion_gen.hpp"
#include "kdspace/collide/moving_scene.hpp"
#include "kdspace/rays/scene_gen.hpp"

int main(int argc, char** argv) {
  if (argc != 6) {
    std::fprintf(stderr,
                 "usage: collide_frames BOXES SHARE FRAMES refit|refit-all|rebuild|rebuild-median "
                 "brownian|free-fall\n");
    return 2;
  }
  const auto n = static_cast<std::size_t>(std::atol(argv[1]));
  const double share = std::atof(argv[2]);
  const int frames = std::atoi(argv[3]);
  const std::string mode = argv[4], kind = argv[5];
  std::vector<kdspace::Box3f> boxes = kdspace::generate_boxes(n, kdspace::SceneKind::uniform, 7);
  for (kdspace::Box3f& b : boxes)
    for (int a = 0; a < 3; ++a) {
      const float centre = 0.5f * b.lo[a] + 0.5f * b.hi[a], quarter = 0.25f * (b.hi[a] - b.lo[a]);
      b.lo[a] = centre - quarter;
      b.hi[a] = centre + quarter;
    }
  kdspace::MotionSimulation motion(
      boxes, kind == "free-fall" ? kdspace::MotionKind::free_fall : kdspace::MotionKind::brownian, share, 11);
  kdspace::MovingSceneParams p;
  if (mode != "refit") p.incremental_share = 0;
  if (mode == "rebuild" || mode == "rebuild-median") p.update = kdspace::TreeUpdate::rebuild;
  if (mode == "rebuild-median") p.build.method = kdspace::BoxBuildMethod::median;
  kdspace::MovingScene scene(p);
  scene.step(motion.boxes());
  std::size_t pairs = 0, rebuilds = 0;
  for (int f = 0; f < frames; ++f) {
    pairs += scene.step(motion.step()).size();
    rebuilds += scene.last_frame().rebuilt ? 1 : 0;
  }
  std::printf("%d frames, %zu pairs, %zu rebuilds\n", frames, pairs, rebuilds);
  return 0;
}
