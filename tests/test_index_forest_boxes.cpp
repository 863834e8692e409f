// Index files of PointForest and BoxTree: round trips (mapped and read) give the same structure and
// the same answers; every changed byte is a clear error; resealed changes never make a query read out
// of bounds (ASan runs these too).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "support.hpp"

namespace io = kdspace::io;
using kdspace::BoxTree;
using kdspace::PointForest;
using kdspace_test::file_bytes;
using kdspace_test::Shape;
using kdspace_test::write_bytes;

namespace {

// Loads the file after every single-byte change: each must throw an Error naming the file.
template <class Load>
void every_byte_is_checked(const std::string& good, const std::string& bad, Load load) {
  const std::vector<unsigned char> bytes = file_bytes(good);
  for (std::size_t at = 0; at < bytes.size(); ++at) {
    std::vector<unsigned char> damaged = bytes;
    damaged[at] = static_cast<unsigned char>(damaged[at] ^ (1u << (at % 8)));
    write_bytes(bad, damaged);
    CAPTURE(at);
    try {
      load(bad);
      FAIL("a damaged file loaded");
    } catch (const kdspace::Error& e) {
      REQUIRE(std::string(e.what()).rfind(bad + ": ", 0) == 0);
    }
  }
}

// Loads the file after random changes with the checksums recomputed; what loads is then used.
template <class LoadAndUse>
void resealed_changes_are_safe(const std::string& good, const std::string& bad, LoadAndUse load_and_use,
                               int trials) {
  const std::vector<unsigned char> bytes = file_bytes(good);
  std::mt19937 rng(5);
  int refused = 0;
  for (int trial = 0; trial < trials; ++trial) {
    std::vector<unsigned char> changed = bytes;
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, bytes.size() - 1)(rng);
    changed[at] = static_cast<unsigned char>(rng());
    io::reseal_index_bytes(changed);
    write_bytes(bad, changed);
    CAPTURE(trial, at);
    try {
      load_and_use(bad);
    } catch (const kdspace::Error& e) {
      ++refused;
      REQUIRE(std::string(e.what()).rfind(bad + ": ", 0) == 0);
    }
  }
  CHECK(refused > 0);
}

}  // namespace

TEMPLATE_TEST_CASE("index: a saved forest loads with the same trees, graph, answers and search setting",
                   "[index][forest]", float, double) {
  using T = TestType;
  kdspace_test::ScratchDir tmp("kdspace-index-forest-", true);
  const std::size_t n = 3000, dim = 24;
  for (bool bytes : {false, true}) {
    CAPTURE(bytes);
    auto points = kdspace_test::make_points<T>(Shape::clustered, n, dim, 3);
    if (bytes)
      for (auto& v : points) v = std::floor(std::abs(v) * 20);  // byte-valued: kept as bytes
    const auto queries = kdspace_test::make_queries(points, n, dim, 40, 4);
    kdspace::ForestParams params;
    params.trees = 3;
    params.threads = 2;
    const PointForest<T> built(points.data(), n, dim, params);
    REQUIRE(built.compact() == bytes);
    REQUIRE(built.has_graph());  // dimension 24: GraphMode::automatic builds it
    const kdspace::ForestSearchParams tuned{300, 2, 40};
    const std::string path = tmp.file("forest.kdx");
    io::save(path, built, &tuned);
    for (auto mode : {io::LoadMode::map, io::LoadMode::read}) {
      kdspace::ForestSearchParams stored;
      const auto loaded = io::load_point_forest<T>(path, mode, &stored);
      REQUIRE(stored.checks == 300);
      REQUIRE(stored.trees == 2);
      REQUIRE(stored.ef == 40);
      REQUIRE(loaded.compact() == bytes);
      REQUIRE(loaded.graph_degree() == built.graph_degree());
      REQUIRE(loaded.graph().links == built.graph().links);
      REQUIRE(loaded.projected_dims() == built.projected_dims());
      REQUIRE(loaded.depth() == built.depth());
      REQUIRE(loaded.leaf_count() == built.leaf_count());
      for (std::size_t t = 0; t < 3; ++t) {
        REQUIRE(loaded.nodes(t).size() == built.nodes(t).size());
        REQUIRE(std::memcmp(loaded.nodes(t).data(), built.nodes(t).data(), built.nodes(t).size() * 16) == 0);
      }
      for (std::size_t checks : {std::size_t{64}, std::size_t{500}, kdspace::unlimited_checks}) {
        const kdspace::ForestSearchParams search{checks, 0};
        REQUIRE(loaded.knn_batch(queries.data(), 40, 6, search, 1).neighbors ==
                built.knn_batch(queries.data(), 40, 6, search, 1).neighbors);
      }
      for (std::size_t ef : {std::size_t{10}, std::size_t{80}}) {
        const kdspace::ForestSearchParams search{kdspace::unlimited_checks, 0, ef};
        REQUIRE(loaded.knn_batch(queries.data(), 40, 6, search, 1).neighbors ==
                built.knn_batch(queries.data(), 40, 6, search, 1).neighbors);
      }
    }
  }
}

