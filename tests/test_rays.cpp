// Tests of ray shooting through BoxTree (kdspace/boxes/box_tree.hpp) against brute force.
//
// The reference tests every box with the slab method in double precision, dividing by the direction
// (the tree multiplies by its precomputed reciprocal), with the contract's rules: closed solid boxes,
// a ray starting inside a box hits it at t_min, equal t goes to the smaller index.
//
// How answers are compared (same_hit below):
//   - a miss must be a miss;
//   - a hit's t must be within 1e-6 * (1 + |t|) of the reference's (the tree rounds t to float);
//   - the box must be the reference's, unless the reference also hits the tree's box at a t within
//     that same tolerance (two boxes whose entry points coincide up to rounding).
// Scenes with integer coordinates and rays with integer origins and power-of-two directions are
// computed exactly by both sides; there rays run along faces, edges and through corners.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "../lib/rays/descent.hpp"
#include "../lib/rays/traversal_ray.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "kdspace/rays/brute_force.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "support.hpp"

using kdspace::Box3f;
using kdspace::BoxBuildMethod;
using kdspace::BoxBuildParams;
using kdspace::BoxTree;
using kdspace::Hit;
using kdspace::Ray;
using kdspace::RayStats;

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();

// ---- the reference --------------------------------------------------------------------------------

// The reference lives in kdspace/rays/brute_force.hpp (slab method in double, by division).
using kdspace::ReferenceHit;

std::optional<double> reference_t(const Box3f& b, const Ray& r, double t_min, double t_max) {
  return kdspace::slab_entry(b, r, t_min, t_max);
}

ReferenceHit reference_closest(const std::vector<Box3f>& boxes, const Ray& r, double t_min = 0,
                               double t_max = inf) {
  return kdspace::brute_force_closest_hit(boxes, r, t_min, t_max);
}

double tolerance(double t) {
  return 1e-6 * (1 + std::abs(t));
}

/// Empty when the tree's answer is acceptable, else a description for the failure message.
std::string compare(const Hit& got, const ReferenceHit& want, const std::vector<Box3f>& boxes, const Ray& r,
                    double t_min, double t_max) {
  if (want.box < 0) return got.hit() ? "hit box " + std::to_string(got.box) + ", expected a miss" : "";
  if (!got.hit())
    return "missed, expected box " + std::to_string(want.box) + " at t " + std::to_string(want.t);
  const double float_max = std::numeric_limits<float>::max();
  if (want.t > float_max) {
    if (got.t != std::numeric_limits<float>::max())
      return "t " + std::to_string(got.t) + ", expected FLT_MAX";
  } else if (std::abs(got.t - want.t) > tolerance(want.t))
    return "t " + std::to_string(got.t) + ", expected " + std::to_string(want.t);
  if (got.box == want.box) return "";
  if (got.box < 0 || static_cast<std::size_t>(got.box) >= boxes.size()) return "box index out of range";
  const auto t_other = reference_t(boxes[static_cast<std::size_t>(got.box)], r, t_min, t_max);
  if (t_other &&
      (std::abs(*t_other - want.t) <= tolerance(want.t) || (*t_other > float_max && want.t > float_max)))
    return "";
  return "box " + std::to_string(got.box) + ", expected box " + std::to_string(want.box) + " at t " +
         std::to_string(want.t);
}

std::string describe(const Ray& r) {
  std::string s = "origin (";
  for (int a = 0; a < 3; ++a) s += std::to_string(r.origin[a]) + (a < 2 ? ", " : ") direction (");
  for (int a = 0; a < 3; ++a)
    s += (std::signbit(r.direction[a]) && r.direction[a] == 0 ? std::string("-0")
                                                              : std::to_string(r.direction[a])) +
         (a < 2 ? ", " : ")");
  return s;
}

// ---- scenes -------------------------------------------------------------------------------------

using kdspace_test::box_of;
using kdspace_test::Rng;
using kdspace_test::uniform;
using kdspace_test::uniform_int;

/// Boxes of very different sizes (spanning three orders of magnitude) in [-10, 10]^3.
std::vector<Box3f> mixed_scale_boxes(std::size_t n, Rng& rng) {
  std::vector<Box3f> boxes(n);
  for (Box3f& b : boxes) {
    const float scale = std::pow(10.0f, uniform(rng, -2, 1));
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = uniform(rng, -10, 10);
      b.hi[a] = b.lo[a] + scale * uniform(rng, 0.05f, 1);
    }
  }
  return boxes;
}

/// Large boxes in the unit cube: every point is covered by many of them.
std::vector<Box3f> overlapping_boxes(std::size_t n, Rng& rng) {
  std::vector<Box3f> boxes(n);
  for (Box3f& b : boxes)
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = uniform(rng, 0, 0.6f);
      b.hi[a] = b.lo[a] + uniform(rng, 0.3f, 0.4f);
    }
  return boxes;
}

/// Flat boxes (zero thickness on one axis) on a coarse grid of planes, many of them coplanar.
std::vector<Box3f> flat_boxes(std::size_t n, Rng& rng) {
  std::vector<Box3f> boxes(n);
  for (Box3f& b : boxes) {
    const int flat_axis = uniform_int(rng, 0, 2);
    for (int a = 0; a < 3; ++a) {
      if (a == flat_axis) {
        b.lo[a] = b.hi[a] = static_cast<float>(uniform_int(rng, 0, 8)) / 8;
      } else {
        b.lo[a] = uniform(rng, 0, 0.9f);
        b.hi[a] = b.lo[a] + uniform(rng, 0.01f, 0.1f);
      }
    }
  }
  return boxes;
}

/// Boxes with integer corners in [0, 12]^3 and extents 0..3 per axis: cubes sharing faces, slabs,
/// flat boxes, segments and points. Ray parameters against them are exact for integer origins.
std::vector<Box3f> integer_boxes(std::size_t n, Rng& rng) {
  std::vector<Box3f> boxes(n);
  for (Box3f& b : boxes)
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = static_cast<float>(uniform_int(rng, 0, 11));
      b.hi[a] = b.lo[a] + static_cast<float>(uniform_int(rng, 0, 3) == 0 ? 0 : uniform_int(rng, 1, 3));
    }
  return boxes;
}

/// Unit cubes on a lattice, some missing: neighbours share whole faces.
std::vector<Box3f> cube_lattice(Rng& rng) {
  std::vector<Box3f> boxes;
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z)
        if (uniform_int(rng, 0, 2) != 0)
          boxes.push_back(box_of(float(x), float(y), float(z), float(x + 1), float(y + 1), float(z + 1)));
  return boxes;
}

Box3f bounds_of(const std::vector<Box3f>& boxes) {
  Box3f b = boxes.front();
  for (const Box3f& x : boxes)
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], x.lo[a]);
      b.hi[a] = std::max(b.hi[a], x.hi[a]);
    }
  return b;
}

// ---- rays ---------------------------------------------------------------------------------------

