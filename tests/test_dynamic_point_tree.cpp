// DynamicPointTree: after any sequence of insertions and removals, every answer equals that of a
// PointTree built afresh over the points held (in id order), bit for bit, with its indices mapped to
// ids; ids stay stable; queries running during updates see whole updates only ([threads]).
#include <atomic>
#include <catch2/catch.hpp>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"
#include "kdspace/points/dynamic_point_tree.hpp"
#include "support.hpp"

using kdspace::DynamicPointTree;
using kdspace::Index;
using kdspace::PointTree;
using kdspace_test::Shape;

namespace {

// The points a DynamicPointTree should hold: id -> coordinates.
template <class T>
using Model = std::map<Index, std::vector<T>>;

// A PointTree over the model's points in id order, and the id of each of its indices.
template <class T, class Metric>
struct Fresh {
  std::vector<Index> ids;
  std::vector<T> rows;
  std::unique_ptr<PointTree<T, kdspace::Dynamic, Metric>> tree;

  Fresh(const Model<T>& model, std::size_t dim, const kdspace::BuildParams& params) {
    for (const auto& [id, row] : model) {
      ids.push_back(id);
      rows.insert(rows.end(), row.begin(), row.end());
    }
    if (!ids.empty())
      tree = std::make_unique<PointTree<T, kdspace::Dynamic, Metric>>(rows.data(), ids.size(), dim, params);
  }
  std::vector<kdspace::Neighbor<T>> mapped(std::vector<kdspace::Neighbor<T>> found) const {
    for (auto& nb : found) nb.index = ids[nb.index];
    return found;
  }
};

// Every answer of the dynamic tree equals the fresh tree's, mapped to ids.
template <class T, class Metric>
void require_fresh_answers(const DynamicPointTree<T, kdspace::Dynamic, Metric>& dyn, const Model<T>& model,
                           std::size_t dim, const kdspace::BuildParams& params,
                           const std::vector<T>& queries) {
  REQUIRE(dyn.size() == model.size());
  const Fresh<T, Metric> fresh(model, dim, params);
  const std::size_t nq = queries.size() / dim;
  if (model.empty()) {
    CHECK_THROWS_AS(dyn.knn(queries.data(), 1), kdspace::Error);
    return;
  }
  for (std::size_t k : {std::size_t{1}, std::min<std::size_t>(4, model.size()),
                        std::min<std::size_t>(13, model.size()), model.size()}) {
    const auto batch = dyn.knn_batch(queries.data(), nq, k, {}, 1);
    for (std::size_t q = 0; q < nq; ++q) {
      const T* query = queries.data() + q * dim;
      const auto want = fresh.mapped(fresh.tree->knn(query, k));
      REQUIRE(dyn.knn(query, k) == want);
      const auto row = batch.row(q);
      REQUIRE(std::vector<kdspace::Neighbor<T>>(row.begin(), row.end()) == want);
    }
  }
  for (std::size_t q = 0; q < nq; ++q) {
    const T* query = queries.data() + q * dim;
    REQUIRE(dyn.radius(query, T(0.4)) == fresh.mapped(fresh.tree->radius(query, T(0.4))));
    REQUIRE(dyn.radius(query, T(0.4), 3) == fresh.mapped(fresh.tree->radius(query, T(0.4), 3)));
    std::vector<T> lo(query, query + dim), hi = lo;
    for (std::size_t a = 0; a < dim; ++a) lo[a] -= T(0.3), hi[a] += T(0.3);
    std::vector<Index> want;
    for (Index i : fresh.tree->box(lo.data(), hi.data())) want.push_back(fresh.ids[i]);
    std::sort(want.begin(), want.end());
    REQUIRE(dyn.box(lo.data(), hi.data()) == want);
  }
}

// Random insertions (single points and batches) and removals (single ids and batches), checked
// against a fresh build after every step.
template <class T, class Metric>
void random_sequence(Shape shape, std::size_t dim, std::uint32_t seed, const kdspace::BuildParams& params,
                     int steps) {
  std::mt19937 rng(seed);
  const auto pool = kdspace_test::make_points<T>(shape, 4000, dim, seed);
  const auto queries = kdspace_test::make_queries(pool, 4000, dim, 12, seed + 1);
  std::size_t used = 0;                                               // rows of the pool inserted so far
  DynamicPointTree<T, kdspace::Dynamic, Metric> dyn(dim, params, 4);  // small parts: many levels
  Model<T> model;
  std::size_t most_parts = 0, most_removed = 0, most_buffered = 0;
  for (int step = 0; step < steps; ++step) {
    most_parts = std::max(most_parts, dyn.part_count());
    most_removed = std::max(most_removed, dyn.removed_count());
    most_buffered = std::max(most_buffered, dyn.buffered());
    CAPTURE(step, model.size(), dyn.part_count());
    const int action = std::uniform_int_distribution<int>(0, 9)(rng);
    if (action < 5 || model.size() < 2) {
      const std::size_t batch = action == 0 ? std::uniform_int_distribution<std::size_t>(50, 400)(rng)
                                            : std::uniform_int_distribution<std::size_t>(1, 6)(rng);
      const std::size_t n = std::min(batch, 4000 - used);
      if (n == 0) continue;
      const Index first = dyn.insert(pool.data() + used * dim, n);
      REQUIRE(first == dyn.next_id() - n);
      for (std::size_t i = 0; i < n; ++i)
        model[static_cast<Index>(first + i)] =
            std::vector<T>(pool.begin() + static_cast<long>((used + i) * dim),
                           pool.begin() + static_cast<long>((used + i + 1) * dim));
      used += n;
    } else {
      // Remove a random share of the points, up to most of them (which makes parts compact).
      const std::size_t n =
          action == 9 ? model.size() * 3 / 4 : std::uniform_int_distribution<std::size_t>(1, 5)(rng);
      std::vector<Index> live;
      for (const auto& entry : model) live.push_back(entry.first);
      std::shuffle(live.begin(), live.end(), rng);
      live.resize(std::min(n, live.size()));
      dyn.remove(live.data(), live.size());
      for (Index id : live) {
        REQUIRE_FALSE(dyn.contains(id));
        model.erase(id);
      }
    }
    require_fresh_answers(dyn, model, dim, params, queries);
  }
  CHECK(most_parts >= 2);  // the sequence did merge parts, leave tombstones and buffer points
  CHECK(most_removed > 0);
  CHECK(most_buffered > 0);
}

}  // namespace

