// MotionSimulation (kdspace/collide/motion_gen.hpp).
#include "kdspace/collide/motion_gen.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "kdspace/error.hpp"

namespace kdspace {

MotionSimulation::MotionSimulation(std::vector<Box3f> boxes, MotionKind kind, double moving_share,
                                   std::uint32_t seed)
    : boxes_(std::move(boxes)), kind_(kind), state_(seed * 0x9e3779b97f4a7c15ull + 0x2545f4914f6cdd1dull) {
  if (!(moving_share >= 0 && moving_share <= 1)) throw Error("moving_share must be in [0, 1]");
  world_ = boxes_.empty() ? Box3f{} : boxes_.front();
  double extent = 0;
  for (const Box3f& b : boxes_)
    for (int a = 0; a < 3; ++a) {
      world_.lo[a] = std::min(world_.lo[a], b.lo[a]);
      world_.hi[a] = std::max(world_.hi[a], b.hi[a]);
      extent += static_cast<double>(b.hi[a]) - b.lo[a];
    }
  const double mean_extent = boxes_.empty() ? 1 : extent / (3.0 * static_cast<double>(boxes_.size()));
  // Brownian: steps up to a quarter of a box; free fall: a box at rest falls its own size in about
  // ten frames.
  step_ = kind == MotionKind::brownian ? 0.25 * mean_extent : 0.02 * mean_extent;
  for (std::size_t i = 0; i < boxes_.size(); ++i)
    if (uniform() < moving_share) moving_.push_back(static_cast<std::uint32_t>(i));
  velocity_.assign(moving_.size(), 0.0);
}

std::uint64_t MotionSimulation::next() {
  // SplitMix64 (Steele, Lea & Flood 2014).
  std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

double MotionSimulation::uniform() {
  return static_cast<double>(next() >> 11) * (1.0 / 9007199254740992.0);
}

const std::vector<Box3f>& MotionSimulation::step() {
  for (std::size_t k = 0; k < moving_.size(); ++k) {
    Box3f& b = boxes_[moving_[k]];
    double shift[3] = {0, 0, 0};
    if (kind_ == MotionKind::brownian) {
      for (double& s : shift) s = (2 * uniform() - 1) * step_;
    } else {
      velocity_[k] -= step_;
      shift[2] = velocity_[k];
    }
    for (int a = 0; a < 3; ++a) {
      // Kept inside the world: a box that would leave it is turned back (and, falling, bounces).
      const double lo = b.lo[a], hi = b.hi[a];
      double s = shift[a];
      if (lo + s < world_.lo[a] || hi + s > world_.hi[a]) {
        s = -s;
        if (a == 2 && kind_ == MotionKind::free_fall) velocity_[k] = -velocity_[k];
        if (lo + s < world_.lo[a] || hi + s > world_.hi[a]) s = 0;
      }
      b.lo[a] = static_cast<float>(lo + s);
      b.hi[a] = std::max(b.lo[a], static_cast<float>(hi + s));
    }
  }
  return boxes_;
}

}  // namespace kdspace