/// Random origins around the scene, random directions of random length (0.1 to 10).
std::vector<Ray> random_rays(std::size_t m, const Box3f& bounds, Rng& rng) {
  std::vector<Ray> rays(m);
  for (Ray& r : rays) {
    for (int a = 0; a < 3; ++a) {
      const float grow = 0.2f * (bounds.hi[a] - bounds.lo[a]) + 0.1f;
      r.origin[a] = uniform(rng, bounds.lo[a] - grow, bounds.hi[a] + grow);
    }
    const float length = std::pow(10.0f, uniform(rng, -1, 1));
    float len2 = 0;
    do {
      for (int a = 0; a < 3; ++a) r.direction[a] = uniform(rng, -1, 1);
      len2 =
          r.direction[0] * r.direction[0] + r.direction[1] * r.direction[1] + r.direction[2] * r.direction[2];
    } while (len2 < 1e-4f);
    for (int a = 0; a < 3; ++a) r.direction[a] *= length;
  }
  return rays;
}

/// Rays starting inside random boxes.
std::vector<Ray> inside_rays(std::size_t m, const std::vector<Box3f>& boxes, Rng& rng) {
  std::vector<Ray> rays = random_rays(m, bounds_of(boxes), rng);
  for (Ray& r : rays) {
    const Box3f& b = boxes[static_cast<std::size_t>(uniform_int(rng, 0, static_cast<int>(boxes.size()) - 1))];
    for (int a = 0; a < 3; ++a) r.origin[a] = b.lo[a] == b.hi[a] ? b.lo[a] : uniform(rng, b.lo[a], b.hi[a]);
  }
  return rays;
}

/// Integer origins (on the lattice planes of integer scenes, so on faces, edges and corners) with
/// directions whose components are 0 (of either sign), +-1, +-2 or +-0.5: axis-parallel rays, rays
/// along face diagonals and through corners, all computed exactly.
std::vector<Ray> lattice_rays(std::size_t m, int lo, int hi, Rng& rng) {
  static const float steps[] = {1, 2, 0.5f};
  std::vector<Ray> rays(m);
  for (Ray& r : rays) {
    for (int a = 0; a < 3; ++a) r.origin[a] = static_cast<float>(uniform_int(rng, lo, hi));
    const int zeros = uniform_int(rng, 0, 2);  // 0: through corners, 1: in a plane, 2: along an axis
    for (int a = 0; a < 3; ++a) {
      const float sign = uniform_int(rng, 0, 1) ? 1.0f : -1.0f;
      r.direction[a] = sign * steps[uniform_int(rng, 0, 2)];
    }
    for (int z = 0; z < zeros; ++z) {
      const int a = uniform_int(rng, 0, 2);
      r.direction[a] = uniform_int(rng, 0, 1) ? 0.0f : -0.0f;
    }
    if (r.direction[0] == 0 && r.direction[1] == 0 && r.direction[2] == 0) r.direction[0] = 1;
  }
  return rays;
}

// ---- builds -------------------------------------------------------------------------------------

struct NamedParams {
  std::string name;
  BoxBuildParams params;
};

std::vector<NamedParams> all_builds() {
  std::vector<NamedParams> builds;
  BoxBuildParams p;
  p.method = BoxBuildMethod::median;
  builds.push_back({"median middle", p});
  p.median_position = kdspace::MedianPosition::object_median;
  p.leaf_size = 1;
  builds.push_back({"median object, leaf 1", p});
  p = BoxBuildParams{};
  p.method = BoxBuildMethod::sah;
  builds.push_back({"sah", p});
  p.method = BoxBuildMethod::sah_nlogn;
  builds.push_back({"sah_nlogn", p});
  p.binning_threshold = 1;
  builds.push_back({"sah_nlogn binned at every node", p});
  p.binning_threshold = 0;
  builds.push_back({"sah_nlogn exact at every node", p});
  p.probability = kdspace::HitProbability::volume;
  builds.push_back({"sah_nlogn volume", p});
  p = BoxBuildParams{};
  p.K_t = 0.1f;
  p.K_i = 4;
  p.empty_bonus = 0.9f;
  builds.push_back({"sah_nlogn deep (K_t 0.1, K_i 4, bonus 0.9)", p});
  p = BoxBuildParams{};
  p.max_depth = 3;
  builds.push_back({"sah_nlogn max depth 3", p});
  p = BoxBuildParams{};
  p.method = BoxBuildMethod::binned;
  builds.push_back({"binned", p});
  return builds;
}

/// Checks closest_hit of every build against the reference for every ray over [t_min, t_max].
void check_scene(const std::vector<Box3f>& boxes, const std::vector<Ray>& rays, double t_min = 0,
                 double t_max = inf) {
  std::vector<ReferenceHit> want(rays.size());
  for (std::size_t i = 0; i < rays.size(); ++i) want[i] = reference_closest(boxes, rays[i], t_min, t_max);
  for (const NamedParams& b : all_builds()) {
    const BoxTree tree(boxes, b.params);
    std::size_t failures = 0;
    for (std::size_t i = 0; i < rays.size() && failures < 5; ++i) {
      const Hit got = tree.closest_hit(rays[i], static_cast<float>(t_min), static_cast<float>(t_max));
      const std::string problem = compare(got, want[i], boxes, rays[i], t_min, t_max);
      if (!problem.empty()) {
        ++failures;
        FAIL_CHECK(b.name << ", " << boxes.size() << " boxes, ray " << i << " " << describe(rays[i]) << ": "
                          << problem);
      }
    }
  }
}

}  // namespace

// ---- closest hit against brute force --------------------------------------------------------------

TEST_CASE("rays: every build finds the brute-force closest hit in uniform and clustered scenes", "[rays]") {
  for (std::uint32_t seed = 1; seed <= 3; ++seed) {
    Rng rng(seed);
    for (const auto kind : {kdspace::SceneKind::uniform, kdspace::SceneKind::clustered}) {
      const std::vector<Box3f> boxes = kdspace::generate_boxes(1500, kind, seed);
      check_scene(boxes, random_rays(1500, bounds_of(boxes), rng));
    }
  }
}

TEST_CASE("rays: every build finds the brute-force closest hit among boxes of mixed sizes", "[rays]") {
  for (std::uint32_t seed = 1; seed <= 3; ++seed) {
    Rng rng(seed);
    for (const std::size_t n : {1, 2, 7, 60, 800}) {
      const std::vector<Box3f> boxes = mixed_scale_boxes(n, rng);
      check_scene(boxes, random_rays(800, bounds_of(boxes), rng));
    }
  }
}

TEST_CASE("rays: heavily overlapping boxes are traced correctly", "[rays]") {
  Rng rng(11);
  const std::vector<Box3f> boxes = overlapping_boxes(400, rng);
  check_scene(boxes, random_rays(1000, bounds_of(boxes), rng));
  check_scene(boxes, inside_rays(500, boxes, rng));
}

TEST_CASE("rays: flat boxes, many of them coplanar, are hit from both sides and along their plane",
          "[rays]") {
  for (std::uint32_t seed = 1; seed <= 3; ++seed) {
    Rng rng(seed);
    const std::vector<Box3f> boxes = flat_boxes(600, rng);
    check_scene(boxes, random_rays(1000, bounds_of(boxes), rng));
    // Rays lying in the grid planes of the flat boxes.
    std::vector<Ray> in_plane = random_rays(600, bounds_of(boxes), rng);
    for (Ray& r : in_plane) {
      const int a = uniform_int(rng, 0, 2);
      r.origin[a] = static_cast<float>(uniform_int(rng, 0, 8)) / 8;
      r.direction[a] = uniform_int(rng, 0, 1) ? 0.0f : -0.0f;
    }
    check_scene(boxes, in_plane);
  }
}

