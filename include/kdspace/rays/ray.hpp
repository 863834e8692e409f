// Ray, Hit and RayStats: what goes into and comes out of a BoxTree query.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <string>

#include "kdspace/box.hpp"

namespace kdspace {

/// A ray: the points origin + t * direction. The direction need not have unit length; t is measured
/// in multiples of it. A usable ray has finite coordinates and a direction other than (0, 0, 0);
/// components may be +0 or -0 (the ray is then parallel to that axis). Laid out as 6 floats, the
/// record of a .rays file.
struct Ray {
  std::array<float, 3> origin{};
  std::array<float, 3> direction{};
};

/// The answer to a ray query: the box hit (its position in the input) and where, or no box.
struct Hit {
  static constexpr std::int32_t none = -1;

  std::int32_t box = none;                           ///< box index, or none (-1) for a miss
  float t = std::numeric_limits<float>::infinity();  ///< ray parameter of the hit; +inf for a miss

  bool hit() const { return box != none; }
  friend bool operator==(const Hit& a, const Hit& b) { return a.box == b.box && (a.t == b.t || !a.hit()); }
  friend bool operator!=(const Hit& a, const Hit& b) { return !(a == b); }
};

/// The part of each ray a batch looks at: t in [t_min, t_max] (t_min finite, t_min <= t_max). A
/// shadow ray from a point p towards a light at q is {p, q - p} over [epsilon, 1].
struct RayRange {
  float t_min = 0;
  float t_max = std::numeric_limits<float>::infinity();
};

/// What queries cost, summed over the rays traced: add the stats of many calls with +=.
struct RayStats {
  std::uint64_t rays = 0;
  std::uint64_t nodes_visited = 0;  ///< inner nodes and leaves entered
  std::uint64_t boxes_tested = 0;   ///< ray-box (slab) tests in leaves; a box in two leaves may count twice

  RayStats& operator+=(const RayStats& o) {
    rays += o.rays;
    nodes_visited += o.nodes_visited;
    boxes_tested += o.boxes_tested;
    return *this;
  }
  double nodes_visited_per_ray() const {
    return rays ? static_cast<double>(nodes_visited) / static_cast<double>(rays) : 0;
  }
  double boxes_tested_per_ray() const {
    return rays ? static_cast<double>(boxes_tested) / static_cast<double>(rays) : 0;
  }
};

/// What is wrong with a box, or "" when it is usable (finite, min <= max on every axis).
/// Examples: "min x 3 > max x 1", "max y is nan". Callers prefix where: "box 17: ".
std::string box_problem(const Box3f& box);

/// What is wrong with a ray, or "" when it is usable (finite, non-zero direction).
/// Examples: "direction is zero", "origin z is inf".
std::string ray_problem(const Ray& ray);

}  // namespace kdspace
