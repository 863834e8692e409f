// Tests of moving boxes: BoxTree::refit and MovingScene (kdspace/collide/moving_scene.hpp) give, frame
// after frame, exactly the pairs of brute force, whether the tree is refitted or rebuilt and whether
// all boxes or a few of them move.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/brute_force.hpp"
#include "kdspace/collide/contact.hpp"
#include "kdspace/collide/motion_gen.hpp"
#include "kdspace/collide/moving_scene.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/error.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "support.hpp"

using kdspace::Box3f;
using kdspace::BoxBuildMethod;
using kdspace::BoxBuildParams;
using kdspace::BoxTree;
using kdspace::IndexPair;
using kdspace::LeafBlock;
using kdspace::MotionKind;
using kdspace::MotionSimulation;
using kdspace::MovingScene;
using kdspace::MovingSceneParams;
using kdspace::TreeUpdate;
using kdspace_test::box_of;
using kdspace_test::CollisionScene;
using kdspace_test::make_collision_scene;

namespace {

/// The leaf layout after a refit: each leaf's references padded to a multiple of 4 with its last
/// index, and the leaf blocks holding box(references()[r]) in lane r % 4 of block r / 4.
void check_layout(const BoxTree& tree) {
  const auto& refs = tree.references();
  const auto& blocks = tree.leaf_blocks();
  REQUIRE(refs.size() == 4 * blocks.size());
  std::size_t next = 0;
  for (const kdspace::BoxNode& n : tree.nodes()) {
    if (!n.is_leaf()) continue;
    REQUIRE(n.first() == next);
    next += (n.count() + 3) / 4 * 4;
    for (std::size_t r = n.first() + n.count(); r < next; ++r) REQUIRE(refs[r] == refs[r - 1]);
  }
  REQUIRE(next == refs.size());
  for (std::size_t r = 0; r < refs.size(); ++r)
    for (int a = 0; a < 3; ++a) {
      REQUIRE(blocks[r / 4].plane[a][r % 4] == tree.box(refs[r]).lo[a]);
      REQUIRE(blocks[r / 4].plane[3 + a][r % 4] == tree.box(refs[r]).hi[a]);
    }
}

BoxBuildParams with_method(BoxBuildMethod m) {
  BoxBuildParams p;
  p.method = m;
  return p;
}

}  // namespace

TEST_CASE("refit: queries after a refit equal brute force on the moved boxes", "[collide][refit]") {
  for (const BoxBuildMethod m : {BoxBuildMethod::median, BoxBuildMethod::sah_nlogn, BoxBuildMethod::binned}) {
    MotionSimulation motion(make_collision_scene(CollisionScene::uniform, 2000, 3), MotionKind::brownian, 1.0,
                            4);
    BoxTree tree(motion.boxes(), with_method(m));
    for (int frame = 0; frame < 10; ++frame) {
      const std::vector<Box3f>& boxes = motion.step();
      REQUIRE(tree.refit(boxes.data(), boxes.size()));
      INFO("method " << static_cast<int>(m) << ", frame " << frame);
      check_layout(tree);
      REQUIRE(kdspace::overlapping_pairs(tree) == kdspace::brute_force_pairs(boxes));
      // Rays read the refitted leaf blocks: the same hits as a tree built over the moved boxes.
      const BoxTree built(boxes);
      for (int r = 0; r < 20; ++r) {
        const Box3f& target = boxes[static_cast<std::size_t>(r) * 97];
        const float y = 0.5f * target.lo[1] + 0.5f * target.hi[1], z = 0.5f * target.lo[2] + 0.5f * target.hi[2];
        const kdspace::Ray ray{{-5.0f, y, z}, {1.0f, 0.01f * static_cast<float>(r - 10), 0.02f}};
        REQUIRE(tree.closest_hit(ray) == built.closest_hit(ray));
        REQUIRE(tree.any_hit(ray).hit() == built.any_hit(ray).hit());
      }
      const Box3f query = boxes[static_cast<std::size_t>(frame) * 7];
      REQUIRE(kdspace::overlapping(tree, query) == kdspace::brute_force_overlapping(boxes, query));
      const auto contact = kdspace::first_contact(tree, query, {0.1f, -0.05f, 0});
      const auto expected = kdspace::brute_force_first_contact(boxes, query, {0.1f, -0.05f, 0});
      REQUIRE(contact.box == expected.box);
      REQUIRE(contact.t == expected.t);
    }
  }
}

TEST_CASE("refit: refitting the moved boxes only makes the tree of refitting all", "[collide][refit]") {
  MotionSimulation motion(make_collision_scene(CollisionScene::clustered, 3000, 5), MotionKind::brownian, 0.1,
                          6);
  BoxTree partial(motion.boxes(), with_method(BoxBuildMethod::binned));
  BoxTree full = partial;
  for (int frame = 0; frame < 5; ++frame) {
    const std::vector<Box3f>& boxes = motion.step();
    REQUIRE(partial.refit(boxes.data(), motion.moving().data(), motion.moving().size()));
    REQUIRE(full.refit(boxes.data(), boxes.size()));
    REQUIRE(partial.nodes() == full.nodes());
    REQUIRE(partial.references() == full.references());
    check_layout(partial);
    REQUIRE(partial.leaf_blocks().size() == full.leaf_blocks().size());
    REQUIRE(std::memcmp(partial.leaf_blocks().data(), full.leaf_blocks().data(),
                        full.leaf_blocks().size() * sizeof(LeafBlock)) == 0);
    CHECK(partial.bounds().lo == full.bounds().lo);
    CHECK(partial.bounds().hi == full.bounds().hi);
  }
}

