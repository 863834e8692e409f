// Tests of the collision queries on BoxTree (kdspace/collide/) against brute force: overlap queries,
// overlapping pairs of one set and of two sets, first contact of a moving box, and their batch forms.
// Every answer must equal the reference exactly: the same ids, the same pairs, the same contact box
// and the same t bit for bit.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/brute_force.hpp"
#include "kdspace/collide/contact.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/error.hpp"
#include "support.hpp"

using kdspace::Box3f;
using kdspace::BoxBuildMethod;
using kdspace::BoxBuildParams;
using kdspace::BoxTree;
using kdspace::CollideStats;
using kdspace::Contact;
using kdspace::IndexPair;
using kdspace::MovingBox;
using kdspace::Vec3f;
using kdspace_test::all_collision_scenes;
using kdspace_test::box_of;
using kdspace_test::CollisionScene;
using kdspace_test::make_collision_scene;
using kdspace_test::Rng;
using kdspace_test::uniform;
using kdspace_test::uniform_int;

namespace {

constexpr float inf = std::numeric_limits<float>::infinity();

struct BuildChoice {
  const char* name;
  BoxBuildParams params;
};

std::vector<BuildChoice> all_builds() {
  std::vector<BuildChoice> builds;
  BoxBuildParams p;
  p.method = BoxBuildMethod::median;
  builds.push_back({"median", p});
  p.median_position = kdspace::MedianPosition::object_median;
  builds.push_back({"median object", p});
  p = {};
  p.method = BoxBuildMethod::sah;
  builds.push_back({"sah", p});
  p.method = BoxBuildMethod::sah_nlogn;
  builds.push_back({"sah_nlogn", p});
  p.leaf_size = 1;
  p.method = BoxBuildMethod::median;
  p.max_depth = 20;
  builds.push_back({"median leaf 1", p});
  p = {};
  p.method = BoxBuildMethod::binned;
  builds.push_back({"binned", p});
  p.leaf_size = 1;
  builds.push_back({"binned leaf 1", p});
  return builds;
}

/// The bounds of a scene, grown by a quarter of its size on every side.
Box3f grown_bounds(const std::vector<Box3f>& boxes) {
  Box3f b = boxes.front();
  for (const Box3f& x : boxes)
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], x.lo[a]);
      b.hi[a] = std::max(b.hi[a], x.hi[a]);
    }
  for (int a = 0; a < 3; ++a) {
    const float margin = 0.25f * (b.hi[a] - b.lo[a]) + 0.5f;
    b.lo[a] -= margin;
    b.hi[a] += margin;
  }
  return b;
}

/// Query boxes for a scene: random boxes of several sizes, the scene's own boxes, their faces and
/// corners (touching exactly), and points.
std::vector<Box3f> query_boxes(const std::vector<Box3f>& boxes, std::size_t n, std::uint32_t seed) {
  Rng rng(seed);
  const Box3f range = grown_bounds(boxes);
  std::vector<Box3f> queries;
  for (std::size_t q = 0; q < n; ++q) {
    const Box3f& some =
        boxes[static_cast<std::size_t>(uniform_int(rng, 0, static_cast<int>(boxes.size()) - 1))];
    Box3f b;
    switch (q % 5) {
      case 0:  // random, up to a fifth of the range wide
        for (int a = 0; a < 3; ++a) {
          b.lo[a] = uniform(rng, range.lo[a], range.hi[a]);
          b.hi[a] = b.lo[a] + uniform(rng, 0, 0.2f) * (range.hi[a] - range.lo[a]);
        }
        break;
      case 1:  // a box of the scene
        b = some;
        break;
      case 2: {  // the upper face of a box of the scene, on a random axis
        b = some;
        const int a = uniform_int(rng, 0, 2);
        b.lo[a] = b.hi[a];
        break;
      }
      case 3:  // the upper corner of a box of the scene
        b.lo = b.hi = some.hi;
        break;
      default:  // a box ending exactly where a scene box begins
        for (int a = 0; a < 3; ++a) {
          b.hi[a] = some.lo[a];
          b.lo[a] = some.lo[a] - uniform(rng, 0, 1);
        }
        break;
    }
    queries.push_back(b);
  }
  return queries;
}

std::string describe(const IndexPair& p) {
  return "(" + std::to_string(p.a) + ", " + std::to_string(p.b) + ")";
}