TEST_CASE("rays: rays along faces, edges and through corners of integer boxes are exact", "[rays]") {
  for (std::uint32_t seed = 1; seed <= 4; ++seed) {
    Rng rng(seed);
    const std::vector<Box3f> boxes = integer_boxes(seed == 1 ? 40 : 300, rng);
    check_scene(boxes, lattice_rays(1500, -1, 15, rng));
  }
}

TEST_CASE("rays: cubes sharing faces: rays along the shared faces and edges", "[rays]") {
  Rng rng(5);
  const std::vector<Box3f> boxes = cube_lattice(rng);
  check_scene(boxes, lattice_rays(2000, -1, 9, rng));
  check_scene(boxes, random_rays(500, bounds_of(boxes), rng));
}

TEST_CASE("rays: a ray starting inside a box hits it at t_min", "[rays]") {
  Rng rng(6);
  const std::vector<Box3f> boxes = kdspace::generate_boxes(500, kdspace::SceneKind::uniform, 6);
  const std::vector<Ray> rays = inside_rays(500, boxes, rng);
  check_scene(boxes, rays);
  const BoxTree tree(boxes);
  for (const Ray& r : rays) {
    const Hit h = tree.closest_hit(r);
    REQUIRE(h.hit());
    CHECK(h.t == 0.0f);
    const Hit later = tree.closest_hit(r, 0.25f);
    if (later.hit()) CHECK(later.t >= 0.25f);
  }
  // A single box, from its centre (still inside at t_min = 0.5), and leaving from a corner and from a
  // face: the starting point is on the closed box, the points beyond it are not.
  const BoxTree one(std::vector<Box3f>{box_of(0, 0, 0, 1, 1, 1)});
  const Hit centre = one.closest_hit(Ray{{0.5f, 0.5f, 0.5f}, {1, 0, 0}}, 0.5f);
  CHECK(centre.box == 0);
  CHECK(centre.t == 0.5f);
  for (const Ray& r : {Ray{{0, 0, 0}, {-1, -1, -1}}, Ray{{1, 0.5f, 0.5f}, {1, 0, 0}}}) {
    const Hit start = one.closest_hit(r);
    CHECK(start.box == 0);
    CHECK(start.t == 0.0f);
    CHECK_FALSE(one.closest_hit(r, 0.5f).hit());
  }
}

TEST_CASE("rays: t_min and t_max bound the hits", "[rays]") {
  Rng rng(7);
  const std::vector<Box3f> boxes = kdspace::generate_boxes(800, kdspace::SceneKind::uniform, 7);
  const std::vector<Ray> rays = random_rays(500, bounds_of(boxes), rng);
  check_scene(boxes, rays, 0.3, 0.9);
  check_scene(boxes, rays, 0.5, 0.5);
  check_scene(boxes, rays, -2.0, 0.1);
}

TEST_CASE("rays: equal t goes to the smaller box index", "[rays]") {
  // Identical boxes, listed out of order among others: the smallest index of the copies wins.
  std::vector<Box3f> boxes;
  Rng rng(8);
  for (int i = 0; i < 30; ++i) boxes.push_back(box_of(5, 5, 5, 6, 6, 6));
  for (const Box3f& b : mixed_scale_boxes(50, rng)) boxes.push_back(b);
  for (int i = 0; i < 30; ++i) boxes.push_back(box_of(5, 5, 5, 6, 6, 6));
  for (const NamedParams& b : all_builds()) {
    const BoxTree tree(boxes, b.params);
    const Hit h = tree.closest_hit(Ray{{5.5f, 5.5f, -20}, {0, 0, 1}});
    CHECK(h.box == 0);
    CHECK(h.t == 25.0f);
  }
  // Two cubes sharing the face x = 1, the ray arriving along that face: both are entered at t = 1.
  const std::vector<Box3f> pair{box_of(1, 0, 0, 2, 1, 1), box_of(0, 0, 0, 1, 1, 1)};
  for (const NamedParams& b : all_builds()) {
    const BoxTree tree(pair, b.params);
    const Hit h = tree.closest_hit(Ray{{1, 0.5f, -1}, {0, 0, 1}});
    CHECK(h.box == 0);
    CHECK(h.t == 1.0f);
  }
}

TEST_CASE("rays: direction components +0 and -0 give the same answers", "[rays]") {
  Rng rng(9);
  const std::vector<Box3f> boxes = integer_boxes(300, rng);
  const BoxTree tree(boxes);
  for (const Ray& base : lattice_rays(1000, -1, 15, rng)) {
    Ray flipped = base;
    for (float& d : flipped.direction)
      if (d == 0) d = std::signbit(d) ? 0.0f : -0.0f;
    const Hit a = tree.closest_hit(base), b = tree.closest_hit(flipped);
    CHECK(a.box == b.box);
    if (a.hit()) CHECK(a.t == b.t);
  }
}

TEST_CASE("rays: a single box, a single point and a single flat box", "[rays]") {
  Rng rng(10);
  for (const Box3f& box : {box_of(1, 2, 3, 4, 5, 6), box_of(1, 1, 1, 1, 1, 1), box_of(0, 0, 2, 3, 3, 2)}) {
    const std::vector<Box3f> boxes{box};
    check_scene(boxes, lattice_rays(500, -1, 6, rng));
    check_scene(boxes, random_rays(200, bounds_of(boxes), rng));
  }
  const BoxTree point(std::vector<Box3f>{box_of(1, 1, 1, 1, 1, 1)});
  const Hit h = point.closest_hit(Ray{{0, 0, 0}, {1, 1, 1}});
  CHECK(h.box == 0);
  CHECK(h.t == 1.0f);
  CHECK_FALSE(point.closest_hit(Ray{{0, 0, 0}, {1, 1, 1.0001f}}).hit());
}

TEST_CASE("rays: degenerate scenes: identical boxes, identical points, a flat scene", "[rays]") {
  Rng rng(12);
  std::vector<Box3f> same(200, box_of(0, 0, 0, 1, 1, 1));
  std::vector<Box3f> points(200, box_of(2, 2, 2, 2, 2, 2));
  std::vector<Box3f> plane = flat_boxes(300, rng);
  for (Box3f& b : plane) b.lo[2] = b.hi[2] = 0.5f;  // all in the plane z = 0.5
  std::vector<Box3f> grid_points;
  for (int x = 0; x < 6; ++x)
    for (int y = 0; y < 6; ++y)
      for (int z = 0; z < 6; ++z)
        grid_points.push_back(box_of(float(x), float(y), float(z), float(x), float(y), float(z)));
  for (const std::vector<Box3f>* boxes : {&same, &points, &plane, &grid_points}) {
    check_scene(*boxes, random_rays(300, bounds_of(*boxes), rng));
    check_scene(*boxes, lattice_rays(600, -1, 7, rng));
  }
  const BoxTree tree(same);
  CHECK(tree.leaf_count() == 1);
  CHECK(tree.closest_hit(Ray{{0.5f, 0.5f, 3}, {0, 0, -1}}).box == 0);
}