TEST_CASE("refit: more boxes, fewer boxes, boxes far outside the old bounds", "[collide][refit]") {
  std::vector<Box3f> boxes = make_collision_scene(CollisionScene::face_sharing, 500, 7);
  BoxTree tree(boxes);
  boxes.resize(300);
  boxes.push_back(box_of(-100, -100, -100, -99, -99, -99));
  boxes.push_back(box_of(-99, -99, -99, -98, 50, 50));
  REQUIRE(tree.refit(boxes.data(), boxes.size()));
  check_layout(tree);
  CHECK(tree.size() == boxes.size());
  CHECK(kdspace::overlapping_pairs(tree) == kdspace::brute_force_pairs(boxes));
  CHECK(tree.bounds().lo[0] == -100);
  const Box3f empty_refit_check = box_of(-100, -100, -100, 100, 100, 100);
  CHECK(kdspace::overlapping(tree, empty_refit_check).size() == boxes.size());
}

TEST_CASE("refit: a refit that would copy boxes into too many leaves is refused and changes nothing",
          "[collide][refit]") {
  const std::vector<Box3f> small = make_collision_scene(CollisionScene::uniform, 2000, 8);
  BoxBuildParams p = with_method(BoxBuildMethod::binned);
  p.max_references_per_box = 4;
  BoxTree tree(small, p);
  const auto nodes = tree.nodes();
  const auto references = tree.references();
  const std::vector<Box3f> huge(small.size(), box_of(-1, -1, -1, 2, 2, 2));  // each box in every leaf
  CHECK_FALSE(tree.refit(huge.data(), huge.size()));
  CHECK(tree.nodes() == nodes);
  CHECK(tree.references() == references);
  CHECK(kdspace::overlapping_pairs(tree) == kdspace::brute_force_pairs(small));
}

TEST_CASE("refit: bad boxes and moved lists throw and change nothing", "[collide][refit]") {
  std::vector<Box3f> boxes = make_collision_scene(CollisionScene::uniform, 100, 9);
  BoxTree tree(boxes);
  const auto references = tree.references();
  boxes[5].lo[1] = NAN;
  CHECK_THROWS_WITH(tree.refit(boxes.data(), boxes.size()), "box 6: min y is nan");
  const std::uint32_t moved[] = {2, 5};
  CHECK_THROWS_WITH(tree.refit(boxes.data(), moved, 2), "box 6: min y is nan");
  const std::uint32_t unordered[] = {3, 2};
  CHECK_THROWS_AS(tree.refit(boxes.data(), unordered, 2), kdspace::Error);
  const std::uint32_t out_of_range[] = {100};
  CHECK_THROWS_AS(tree.refit(boxes.data(), out_of_range, 1), kdspace::Error);
  CHECK(tree.references() == references);
}

// ---- MovingScene ----------------------------------------------------------------------------------

namespace {

struct SceneSetup {
  const char* name;
  MovingSceneParams params;
};

std::vector<SceneSetup> scene_setups() {
  std::vector<SceneSetup> setups;
  MovingSceneParams p;
  setups.push_back({"refit (default)", p});
  p.update = TreeUpdate::rebuild;
  setups.push_back({"rebuild binned", p});
  p.build.method = BoxBuildMethod::sah_nlogn;
  setups.push_back({"rebuild sah_nlogn", p});
  p = MovingSceneParams{};
  p.incremental_share = 0;
  setups.push_back({"refit, never incremental", p});
  p.incremental_share = 1;
  p.rebuild_factor = 1;
  setups.push_back({"refit, always incremental, eager rebuilds", p});
  return setups;
}

}  // namespace

TEST_CASE("moving scene: 100 frames of motion give the brute-force pairs every frame", "[collide][moving]") {
  struct Motion {
    const char* name;
    CollisionScene scene;
    MotionKind kind;
    double share;
  };
  const Motion motions[] = {
      {"brownian, all move", CollisionScene::uniform, MotionKind::brownian, 1.0},
      {"free fall, all move", CollisionScene::clustered, MotionKind::free_fall, 1.0},
      {"brownian, 10% move", CollisionScene::uniform, MotionKind::brownian, 0.1},
      {"free fall, 10% move, face-sharing", CollisionScene::face_sharing, MotionKind::free_fall, 0.1}};
  for (const Motion& m : motions)
    for (const SceneSetup& setup : scene_setups()) {
      MotionSimulation motion(make_collision_scene(m.scene, 400, 11), m.kind, m.share, 12);
      MovingScene scene(setup.params);
      std::size_t rebuilt = 0, incremental = 0;
      for (int frame = 0; frame < 100; ++frame) {
        const std::vector<Box3f>& boxes = frame == 0 ? motion.boxes() : motion.step();
        const std::vector<IndexPair>& pairs = scene.step(boxes);
        INFO(m.name << ", " << setup.name << ", frame " << frame);
        REQUIRE(pairs == kdspace::brute_force_pairs(boxes));
        REQUIRE(scene.last_frame().pairs == pairs.size());
        rebuilt += scene.last_frame().rebuilt;
        incremental += scene.last_frame().incremental;
      }
      INFO(m.name << ", " << setup.name);
      CHECK(rebuilt >= 1);  // the first frame
      if (setup.params.update == TreeUpdate::rebuild) CHECK(rebuilt == 100);
      if (m.share < 0.2 && setup.params.incremental_share >= 0.2) CHECK(incremental == 99);
      if (setup.params.incremental_share == 0) CHECK(incremental == 0);
    }
}