TEST_CASE("dynamic: after random inserts and removes, answers equal a fresh build's bit for bit",
          "[points][dynamic]") {
  kdspace::BuildParams params;
  params.leaf_size = 4;
  std::uint32_t seed = 100;
  for (Shape shape : {Shape::uniform, Shape::clustered, Shape::duplicates, Shape::identical, Shape::grid}) {
    for (std::size_t dim : {2, 5}) {
      CAPTURE(kdspace_test::name(shape), dim);
      random_sequence<float, kdspace::L2>(shape, dim, ++seed, params, 40);
    }
  }
  SECTION("double, other metrics and split rules") {
    params.position = kdspace::PositionRule::sliding_midpoint;
    random_sequence<double, kdspace::L2>(Shape::uniform, 3, 7, params, 30);
    random_sequence<float, kdspace::L1>(Shape::grid, 3, 8, params, 30);
    params.position = kdspace::PositionRule::middle;
    random_sequence<double, kdspace::Linf>(Shape::duplicates, 4, 9, params, 30);
  }
}

TEST_CASE("dynamic: ids are stable and never reused; bad removals change nothing",
          "[points][dynamic][errors]") {
  const auto pts = kdspace_test::make_points<float>(Shape::uniform, 300, 3, 1);
  DynamicPointTree<float> dyn(pts.data(), 100, 3);
  REQUIRE(dyn.size() == 100);
  REQUIRE(dyn.next_id() == 100);
  REQUIRE(dyn.insert(pts.data() + 300, 50) == 100);
  const Index gone[] = {3, 120};
  dyn.remove(gone, 2);
  REQUIRE(dyn.size() == 148);
  REQUIRE(dyn.insert(pts.data() + 450, 1) == 150);  // removed ids are not given again
  REQUIRE(dyn.contains(149));
  REQUIRE_FALSE(dyn.contains(3));
  REQUIRE_FALSE(dyn.contains(151));
  // The point at id 7 is still found under id 7 after all this.
  REQUIRE(dyn.knn(pts.data() + 7 * 3, 1)[0].index == 7);

  const Index unknown[] = {5, 3};  // 3 was removed
  CHECK_THROWS_WITH(dyn.remove(unknown, 2), "remove: id 3 is not in the index (never given, or removed)");
  REQUIRE(dyn.contains(5));  // nothing removed
  const Index twice[] = {6, 8, 6};
  CHECK_THROWS_WITH(dyn.remove(twice, 3), "remove: id 6 is given twice");
  REQUIRE(dyn.contains(6));
  REQUIRE(dyn.size() == 149);
  std::vector<float> bad(3, 0.f);
  bad[1] = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH(dyn.insert(bad.data(), 1), "row 1: coordinate 2 is not finite (nan)");
  REQUIRE(dyn.next_id() == 151);
  CHECK_THROWS_WITH(dyn.knn(pts.data(), 150), "k = 150 exceeds the number of points (149)");
  CHECK(dyn.insert(pts.data(), 0) == 151);  // nothing added
}

