// The collision pairs against CGAL's box_intersection_d (Zomorodian & Edelsbrunner's streamed segment
// tree), an implementation independent of ours: the same pair sets, pair for pair, on uniform,
// clustered, heavily overlapping, flat, face-sharing and degenerate scenes, across two sets, and over
// 100 frames of motion. Its own executable (kdspace_cgal_tests), since CGAL's headers compile slowly.
#include <CGAL/box_intersection_d.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdint>
#include <string>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/motion_gen.hpp"
#include "kdspace/collide/moving_scene.hpp"
#include "kdspace/collide/overlap.hpp"
#include "support.hpp"

using kdspace::Box3f;
using kdspace::BoxBuildMethod;
using kdspace::BoxBuildParams;
using kdspace::BoxTree;
using kdspace::IndexPair;
using kdspace_test::all_collision_scenes;
using kdspace_test::CollisionScene;
using kdspace_test::make_collision_scene;

namespace {

// ID_EXPLICIT: every box gets its own id when made, which box_self_intersection_d needs (it works on
// a copy of the boxes); info() carries our index.
using CgalBox =
    CGAL::Box_intersection_d::Box_with_info_d<float, 3, std::uint32_t, CGAL::Box_intersection_d::ID_EXPLICIT>;

std::vector<CgalBox> to_cgal(const std::vector<Box3f>& boxes) {
  std::vector<CgalBox> out;
  out.reserve(boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    float lo[3] = {boxes[i].lo[0], boxes[i].lo[1], boxes[i].lo[2]};
    float hi[3] = {boxes[i].hi[0], boxes[i].hi[1], boxes[i].hi[2]};
    out.emplace_back(lo, hi, static_cast<std::uint32_t>(i));
  }
  return out;
}

/// CGAL's pairs within one set, closed boxes, as (a, b) with a < b, sorted.
std::vector<IndexPair> cgal_pairs(const std::vector<Box3f>& boxes) {
  std::vector<CgalBox> cgal = to_cgal(boxes);
  std::vector<IndexPair> pairs;
  CGAL::box_self_intersection_d(
      cgal.begin(), cgal.end(),
      [&](const CgalBox& x, const CgalBox& y) {
        pairs.push_back({std::min(x.info(), y.info()), std::max(x.info(), y.info())});
      },
      std::ptrdiff_t(10), CGAL::Box_intersection_d::CLOSED);
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

/// CGAL's pairs across two sets (a in the first, b in the second), sorted.
std::vector<IndexPair> cgal_pairs(const std::vector<Box3f>& first, const std::vector<Box3f>& second) {
  std::vector<CgalBox> a = to_cgal(first), b = to_cgal(second);
  std::vector<IndexPair> pairs;
  CGAL::box_intersection_d(
      a.begin(), a.end(), b.begin(), b.end(),
      [&](const CgalBox& x, const CgalBox& y) {
        pairs.push_back({x.info(), y.info()});
      },
      std::ptrdiff_t(10), CGAL::Box_intersection_d::CLOSED, CGAL::Box_intersection_d::BIPARTITE);
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

std::vector<BoxBuildParams> builds() {
  std::vector<BoxBuildParams> list;
  for (const BoxBuildMethod m : {BoxBuildMethod::binned, BoxBuildMethod::sah_nlogn, BoxBuildMethod::median}) {
    BoxBuildParams p;
    p.method = m;
    list.push_back(p);
  }
  return list;
}

std::string first_difference(const std::vector<IndexPair>& got, const std::vector<IndexPair>& want) {
  for (std::size_t i = 0; i < std::min(got.size(), want.size()); ++i)
    if (got[i] != want[i])
      return "pair " + std::to_string(i) + ": (" + std::to_string(got[i].a) + ", " +
             std::to_string(got[i].b) + "), CGAL (" + std::to_string(want[i].a) + ", " +
             std::to_string(want[i].b) + ")";
  return got.size() == want.size()
             ? ""
             : std::to_string(got.size()) + " pairs, CGAL " + std::to_string(want.size());
}

}  // namespace

TEST_CASE("cgal: pairs within one set equal box_self_intersection_d on every scene", "[collide][cgal]") {
  for (const CollisionScene scene : all_collision_scenes) {
    const std::vector<Box3f> boxes = make_collision_scene(scene, 2500, 101);
    const std::vector<IndexPair> expected = cgal_pairs(boxes);
    CHECK(!expected.empty());
    for (const BoxBuildParams& p : builds()) {
      INFO(kdspace_test::name(scene) << ", build " << static_cast<int>(p.method));
      const BoxTree tree(boxes, p);
      REQUIRE(first_difference(kdspace::overlapping_pairs(tree, 2), expected) == "");
    }
  }
}

TEST_CASE("cgal: pairs across two sets equal box_intersection_d on every scene", "[collide][cgal]") {
  for (const CollisionScene scene : all_collision_scenes) {
    const std::vector<Box3f> first = make_collision_scene(scene, 1500, 102);
    const std::vector<Box3f> second = make_collision_scene(scene, 1000, 103);
    const std::vector<IndexPair> expected = cgal_pairs(first, second);
    CHECK(!expected.empty());
    for (const BoxBuildParams& p : builds()) {
      INFO(kdspace_test::name(scene) << ", build " << static_cast<int>(p.method));
      const BoxTree a(first, p), b(second, p);
      REQUIRE(first_difference(kdspace::overlapping_pairs(a, b, 2), expected) == "");
    }
  }
}

TEST_CASE("cgal: 100 frames of motion give CGAL's pairs every frame", "[collide][cgal]") {
  const kdspace::MotionKind kinds[] = {kdspace::MotionKind::brownian, kdspace::MotionKind::free_fall};
  for (const kdspace::MotionKind kind : kinds)
    for (const double share : {1.0, 0.1}) {
      kdspace::MotionSimulation motion(make_collision_scene(CollisionScene::uniform, 1500, 104), kind, share,
                                       105);
      kdspace::MovingScene scene;
      for (int frame = 0; frame < 100; ++frame) {
        const std::vector<Box3f>& boxes = frame == 0 ? motion.boxes() : motion.step();
        INFO("motion " << static_cast<int>(kind) << ", share " << share << ", frame " << frame);
        REQUIRE(first_difference(scene.step(boxes), cgal_pairs(boxes)) == "");
      }
    }
}