TEST_CASE("rays: an empty tree misses every ray", "[rays]") {
  const BoxTree tree(std::vector<Box3f>{});
  CHECK(tree.size() == 0);
  CHECK_FALSE(tree.closest_hit(Ray{{0, 0, 0}, {1, 0, 0}}).hit());
  CHECK_FALSE(tree.any_hit(Ray{{0, 0, 0}, {1, 0, 0}}).hit());
  CHECK(tree.closest_hit_batch(std::vector<Ray>(3, Ray{{0, 0, 0}, {0, 1, 0}})).size() == 3);
}

// ---- any hit ------------------------------------------------------------------------------------

TEST_CASE("rays: any_hit agrees with closest_hit on hit or miss and returns a real hit", "[rays]") {
  Rng rng(13);
  for (const auto kind : {kdspace::SceneKind::uniform, kdspace::SceneKind::clustered}) {
    const std::vector<Box3f> boxes = kdspace::generate_boxes(1000, kind, 13);
    std::vector<Ray> rays = random_rays(1000, bounds_of(boxes), rng);
    const std::vector<Ray> lattice = lattice_rays(300, 0, 1, rng);
    rays.insert(rays.end(), lattice.begin(), lattice.end());
    for (const NamedParams& b : all_builds()) {
      const BoxTree tree(boxes, b.params);
      for (const Ray& r : rays)
        for (const auto& [t_min, t_max] :
             {std::pair<float, float>{0, INFINITY}, std::pair<float, float>{0.2f, 0.6f}}) {
          const Hit closest = tree.closest_hit(r, t_min, t_max);
          const Hit any = tree.any_hit(r, t_min, t_max);
          REQUIRE(closest.hit() == any.hit());
          if (!any.hit()) continue;
          const auto t = reference_t(boxes[static_cast<std::size_t>(any.box)], r, t_min, t_max);
          REQUIRE(t.has_value());
          CHECK(std::abs(*t - any.t) <= tolerance(*t));
          CHECK(any.t >= closest.t);
        }
    }
  }
}

TEST_CASE("rays: any_hit stops early: it visits no more than closest_hit", "[rays]") {
  const std::vector<Box3f> boxes = kdspace::generate_boxes(5000, kdspace::SceneKind::uniform, 14);
  Rng rng(14);
  const std::vector<Ray> rays = random_rays(2000, bounds_of(boxes), rng);
  const BoxTree tree(boxes);
  RayStats closest, any;
  tree.closest_hit_batch(rays, 1, &closest);
  tree.any_hit_batch(rays, 1, &any);
  CHECK(any.rays == closest.rays);
  CHECK(any.boxes_tested <= closest.boxes_tested);
  CHECK(any.nodes_visited <= closest.nodes_visited);
}

// ---- batches ------------------------------------------------------------------------------------

TEST_CASE("rays: batches give the hits and stats of single rays on 1, 2 and 4 threads", "[rays][threads]") {
  // Random rays go one by one; a camera's rays mostly four at a time (trace_packet), with single
  // rays wherever four neighbours' directions differ in sign.
  Rng rng(15);
  for (const std::vector<Box3f>& boxes :
       {kdspace::generate_boxes(3000, kdspace::SceneKind::clustered, 15), integer_boxes(400, rng)}) {
    const Box3f bounds = bounds_of(boxes);
    std::vector<Ray> rays = random_rays(3000, bounds, rng);
    for (const auto& camera :
         {kdspace::fit_camera(bounds, 1.0), kdspace::Camera{{5, 6, 30}, {6, 5, 6}, {0, 0, 1}, 70}}) {
      const std::vector<Ray> primary = kdspace::primary_rays(camera, 61, 47);
      rays.insert(rays.end(), primary.begin(), primary.end());
    }
    const BoxTree tree(boxes);
    std::vector<Hit> single_closest, single_any;
    RayStats single_stats;
    for (const Ray& r : rays) {
      single_closest.push_back(tree.closest_hit(r, 0, INFINITY, &single_stats));
      single_any.push_back(tree.any_hit(r));
    }
    for (const unsigned threads : {1u, 2u, 4u}) {
      RayStats stats;
      const std::vector<Hit> closest = tree.closest_hit_batch(rays, threads, &stats);
      const std::vector<Hit> any = tree.any_hit_batch(rays, threads);
      REQUIRE(closest.size() == rays.size());
      for (std::size_t i = 0; i < rays.size(); ++i) {
        REQUIRE(closest[i].box == single_closest[i].box);
        REQUIRE(closest[i].t == single_closest[i].t);
        REQUIRE(any[i].box == single_any[i].box);
      }
      CHECK(stats.rays == single_stats.rays);
      CHECK(stats.nodes_visited == single_stats.nodes_visited);
      CHECK(stats.boxes_tested == single_stats.boxes_tested);
    }
  }
}

TEST_CASE("rays: packet keys are the direction's signs, or say the ray cannot join a packet", "[rays]") {
  using kdspace::detail::packet_key;
  CHECK(packet_key(Ray{{1, 2, 3}, {1, 2, 3}}) == 0u);
  CHECK(packet_key(Ray{{1, 2, 3}, {-1, 2, -3}}) == 5u);
  CHECK(packet_key(Ray{{0, 0, 0}, {-0.5f, -2, -1e-10f}}) == 7u);
  // Rays the float traversal turns away (fits_float_traversal), and zero components: bit 3.
  for (const Ray& r :
       {Ray{{0, 0, 0}, {0, 1, 1}}, Ray{{0, 0, 0}, {1, -0.0f, 1}}, Ray{{0, 0, 0}, {1, 0x1p-65f, 1}},
        Ray{{0, 0, 0}, {1, 1, 0x1p65f}}, Ray{{0x1p63f, 0, 0}, {1, 1, 1}}, Ray{{0, -0x1p63f, 0}, {1, 1, 1}}}) {
    CHECK(packet_key(r) >= 8u);
    CHECK((!kdspace::detail::fits_float_traversal(r, 0x1p62f) || r.direction[0] == 0 || r.direction[1] == 0 ||
           r.direction[2] == 0));
  }
  CHECK(packet_key(Ray{{0x1p62f, 0, 0}, {0x1p-64f, 0x1p64f, -0x1p64f}}) == 4u);  // the range's ends
}