/// "" when the lists are equal, else the first difference.
std::string compare_pairs(const std::vector<IndexPair>& got, const std::vector<IndexPair>& want) {
  for (std::size_t i = 0; i < std::min(got.size(), want.size()); ++i)
    if (got[i] != want[i])
      return "at " + std::to_string(i) + ": got " + describe(got[i]) + ", expected " + describe(want[i]);
  if (got.size() != want.size())
    return "got " + std::to_string(got.size()) + " pairs, expected " + std::to_string(want.size());
  return "";
}

}  // namespace

// ---- overlap queries ------------------------------------------------------------------------------

TEST_CASE("collide: overlapping equals brute force on every scene and build", "[collide]") {
  for (const CollisionScene scene : all_collision_scenes) {
    const std::vector<Box3f> boxes = make_collision_scene(scene, 600, 11);
    const std::vector<Box3f> queries = query_boxes(boxes, 200, 12);
    for (const BuildChoice& build : all_builds()) {
      const BoxTree tree(boxes, build.params);
      for (std::size_t q = 0; q < queries.size(); ++q) {
        INFO(kdspace_test::name(scene) << ", " << build.name << " build, query " << q);
        REQUIRE(kdspace::overlapping(tree, queries[q]) ==
                kdspace::brute_force_overlapping(boxes, queries[q]));
      }
    }
  }
}

TEST_CASE("collide: touching counts: a box sharing only a face, an edge or a corner overlaps", "[collide]") {
  const std::vector<Box3f> boxes = {box_of(0, 0, 0, 1, 1, 1), box_of(1, 0, 0, 2, 1, 1),
                                    box_of(1, 1, 0, 2, 2, 1), box_of(1, 1, 1, 2, 2, 2),
                                    box_of(3, 3, 3, 4, 4, 4)};
  const BoxTree tree(boxes);
  using Ids = std::vector<std::uint32_t>;
  CHECK(kdspace::overlapping(tree, boxes[0]) == Ids{0, 1, 2, 3});
  CHECK(kdspace::overlapping(tree, box_of(2, 2, 2, 3, 3, 3)) == Ids{3, 4});  // corners: (2,2,2) and (3,3,3)
  CHECK(kdspace::overlapping(tree, box_of(2.5f, 2.5f, 2.5f, 2.9f, 2.9f, 2.9f)).empty());
  const std::vector<IndexPair> expected = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  CHECK(kdspace::overlapping_pairs(tree) == expected);
}

TEST_CASE("collide: overlapping on an empty tree finds nothing; a bad query box throws", "[collide]") {
  const BoxTree empty(std::vector<Box3f>{});
  CHECK(kdspace::overlapping(empty, box_of(0, 0, 0, 1, 1, 1)).empty());
  CHECK(kdspace::overlapping_pairs(empty).empty());
  CHECK(kdspace::overlapping_pairs(empty, empty).empty());
  CHECK_FALSE(kdspace::first_contact(empty, box_of(0, 0, 0, 1, 1, 1), {1, 0, 0}).hit());
  const BoxTree tree(std::vector<Box3f>{box_of(0, 0, 0, 1, 1, 1)});
  CHECK_THROWS_WITH(kdspace::overlapping(tree, box_of(0, 0, 0, -1, 1, 1)), "query box: min x 0 > max x -1");
  CHECK_THROWS_WITH(kdspace::overlapping(tree, box_of(0, NAN, 0, 1, 1, 1)), "query box: min y is nan");
  const std::vector<Box3f> queries = {box_of(0, 0, 0, 1, 1, 1), box_of(0, 0, inf, 1, 1, inf)};
  CHECK_THROWS_WITH(kdspace::overlapping_batch(tree, queries), "query 2: min z is inf");
}

TEST_CASE("collide: overlapping_batch gives the rows of single queries on 1, 2 and 4 threads",
          "[collide][threads]") {
  const std::vector<Box3f> boxes = make_collision_scene(CollisionScene::clustered, 3000, 5);
  const std::vector<Box3f> queries = query_boxes(boxes, 1500, 6);
  const BoxTree tree(boxes);
  CollideStats single;
  std::vector<std::vector<std::uint32_t>> expected;
  for (const Box3f& q : queries) expected.push_back(kdspace::overlapping(tree, q, &single));
  for (unsigned threads : {1u, 2u, 4u}) {
    CollideStats stats;
    const kdspace::OverlapLists lists = kdspace::overlapping_batch(tree, queries, threads, &stats);
    REQUIRE(lists.rows() == queries.size());
    for (std::size_t q = 0; q < queries.size(); ++q) {
      const auto row = lists.row(q);
      REQUIRE(std::vector<std::uint32_t>(row.begin(), row.end()) == expected[q]);
    }
    CHECK(stats.queries == single.queries);
    CHECK(stats.nodes_visited == single.nodes_visited);
    CHECK(stats.boxes_tested == single.boxes_tested);
  }
}