TEST_CASE("index: forest files: every changed byte is an error, resealed changes are safe",
          "[index][forest][errors]") {
  kdspace_test::ScratchDir tmp("kdspace-index-forest-", true);
  const auto points = kdspace_test::make_points<float>(Shape::uniform, 80, 5, 3);
  const auto queries = kdspace_test::make_queries(points, 80, 5, 10, 4);
  kdspace::ForestParams params;
  params.trees = 2;
  params.leaf_size = 4;
  params.graph = kdspace::GraphMode::on;
  params.graph_degree = 6;
  io::save(tmp.file("f.kdx"), PointForest<float>(points.data(), 80, 5, params));
  every_byte_is_checked(tmp.file("f.kdx"), tmp.file("bad.kdx"),
                        [](const std::string& p) { io::load_point_forest<float>(p); });
  resealed_changes_are_safe(
      tmp.file("f.kdx"), tmp.file("bad.kdx"),
      [&](const std::string& p) {
        const auto forest = io::load_point_forest<float>(p);
        forest.knn_batch(queries.data(), 10, 3, {kdspace::unlimited_checks, 0}, 1);
        if (forest.has_graph()) forest.knn_batch(queries.data(), 10, 3, {kdspace::unlimited_checks, 0, 8}, 1);
      },
      1500);
}

TEST_CASE("index: forest parts: the graph's degree, size and links are checked", "[index][forest][errors]") {
  const auto points = kdspace_test::make_points<float>(Shape::uniform, 60, 4, 3);
  kdspace::ForestParams params;
  params.trees = 2;
  params.graph = kdspace::GraphMode::on;
  params.graph_degree = 4;
  const PointForest<float> built(points.data(), 60, 4, params);
  REQUIRE(built.graph_degree() == 4);
  auto forged = [&](std::size_t degree, std::vector<std::uint32_t> links) {
    auto p = built.parts();
    p.graph_degree = degree;
    p.graph_links = kdspace::detail::Storage<std::uint32_t>(std::move(links));
    return p;
  };
  const std::vector<std::uint32_t> good(built.graph().links.begin(), built.graph().links.end());
  CHECK(PointForest<float>(forged(4, good)).graph().links == built.graph().links);
  CHECK(!PointForest<float>(forged(0, {})).has_graph());
  std::vector<std::uint32_t> out_of_range = good;
  out_of_range[77] = 60;
  CHECK_THROWS_WITH(PointForest<float>(forged(4, out_of_range)), Catch::Contains("graph link 60 of row 19"));
  CHECK_THROWS_WITH(PointForest<float>(forged(4, std::vector<std::uint32_t>(good.begin(), good.end() - 1))),
                    Catch::Contains("239 graph links for 60 points"));
  CHECK_THROWS_WITH(PointForest<float>(forged(1, std::vector<std::uint32_t>(60))), Catch::Contains("graph degree 1"));
  CHECK_THROWS_WITH(PointForest<float>(forged(0, good)), Catch::Contains("graph degree 0"));
}