TEST_CASE("rays: batches with rays that cannot join a packet give the hits of single rays", "[rays]") {
  // A camera's rays, every few of them changed so that it cannot join a packet (a zero or tiny
  // direction component, an origin far away): the batch traces packets of eight, four and single
  // rays side by side, and the check of the batch takes its slower path.
  Rng rng(26);
  const std::vector<Box3f> boxes = kdspace::generate_boxes(3000, kdspace::SceneKind::clustered, 26);
  const Box3f bounds = bounds_of(boxes);
  std::vector<Ray> rays = kdspace::primary_rays(kdspace::fit_camera(bounds, 1.0), 64, 48);
  for (std::size_t i = 0; i < rays.size(); i += static_cast<std::size_t>(3 + uniform_int(rng, 0, 20))) {
    switch (uniform_int(rng, 0, 3)) {
      case 0:
        rays[i].direction[1] = 0;
        break;
      case 1:
        rays[i].direction[2] = 0x1p-70f;
        break;
      case 2:
        rays[i].origin[0] = -0x1p63f;
        break;
      default:
        rays[i].direction[0] = -rays[i].direction[0];
        break;
    }
  }
  const BoxTree tree(boxes);
  RayStats single_stats, batch_stats;
  const std::vector<Hit> closest = tree.closest_hit_batch(rays, 1, &batch_stats);
  const std::vector<Hit> any = tree.any_hit_batch(rays, 1);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Hit c = tree.closest_hit(rays[i], 0, INFINITY, &single_stats);
    REQUIRE(closest[i].box == c.box);
    REQUIRE(closest[i].t == c.t);
    REQUIRE(any[i].box == tree.any_hit(rays[i]).box);
  }
  CHECK(batch_stats.nodes_visited == single_stats.nodes_visited);
  CHECK(batch_stats.boxes_tested == single_stats.boxes_tested);
  // A ray that is not usable is named by its position, wherever it lies in the batch.
  for (const std::size_t bad : {std::size_t{0}, std::size_t{63}, std::size_t{64}, rays.size() - 1}) {
    std::vector<Ray> broken = rays;
    broken[bad].direction = {0, 0, 0};
    CHECK_THROWS_WITH(tree.closest_hit_batch(broken),
                      Catch::Contains("ray " + std::to_string(bad + 1) + ":"));
    broken[bad] = rays[bad];
    broken[bad].origin[2] = NAN;
    CHECK_THROWS_WITH(tree.any_hit_batch(broken), Catch::Contains("ray " + std::to_string(bad + 1) + ":"));
  }
}

TEST_CASE("rays: streams of incoherent rays give the hits and stats of single rays", "[rays]") {
  // Random rays form no packets: a batch sends them through the tree in streams, one a direction
  // octant (lib/rays/trace_stream.cpp), thousands of rays a stream here, so that sets split at many
  // nodes, leaves see groups of eight rays and stragglers walk alone. Lattice rays (integer origins,
  // directions +-1, +-2, +-0.5: no zero component, so they stream too) meet faces, edges, corners
  // and split planes exactly, and boxes sharing faces give ties at equal t.
  Rng rng(31);
  const auto lattice_without_zeros = [&rng](std::size_t m, int lo, int hi) {
    std::vector<Ray> rays = lattice_rays(m, lo, hi, rng);
    for (Ray& r : rays)
      for (int a = 0; a < 3; ++a)
        if (r.direction[a] == 0) r.direction[a] = uniform_int(rng, 0, 1) ? 1.0f : -0.5f;
    return rays;
  };
  std::vector<std::vector<Box3f>> scenes = {kdspace::generate_boxes(20000, kdspace::SceneKind::clustered, 31),
                                            mixed_scale_boxes(5000, rng),
                                            overlapping_boxes(1500, rng),
                                            flat_boxes(3000, rng),
                                            integer_boxes(3000, rng),
                                            cube_lattice(rng),
                                            std::vector<Box3f>(500, box_of(1, 2, 3, 2, 4, 4))};
  for (std::size_t scene = 0; scene < scenes.size(); ++scene) {
    const std::vector<Box3f>& boxes = scenes[scene];
    const Box3f bounds = bounds_of(boxes);
    std::vector<Ray> rays = random_rays(12000, bounds, rng);
    const std::vector<Ray> inside = inside_rays(3000, boxes, rng);
    const std::vector<Ray> lattice = lattice_without_zeros(6000, -1, 13);
    rays.insert(rays.end(), inside.begin(), inside.end());
    rays.insert(rays.end(), lattice.begin(), lattice.end());
    // Grazing rays: aimed at a corner of a box, or at the middle of one of its edges, so that whether
    // they touch it is decided within rounding (the float filters' widening at work).
    for (const Ray& from : random_rays(4000, bounds, rng)) {
      const Box3f& b = boxes[static_cast<std::size_t>(uniform_int(rng, 0, static_cast<int>(boxes.size()) - 1))];
      const int corner = uniform_int(rng, 0, 7), edge_axis = uniform_int(rng, -1, 2);
      Ray r = from;
      for (int a = 0; a < 3; ++a) {
        const float target = a == edge_axis ? 0.5f * (b.lo[a] + b.hi[a]) : (corner >> a & 1) ? b.hi[a] : b.lo[a];
        r.direction[a] = target - r.origin[a];
        if (r.direction[a] == 0) r.direction[a] = 0x1p-20f;
      }
      rays.push_back(r);
    }
    const BoxTree tree(boxes);
    for (const kdspace::RayRange range : {kdspace::RayRange{}, kdspace::RayRange{0.25f, 3}}) {
      RayStats single_stats, single_any_stats;
      std::vector<Hit> single_closest, single_any;
      for (const Ray& r : rays) {
        single_closest.push_back(tree.closest_hit(r, range.t_min, range.t_max, &single_stats));
        single_any.push_back(tree.any_hit(r, range.t_min, range.t_max, &single_any_stats));
      }
      for (const unsigned threads : scene == 0 ? std::vector<unsigned>{1, 2} : std::vector<unsigned>{1}) {
        INFO("scene " << scene << ", range [" << range.t_min << ", " << range.t_max << "], " << threads
                      << " threads");
        RayStats stats, any_stats;
        const std::vector<Hit> closest = tree.closest_hit_batch(rays, range, threads, &stats);
        const std::vector<Hit> any = tree.any_hit_batch(rays, range, threads, &any_stats);
        for (std::size_t i = 0; i < rays.size(); ++i) {
          INFO("ray " << i << ": " << describe(rays[i]));
          REQUIRE(closest[i].box == single_closest[i].box);
          REQUIRE(closest[i].t == single_closest[i].t);
          REQUIRE(any[i].box == single_any[i].box);
          REQUIRE(any[i].t == single_any[i].t);
        }
        CHECK(stats.rays == single_stats.rays);
        CHECK(stats.nodes_visited == single_stats.nodes_visited);
        CHECK(stats.boxes_tested == single_stats.boxes_tested);
        CHECK(any_stats.nodes_visited == single_any_stats.nodes_visited);
        CHECK(any_stats.boxes_tested == single_any_stats.boxes_tested);
      }
    }
  }
}

TEST_CASE("rays: batches over a range give the hits of single rays over it", "[rays]") {
  Rng rng(25);
  const std::vector<Box3f> boxes = kdspace::generate_boxes(2000, kdspace::SceneKind::clustered, 25);
  const Box3f bounds = bounds_of(boxes);
  std::vector<Ray> rays = random_rays(1000, bounds, rng);
  const std::vector<Ray> primary = kdspace::primary_rays(kdspace::fit_camera(bounds, 1.0), 40, 40);
  rays.insert(rays.end(), primary.begin(), primary.end());
  const BoxTree tree(boxes);
  for (const kdspace::RayRange range :
       {kdspace::RayRange{0.5f, 1.5f}, kdspace::RayRange{-1, 0.25f}, kdspace::RayRange{1, 1}}) {
    RayStats batch_stats, single_stats;
    const std::vector<Hit> closest = tree.closest_hit_batch(rays, range, 2, &batch_stats);
    const std::vector<Hit> any = tree.any_hit_batch(rays, range);
    for (std::size_t i = 0; i < rays.size(); ++i) {
      const Hit c = tree.closest_hit(rays[i], range.t_min, range.t_max, &single_stats);
      REQUIRE(closest[i].box == c.box);
      REQUIRE(closest[i].t == c.t);
      REQUIRE(any[i].box == tree.any_hit(rays[i], range.t_min, range.t_max).box);
      if (c.hit()) CHECK((c.t >= range.t_min && c.t <= range.t_max));
    }
    CHECK(batch_stats.nodes_visited == single_stats.nodes_visited);
    CHECK(batch_stats.boxes_tested == single_stats.boxes_tested);
  }
  CHECK_THROWS_WITH(tree.closest_hit_batch(rays, kdspace::RayRange{2, 1}), Catch::Contains("exceeds t_max"));
  CHECK_THROWS_WITH(tree.any_hit_batch(rays, kdspace::RayRange{NAN, 1}),
                    Catch::Contains("t_min must be finite"));
}