// ---- pairs within one set -------------------------------------------------------------------------

TEST_CASE("collide: overlapping_pairs equals brute force on every scene and build", "[collide]") {
  for (const CollisionScene scene : all_collision_scenes) {
    for (std::size_t n : {1, 2, 7, 900}) {
      const std::vector<Box3f> boxes = make_collision_scene(scene, n, static_cast<std::uint32_t>(n + 3));
      const std::vector<IndexPair> expected = kdspace::brute_force_pairs(boxes);
      for (const BuildChoice& build : all_builds()) {
        INFO(kdspace_test::name(scene) << ", n = " << n << ", " << build.name << " build");
        const BoxTree tree(boxes, build.params);
        REQUIRE(compare_pairs(kdspace::overlapping_pairs(tree), expected) == "");
      }
    }
  }
}

TEST_CASE("collide: boxes that only touch in a split plane are paired once", "[collide]") {
  // A row of unit cubes along x: the median build splits at their shared faces, so neighbours touch
  // only in split planes and no leaf holds both.
  std::vector<Box3f> row;
  for (int i = 0; i < 64; ++i)
    row.push_back(box_of(static_cast<float>(i), 0, 0, static_cast<float>(i + 1), 1, 1));
  std::vector<IndexPair> expected;
  for (std::uint32_t i = 0; i + 1 < 64; ++i) expected.push_back({i, i + 1});
  for (const BuildChoice& build : all_builds()) {
    INFO(build.name);
    const BoxTree tree(row, build.params);
    CHECK(compare_pairs(kdspace::overlapping_pairs(tree), expected) == "");
  }
}

TEST_CASE("collide: overlapping_pairs is the same on 1, 2, 3 and 4 threads", "[collide][threads]") {
  for (const CollisionScene scene :
       {CollisionScene::uniform, CollisionScene::face_sharing, CollisionScene::flat}) {
    const std::vector<Box3f> boxes = make_collision_scene(scene, 20000, 21);
    const BoxTree tree(boxes);
    CollideStats one_thread;
    const std::vector<IndexPair> expected = kdspace::overlapping_pairs(tree, 1, &one_thread);
    for (unsigned threads : {2u, 3u, 4u}) {
      CollideStats stats;
      INFO(kdspace_test::name(scene) << ", " << threads << " threads");
      REQUIRE(compare_pairs(kdspace::overlapping_pairs(tree, threads, &stats), expected) == "");
      CHECK(stats.boxes_tested == one_thread.boxes_tested);
    }
  }
}

// ---- pairs across two sets ------------------------------------------------------------------------

TEST_CASE("collide: overlapping_pairs of two trees equals brute force", "[collide]") {
  for (const CollisionScene scene : all_collision_scenes) {
    const std::vector<Box3f> first = make_collision_scene(scene, 500, 31);
    const std::vector<Box3f> second = make_collision_scene(scene, 300, 32);
    const std::vector<IndexPair> expected = kdspace::brute_force_pairs(first, second);
    for (const BuildChoice& build : all_builds()) {
      INFO(kdspace_test::name(scene) << ", " << build.name << " build");
      const BoxTree a(first, build.params);
      const BoxTree b(second);  // default build: the two trees' planes differ
      REQUIRE(compare_pairs(kdspace::overlapping_pairs(a, b), expected) == "");
    }
  }
}

TEST_CASE("collide: pairs of a tree with itself are the self pairs both ways, and the diagonal",
          "[collide]") {
  const std::vector<Box3f> boxes = make_collision_scene(CollisionScene::face_sharing, 700, 41);
  const BoxTree tree(boxes);
  std::vector<IndexPair> expected;
  for (const IndexPair& p : kdspace::overlapping_pairs(tree)) {
    expected.push_back(p);
    expected.push_back({p.b, p.a});
  }
  for (std::uint32_t i = 0; i < boxes.size(); ++i) expected.push_back({i, i});
  std::sort(expected.begin(), expected.end());
  CHECK(compare_pairs(kdspace::overlapping_pairs(tree, tree), expected) == "");
}