TEST_CASE("index: a saved box tree loads with the same nodes, statistics and hits", "[index][boxes]") {
  kdspace_test::ScratchDir tmp("kdspace-index-boxes-", true);
  const auto boxes = kdspace::generate_boxes(2000, kdspace::SceneKind::clustered, 7);
  kdspace::Box3f bounds{{0, 0, 0}, {1, 1, 1}};
  const auto rays = kdspace::random_rays(2000, bounds, 8);
  for (auto method : {kdspace::BoxBuildMethod::median, kdspace::BoxBuildMethod::sah,
                      kdspace::BoxBuildMethod::sah_nlogn, kdspace::BoxBuildMethod::binned}) {
    kdspace::BoxBuildParams params;
    params.method = method;
    const BoxTree built(boxes, params);
    const std::string path = tmp.file("boxes.kdx");
    io::save(path, built);
    for (auto mode : {io::LoadMode::map, io::LoadMode::read}) {
      const BoxTree loaded = io::load_box_tree(path, mode);
      REQUIRE(loaded.nodes() == built.nodes());
      REQUIRE(loaded.references() == built.references());
      REQUIRE(loaded.params().method == method);
      REQUIRE(loaded.stats().depth == built.stats().depth);
      REQUIRE(loaded.stats().max_depth == built.stats().max_depth);
      REQUIRE(loaded.stats().sah_cost == built.stats().sah_cost);
      const auto a = loaded.closest_hit_batch(rays, 1), b = built.closest_hit_batch(rays, 1);
      for (std::size_t i = 0; i < rays.size(); ++i) {
        REQUIRE(a[i].box == b[i].box);
        REQUIRE(a[i].t == b[i].t);
      }
      const auto c = loaded.any_hit_batch(rays, 1), d = built.any_hit_batch(rays, 1);
      for (std::size_t i = 0; i < rays.size(); ++i) REQUIRE(c[i].box == d[i].box);
    }
  }
  // An empty tree too.
  io::save(tmp.file("empty.kdx"), BoxTree(std::vector<kdspace::Box3f>{}));
  REQUIRE(io::load_box_tree(tmp.file("empty.kdx")).closest_hit(rays[0]).box == kdspace::Hit::none);
}

// A refitted tree's root cell keeps the cells its planes were made in, so it is saved with the tree;
// a tree loaded mapped can be refitted (it copies its arrays then), and neither the file nor the
// answers of another tree loaded from it change.
TEST_CASE("index: box trees refitted before saving and after a mapped load", "[index][boxes]") {
  kdspace_test::ScratchDir tmp("kdspace-index-refit-", true);
  auto boxes = kdspace::generate_boxes(1500, kdspace::SceneKind::clustered, 11);
  const auto rays = kdspace::random_rays(1500, kdspace::Box3f{{-0.5f, -0.5f, -0.5f}, {1.5f, 1.5f, 1.5f}}, 12);
  auto shifted = [](std::vector<kdspace::Box3f> b, float by) {
    for (std::size_t i = 0; i < b.size(); i += 3)
      for (int a = 0; a < 3; ++a) {
        b[i].lo[a] -= by;
        b[i].hi[a] -= by;
      }
    return b;
  };
  auto same_hits = [&](const BoxTree& x, const BoxTree& y) {
    const auto a = x.closest_hit_batch(rays, 1), b = y.closest_hit_batch(rays, 1);
    for (std::size_t i = 0; i < rays.size(); ++i) {
      REQUIRE(a[i].box == b[i].box);
      REQUIRE(a[i].t == b[i].t);
    }
  };
  kdspace::BoxBuildParams params;
  params.method = kdspace::BoxBuildMethod::binned;
  BoxTree tree(boxes, params);
  const auto moved = shifted(boxes, 0.25f);  // some boxes leave the old root cell
  REQUIRE(tree.refit(moved.data(), moved.size()));
  const std::string path = tmp.file("refitted.kdx");
  io::save(path, tree);
  const BoxTree loaded = io::load_box_tree(path);
  REQUIRE(loaded.bounds().lo == tree.bounds().lo);
  REQUIRE(loaded.bounds().hi == tree.bounds().hi);
  REQUIRE(loaded.nodes() == tree.nodes());
  same_hits(loaded, tree);
  same_hits(loaded, BoxTree(moved));  // and the refitted tree answers as a fresh build

  // Refit a mapped tree: back to the first boxes, all of them, then one in three only.
  BoxTree mapped = io::load_box_tree(path, io::LoadMode::map);
  REQUIRE(mapped.refit(boxes.data(), boxes.size()));
  same_hits(mapped, BoxTree(boxes));
  BoxTree mapped_again = io::load_box_tree(path, io::LoadMode::map);
  std::vector<std::uint32_t> ids;
  for (std::uint32_t i = 0; i < boxes.size(); i += 3) ids.push_back(i);
  REQUIRE(mapped_again.refit(boxes.data(), ids.data(), ids.size()));
  same_hits(mapped_again, BoxTree(boxes));
  same_hits(io::load_box_tree(path), tree);  // the file is unchanged
}