TEST_CASE("rays: trace statistics count rays, nodes and box tests", "[rays]") {
  const std::vector<Box3f> boxes = kdspace::generate_boxes(2000, kdspace::SceneKind::uniform, 16);
  Rng rng(16);
  const std::vector<Ray> rays = random_rays(1000, bounds_of(boxes), rng);
  const BoxTree tree(boxes);
  RayStats stats;
  tree.closest_hit_batch(rays, 1, &stats);
  CHECK(stats.rays == rays.size());
  CHECK(stats.nodes_visited >= stats.rays / 2);  // rays that meet the scene bounds enter the root
  CHECK(stats.boxes_tested_per_ray() < 100);     // far fewer than the 2000 of brute force
  CHECK(stats.nodes_visited_per_ray() > 1);
}

// ---- bad input ----------------------------------------------------------------------------------

TEST_CASE("rays: bad boxes throw an Error naming the box, 1-based", "[rays]") {
  using Catch::Contains;
  std::vector<Box3f> boxes(20, box_of(0, 0, 0, 1, 1, 1));
  boxes[16] = box_of(3, 0, 0, 1, 1, 1);
  CHECK_THROWS_WITH(BoxTree(boxes), "box 17: min x 3 > max x 1");
  boxes[16] = box_of(0, 0, 0, 1, 1, 1);
  boxes[4].lo[1] = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH(BoxTree(boxes), "box 5: min y is nan");
  boxes[4].lo[1] = 0;
  boxes[0].hi[2] = std::numeric_limits<float>::infinity();
  CHECK_THROWS_WITH(BoxTree(boxes), "box 1: max z is inf");
  boxes[0].hi[2] = 1;
  CHECK_NOTHROW(BoxTree(boxes));
}

TEST_CASE("rays: bad rays and ranges throw an Error", "[rays]") {
  const BoxTree tree(std::vector<Box3f>{box_of(0, 0, 0, 1, 1, 1)});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH(tree.closest_hit(Ray{{0, 0, 0}, {0, 0, 0}}), "ray: direction is zero");
  CHECK_THROWS_WITH(tree.closest_hit(Ray{{0, 0, 0}, {-0.0f, 0, -0.0f}}), "ray: direction is zero");
  CHECK_THROWS_WITH(tree.any_hit(Ray{{0, nan, 0}, {1, 0, 0}}), "ray: origin y is nan");
  CHECK_THROWS_WITH(tree.closest_hit(Ray{{0, 0, 0}, {1, 0, INFINITY}}), "ray: direction z is inf");
  CHECK_THROWS_AS(tree.closest_hit(Ray{{0, 0, 0}, {1, 0, 0}}, 2, 1), kdspace::Error);
  CHECK_THROWS_AS(tree.closest_hit(Ray{{0, 0, 0}, {1, 0, 0}}, nan), kdspace::Error);
  CHECK_THROWS_AS(tree.closest_hit(Ray{{0, 0, 0}, {1, 0, 0}}, 0, nan), kdspace::Error);
  CHECK_THROWS_AS(tree.closest_hit(Ray{{0, 0, 0}, {1, 0, 0}}, -INFINITY), kdspace::Error);
  std::vector<Ray> rays(20, Ray{{0, 0, 0}, {1, 0, 0}});
  rays[11].direction = {0, 0, 0};
  CHECK_THROWS_WITH(tree.closest_hit_batch(rays, 2), "ray 12: direction is zero");
  CHECK_THROWS_WITH(tree.any_hit_batch(rays, 1), "ray 12: direction is zero");
  // A tiny direction is fine: its reciprocal is computed in double.
  const Hit h = tree.closest_hit(Ray{{-1e-35f, 0.5f, 0.5f}, {1e-40f, 0, 0}});
  CHECK(h.box == 0);
  CHECK(h.t == Approx(1e5).epsilon(1e-5));
}

TEST_CASE("rays: bad build parameters throw an Error", "[rays]") {
  const std::vector<Box3f> boxes(3, box_of(0, 0, 0, 1, 1, 1));
  BoxBuildParams p;
  p.K_i = 0;
  CHECK_THROWS_AS(BoxTree(boxes, p), kdspace::Error);
  p = BoxBuildParams{};
  p.K_t = -1;
  CHECK_THROWS_AS(BoxTree(boxes, p), kdspace::Error);
  p = BoxBuildParams{};
  p.empty_bonus = 1;
  CHECK_THROWS_AS(BoxTree(boxes, p), kdspace::Error);
  p = BoxBuildParams{};
  p.max_depth = kdspace::max_box_tree_depth + 1;
  CHECK_THROWS_AS(BoxTree(boxes, p), kdspace::Error);
  p = BoxBuildParams{};
  p.method = BoxBuildMethod::median;
  p.leaf_size = 0;
  CHECK_THROWS_AS(BoxTree(boxes, p), kdspace::Error);
}

// ---- coordinates at the extremes of float -----------------------------------------------------------

TEST_CASE("rays: boxes near the float range and far from the origin", "[rays]") {
  Rng rng(17);
  std::vector<Box3f> boxes;
  const float big = 1e38f;
  boxes.push_back(box_of(-3e38f, -big, -big, -1e37f, big, big));
  boxes.push_back(box_of(1e30f, 1e30f, 1e30f, 2e30f, 2e30f, 2e30f));
  for (const Box3f& b : mixed_scale_boxes(100, rng)) {
    Box3f far = b;
    for (int a = 0; a < 3; ++a) {
      far.lo[a] += 1e6f;
      far.hi[a] += 1e6f;
    }
    boxes.push_back(far);
  }
  std::vector<Ray> rays =
      random_rays(300, bounds_of(std::vector<Box3f>(boxes.begin() + 2, boxes.end())), rng);
  rays.push_back(Ray{{0, 0, 0}, {1, 1, 1}});
  rays.push_back(Ray{{-3e38f, 0, 0}, {-1, 0, 0}});
  check_scene(boxes, rays);
}

