// Brute force for rays: every box tested with the slab method in double precision, by division. The
// reference the BoxTree is checked against (tests, demo); independent of the tree's arithmetic.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace {

/// Where the ray enters the closed solid box within [t_min, t_max] (t_min when it starts inside),
/// or nothing.
inline std::optional<double> slab_entry(const Box3f& box, const Ray& ray, double t_min, double t_max) {
  double lo = t_min, hi = t_max;
  for (int a = 0; a < 3; ++a) {
    const double o = ray.origin[a], d = ray.direction[a];
    if (d == 0) {  // parallel to the slab: inside it or never
      if (o < box.lo[a] || o > box.hi[a]) return std::nullopt;
      continue;
    }
    double t0 = (box.lo[a] - o) / d, t1 = (box.hi[a] - o) / d;
    if (t0 > t1) std::swap(t0, t1);
    lo = std::max(lo, t0);
    hi = std::min(hi, t1);
  }
  if (lo > hi) return std::nullopt;
  return lo;
}

struct ReferenceHit {
  std::int32_t box = -1;  ///< -1: no hit
  double t = std::numeric_limits<double>::infinity();
};

/// The closest hit by testing every box: smallest t, equal t to the smaller index.
inline ReferenceHit brute_force_closest_hit(const std::vector<Box3f>& boxes, const Ray& ray, double t_min = 0,
                                            double t_max = std::numeric_limits<double>::infinity()) {
  ReferenceHit best;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const auto t = slab_entry(boxes[i], ray, t_min, t_max);
    if (t && (*t < best.t || best.box < 0)) best = ReferenceHit{static_cast<std::int32_t>(i), *t};
  }
  return best;
}

/// Whether a tree's hit agrees with the reference: both miss, or t within 1e-6 * (1 + |t|) (the tree
/// rounds t to float) and the same box, or another box that the ray enters at that same t.
inline bool agrees_with_reference(const Hit& got, const ReferenceHit& want, const std::vector<Box3f>& boxes,
                                  const Ray& ray, double t_min = 0,
                                  double t_max = std::numeric_limits<double>::infinity()) {
  if (want.box < 0 || got.box < 0) return want.box < 0 && got.box < 0;
  const double tolerance = 1e-6 * (1 + std::abs(want.t));
  if (std::abs(static_cast<double>(got.t) - want.t) > tolerance) return false;
  if (got.box == want.box) return true;
  if (static_cast<std::size_t>(got.box) >= boxes.size()) return false;
  const auto t_other = slab_entry(boxes[static_cast<std::size_t>(got.box)], ray, t_min, t_max);
  return t_other && std::abs(*t_other - want.t) <= tolerance;
}

}  // namespace kdspace