TEST_CASE("index: box tree files: every changed byte is an error, resealed changes are safe",
          "[index][boxes][errors]") {
  kdspace_test::ScratchDir tmp("kdspace-index-boxes-", true);
  const auto boxes = kdspace::generate_boxes(40, kdspace::SceneKind::uniform, 2);
  const auto rays = kdspace::random_rays(50, kdspace::Box3f{{0, 0, 0}, {1, 1, 1}}, 3);
  io::save(tmp.file("b.kdx"), BoxTree(boxes));
  every_byte_is_checked(tmp.file("b.kdx"), tmp.file("bad.kdx"),
                        [](const std::string& p) { io::load_box_tree(p); });
  resealed_changes_are_safe(
      tmp.file("b.kdx"), tmp.file("bad.kdx"),
      [&](const std::string& p) {
        const BoxTree tree = io::load_box_tree(p);
        tree.closest_hit_batch(rays, 1);
        tree.any_hit_batch(rays, 1);
      },
      1500);
}

namespace {

// A tree's parts as owned copies, to be changed and checked again.
kdspace::BoxTreeParts owned_parts(const BoxTree& tree) {
  const kdspace::BoxTreeParts borrowed = tree.parts();
  kdspace::BoxTreeParts p;
  p.params = borrowed.params;
  p.max_depth = borrowed.max_depth;
  p.boxes = kdspace::detail::Storage<kdspace::Box3f>({borrowed.boxes.begin(), borrowed.boxes.end()});
  p.nodes = kdspace::detail::Storage<kdspace::BoxNode>({borrowed.nodes.begin(), borrowed.nodes.end()});
  p.references =
      kdspace::detail::Storage<std::uint32_t>({borrowed.references.begin(), borrowed.references.end()});
  p.blocks = kdspace::detail::Storage<kdspace::LeafBlock>({borrowed.blocks.begin(), borrowed.blocks.end()});
  p.bounds = borrowed.bounds;
  return p;
}

// Applies `change` to vectors of the parts and requires BoxTree(parts) to refuse them with `message`.
template <class Change>
void refused(const BoxTree& tree, const std::string& message, Change change) {
  kdspace::BoxTreeParts p = owned_parts(tree);
  std::vector<kdspace::Box3f> boxes(p.boxes.begin(), p.boxes.end());
  std::vector<kdspace::BoxNode> nodes(p.nodes.begin(), p.nodes.end());
  std::vector<std::uint32_t> refs(p.references.begin(), p.references.end());
  std::vector<kdspace::LeafBlock> blocks(p.blocks.begin(), p.blocks.end());
  change(boxes, nodes, refs, blocks);
  p.boxes = kdspace::detail::Storage<kdspace::Box3f>(boxes);
  p.nodes = kdspace::detail::Storage<kdspace::BoxNode>(nodes);
  p.references = kdspace::detail::Storage<std::uint32_t>(refs);
  p.blocks = kdspace::detail::Storage<kdspace::LeafBlock>(blocks);
  CAPTURE(message);
  REQUIRE_THROWS_WITH(BoxTree(std::move(p)), Catch::Contains(message));
}

}  // namespace