TEST_CASE("rays: the float traversal gives the double traversal's answers, bit for bit", "[rays]") {
  // The same boxes traced twice: as they are (float traversal) and with one more box far beyond
  // 2^62, which puts the scene out of the float range (double traversal). The closest hits must be
  // equal in box and t; any hits agree on hit or miss (the two traversals may meet the boxes in a
  // different order).
  Rng rng(21);
  const std::vector<std::vector<Box3f>> scenes{
      kdspace::generate_boxes(3000, kdspace::SceneKind::clustered, 21), integer_boxes(600, rng),
      flat_boxes(600, rng), mixed_scale_boxes(600, rng), overlapping_boxes(300, rng)};
  for (std::size_t s = 0; s < scenes.size(); ++s) {
    INFO("scene " << s);
    const std::vector<Box3f>& boxes = scenes[s];
    std::vector<Box3f> with_far = boxes;
    with_far.push_back(box_of(1e25f, 1e25f, 1e25f, 2e25f, 2e25f, 2e25f));
    const BoxTree in_float(boxes), in_double(with_far);
    const Box3f bounds = bounds_of(boxes);
    std::vector<Ray> rays = random_rays(1500, bounds, rng);
    const std::vector<Ray> lattice = lattice_rays(500, 0, 12, rng);
    rays.insert(rays.end(), lattice.begin(), lattice.end());
    // Nearly parallel rays: components of 1e-7 .. 1e-19 are traced in float, 1e-25 in double.
    for (const float tiny : {1e-7f, 1e-12f, 1e-19f, 1e-25f})
      for (int k = 0; k < 100; ++k) {
        Ray r = random_rays(1, bounds, rng)[0];
        r.direction[static_cast<std::size_t>(k % 3)] = (k % 2 ? tiny : -tiny);
        rays.push_back(r);
      }
    std::size_t failures = 0;
    for (std::size_t i = 0; i < rays.size() && failures < 5; ++i) {
      const Hit a = in_float.closest_hit(rays[i]), b = in_double.closest_hit(rays[i]);
      if (b.box == static_cast<std::int32_t>(boxes.size())) continue;  // the far box
      if (a.box != b.box || (a.hit() && a.t != b.t)) {
        ++failures;
        FAIL_CHECK("ray " << i << " " << describe(rays[i]) << ": float traversal box " << a.box << " t "
                          << a.t << ", double traversal box " << b.box << " t " << b.t);
      }
      const Hit any_a = in_float.any_hit(rays[i]), any_b = in_double.any_hit(rays[i]);
      if (any_b.box != static_cast<std::int32_t>(boxes.size())) CHECK(any_a.hit() == any_b.hit());
    }
  }
}

TEST_CASE("rays: nearly parallel rays and rays with subnormal direction components", "[rays]") {
  Rng rng(23);
  const std::vector<Box3f> boxes = mixed_scale_boxes(800, rng);
  const Box3f bounds = bounds_of(boxes);
  std::vector<Ray> rays;
  for (const float tiny : {1e-3f, 1e-9f, 1e-18f, 0x1p-64f, 0x1p-65f, 1e-30f, 1e-40f, 1e-45f})
    for (int k = 0; k < 60; ++k) {
      Ray r = random_rays(1, bounds, rng)[0];
      for (int a = 0; a < 3; ++a)
        if (a != k % 3 && (k / 3) % 2 == 0) r.direction[static_cast<std::size_t>(a)] = (a % 2 ? tiny : -tiny);
      if (k % 5 == 0) r.direction[static_cast<std::size_t>(k % 3)] = tiny;
      rays.push_back(r);
    }
  check_scene(boxes, rays);
}

TEST_CASE("rays: a hit's t rounded up to float is the smallest float at or above it", "[rays]") {
  // round_up<float> finds it without a branch on the rounding: checked against the float nearest t
  // stepped up by std::nextafter where it lies below t, on t of every exponent and sign, exact
  // floats, halfway and near-halfway doubles, zeros, subnormals and the ends of the float range.
  using kdspace::detail::round_up;
  const float inf = std::numeric_limits<float>::infinity(), largest = std::numeric_limits<float>::max();
  const auto expected = [&](double t) {
    if (t > static_cast<double>(largest)) return inf;
    if (t < -static_cast<double>(largest)) return -largest;
    const auto f = static_cast<float>(t);
    return static_cast<double>(f) < t ? std::nextafter(f, inf) : f;
  };
  std::size_t checked = 0;
  const auto check = [&](double t) {
    ++checked;
    INFO("t " << t);
    const float up = round_up<float>(t), want = expected(t);
    REQUIRE(std::memcmp(&up, &want, sizeof up) == 0);  // -0 stays -0
    REQUIRE(static_cast<double>(up) >= t);
  };
  Rng rng(37);
  std::uniform_int_distribution<int> exponent(-160, 130);
  std::uniform_real_distribution<double> mantissa(1.0, 2.0);
  for (int i = 0; i < 200000; ++i) {
    const double t = std::ldexp(mantissa(rng), exponent(rng)) * (i % 2 ? -1.0 : 1.0);
    check(t);
    const auto f = static_cast<float>(t);
    const double exact = f, next = std::nextafter(f, inf);
    check(exact);
    check((exact + next) / 2);  // halfway: the conversion rounds to even, either way
    check(std::nextafter((exact + next) / 2, 0.0));
    check(std::nextafter(exact, -1e300));
    check(std::nextafter(exact, 1e300));
  }
  const double edges[] = {0.0,
                          -0.0,
                          1e-320,
                          -1e-320,
                          0x1p-150,
                          -0x1p-150,
                          0x1p-149,
                          -0x1p-149,
                          0x1.8p-149,
                          0x1p-126,
                          std::nextafter(0x1p-126, 0.0),
                          1.0,
                          -1.0,
                          static_cast<double>(largest),
                          std::nextafter(static_cast<double>(largest), 1e300),
                          -static_cast<double>(largest),
                          std::nextafter(-static_cast<double>(largest), -1e300),
                          1e300,
                          -1e300};
  for (const double t : edges) check(t);
  CHECK(checked > 1200000);
}

TEST_CASE("rays: the leaf filter's comparison from t >= 0 accepts every interval the widenings accept",
          "[rays]") {
  // may_hit_from_nonnegative must be conservative: wherever widen_down(t_near) <= widen_up(t_far)
  // holds for a t_near >= 0, it holds too. Intervals at and around equality at every scale (ratios a
  // few ulps to 2^-16 apart), subnormal and zero ends, negative and infinite far ends.
  using kdspace::detail::may_hit_from_nonnegative;
  using kdspace::detail::widen_down;
  using kdspace::detail::widen_up;
  const float inf = std::numeric_limits<float>::infinity();
  Rng rng(31);
  std::uniform_int_distribution<int> exponent(-149, 127);
  std::uniform_int_distribution<int> ulps(-600, 600);
  std::uniform_real_distribution<float> mantissa(1.0f, 2.0f);
  std::size_t accepted = 0, checked = 0;
  const auto check = [&](float t_near, float t_far) {
    if (!(t_near >= 0) || std::isnan(t_far)) return;
    ++checked;
    if (!(widen_down(t_near) <= widen_up(t_far))) return;
    ++accepted;
    INFO("t_near " << t_near << " t_far " << t_far);
    REQUIRE(may_hit_from_nonnegative(t_near, t_far));
  };
  for (int i = 0; i < 400000; ++i) {
    const float t_near = std::ldexp(mantissa(rng), exponent(rng));
    // t_far up to 39 ulps either side of t_near, every third one also scaled by up to 600 * 2^-25
    // (about 2^-16) either way.
    float t_far = t_near;
    const int step = ulps(rng);
    for (int k = 0; k < std::abs(step) % 40; ++k) t_far = std::nextafter(t_far, step < 0 ? 0.0f : inf);
    if (i % 3 == 0) t_far = t_far * (1.0f + static_cast<float>(step) * 0x1p-25f);
    check(t_near, t_far);
    check(t_far, t_near);
    check(0.0f, -t_far);
  }
  const float edges[] = {0.0f,      -0.0f,     std::numeric_limits<float>::denorm_min(),
                         0x1p-127f, 0x1p-126f, 0x1p-125f,
                         0x1p-124f, 0x1p-123f, 1.0f,
                         0x1p100f,  std::numeric_limits<float>::max(), inf};
  for (const float a : edges)
    for (const float b : edges) {
      check(a, b);
      check(a, -b);
      check(a, std::nextafter(b, 0.0f));
      check(a, std::nextafter(-b, 0.0f));
    }
  CHECK(accepted > checked / 4);
  CHECK(accepted < checked);
}