TEST_CASE("dynamic: parts stay few, and compact() leaves one", "[points][dynamic]") {
  const auto pts = kdspace_test::make_points<float>(Shape::uniform, 20000, 2, 4);
  DynamicPointTree<float> dyn(2);
  for (std::size_t i = 0; i < 20000; ++i) dyn.insert(pts.data() + i * 2, 1);
  CHECK(dyn.part_count() <= 10);  // about log2(20000 / 64) + 1 at most
  std::vector<Index> ids(10000);
  for (Index i = 0; i < 10000; ++i) ids[i] = 2 * i;
  dyn.remove(ids.data(), ids.size());
  CHECK(dyn.removed_count() <= dyn.size());  // mostly dead parts were rebuilt
  dyn.compact();
  CHECK(dyn.part_count() == 1);
  CHECK(dyn.removed_count() == 0);
  Model<float> odd;
  for (Index i = 1; i < 20000; i += 2) odd[i] = {pts[i * 2], pts[i * 2 + 1]};
  const std::vector<float> queries(pts.begin(), pts.begin() + 20);
  require_fresh_answers(dyn, odd, 2, kdspace::BuildParams{}, queries);
}

TEST_CASE("dynamic: saved with removals pending and loaded back, it answers the same",
          "[points][dynamic][index]") {
  kdspace_test::ScratchDir tmp("kdspace-dynamic-test-", true);
  const auto pts = kdspace_test::make_points<float>(Shape::clustered, 3000, 3, 5);
  const auto queries = kdspace_test::make_queries(pts, 3000, 3, 30, 6);
  DynamicPointTree<float> dyn(pts.data(), 1500, 3);
  for (std::size_t i = 1500; i < 3000; i += 100) dyn.insert(pts.data() + i * 3, 100);
  std::vector<Index> gone;
  for (Index i = 0; i < 3000; i += 7) gone.push_back(i);
  dyn.remove(gone.data(), gone.size());
  dyn.insert(pts.data() + 11 * 3, 5);  // waits in the buffer
  REQUIRE(dyn.removed_count() > 0);
  REQUIRE(dyn.part_count() > 1);
  REQUIRE(dyn.buffered() == 5);
  const std::string path = tmp.file("dyn.kdx");
  kdspace::io::save(path, dyn);
  for (auto mode : {kdspace::io::LoadMode::map, kdspace::io::LoadMode::read}) {
    auto loaded = kdspace::io::load_dynamic_point_tree<float>(path, mode);
    REQUIRE(loaded.size() == dyn.size());
    REQUIRE(loaded.next_id() == dyn.next_id());
    REQUIRE(loaded.next_id() == 3005);
    REQUIRE(loaded.part_count() == dyn.part_count());
    REQUIRE(loaded.removed_count() == dyn.removed_count());
    REQUIRE(loaded.buffered() == 5);
    REQUIRE(loaded.knn_batch(queries.data(), 30, 9, {}, 1).neighbors ==
            dyn.knn_batch(queries.data(), 30, 9, {}, 1).neighbors);
    // And it goes on taking updates, from the mapping.
    const Index first = loaded.insert(pts.data(), 10);
    REQUIRE(first == 3005);
    const Index more[] = {1, 2, 3000, 3005};  // in a part, in a part, in the buffer, new
    loaded.remove(more, 4);
    REQUIRE(loaded.size() == dyn.size() + 6);
  }
  // A PointTree file loads as a DynamicPointTree whose ids are the tree's indices.
  const PointTree<float> tree(pts.data(), 3000, 3);
  kdspace::io::save(tmp.file("tree.kdx"), tree);
  auto from_tree = kdspace::io::load_dynamic_point_tree<float>(tmp.file("tree.kdx"));
  REQUIRE(from_tree.next_id() == 3000);
  REQUIRE(from_tree.knn_batch(queries.data(), 30, 9, {}, 1).neighbors ==
          tree.knn_batch(queries.data(), 30, 9, {}, 1).neighbors);
  // But not the other way round.
  CHECK_THROWS_WITH(kdspace::io::load_point_tree<float>(path),
                    path + ": holds an updatable point tree, not a point tree");
}