TEST_CASE("moving scene: the number of boxes may change; a frame without motion keeps the pairs",
          "[collide][moving]") {
  MovingScene scene;
  std::vector<Box3f> boxes = make_collision_scene(CollisionScene::face_sharing, 300, 13);
  CHECK(scene.step(boxes) == kdspace::brute_force_pairs(boxes));
  CHECK(scene.step(boxes) == kdspace::brute_force_pairs(boxes));
  CHECK(scene.last_frame().moved == 0);
  CHECK(scene.last_frame().incremental);
  boxes.resize(150);
  CHECK(scene.step(boxes) == kdspace::brute_force_pairs(boxes));
  CHECK(scene.last_frame().rebuilt);
  CHECK(scene.step(std::vector<Box3f>{}).empty());
  CHECK(scene.step(boxes) == kdspace::brute_force_pairs(boxes));
  CHECK(scene.tree().size() == boxes.size());
}

TEST_CASE("moving scene: a bad box throws and the scene goes on from the frame before", "[collide][moving]") {
  MovingScene scene;
  std::vector<Box3f> boxes = make_collision_scene(CollisionScene::uniform, 200, 14);
  scene.step(boxes);
  std::vector<Box3f> bad = boxes;
  bad[3].hi[0] = bad[3].lo[0] - 1;
  CHECK_THROWS_WITH(scene.step(bad), Catch::StartsWith("box 4: min x"));
  CHECK_THROWS_AS(MovingScene().tree(), kdspace::Error);
  boxes[7].lo[2] -= 0.01f;
  CHECK(scene.step(boxes) == kdspace::brute_force_pairs(boxes));
}

TEST_CASE("moving scene: the same pairs on 1, 2 and 4 threads", "[collide][moving][threads]") {
  for (const double share : {1.0, 0.1}) {
    std::vector<std::vector<IndexPair>> answers;
    for (const unsigned threads : {1u, 2u, 4u}) {
      MovingSceneParams p;
      p.threads = threads;
      MovingScene scene(p);
      MotionSimulation motion(make_collision_scene(CollisionScene::clustered, 5000, 15), MotionKind::brownian,
                              share, 16);
      std::vector<IndexPair> all;
      for (int frame = 0; frame < 5; ++frame) {
        const auto& pairs = scene.step(frame == 0 ? motion.boxes() : motion.step());
        all.insert(all.end(), pairs.begin(), pairs.end());
      }
      answers.push_back(all);
    }
    CHECK(answers[1] == answers[0]);
    CHECK(answers[2] == answers[0]);
  }
}

// A refit that moves a box beyond the float traversal's range (2^62) must switch the tree to the
// double traversal, as a build over those boxes does: the hits equal a fresh build's, also for rays
// whose parameters reach that box only beyond the float range.
TEST_CASE("moving: a refit beyond the float range traces as a fresh build does", "[refit][rays]") {
  std::vector<Box3f> boxes = kdspace::generate_boxes(800, kdspace::SceneKind::clustered, 31);
  BoxTree tree(boxes);
  boxes[5] = Box3f{{1e25f, 1e25f, 1e25f}, {2e25f, 2e25f, 2e25f}};
  REQUIRE(tree.refit(boxes.data(), boxes.size()));
  const BoxTree fresh(boxes);
  std::vector<kdspace::Ray> rays = kdspace::random_rays(2000, Box3f{{0, 0, 0}, {1, 1, 1}}, 32);
  for (const float tiny : {1e-7f, 1e-19f, 1e-25f}) {
    rays.push_back(kdspace::Ray{{0.5f, 0.5f, 0.5f}, {1, 1, 1}});
    rays.push_back(kdspace::Ray{{0, 0, 0}, {tiny, tiny, tiny}});
    rays.push_back(kdspace::Ray{{0.5f, 0.5f, 0.5f}, {tiny, 1, tiny}});
  }
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const kdspace::Hit a = tree.closest_hit(rays[i]), b = fresh.closest_hit(rays[i]);
    INFO("ray " << i);
    REQUIRE(a.box == b.box);
    REQUIRE(a.t == b.t);
    REQUIRE(tree.any_hit(rays[i]).hit() == fresh.any_hit(rays[i]).hit());
  }
}