TEST_CASE("collide: pairs of two trees are the same on 1, 2 and 4 threads", "[collide][threads]") {
  const std::vector<Box3f> first = make_collision_scene(CollisionScene::clustered, 20000, 51);
  const std::vector<Box3f> second = make_collision_scene(CollisionScene::uniform, 10000, 52);
  const BoxTree a(first), b(second);
  const std::vector<IndexPair> expected = kdspace::overlapping_pairs(a, b, 1);
  CHECK(expected.size() > 1000);
  for (unsigned threads : {2u, 4u}) {
    INFO(threads << " threads");
    CHECK(compare_pairs(kdspace::overlapping_pairs(a, b, threads), expected) == "");
  }
}

// ---- first contact --------------------------------------------------------------------------------

namespace {

/// Motions for the contact tests: random, along one axis (others +0 or -0), diagonal, zero.
std::vector<Vec3f> motions(std::size_t n, float scale, std::uint32_t seed) {
  Rng rng(seed);
  std::vector<Vec3f> out;
  for (std::size_t i = 0; i < n; ++i) {
    Vec3f m{};
    switch (i % 5) {
      case 0:
      case 1:
        for (float& c : m) c = uniform(rng, -scale, scale);
        break;
      case 2: {
        const int a = uniform_int(rng, 0, 2);
        m = {uniform_int(rng, 0, 1) ? 0.0f : -0.0f, -0.0f, 0.0f};
        m[a] = uniform_int(rng, 0, 1) ? scale : -scale;
        break;
      }
      case 3:
        m = {scale, scale, uniform_int(rng, 0, 1) ? scale : -scale};
        break;
      default:
        break;  // zero
    }
    out.push_back(m);
  }
  return out;
}

bool same_contact(const Contact& a, const Contact& b) {
  return a.box == b.box && (a.box < 0 || std::memcmp(&a.t, &b.t, sizeof a.t) == 0);
}

}  // namespace

TEST_CASE("collide: first_contact equals brute force bit for bit on every scene and build", "[collide]") {
  for (const CollisionScene scene : all_collision_scenes) {
    const std::vector<Box3f> boxes = make_collision_scene(scene, 500, 61);
    const Box3f range = grown_bounds(boxes);
    const float scale =
        std::max({range.hi[0] - range.lo[0], range.hi[1] - range.lo[1], range.hi[2] - range.lo[2]});
    const std::vector<Box3f> moving = query_boxes(boxes, 150, 62);
    const std::vector<Vec3f> motion = motions(moving.size(), scale, 63);
    for (const BuildChoice& build : all_builds()) {
      const BoxTree tree(boxes, build.params);
      for (std::size_t q = 0; q < moving.size(); ++q)
        for (const float t_max : {inf, 1.0f, 0.25f, 0.0f}) {
          INFO(kdspace_test::name(scene)
               << ", " << build.name << " build, moving box " << q << ", t_max " << t_max);
          const Contact got = kdspace::first_contact(tree, moving[q], motion[q], t_max);
          const Contact want = kdspace::brute_force_first_contact(boxes, moving[q], motion[q], t_max);
          REQUIRE(same_contact(got, want));
        }
    }
  }
}

TEST_CASE("collide: contact at t = 0 is exactly overlap now; with t_max = 0 it is overlapping()",
          "[collide]") {
  const std::vector<Box3f> boxes = make_collision_scene(CollisionScene::face_sharing, 800, 71);
  const BoxTree tree(boxes);
  const std::vector<Box3f> moving = query_boxes(boxes, 300, 72);
  const std::vector<Vec3f> motion = motions(moving.size(), 3, 73);
  for (std::size_t q = 0; q < moving.size(); ++q) {
    const std::vector<std::uint32_t> now = kdspace::overlapping(tree, moving[q]);
    const Contact c = kdspace::first_contact(tree, moving[q], motion[q], 0);
    INFO("moving box " << q);
    if (now.empty()) {
      CHECK_FALSE(c.hit());
    } else {
      CHECK(c.box == static_cast<std::int32_t>(now.front()));  // equal t = 0: the smallest index
      CHECK(c.t == 0);
    }
    const Contact later = kdspace::first_contact(tree, moving[q], motion[q]);
    if (c.hit())
      CHECK(same_contact(later, c));  // what touches now is the first contact
    else
      CHECK((!later.hit() || later.t > 0));
  }
}