TEST_CASE("dynamic: a damaged or forged file is a clear error, or loads as a sound index",
          "[points][dynamic][index][errors]") {
  // A small file with every section a DynamicPointTree writes: parts, tombstones and the buffer.
  kdspace_test::ScratchDir tmp("kdspace-dynamic-test-", true);
  const auto pts = kdspace_test::make_points<float>(Shape::uniform, 40, 2, 8);
  const auto queries = kdspace_test::make_queries(pts, 40, 2, 5, 9);
  kdspace::BuildParams params;
  params.leaf_size = 3;
  DynamicPointTree<float> dyn(2, params, 4);
  for (std::size_t i = 0; i < 36; i += 6) dyn.insert(pts.data() + i * 2, 6);
  const Index gone[] = {1, 7, 20};
  dyn.remove(gone, 3);
  dyn.insert(pts.data() + 36 * 2, 3);
  REQUIRE(dyn.buffered() == 3);
  REQUIRE(dyn.removed_count() > 0);
  const std::string good = tmp.file("good.kdx"), bad = tmp.file("bad.kdx");
  kdspace::io::save(good, dyn);
  std::vector<unsigned char> bytes;
  {
    std::ifstream in(good, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  auto write = [&](const std::vector<unsigned char>& b) {
    std::ofstream out(bad, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  };
  auto message = [&]() -> std::string {
    try {
      auto loaded = kdspace::io::load_dynamic_point_tree<float>(bad);
      // What loads is sound: every query answers k live ids below the next id, in order.
      const std::size_t k = std::min<std::size_t>(4, loaded.size());
      if (k == 0) return "";
      const auto lists = loaded.knn_batch(queries.data(), 5, k, {}, 1);
      for (const auto& n : lists.neighbors) REQUIRE(n.index < loaded.next_id());
      return "";
    } catch (const kdspace::Error& e) {
      return e.what();
    }
  };
  for (std::size_t at = 0; at < bytes.size(); ++at) {  // every changed byte: the checksums
    std::vector<unsigned char> damaged = bytes;
    damaged[at] ^= 0xff;
    write(damaged);
    CAPTURE(at);
    REQUIRE(message().rfind(bad + ": ", 0) == 0);
  }
  std::mt19937 rng(23);
  std::size_t refused = 0;
  for (int trial = 0; trial < 1000; ++trial) {  // resealed: the structural checks
    std::vector<unsigned char> changed = bytes;
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, bytes.size() - 1)(rng);
    changed[at] = static_cast<unsigned char>(changed[at] ^ (1u << (rng() % 8)));
    kdspace::io::reseal_index_bytes(changed);
    write(changed);
    CAPTURE(trial, at);
    const std::string m = message();
    if (!m.empty()) {
      ++refused;
      REQUIRE(m.rfind(bad + ": ", 0) == 0);
    }
  }
  CHECK(refused > 100);
}

TEST_CASE("dynamic: queries during updates see whole updates, in order", "[points][dynamic][threads]") {
  // The updates are replayed first on a second index, recording the answers after each; then
  // readers query while a writer applies them: every answer must be one of the recorded states, and
  // no reader may see an older state after a newer one.
  const std::size_t dim = 3;
  const auto pts = kdspace_test::make_points<float>(Shape::uniform, 6000, dim, 9);
  const auto queries = kdspace_test::make_queries(pts, 6000, dim, 6, 10);
  const std::size_t nq = 6, k = 5;
  struct Update {
    bool insert;
    std::size_t first, count;  // rows of pts to insert, or ids to remove (every third from first)
  };
  std::vector<Update> updates;
  for (std::size_t u = 0; u < 24; ++u)
    updates.push_back(u % 3 == 2 ? Update{false, u * 80, 60}
                                 : Update{true, 1000 + u * 200, u % 2 ? std::size_t{1} : std::size_t{200}});
  auto apply = [&](DynamicPointTree<float>& dyn, const Update& u) {
    if (u.insert) {
      dyn.insert(pts.data() + u.first * dim, u.count);
      return;
    }
    std::vector<Index> ids;
    for (std::size_t i = 0; i < u.count; ++i) ids.push_back(static_cast<Index>(u.first + 3 * i));
    dyn.remove(ids.data(), ids.size());
  };
  std::vector<std::vector<kdspace::Neighbor<float>>> states;
  {
    DynamicPointTree<float> replay(pts.data(), 1000, dim);
    states.push_back(replay.knn_batch(queries.data(), nq, k, {}, 1).neighbors);
    for (const Update& u : updates) {
      apply(replay, u);
      states.push_back(replay.knn_batch(queries.data(), nq, k, {}, 1).neighbors);
    }
  }
  DynamicPointTree<float> dyn(pts.data(), 1000, dim);
  std::atomic<bool> done{false};
  std::atomic<int> mismatches{0}, reads{0};
  auto reader = [&] {
    std::size_t seen = 0;
    while (!done.load()) {
      const auto answer = dyn.knn_batch(queries.data(), nq, k, {}, 1).neighbors;
      std::size_t s = seen;
      while (s < states.size() && states[s] != answer) ++s;
      if (s == states.size())
        ++mismatches;
      else
        seen = s;
      ++reads;
    }
  };
  std::vector<std::thread> readers;
  for (int r = 0; r < 3; ++r) readers.emplace_back(reader);
  for (const Update& u : updates) {
    const int before = reads.load();
    apply(dyn, u);
    while (reads.load() < before + 3) std::this_thread::yield();  // let the readers overlap the next one
  }
  done = true;
  for (auto& t : readers) t.join();
  CHECK(mismatches.load() == 0);
  REQUIRE(dyn.knn_batch(queries.data(), nq, k, {}, 1).neighbors == states.back());
}