TEST_CASE("index: box tree parts: padding, order, blocks and depth are checked", "[index][boxes][errors]") {
  const auto boxes = kdspace::generate_boxes(300, kdspace::SceneKind::clustered, 4);
  kdspace::BoxBuildParams params;
  params.binning_threshold = 17;
  params.threads = 3;
  const BoxTree tree(boxes, params);
  // The parts, copied, make the same tree.
  const BoxTree again(owned_parts(tree));
  REQUIRE(again.nodes() == tree.nodes());
  REQUIRE(again.stats().sah_cost == tree.stats().sah_cost);
  REQUIRE(again.bounds().lo == tree.bounds().lo);
  // A root cell that does not hold every box.
  kdspace::BoxTreeParts shrunk = owned_parts(tree);
  shrunk.bounds.hi[1] = std::nextafter(shrunk.bounds.hi[1], 0.0f);
  REQUIRE_THROWS_WITH(BoxTree(std::move(shrunk)), Catch::Contains("lies outside the bounds"));

  // The first leaf of at least 2 boxes whose count is not a multiple of 4 (so that it has padding).
  std::size_t leaf = 0;
  bool found = false;
  for (std::size_t i = 0; i < tree.nodes().size() && !found; ++i) {
    const kdspace::BoxNode& n = tree.nodes()[i];
    if (n.is_leaf() && n.count() >= 2 && n.count() % 4 != 0) leaf = i, found = true;
  }
  REQUIRE(found);
  const std::size_t first = tree.nodes()[leaf].first(), count = tree.nodes()[leaf].count();
  using Boxes = std::vector<kdspace::Box3f>;
  using Nodes = std::vector<kdspace::BoxNode>;
  using Refs = std::vector<std::uint32_t>;
  using Blocks = std::vector<kdspace::LeafBlock>;
  auto swap_refs = [&](Refs& r, Blocks& b, std::size_t i, std::size_t j) {
    std::swap(r[i], r[j]);
    for (int c = 0; c < 6; ++c) std::swap(b[i / 4].plane[c][i % 4], b[j / 4].plane[c][j % 4]);
  };
  refused(tree, "references not ascending",
          [&](Boxes&, Nodes&, Refs& r, Blocks& b) { swap_refs(r, b, first, first + 1); });
  refused(tree, "padding does not repeat the last reference", [&](Boxes& x, Nodes&, Refs& r, Blocks& b) {
    // The padding names another box, and its block lane holds that box: only the padding rule fails.
    const std::uint32_t other = r[first + count - 1] == 0 ? 1 : 0;
    r[first + count] = other;
    const kdspace::Box3f& box = x[other];
    for (int a = 0; a < 3; ++a) {
      b[(first + count) / 4].plane[a][(first + count) % 4] = box.lo[a];
      b[(first + count) / 4].plane[3 + a][(first + count) % 4] = box.hi[a];
    }
  });
  refused(tree, "differs from box", [&](Boxes&, Nodes&, Refs&, Blocks& b) { b[first / 4].plane[4][1] += 1; });
  refused(tree, "reference names box 300 of 300",
          [&](Boxes&, Nodes&, Refs& r, Blocks&) { r[first + count - 1] = 300; });
  refused(tree, "one block per 4 references", [&](Boxes&, Nodes&, Refs&, Blocks& b) { b.pop_back(); });
  refused(tree, "one block per 4 references",
          [&](Boxes&, Nodes&, Refs& r, Blocks&) { r.push_back(r.back()); });
  refused(tree, "references out of place", [&](Boxes&, Nodes& n, Refs&, Blocks&) {
    n[leaf] =
        kdspace::BoxNode::leaf(static_cast<std::uint32_t>(first + 1), static_cast<std::uint32_t>(count));
  });
  refused(tree, "is in no leaf", [&](Boxes& x, Nodes&, Refs&, Blocks&) { x.push_back(x[0]); });

  // A chain of 65 inner nodes over one box: deeper than the traversal's stack allows.
  kdspace::BoxTreeParts deep;
  deep.params = tree.params();
  const kdspace::Box3f one{{0, 0, 0}, {1, 1, 1}};
  deep.boxes = kdspace::detail::Storage<kdspace::Box3f>(std::vector<kdspace::Box3f>{one});
  // Depth first: inner i at i, its left child i + 1; each right child an empty leaf after the left
  // subtree. Left spine of 65 inner nodes, then the leaf holding the box, then 65 empty leaves.
  std::vector<kdspace::BoxNode> nodes;
  const std::uint32_t spine = 65;
  for (std::uint32_t i = 0; i < spine; ++i) nodes.push_back(kdspace::BoxNode::inner(0, 0.5f, 2 * spine - i));
  nodes.push_back(kdspace::BoxNode::leaf(0, 1));
  for (std::uint32_t i = 0; i < spine; ++i) nodes.push_back(kdspace::BoxNode::leaf(4, 0));
  deep.nodes = kdspace::detail::Storage<kdspace::BoxNode>(nodes);
  deep.references = kdspace::detail::Storage<std::uint32_t>(std::vector<std::uint32_t>{0, 0, 0, 0});
  kdspace::LeafBlock block{};
  for (int lane = 0; lane < 4; ++lane)
    for (int a = 0; a < 3; ++a) block.plane[a][lane] = 0, block.plane[3 + a][lane] = 1;
  deep.blocks = kdspace::detail::Storage<kdspace::LeafBlock>(std::vector<kdspace::LeafBlock>{block});
  REQUIRE_THROWS_WITH(BoxTree(std::move(deep)), Catch::Contains("deeper than 64"));
}