TEST_CASE("rays: the eight-box leaf filter lets through exactly the lanes of two four-box filters",
          "[rays]") {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (!kdspace::detail::avx2_dispatch()) return;  // no AVX2 (or KDSPACE_NO_AVX2): the traversal never uses it
  // Blocks of flat, thin and overlapping boxes, rays from inside and outside with zero, tiny and
  // negative direction components, over several intervals: the masks must agree bit for bit (the
  // eight lanes compute what the four lanes compute, in the same order of operations).
  Rng rng(29);
  std::vector<Box3f> boxes = flat_boxes(400, rng);
  const std::vector<Box3f> more = mixed_scale_boxes(400, rng);
  boxes.insert(boxes.end(), more.begin(), more.end());
  std::vector<kdspace::LeafBlock> blocks(boxes.size() / 4);
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      blocks[i / 4].plane[a][i % 4] = boxes[i].lo[a];
      blocks[i / 4].plane[3 + a][i % 4] = boxes[i].hi[a];
    }
  std::vector<Ray> rays = random_rays(400, bounds_of(boxes), rng);
  for (std::size_t k = 0; k < rays.size(); k += 3) rays[k].direction[k % 3] = k % 2 ? 0.0f : -0.0f;
  for (std::size_t k = 1; k < rays.size(); k += 5) rays[k].direction[k % 3] = 1e-20f;
  std::size_t passed = 0;
  for (const Ray& ray : rays) {
    const kdspace::detail::TraversalRay<float> r(ray);
    for (const float t_hi : {std::numeric_limits<float>::infinity(), 0.5f, 1e-3f}) {
      for (std::size_t b = 0; b + 1 < blocks.size(); b += 2) {
        const unsigned four = kdspace::detail::block_candidates<float>(blocks[b], r, 0.0f, t_hi) |
                              kdspace::detail::block_candidates<float>(blocks[b + 1], r, 0.0f, t_hi) << 4;
        const unsigned eight =
            kdspace::detail::block_pair_candidates(blocks[b], blocks[b + 1], r, 0.0f, t_hi);
        REQUIRE(eight == four);
        passed += static_cast<std::size_t>(__builtin_popcount(eight));
      }
    }
  }
  CHECK(passed > 0);
#endif
}

TEST_CASE("rays: the vector-register descent makes the scalar descent's choices, bit for bit", "[rays]") {
#if defined(KDSPACE_AVX2_DISPATCH)
  if (!kdspace::detail::avx2_dispatch()) return;  // no AVX2 (or KDSPACE_NO_AVX2): never used
  // Every ray walks the whole tree (every pushed far child popped, no cut by a hit) once with each
  // descent: the leaves reached, the entries pushed (node, t_entry, t_exit bits) and the nodes
  // counted must be the same. Rays in split planes (integer scenes, lattice rays), with +-0, tiny
  // and negative direction components, from inside and outside.
  using kdspace::detail::StackEntry;
  struct Walk {
    std::vector<std::uint64_t> leaves;
    std::vector<std::uint32_t> pushed;  // node, then the bits of t_entry and t_exit
    std::uint64_t visited = 0;
  };
  const auto bits_of = [](float f) {
    std::uint32_t b;
    std::memcpy(&b, &f, sizeof b);
    return b;
  };
  Rng rng(31);
  const std::vector<std::vector<Box3f>> scenes{
      kdspace::generate_boxes(3000, kdspace::SceneKind::clustered, 31), integer_boxes(600, rng),
      flat_boxes(600, rng), mixed_scale_boxes(600, rng), overlapping_boxes(300, rng)};
  std::size_t leaves = 0;
  for (std::size_t s = 0; s < scenes.size(); ++s) {
    INFO("scene " << s);
    const BoxTree tree(scenes[s]);
    const Box3f bounds = tree.bounds();
    std::vector<Ray> rays = random_rays(600, bounds, rng);
    const std::vector<Ray> lattice = lattice_rays(600, -1, 13, rng);
    rays.insert(rays.end(), lattice.begin(), lattice.end());
    for (std::size_t k = 0; k < 600; k += 3) rays[k].direction[k % 3] = k % 2 ? 0.0f : -0.0f;
    for (std::size_t k = 1; k < 600; k += 7) rays[k].direction[k % 3] = -1e-20f;
    for (const Ray& ray : rays) {
      const kdspace::detail::TraversalRay<float> r(ray);
      float t_entry = 0, t_exit = std::numeric_limits<float>::infinity();
      if (!kdspace::detail::clip_widened(bounds, r, t_entry, t_exit)) continue;
      const kdspace::detail::DescentRay d = kdspace::detail::descent_ray(r);
      Walk walks[2];
      for (int form = 0; form < 2; ++form) {
        Walk& walk = walks[form];
        std::vector<StackEntry<float>> stack(kdspace::max_box_tree_depth + 2);
        std::size_t top = 0;
        stack[top++] = StackEntry<float>{0, t_entry, t_exit};
        while (top > 0) {
          const StackEntry<float> entry = stack[--top];
          const std::size_t before = top;
          const kdspace::BoxNode leaf =
              form == 0 ? kdspace::detail::descend(tree.nodes().data(), entry.node, entry.t_entry,
                                                   entry.t_exit, r, stack.data(), top, walk.visited)
                        : kdspace::detail::descend_avx(tree.nodes().data(), entry.node, entry.t_entry,
                                                       entry.t_exit, r, d, stack.data(), top, walk.visited);
          walk.leaves.push_back(kdspace::detail::node_bits(leaf));
          for (std::size_t i = before; i < top; ++i) {
            walk.pushed.push_back(stack[i].node);
            walk.pushed.push_back(bits_of(stack[i].t_entry));
            walk.pushed.push_back(bits_of(stack[i].t_exit));
          }
        }
      }
      INFO(describe(ray));
      REQUIRE(walks[1].leaves == walks[0].leaves);
      REQUIRE(walks[1].pushed == walks[0].pushed);
      REQUIRE(walks[1].visited == walks[0].visited);
      leaves += walks[0].leaves.size();
    }
  }
  CHECK(leaves > 0);
#endif
}