TEST_CASE("collide: a box sliding along a face touches it at once; ties go to the smaller index",
          "[collide]") {
  // Boxes 3 and 1 both start at x = 2 (same contact time); box 0 lies behind the mover.
  const std::vector<Box3f> boxes = {box_of(-3, 0, 0, -2, 1, 1), box_of(2, 0, 0, 3, 1, 1),
                                    box_of(5, 0, 0, 6, 1, 1), box_of(2, 0.5f, 0, 3, 2, 1),
                                    box_of(0, 1, 0, 1, 2, 1)};
  const BoxTree tree(boxes);
  const Box3f mover = box_of(0, 0, 0, 1, 0.75f, 1);
  CHECK(same_contact(kdspace::first_contact(tree, mover, {1, 0, 0}), Contact{1, 1.0f}));
  CHECK(same_contact(kdspace::first_contact(tree, mover, {4, 0, 0}), Contact{1, 0.25f}));
  CHECK(same_contact(kdspace::first_contact(tree, mover, {1, 0, 0}, 0.5f), Contact{}));
  // Moving down: box 0 at t = 2 (its face x = -2 meets the mover's face x = 0).
  CHECK(same_contact(kdspace::first_contact(tree, mover, {-1, 0, 0}), Contact{0, 2.0f}));
  // Moving along +y: box 4 begins at y = 1, a quarter above the mover's top.
  CHECK(same_contact(kdspace::first_contact(tree, mover, {0, 1, 0}), Contact{4, 0.25f}));
  // The mover sharing a face with box 4 (y = 1) touches it at t = 0, whatever it does.
  const Box3f touching = box_of(0, 0, 0, 1, 1, 1);
  CHECK(same_contact(kdspace::first_contact(tree, touching, {0, -1, 0}), Contact{4, 0.0f}));
  CHECK(same_contact(kdspace::first_contact(tree, touching, {0, 0, 0}), Contact{4, 0.0f}));
  // Zero motion and nothing touched.
  CHECK(same_contact(kdspace::first_contact(tree, box_of(10, 10, 10, 11, 11, 11), {0, 0, 0}), Contact{}));
}

TEST_CASE("collide: first_contact_batch gives single answers and stats on 1, 2 and 4 threads",
          "[collide][threads]") {
  const std::vector<Box3f> boxes = make_collision_scene(CollisionScene::uniform, 5000, 81);
  const BoxTree tree(boxes);
  const std::vector<Box3f> starts = query_boxes(boxes, 2000, 82);
  const std::vector<Vec3f> motion = motions(starts.size(), 0.5f, 83);
  std::vector<MovingBox> moving;
  for (std::size_t i = 0; i < starts.size(); ++i) moving.push_back({starts[i], motion[i]});
  CollideStats single;
  std::vector<Contact> expected;
  for (const MovingBox& m : moving)
    expected.push_back(kdspace::first_contact(tree, m.box, m.motion, 2.0f, &single));
  for (unsigned threads : {1u, 2u, 4u}) {
    CollideStats stats;
    const std::vector<Contact> got = kdspace::first_contact_batch(tree, moving, 2.0f, threads, &stats);
    REQUIRE(got.size() == expected.size());
    for (std::size_t i = 0; i < got.size(); ++i) REQUIRE(same_contact(got[i], expected[i]));
    CHECK(stats.nodes_visited == single.nodes_visited);
    CHECK(stats.boxes_tested == single.boxes_tested);
  }
}

TEST_CASE("collide: bad moving boxes, motions and t_max throw an Error", "[collide]") {
  const BoxTree tree(std::vector<Box3f>{box_of(0, 0, 0, 1, 1, 1)});
  const Box3f ok = box_of(2, 0, 0, 3, 1, 1);
  CHECK_THROWS_WITH(kdspace::first_contact(tree, box_of(2, 0, 0, 1, 1, 1), {1, 0, 0}),
                    "moving box: min x 2 > max x 1");
  CHECK_THROWS_AS(kdspace::first_contact(tree, ok, {0, NAN, 0}), kdspace::Error);
  CHECK_THROWS_AS(kdspace::first_contact(tree, ok, {inf, 0, 0}), kdspace::Error);
  CHECK_THROWS_AS(kdspace::first_contact(tree, ok, {1, 0, 0}, -1), kdspace::Error);
  CHECK_THROWS_AS(kdspace::first_contact(tree, ok, {1, 0, 0}, NAN), kdspace::Error);
  const std::vector<MovingBox> moving = {{ok, {-1, 0, 0}}, {ok, {0, 0, NAN}}};
  CHECK_THROWS_WITH(kdspace::first_contact_batch(tree, moving),
                    Catch::StartsWith("moving box 2: motion z is"));
  CHECK(same_contact(kdspace::first_contact(tree, ok, {-1, 0, 0}), Contact{0, 1.0f}));
}