TEST_CASE("index: a large box tree, checked on two threads, names each problem as the one-thread check does",
          "[index][boxes][errors][threads]") {
  // Enough references for the two-thread check (2^16 or more): a problem in the first leaf, in the
  // leaves on either side of the middle of the node array (where the second thread starts) and in the
  // last leaf is named with its leaf, as the one-thread check names it; and so are a box outside the
  // bounds or not finite, at either end, and a box in no leaf.
  const auto boxes = kdspace::generate_boxes(40000, kdspace::SceneKind::uniform, 7);
  const BoxTree tree(boxes);
  REQUIRE(tree.parts().references.size() >= (std::size_t{1} << 16));
  const BoxTree again(owned_parts(tree));
  REQUIRE(again.nodes() == tree.nodes());
  REQUIRE(again.stats().depth == tree.stats().depth);
  REQUIRE(again.stats().sah_cost == tree.stats().sah_cost);

  const auto& nodes = tree.nodes();
  std::vector<std::size_t> leaves;  // non-empty leaves, in node order
  for (std::size_t i = 0; i < nodes.size(); ++i)
    if (nodes[i].is_leaf() && nodes[i].count() >= 2) leaves.push_back(i);
  REQUIRE(leaves.size() > 4);
  const std::size_t middle =
      std::lower_bound(leaves.begin(), leaves.end(), nodes.size() / 2) - leaves.begin();
  REQUIRE(middle > 0);
  REQUIRE(middle < leaves.size());
  using Boxes = std::vector<kdspace::Box3f>;
  using Nodes = std::vector<kdspace::BoxNode>;
  using Refs = std::vector<std::uint32_t>;
  using Blocks = std::vector<kdspace::LeafBlock>;
  for (std::size_t leaf : {leaves.front(), leaves[middle - 1], leaves[middle], leaves.back()}) {
    CAPTURE(leaf);
    const std::size_t first = nodes[leaf].first();
    const std::string at = "leaf " + std::to_string(leaf) + ": ";
    refused(tree, at + "leaf block " + std::to_string(first / 4) + " lane 1 differs from box",
            [&](Boxes&, Nodes&, Refs&, Blocks& b) { b[first / 4].plane[4][1] += 1; });
    refused(tree, at + "reference names box 40000 of 40000",
            [&](Boxes&, Nodes&, Refs& r, Blocks&) { r[first] = 40000; });
    refused(tree, at + "references not ascending", [&](Boxes&, Nodes&, Refs& r, Blocks& b) {
      std::swap(r[first], r[first + 1]);  // and their blocks' lanes: only the order is wrong
      for (int c = 0; c < 6; ++c) std::swap(b[first / 4].plane[c][0], b[first / 4].plane[c][1]);
    });
  }
  refused(tree, "box 1: min x is nan",
          [&](Boxes& x, Nodes&, Refs&, Blocks&) { x[0].lo[0] = std::numeric_limits<float>::quiet_NaN(); });
  refused(tree, "box 40000: min y 2 > max y", [&](Boxes& x, Nodes&, Refs&, Blocks&) { x.back().lo[1] = 2; });
  refused(tree, "is in no leaf", [&](Boxes& x, Nodes&, Refs&, Blocks&) { x.push_back(x[0]); });
  kdspace::BoxTreeParts shrunk = owned_parts(tree);
  shrunk.bounds.hi[2] = std::nextafter(shrunk.bounds.hi[2], 0.0f);
  REQUIRE_THROWS_WITH(BoxTree(std::move(shrunk)), Catch::Contains("lies outside the bounds"));
}

