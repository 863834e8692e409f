// Generated motion: boxes that move every frame, for tests, benchmarks and the demo, in the manner of
// the Broadmark benchmark of broad phases (Serpa & Rodrigues 2019): Brownian motion and free fall,
// with every object moving each frame or only a share of them. Reproducible from a seed on every
// platform (own generator, no std::*_distribution).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/box.hpp"

namespace kdspace {

enum class MotionKind {
  brownian,   ///< each frame a random step, up to a quarter of the mean box extent on each axis
  free_fall,  ///< falling along -z under gravity, bouncing elastically off the floor of the world
};

class MotionSimulation {
 public:
  /// Starts from `boxes`; the world is their bounds. A share `moving_share` (0 to 1) of the boxes,
  /// drawn at random, moves; the others stay where they are.
  MotionSimulation(std::vector<Box3f> boxes, MotionKind kind, double moving_share, std::uint32_t seed);

  /// Advances one frame and returns the boxes.
  const std::vector<Box3f>& step();
  const std::vector<Box3f>& boxes() const { return boxes_; }
  /// The ids of the boxes that move, ascending.
  const std::vector<std::uint32_t>& moving() const { return moving_; }

 private:
  std::uint64_t next();
  double uniform();  ///< in [0, 1)

  std::vector<Box3f> boxes_;
  MotionKind kind_;
  std::vector<std::uint32_t> moving_;
  std::vector<double> velocity_;  ///< free fall: per moving box, its velocity along z
  Box3f world_;
  double step_;  ///< Brownian step bound; free fall: gravity's velocity change per frame
  std::uint64_t state_;
};

}  // namespace kdspace