TEST_CASE("index: a large box tree file, checked on two threads, catches a changed byte in every section",
          "[index][boxes][errors][threads]") {
  // The two threads checksum the boxes, references and leaf blocks as they check them, and share the
  // other sections' chunks: a byte changed at the start, the middle and the end of every section is
  // caught, mapped and read; the untouched file loads with the same nodes and hits.
  kdspace_test::ScratchDir tmp("kdspace-index-boxes-", true);
  const auto boxes = kdspace::generate_boxes(60000, kdspace::SceneKind::clustered, 8);
  const BoxTree tree(boxes);
  REQUIRE(tree.parts().references.size() >= (std::size_t{1} << 16));
  const std::string path = tmp.file("large.kdx");
  io::save(path, tree);
  const std::vector<unsigned char> bytes = file_bytes(path);
  const std::vector<io::SectionEntry> sections = io::IndexFile::open(path)->info().sections;
  for (const io::SectionEntry& s : sections)
    for (std::uint64_t at : {s.offset, s.offset + s.length / 2, s.offset + s.length - 1}) {
      CAPTURE(at);
      std::vector<unsigned char> damaged = bytes;
      damaged[at] ^= 0x20;
      write_bytes(path, damaged);
      for (auto mode : {io::LoadMode::map, io::LoadMode::read})
        REQUIRE_THROWS_WITH(io::load_box_tree(path, mode), Catch::Contains("checksum mismatch"));
    }
  write_bytes(path, bytes);
  const auto rays = kdspace::random_rays(2000, kdspace::Box3f{{0, 0, 0}, {1, 1, 1}}, 9);
  for (auto mode : {io::LoadMode::map, io::LoadMode::read}) {
    const BoxTree loaded = io::load_box_tree(path, mode);
    REQUIRE(loaded.nodes() == tree.nodes());
    const auto x = tree.closest_hit_batch(rays, 1), y = loaded.closest_hit_batch(rays, 1);
    for (std::size_t i = 0; i < rays.size(); ++i)
      REQUIRE((x[i].box == y[i].box && (x[i].t == y[i].t || !x[i].hit())));
  }
}

TEST_CASE("index: box tree files keep the build parameters, and files of the old layout are refused by name",
          "[index][boxes][errors]") {
  kdspace_test::ScratchDir tmp("kdspace-index-boxes-", true);
  const auto boxes = kdspace::generate_boxes(100, kdspace::SceneKind::uniform, 9);
  kdspace::BoxBuildParams params;
  params.binning_threshold = 33;
  params.threads = 2;
  params.max_references_per_box = 3.5f;
  params.K_i = 0.5f;
  io::save(tmp.file("b.kdx"), BoxTree(boxes, params));
  const BoxTree loaded = io::load_box_tree(tmp.file("b.kdx"));
  REQUIRE(loaded.params().binning_threshold == 33);
  REQUIRE(loaded.params().threads == 2);
  REQUIRE(loaded.params().max_references_per_box == 3.5f);
  REQUIRE(loaded.params().K_i == 0.5f);

  // The nodes section marked as layout 1 (unpadded references, leaf boxes): refused, named.
  std::vector<unsigned char> bytes = file_bytes(tmp.file("b.kdx"));
  std::uint32_t sections = 0;
  std::memcpy(&sections, bytes.data() + 28, 4);
  bool marked = false;
  for (std::uint32_t s = 0; s < sections; ++s) {
    unsigned char* entry = bytes.data() + 64 + 40 * s;
    std::uint32_t type = 0;
    std::memcpy(&type, entry, 4);
    if (type != static_cast<std::uint32_t>(io::SectionType::nodes)) continue;
    const std::uint32_t old_layout = 1;
    std::memcpy(entry + 8, &old_layout, 4);
    marked = true;
  }
  REQUIRE(marked);
  io::reseal_index_bytes(bytes);
  write_bytes(tmp.file("old.kdx"), bytes);
  REQUIRE_THROWS_WITH(io::load_box_tree(tmp.file("old.kdx")),
                      Catch::Contains("old.kdx: ") && Catch::Contains("nodes") &&
                          Catch::Contains("layout version 1, this kdspace reads version 2"));
}
