// Tests of the index file format (kdspace/io/index_file.hpp) through PointTree files: round trips by
// memory-mapping and by reading, the checksum, every single-byte change and every truncation of a
// file, changes that keep the checksums valid (only the structural checks stand in their way), and
// atomic saving under a full disk and a crash.
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "../lib/io/crc32c.hpp"
#include "catch_support.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"
#include "mapping_flags.hpp"
#include "support.hpp"

namespace fs = std::filesystem;
namespace io = kdspace::io;
using kdspace::PointTree;
using kdspace_test::error_message;
using kdspace_test::file_bytes;
using kdspace_test::Shape;
using kdspace_test::write_bytes;

namespace {

class TempDir : public kdspace_test::ScratchDir {
 public:
  TempDir() : ScratchDir("kdspace-index-test-", true) {}
};

template <class Tree>
void require_same_nodes(const Tree& a, const Tree& b) {
  REQUIRE(a.node_count() == b.node_count());
  REQUIRE(std::memcmp(a.nodes().data(), b.nodes().data(), a.node_count() * sizeof(typename Tree::Node)) == 0);
}

// Every answer of `got` equals `want`'s: k-NN (batch and single), radius and box.
template <class Tree>
void require_same_answers(const Tree& got, const Tree& want,
                          const std::vector<typename Tree::Scalar>& queries) {
  using T = typename Tree::Scalar;
  const std::size_t d = want.dim(), nq = queries.size() / d;
  for (std::size_t k : {std::size_t{1}, std::size_t{7}, want.size()}) {
    const auto a = got.knn_batch(queries.data(), nq, k, {}, 1);
    const auto b = want.knn_batch(queries.data(), nq, k, {}, 1);
    REQUIRE(a.neighbors == b.neighbors);
  }
  const auto r = got.radius_batch(queries.data(), nq, T(0.3), std::numeric_limits<std::size_t>::max(), 1);
  const auto s = want.radius_batch(queries.data(), nq, T(0.3), std::numeric_limits<std::size_t>::max(), 1);
  REQUIRE(r.offsets == s.offsets);
  REQUIRE(r.neighbors == s.neighbors);
  std::vector<T> lo(queries.begin(), queries.begin() + static_cast<long>(d)), hi = lo;
  for (std::size_t a = 0; a < d; ++a) lo[a] -= T(0.5), hi[a] += T(0.5);
  REQUIRE(got.box(lo.data(), hi.data()) == want.box(lo.data(), hi.data()));
}

// A small tree file for the corruption tests, and the queries that check it.
struct SmallIndex {
  std::vector<float> points = kdspace_test::make_points<float>(Shape::clustered, 60, 3, 5);
  std::vector<float> queries = kdspace_test::make_queries(points, 60, 3, 20, 6);
  kdspace::BuildParams params = [] {
    kdspace::BuildParams p;
    p.leaf_size = 4;
    return p;
  }();
  PointTree<float> tree{points.data(), 60, 3, params};
};

// A 3-D float tree over n points of `shape` (make_points with `seed`), saved at `path`.
PointTree<float> saved_tree(const std::string& path, Shape shape, std::size_t n, std::uint32_t seed) {
  const auto points = kdspace_test::make_points<float>(shape, n, 3, seed);
  PointTree<float> tree(points.data(), n, 3);
  io::save(path, tree);
  return tree;
}

// A 3-D or higher float tree's arrays, copied out to be damaged at will, and their check as a loader
// runs it on them.
struct TreeArrays {
  using Node = kdspace::detail::PointNode<float>;
  std::size_t dim;
  kdspace::BuildParams params;
  std::vector<float> root_lo, root_hi, points;
  std::vector<std::uint32_t> order;
  std::vector<Node> nodes;

  explicit TreeArrays(const PointTree<float>& tree) : dim(tree.dim()) {
    const auto parts = tree.parts();
    params = parts.params;
    root_lo = parts.root_lo;
    root_hi = parts.root_hi;
    points.assign(parts.points.begin(), parts.points.end());
    order.assign(parts.order.begin(), parts.order.end());
    nodes.assign(parts.nodes.begin(), parts.nodes.end());
  }

  // The check's message, or "" when it passes (`shape` then holds what it found).
  std::string check(unsigned threads, kdspace::Verify verify, bool wide_kernels = true,
                    kdspace::detail::TreeShape* shape = nullptr) {
    kdspace::detail::PointTreeParts<float> p{
        dim,
        params,
        kdspace::detail::Storage<float>::borrow(points.data(), points.size()),
        kdspace::detail::Storage<std::uint32_t>::borrow(order.data(), order.size()),
        kdspace::detail::Storage<Node>::borrow(nodes.data(), nodes.size()),
        root_lo,
        root_hi,
        nullptr};
    p.check_threads = threads;
    p.wide_kernels = wide_kernels;
    p.verify = verify;
    try {
      const kdspace::detail::TreeShape found = kdspace::detail::check_point_tree(p);
      if (shape) *shape = found;
      return std::string();
    } catch (const kdspace::Error& e) {
      return std::string(e.what());
    }
  }
};

}  // namespace

TEST_CASE("index: CRC-32C has the standard check value, in hardware (crc32, or folding) and in software",
          "[index]") {
  const char* check = "123456789";
  CHECK(io::detail::crc32c(check, 9) == 0xE3069283u);
  CHECK(io::detail::crc32c_portable(check, 9) == 0xE3069283u);
  CHECK(io::detail::crc32c("", 0) == 0u);
  std::mt19937 rng(3);
  std::vector<unsigned char> data(100000);
  for (auto& b : data) b = static_cast<unsigned char>(rng());
  // Lengths around the three-stream blocks (3 x 4096) and their tails, and around the folding's
  // threshold (1024 bytes) and rounds (256 bytes), at odd starts.
  for (std::size_t n :
       {1, 7, 8, 9, 1023, 1024, 1025, 1279, 1280, 1281, 4095, 12287, 12288, 12289, 24583, 99990})
    for (std::size_t start : {0, 1, 5}) {
      CAPTURE(n, start);
      REQUIRE(io::detail::crc32c(data.data() + start, n) ==
              io::detail::crc32c_portable(data.data() + start, n));
    }
}

TEST_CASE("index: the CRC-32C of two ranges combines into the CRC-32C of both", "[index]") {
  std::mt19937 rng(5);
  std::vector<unsigned char> data(70000);
  for (auto& b : data) b = static_cast<unsigned char>(rng());
  for (std::size_t split : {0, 1, 8, 4096, 12289, 69999, 70000}) {
    CAPTURE(split);
    const std::uint32_t a = io::detail::crc32c(data.data(), split);
    const std::uint32_t b = io::detail::crc32c(data.data() + split, data.size() - split);
    REQUIRE(io::detail::crc32c_combine(a, b, data.size() - split) ==
            io::detail::crc32c(data.data(), data.size()));
  }
  // Every split of a short range, and random ones of the long one.
  for (std::size_t split = 0; split <= 300; ++split) {
    CAPTURE(split);
    REQUIRE(io::detail::crc32c_combine(io::detail::crc32c(data.data(), split),
                                       io::detail::crc32c(data.data() + split, 300 - split),
                                       300 - split) == io::detail::crc32c(data.data(), 300));
  }
  for (int round = 0; round < 200; ++round) {
    const std::size_t split = rng() % (data.size() + 1);
    CAPTURE(split);
    REQUIRE(io::detail::crc32c_combine(io::detail::crc32c(data.data(), split),
                                       io::detail::crc32c(data.data() + split, data.size() - split),
                                       data.size() - split) == io::detail::crc32c(data.data(), data.size()));
  }
}

TEST_CASE("index: combining CRC-32Cs agrees with the bitwise multiplication, lengths up to 2^63", "[index]") {
  std::mt19937_64 rng(11);
  for (int round = 0; round < 2000; ++round) {
    const auto a = static_cast<std::uint32_t>(rng()), b = static_cast<std::uint32_t>(rng());
    const std::size_t length = rng() >> (rng() % 64);  // lengths of every size
    CAPTURE(a, b, length);
    REQUIRE(io::detail::crc32c_combine(a, b, length) == io::detail::crc32c_combine_portable(a, b, length));
  }
}

TEST_CASE("index: the CRC-32C extended piece by piece is the CRC-32C of the whole", "[index]") {
  std::mt19937 rng(7);
  std::vector<unsigned char> data(70000);
  for (auto& b : data) b = static_cast<unsigned char>(rng());
  for (std::size_t piece : {1, 13, 288, 12288, 20000}) {
    CAPTURE(piece);
    std::uint32_t crc = 0;  // the CRC-32C of nothing
    for (std::size_t at = 0; at < data.size(); at += piece)
      crc = io::detail::crc32c_extend(crc, data.data() + at, std::min(piece, data.size() - at));
    REQUIRE(crc == io::detail::crc32c(data.data(), data.size()));
  }
}

TEMPLATE_TEST_CASE("index: a saved point tree loads, mapped or read, with the same nodes and answers",
                   "[index]", float, double) {
  using T = TestType;
  TempDir tmp;
  for (Shape shape :
       {Shape::uniform, Shape::clustered, Shape::duplicates, Shape::identical, Shape::flat, Shape::grid}) {
    for (std::size_t dim : {1, 3, 9}) {
      for (auto position : {kdspace::PositionRule::median, kdspace::PositionRule::middle,
                            kdspace::PositionRule::sliding_midpoint, kdspace::PositionRule::midpoint}) {
        CAPTURE(kdspace_test::name(shape), dim, kdspace_test::name(position));
        const std::size_t n = 700;
        const auto points = kdspace_test::make_points<T>(shape, n, dim, 11);
        const auto queries = kdspace_test::make_queries(points, n, dim, 20, 12);
        kdspace::BuildParams params;
        params.position = position;
        params.leaf_size = 5;
        params.axis = kdspace::AxisRule::cycle;
        const PointTree<T> built(points.data(), n, dim, params);
        const std::string path = tmp.file("tree.kdx");
        io::save(path, built);
        for (auto mode : {io::LoadMode::map, io::LoadMode::read})
          for (auto verify : {kdspace::Verify::safety, kdspace::Verify::full}) {
            const auto loaded = io::load_point_tree<T>(path, mode, verify);
            REQUIRE(loaded.nodes().borrowed());
            REQUIRE(loaded.size() == n);
            REQUIRE(loaded.depth() == built.depth());
            REQUIRE(loaded.leaf_count() == built.leaf_count());
            REQUIRE(loaded.params().position == position);
            REQUIRE(loaded.params().axis == kdspace::AxisRule::cycle);
            REQUIRE(loaded.params().leaf_size == 5);
            require_same_nodes(loaded, built);
            require_same_answers(loaded, built, queries);
          }
      }
    }
  }
}

TEST_CASE("index: metrics, compile-time dimensions and the blocked scan survive a round trip", "[index]") {
  TempDir tmp;
  const std::size_t n = 3000;
  const auto points = kdspace_test::make_points<float>(Shape::uniform, n, 3, 21);
  const auto queries = kdspace_test::make_queries(points, n, 3, 100, 22);
  {
    const PointTree<float, 3> built(points.data(), n, 3);
    io::save(tmp.file("fixed.kdx"), built);
    const auto loaded = io::load_point_tree<float, 3>(tmp.file("fixed.kdx"));
    require_same_answers(loaded, built, queries);
    // The same file serves a tree of run-time dimension.
    const auto dynamic = io::load_point_tree<float>(tmp.file("fixed.kdx"));
    REQUIRE(dynamic.dim() == 3);
  }
  {
    const PointTree<float, kdspace::Dynamic, kdspace::Linf> built(points.data(), n, 3);
    io::save(tmp.file("linf.kdx"), built);
    require_same_answers(io::load_point_tree<float, kdspace::Dynamic, kdspace::Linf>(tmp.file("linf.kdx")),
                         built, queries);
  }
  {
    const std::vector<double> wider(points.begin(), points.end());
    const std::vector<double> wider_queries(queries.begin(), queries.end());
    const PointTree<double, kdspace::Dynamic, kdspace::Minkowski> built(wider.data(), n, 3, {},
                                                                        kdspace::Minkowski(3.5));
    io::save(tmp.file("minkowski.kdx"), built);
    const auto loaded =
        io::load_point_tree<double, kdspace::Dynamic, kdspace::Minkowski>(tmp.file("minkowski.kdx"));
    REQUIRE(loaded.metric().p == 3.5);
    require_same_answers(loaded, built, wider_queries);
  }
  {
    const auto wide = kdspace_test::make_points<float>(Shape::uniform, n, 48, 23);
    const auto wide_queries = kdspace_test::make_queries(wide, n, 48, 70, 24);
    const PointTree<float> built(wide.data(), n, 48);
    io::save(tmp.file("wide.kdx"), built);
    const auto loaded = io::load_point_tree<float>(tmp.file("wide.kdx"));
    kdspace::SearchParams scan;
    scan.batch_method = kdspace::BatchMethod::scan;
    REQUIRE(loaded.knn_batch(wide_queries.data(), 70, 10, scan, 1).neighbors ==
            built.knn_batch(wide_queries.data(), 70, 10, scan, 1).neighbors);
  }
}

TEST_CASE("index: a file of another kind, type, metric or dimension is refused by name", "[index][errors]") {
  TempDir tmp;
  const auto points = kdspace_test::make_points<float>(Shape::uniform, 100, 3, 1);
  io::save(tmp.file("t.kdx"), PointTree<float>(points.data(), 100, 3));
  const std::string path = tmp.file("t.kdx");
  CHECK(error_message([&] { io::load_point_tree<double>(path); }) ==
        path + ": holds float32 coordinates, expected float64");
  CHECK(error_message([&] { io::load_point_tree<float, kdspace::Dynamic, kdspace::L1>(path); }) ==
        path + ": is built for metric l2, expected l1");
  CHECK(error_message([&] { io::load_point_tree<float, 2>(path); }) == path + ": dimension 3, expected 2");
  CHECK(error_message([&] { io::load_box_tree(path); }) == path + ": holds a point tree, not a box tree");
  CHECK(error_message([&] { io::load_point_forest<float>(path); }) ==
        path + ": holds a point tree, not a point forest");
  CHECK(error_message([&] { io::load_point_tree<float>(tmp.file("missing.kdx")); }) ==
        tmp.file("missing.kdx") + ": cannot open: No such file or directory");
  write_bytes(tmp.file("points.fvecs"), {3, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12});
  CHECK(error_message([&] { io::load_point_tree<float>(tmp.file("points.fvecs")); }) ==
        tmp.file("points.fvecs") + ": not a kdspace index file (bad magic bytes)");
  write_bytes(tmp.file("empty.kdx"), {});
  CHECK(error_message([&] { io::load_point_tree<float>(tmp.file("empty.kdx")); }) ==
        tmp.file("empty.kdx") + ": empty file, not an index");
  CHECK(error_message([&] { io::load_point_tree<float>(tmp.path()); }) ==
        tmp.path() + ": is a directory, not an index file");

  // A newer format version (resealed, so that only the version differs).
  std::vector<unsigned char> bytes = file_bytes(path);
  bytes[8] = 2;
  io::reseal_index_bytes(bytes);
  write_bytes(tmp.file("v2.kdx"), bytes);
  CHECK(error_message([&] { io::load_point_tree<float>(tmp.file("v2.kdx")); }) ==
        tmp.file("v2.kdx") + ": format version 2: this kdspace reads version 1");
}

TEST_CASE("index: every single changed byte and every truncation of a file is a clear error",
          "[index][errors]") {
  TempDir tmp;
  SmallIndex small;
  const std::string good = tmp.file("good.kdx"), bad = tmp.file("bad.kdx");
  io::save(good, small.tree);
  const std::vector<unsigned char> bytes = file_bytes(good);
  REQUIRE(bytes.size() > 1000);
  // A CRC catches any damage of up to 32 bits in a row: every byte, changed in any way, is caught.
  for (std::size_t at = 0; at < bytes.size(); ++at) {
    for (int change : {0x01, 0x80, 0xff}) {
      std::vector<unsigned char> damaged = bytes;
      damaged[at] = static_cast<unsigned char>(damaged[at] ^ change);
      write_bytes(bad, damaged);
      CAPTURE(at, change);
      for (auto mode : {io::LoadMode::map, io::LoadMode::read}) {
        const std::string message = error_message([&] { io::load_point_tree<float>(bad, mode); });
        REQUIRE(message.rfind(bad + ": ", 0) == 0);
      }
    }
  }
  for (std::size_t size = 0; size < bytes.size(); ++size) {
    write_bytes(bad, std::vector<unsigned char>(bytes.begin(), bytes.begin() + static_cast<long>(size)));
    CAPTURE(size);
    const std::string message = error_message([&] { io::load_point_tree<float>(bad); });
    REQUIRE(message.rfind(bad + ": ", 0) == 0);
  }
  std::vector<unsigned char> longer = bytes;
  longer.push_back(0);
  write_bytes(bad, longer);
  CHECK(error_message([&] { io::load_point_tree<float>(bad); }) ==
        bad + ": the file has " + std::to_string(bytes.size() + 1) + " bytes, its header says " +
            std::to_string(bytes.size()) + " (extra bytes at the end)");
  std::vector<unsigned char> flipped = bytes;
  flipped[bytes.size() - 1] ^= 1;
  write_bytes(bad, flipped);
  CHECK(error_message([&] {
          io::load_point_tree<float>(bad);
        }).find("checksum mismatch: the file is damaged") != std::string::npos);
}

TEST_CASE(
    "index: changes that keep the checksums valid are caught by the structural checks, or answer exactly",
    "[index][errors]") {
  // Resealing recomputes every checksum after a change, as a forger could. What Verify::full loads
  // must be a sound tree, and a sound tree answers as brute force over its own points. What the
  // default Verify::safety loads must keep every query inside the arrays (ASan watches) and return
  // indices below n; it loads everything Verify::full loads (each names the first problem it meets,
  // so where both refuse their messages may differ).
  TempDir tmp;
  SmallIndex small;
  const std::string good = tmp.file("good.kdx"), bad = tmp.file("bad.kdx");
  io::save(good, small.tree);
  const std::vector<unsigned char> bytes = file_bytes(good);
  std::mt19937 rng(17);
  std::size_t refused = 0, refused_by_both = 0, loaded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<unsigned char> changed = bytes;
    const int changes = 1 + trial % 3;
    for (int c = 0; c < changes; ++c) {
      const std::size_t at = std::uniform_int_distribution<std::size_t>(0, bytes.size() - 1)(rng);
      changed[at] = static_cast<unsigned char>(trial % 2 ? changed[at] ^ (1u << (rng() % 8)) : rng());
    }
    io::reseal_index_bytes(changed);
    write_bytes(bad, changed);
    CAPTURE(trial);
    std::string safety_refused;
    try {
      const auto tree = io::load_point_tree<float>(bad, io::LoadMode::map, kdspace::Verify::safety);
      for (std::size_t k : {std::size_t{1}, std::size_t{5}, tree.size()}) {
        const auto answers = tree.knn_batch(small.queries.data(), 20, k, {}, 1);
        for (const auto& nb : answers.neighbors) REQUIRE(nb.index < tree.size());
      }
      const auto within = tree.radius_batch(small.queries.data(), 20, 0.5f, 1000, 1);
      for (const auto& nb : within.neighbors) REQUIRE(nb.index < tree.size());
    } catch (const kdspace::Error& e) {
      safety_refused = e.what();
      REQUIRE(safety_refused.rfind(bad + ": ", 0) == 0);
    }
    try {
      const auto tree = io::load_point_tree<float>(bad, io::LoadMode::map, kdspace::Verify::full);
      REQUIRE(safety_refused == "");
      ++loaded;
      const auto parts = tree.parts();
      std::vector<float> rows(tree.size() * 3);  // the loaded points, by original index
      for (std::size_t r = 0; r < tree.size(); ++r)
        std::copy_n(parts.points.data() + r * 3, 3, rows.begin() + static_cast<long>(parts.order[r] * 3));
      const auto answers = tree.knn_batch(small.queries.data(), 20, 5, {}, 1);
      REQUIRE(kdspace_test::differs_from_brute_force(answers, rows, tree.size(), 3, small.queries, 5) == "");
    } catch (const kdspace::Error& e) {
      ++refused;
      REQUIRE(std::string(e.what()).rfind(bad + ": ", 0) == 0);
      if (safety_refused != "") ++refused_by_both;
    }
  }
  CHECK(refused > 1000);
  CHECK(refused_by_both > 500);      // the header, the section table, the nodes, the order's range
  CHECK(refused_by_both < refused);  // and points moved out of their cells, which only Verify::full reads
  CHECK(loaded > 100);               // changes of coordinates that keep the tree sound
}

TEST_CASE("index: a large file, checked in chunks on two threads, still catches every damaged chunk",
          "[index][errors]") {
  // Sections of several 256 KiB checksum chunks, and a tree large enough that its point order is
  // checked on a second thread: a byte changed at either side of every chunk boundary, in the middle
  // of every chunk and at the ends of every section is caught, mapped and read.
  TempDir tmp;
  const std::size_t n = std::size_t{3} << 16;  // above kdspace::detail::parallel_tree_check
  REQUIRE(n >= kdspace::detail::parallel_tree_check);
  const std::string path = tmp.file("large.kdx");
  const PointTree<float> tree = saved_tree(path, Shape::uniform, n, 8);
  const auto info = io::IndexFile::open(path)->info();
  std::vector<std::uint64_t> spots;
  for (const io::SectionEntry& s : info.sections) {
    spots.push_back(s.offset);
    spots.push_back(s.offset + s.length - 1);
    for (std::uint64_t at = 0; at < s.length; at += 1u << 17) spots.push_back(s.offset + at);
    for (std::uint64_t at = std::uint64_t{1} << 18; at < s.length; at += 1u << 18) {
      spots.push_back(s.offset + at - 1);
      spots.push_back(s.offset + at);
    }
  }
  REQUIRE(spots.size() > 20);
  std::fstream file(path, std::ios::binary | std::ios::in | std::ios::out);
  auto change = [&file](std::uint64_t at) {
    file.seekg(static_cast<std::streamoff>(at));
    const int old = file.get();
    file.seekp(static_cast<std::streamoff>(at));
    file.put(static_cast<char>(old ^ 0x10));
    file.flush();
  };
  for (std::uint64_t at : spots) {
    CAPTURE(at);
    change(at);
    for (auto mode : {io::LoadMode::map, io::LoadMode::read})
      REQUIRE(error_message([&] { io::load_point_tree<float>(path, mode); }).find("checksum mismatch") !=
              std::string::npos);
    // Checked on five threads: the tree in more pieces, each checksummed by the thread that reads it.
    REQUIRE(error_message([&] {
              io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::safety, 5);
            }).find("checksum mismatch") != std::string::npos);
    change(at);  // back as it was
  }
  const auto loaded = io::load_point_tree<float>(path);
  require_same_nodes(loaded, tree);
  require_same_nodes(io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::full, 5), tree);
}

TEST_CASE("index: a load that leaves its checksums pending answers as the saved tree, and wait() names "
          "every damaged section",
          "[index][errors][threads]") {
  // A tree of more than 131,072 points, so that its check runs in pieces on two threads.
  const std::size_t n = kdspace::detail::parallel_tree_check + 3000;
  TempDir tmp;
  const std::string path = tmp.file("pending.kdx");
  const PointTree<float> tree = saved_tree(path, Shape::clustered, n, 12);
  const auto queries = kdspace_test::make_queries(
      std::vector<float>(tree.parts().points.begin(), tree.parts().points.end()), n, 3, 40, 13);
  auto load = [&](io::PendingChecksums& pending, unsigned threads,
                  kdspace::Verify verify = kdspace::Verify::safety) {
    return io::load_point_tree_deferred<float>(io::IndexFile::open(path, io::LoadMode::map, io::Checksums::deferred),
                                               verify, threads, &pending);
  };
  for (unsigned threads : {0u, 1u, 2u, 3u}) {
    CAPTURE(threads);
    io::PendingChecksums pending;
    const auto before = std::chrono::steady_clock::now();
    const auto loaded = load(pending, threads);
    CHECK(pending.started());
    require_same_nodes(loaded, tree);
    if (threads == 2) require_same_answers(loaded, tree, queries);
    pending.wait();
    CHECK(pending.done_at() >= before);
    pending.wait();  // again: nothing more to do
  }
  {  // Verify::full reads every byte in its check: it takes the checksums itself, none pending
    io::PendingChecksums pending;
    require_same_nodes(load(pending, 2, kdspace::Verify::full), tree);
    CHECK(!pending.started());
  }

  // One changed byte in each section, in turn: the structural check may pass (a changed coordinate
  // breaks no structure) or fail; either way the message is the checksum's, naming the section.
  const std::vector<unsigned char> good = file_bytes(path);
  const auto sections = io::IndexFile::open(path)->info().sections;
  for (const io::SectionEntry& s : sections) {
    if (s.length == 0) continue;
    std::vector<unsigned char> bad = good;
    bad[s.offset + s.length / 2] ^= 0x40;
    write_bytes(path, bad);
    const std::string section = io::name_of(s.type);
    CAPTURE(section);
    for (unsigned threads : {1u, 2u}) {
      io::PendingChecksums pending;
      const std::string message = error_message([&] {
        const auto loaded = load(pending, threads);
        pending.wait();
      });
      CHECK(message.find("checksum mismatch: the file is damaged") != std::string::npos);
      CHECK(message.find("section '" + section + "'") != std::string::npos);
      if (pending.started()) CHECK(error_message([&] { pending.wait(); }) == message);  // the same, again
    }
  }
  write_bytes(path, good);
  io::PendingChecksums pending;
  require_same_nodes(load(pending, 2), tree);
  pending.wait();
}

TEST_CASE("index: a point order that is no permutation is named, in a tree checked on two threads",
          "[index][errors]") {
  // With every checksum resealed, only the structural checks stand in the way: the message names the
  // first index that is out of range or (Verify::full) given twice, as the one-thread check did. The
  // default Verify::safety names an index out of range alike, and loads one given twice.
  const std::size_t n = kdspace::detail::parallel_tree_check + 1000;
  TempDir tmp;
  const std::string path = tmp.file("order.kdx");
  saved_tree(path, Shape::clustered, n, 9);
  const std::vector<unsigned char> bytes = file_bytes(path);
  const io::SectionEntry order = *io::IndexFile::open(path)->find(io::SectionType::order);
  auto with_order = [&](std::size_t i, std::uint32_t value, kdspace::Verify verify = kdspace::Verify::full) {
    std::vector<unsigned char> changed = bytes;
    std::memcpy(changed.data() + order.offset + 4 * i, &value, 4);
    io::reseal_index_bytes(changed);
    write_bytes(path, changed);
    const std::string message =
        error_message([&] { io::load_point_tree<float>(path, io::LoadMode::map, verify); });
    CHECK(message == error_message([&] { io::load_point_tree<float>(path, io::LoadMode::map, verify, 1); }));
    return message;
  };
  auto value_at = [&](std::size_t i) {
    std::uint32_t v;
    std::memcpy(&v, bytes.data() + order.offset + 4 * i, 4);
    return v;
  };
  for (const kdspace::Verify verify : {kdspace::Verify::full, kdspace::Verify::safety}) {
    for (const std::size_t i : {std::size_t{0}, n / 2, n - 1})
      CHECK(with_order(i, static_cast<std::uint32_t>(n + i), verify) ==
            path + ": point tree: index " + std::to_string(i) + " of the point order is " +
                std::to_string(n + i) + " (out of range)");
  }
  const std::size_t later = n / 2;  // the values of a permutation differ: value_at(later) != value_at(5)
  CHECK(with_order(later, value_at(5)) == path + ": point tree: index " + std::to_string(later) +
                                              " of the point order is " + std::to_string(value_at(5)) +
                                              " (given twice)");
  {  // Verify::safety loads it: the indices stay below n
    std::vector<unsigned char> changed = bytes;
    const std::uint32_t twice = value_at(5);
    std::memcpy(changed.data() + order.offset + 4 * later, &twice, 4);
    io::reseal_index_bytes(changed);
    write_bytes(path, changed);
    CHECK_NOTHROW(io::load_point_tree<float>(path));
    CHECK_NOTHROW(io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::safety, 1));
  }
}

TEST_CASE(
    "index: a large tree, checked in two walks, names a point out of its cell on either side of the split",
    "[index][errors][threads]") {
  // With every checksum resealed, a point moved out of the root cell must be found by whichever walk
  // reads it (the first points, those around the middle where the second walk starts, the last),
  // and named as the one-thread check names it: its leaf (Verify::full; the default Verify::safety
  // does not read the points, and loads it). A broken link of the root (on the path the two walks
  // split along) is named too, at either level.
  const std::size_t n = std::size_t{3} << 16;
  REQUIRE(n >= kdspace::detail::parallel_tree_check);
  TempDir tmp;
  const std::string path = tmp.file("walks.kdx");
  const PointTree<float> tree = saved_tree(path, Shape::uniform, n, 10);
  const std::vector<unsigned char> bytes = file_bytes(path);
  const auto file = io::IndexFile::open(path);
  const io::SectionEntry nodes = *file->find(io::SectionType::nodes);
  const io::SectionEntry rows = *file->find(io::SectionType::points);
  using Node = kdspace::detail::PointNode<float>;
  std::vector<Node> node_array(nodes.length / sizeof(Node));
  std::memcpy(node_array.data(), bytes.data() + nodes.offset, nodes.length);
  auto leaf_of = [&](std::size_t row) {
    for (std::size_t id = 0; id < node_array.size(); ++id)
      if (node_array[id].is_leaf() && node_array[id].first() <= row &&
          row < node_array[id].first() + node_array[id].count())
        return id;
    return node_array.size();
  };
  // The same message whether the check runs on two threads or on one (threads 1).
  auto load_changed = [&](std::vector<unsigned char> changed,
                          kdspace::Verify verify = kdspace::Verify::full) {
    io::reseal_index_bytes(changed);
    write_bytes(path, changed);
    const std::string alone =
        error_message([&] { io::load_point_tree<float>(path, io::LoadMode::map, verify, 1); });
    const std::string message =
        error_message([&] { io::load_point_tree<float>(path, io::LoadMode::map, verify); });
    CHECK(alone == message);
    return message;
  };
  for (std::size_t row : {std::size_t{0}, n / 2 - 1, n / 2, n / 2 + 1, n - 1}) {
    CAPTURE(row);
    std::vector<unsigned char> changed = bytes;
    const float far = 1e30f;
    std::memcpy(changed.data() + rows.offset + 12 * row + 4, &far, 4);  // its y
    CHECK(load_changed(changed) ==
          path + ": point tree: node " + std::to_string(leaf_of(row)) +
              ": a point lies outside the bounds and splits above its leaf, or is not finite");
    CHECK_NOTHROW(io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::safety));
    CHECK_NOTHROW(io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::safety, 1));
  }
  std::vector<unsigned char> changed = bytes;
  const std::uint32_t link = node_array[0].right_child() + 1;
  std::memcpy(changed.data() + nodes.offset + offsetof(Node, link), &link, 4);
  for (const kdspace::Verify verify : {kdspace::Verify::full, kdspace::Verify::safety})
    CHECK(load_changed(changed, verify)
              .rfind(path + ": point tree: node 0: right child " + std::to_string(link), 0) == 0);
  write_bytes(path, bytes);
  require_same_nodes(io::load_point_tree<float>(path), tree);
  require_same_nodes(io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::safety, 1), tree);
  require_same_nodes(io::load_point_tree<float>(path, io::LoadMode::map, kdspace::Verify::full, 1), tree);
}

TEST_CASE("index: the check's wide kernels decide as the baseline loops do", "[index]") {
  // 3-D float leaves of 8 to 40 points against their cell (every coordinate moved below or above it,
  // or made NaN, in turn), and the order's bits, with the AVX2 and BMI2 kernels against plain loops.
#if defined(KDSPACE_AVX2_DISPATCH)
  if (kdspace::detail::tree_check_kernels()) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    const float lo[4] = {-1.f, -1.f, -1.f, 0.f}, hi[4] = {1.f, 1.f, 1.f, 0.f};
    auto plain = [&](const std::vector<float>& rows) {
      bool ok = true;
      for (std::size_t i = 0; i < rows.size(); ++i) ok = ok && lo[i % 3] <= rows[i] && rows[i] <= hi[i % 3];
      return ok;
    };
    for (std::size_t count = 8; count <= 40; ++count) {
      std::vector<float> rows(3 * count);
      for (float& v : rows) v = u(rng);
      rows[0] = -1.f;  // on the cell's faces: inside
      rows[3 * count - 1] = 1.f;
      REQUIRE(kdspace::detail::points3_inside_avx2(rows.data(), count, lo, hi));
      for (std::size_t i = 0; i < rows.size(); ++i)
        for (float bad : {-1.0001f, 1.0001f, std::numeric_limits<float>::quiet_NaN()}) {
          CAPTURE(count, i, bad);
          const float kept = rows[i];
          rows[i] = bad;
          REQUIRE(!plain(rows));
          REQUIRE(!kdspace::detail::points3_inside_avx2(rows.data(), count, lo, hi));
          rows[i] = kept;
        }
    }
    for (std::size_t count :
         {std::size_t{0}, std::size_t{1}, std::size_t{5}, std::size_t{8}, std::size_t{1000}})
      for (bool in_range : {true, false}) {
        CAPTURE(count, in_range);
        const auto n = static_cast<std::uint32_t>(count + 3);
        std::vector<std::uint32_t> values(count);
        for (auto& v : values) v = static_cast<std::uint32_t>(rng() % n);
        if (!in_range) values.push_back(rng() % 2 ? n : 0xffffffffu);
        std::vector<std::uint64_t> wide(n / 64 + 1, 0), narrow(n / 64 + 1, 0);
        if (in_range)
          for (std::uint32_t v : values) narrow[v >> 6] |= std::uint64_t{1} << (v & 63);
        CHECK(kdspace::detail::mark_values_avx2(values.data(), values.size(), n, wide.data()) == in_range);
        if (in_range) CHECK(wide == narrow);
      }
  }
#endif
  SUCCEED("without AVX2 and BMI2 only the baseline loops run");
}

TEST_CASE("index: the 3-D float check in one AVX2 loop decides as the baseline walk does", "[index]") {
  // Parts of 3-D float trees (uniform and duplicate-heavy points, so leaves of identical points too;
  // leaves of up to 3 and up to 24 points) with a node's field, a coordinate or an order value
  // changed at random, as a forged file could hold them: checked with the wide kernels and with the
  // baseline loops alone, the same verdict and the same message, on one thread and on two.
  using Node = kdspace::detail::PointNode<float>;
  struct Case {
    Shape shape;
    std::size_t n, leaf_size;
    unsigned threads;
    int trials;
  };
  std::mt19937 rng(23);
  for (const Case& c : {Case{Shape::uniform, 3000, 24, 1, 1500}, Case{Shape::duplicates, 3000, 24, 1, 1500},
                        Case{Shape::uniform, 2000, 3, 1, 1000}, Case{Shape::clustered, 140000, 24, 2, 60}}) {
    CAPTURE(kdspace_test::name(c.shape), c.n, c.leaf_size, c.threads);
    const auto rows = kdspace_test::make_points<float>(c.shape, c.n, 3, 5);
    kdspace::BuildParams params;
    params.leaf_size = c.leaf_size;
    const PointTree<float> tree(rows.data(), c.n, 3, params);
    TreeArrays arrays(tree);
    auto& points = arrays.points;
    auto& order = arrays.order;
    auto& nodes = arrays.nodes;
    const auto verdict = [&](bool wide) { return arrays.check(c.threads, kdspace::Verify::full, wide); };
    REQUIRE(verdict(true) == "");
    REQUIRE(verdict(false) == "");
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    int refused = 0;
    for (int trial = 0; trial < c.trials; ++trial) {
      const auto pick = [&](std::size_t size) {
        return std::uniform_int_distribution<std::size_t>(0, size - 1)(rng);
      };
      const auto nudge = [&](float v) {  // a value near v, or one far off
        switch (rng() % 6) {
          case 0:
            return nan;
          case 1:
            return rng() % 2 ? inf : -inf;
          case 2:
            return std::nextafter(v, inf);
          case 3:
            return std::nextafter(v, -inf);
          default:
            return v + std::uniform_real_distribution<float>(-0.05f, 0.05f)(rng);
        }
      };
      const TreeArrays kept = arrays;
      const int changes = 1 + trial % 2;
      for (int k = 0; k < changes; ++k) {
        Node& node = nodes[pick(nodes.size())];
        switch (rng() % 8) {
          case 0:
            node.left_max = nudge(node.left_max);
            break;
          case 1:
            node.right_min = nudge(node.right_min);
            break;
          case 2:
            std::swap(node.left_max, node.right_min);
            break;
          case 3:
            node.link = static_cast<std::uint32_t>(node.link + (rng() % 5) - 2);
            break;
          case 4:
            node.info ^= std::uint32_t{1} << (rng() % 32);
            break;
          case 5:
            node.info = static_cast<std::uint32_t>(rng() % 4);
            break;
          case 6: {
            float& v = points[pick(points.size())];
            v = nudge(v);
            break;
          }
          default:
            order[pick(order.size())] =
                rng() % 8 ? order[pick(order.size())] : static_cast<std::uint32_t>(c.n);
        }
      }
      CAPTURE(trial);
      const std::string wide = verdict(true);
      REQUIRE(wide == verdict(false));
      refused += wide.empty() ? 0 : 1;
      arrays = kept;
    }
    CHECK(refused > c.trials / 4);
    CHECK(refused < c.trials);  // some changes leave a sound tree
  }
}

TEST_CASE("index: the check in pieces decides as the one-thread check, on any number of threads",
          "[index][errors][threads]") {
  // Large trees (3-D and 5-D; uniform, clustered and duplicate-heavy points; leaves of up to 3 and up
  // to 24 points), sound and with a node's field, a coordinate or an order value changed at random:
  // checked on 2, 3, 5 and 8 threads (the tree cut into subtrees the threads take in turn), the
  // verdict, the message and the shape are the one-thread check's, at both verification levels.
  using Node = kdspace::detail::PointNode<float>;
  struct Case {
    Shape shape;
    std::size_t n, dim, leaf_size;
  };
  std::mt19937 rng(29);
  for (const Case& c : {Case{Shape::uniform, 140000, 3, 24}, Case{Shape::clustered, 150000, 3, 3},
                        Case{Shape::duplicates, 140000, 3, 24}, Case{Shape::clustered, 140000, 5, 8}}) {
    CAPTURE(kdspace_test::name(c.shape), c.n, c.dim, c.leaf_size);
    REQUIRE(c.n >= kdspace::detail::parallel_tree_check);
    const auto rows = kdspace_test::make_points<float>(c.shape, c.n, c.dim, 6);
    kdspace::BuildParams params;
    params.leaf_size = c.leaf_size;
    const PointTree<float> tree(rows.data(), c.n, c.dim, params);
    TreeArrays arrays(tree);
    const auto verdict = [&](unsigned threads, kdspace::Verify verify) {
      kdspace::detail::TreeShape shape;
      const std::string message = arrays.check(threads, verify, true, &shape);
      return message.empty()
                 ? "depth " + std::to_string(shape.depth) + ", leaves " + std::to_string(shape.leaves)
                 : message;
    };
    const std::string sound =
        "depth " + std::to_string(tree.depth()) + ", leaves " + std::to_string(tree.leaf_count());
    for (const kdspace::Verify verify : {kdspace::Verify::full, kdspace::Verify::safety})
      for (unsigned threads : {0u, 1u, 2u, 3u, 5u, 8u}) {  // 0: as many as pay for their start
        CAPTURE(threads);
        REQUIRE(verdict(threads, verify) == sound);
      }
    int refused = 0;
    const int trials = 40;
    for (int trial = 0; trial < trials; ++trial) {
      const auto pick = [&](std::size_t size) {
        return std::uniform_int_distribution<std::size_t>(0, size - 1)(rng);
      };
      const TreeArrays kept = arrays;
      Node& node = arrays.nodes[pick(arrays.nodes.size())];
      switch (rng() % 6) {
        case 0:
          node.left_max = node.right_min + 1.0f;
          break;
        case 1:
          node.link = static_cast<std::uint32_t>(node.link + (rng() % 5) - 2);
          break;
        case 2:
          node.info ^= std::uint32_t{1} << (rng() % 32);
          break;
        case 3:
          node.info = static_cast<std::uint32_t>(rng() % 4);
          break;
        case 4:
          arrays.points[pick(arrays.points.size())] = std::numeric_limits<float>::infinity();
          break;
        default:
          arrays.order[pick(arrays.order.size())] =
              rng() % 2 ? arrays.order[pick(arrays.order.size())] : static_cast<std::uint32_t>(c.n);
      }
      CAPTURE(trial);
      for (const kdspace::Verify verify : {kdspace::Verify::full, kdspace::Verify::safety}) {
        const std::string alone = verdict(1, verify);
        for (unsigned threads : {2u, 3u, 5u, 8u}) {
          CAPTURE(threads);
          REQUIRE(verdict(threads, verify) == alone);
        }
        refused += alone == sound ? 0 : 1;
      }
      arrays = kept;
    }
    CHECK(refused > trials / 2);
  }
}

TEST_CASE("index: a check left to choose its threads starts as many as pay for their start", "[index]") {
  // About the square root of the MiB checked, at least one, at most what the hardware has; never
  // fewer for a larger file.
  using kdspace::detail::check_threads_that_pay;
  constexpr std::size_t MiB = std::size_t{1} << 20;
  CHECK(check_threads_that_pay(0, 16) == 1);
  CHECK(check_threads_that_pay(MiB, 16) == 1);
  CHECK(check_threads_that_pay(4 * MiB, 16) == 2);
  CHECK(check_threads_that_pay(17984536, 16) == 4);  // the index of 1e6 3-D float points
  CHECK(check_threads_that_pay(256 * MiB, 16) == 16);
  CHECK(check_threads_that_pay(std::size_t{1} << 34, 16) == 16);
  CHECK(check_threads_that_pay(17984536, 2) == 2);
  CHECK(check_threads_that_pay(17984536, 0) == 1);  // hardware_concurrency() may say 0: one thread
  unsigned before = 1;
  for (std::size_t bytes = 1; bytes < (std::size_t{1} << 36); bytes = bytes * 3 / 2 + 1) {
    const unsigned threads = check_threads_that_pay(bytes, 64);
    REQUIRE(threads >= before);
    before = threads;
  }
  CHECK(before == 64);
}

TEST_CASE("index: a full disk mid-save leaves the old file intact, and no temporary file",
          "[index][errors]") {
  TempDir tmp;
  const std::string path = tmp.file("tree.kdx");
  SmallIndex small;
  io::save(path, small.tree);
  const std::vector<unsigned char> before = file_bytes(path);
  const auto big = kdspace_test::make_points<float>(Shape::uniform, 20000, 3, 2);
  const PointTree<float> bigger(big.data(), 20000, 3);

  // A file size limit makes write() fail with EFBIG part way, as a full disk fails with ENOSPC.
  struct rlimit old_limit {};
  REQUIRE(getrlimit(RLIMIT_FSIZE, &old_limit) == 0);
  const auto old_handler = signal(SIGXFSZ, SIG_IGN);
  struct rlimit small_limit = old_limit;
  small_limit.rlim_cur = 100000;
  REQUIRE(setrlimit(RLIMIT_FSIZE, &small_limit) == 0);
  const std::string message = error_message([&] { io::save(path, bigger); });
  setrlimit(RLIMIT_FSIZE, &old_limit);
  signal(SIGXFSZ, old_handler);

  CHECK(message.rfind(path + ": cannot save: writing ", 0) == 0);
  CHECK(message.find("(the old file, if any, is unchanged)") != std::string::npos);
  CHECK(file_bytes(path) == before);
  require_same_answers(io::load_point_tree<float>(path), small.tree, small.queries);
  std::size_t files = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(path).parent_path()))
    files += entry.is_regular_file();
  CHECK(files == 1);
}

TEST_CASE("index: a file of more pieces than one write takes is written whole, in order",
          "[index]") {
  // 1,500 sections of 1 to 97 bytes, each but a few padded to 64 bytes: some 3,000 pieces, more than
  // the 1,024 a writev() call takes.
  TempDir tmp;
  const std::string path = tmp.file("many.kdx");
  io::IndexWriter w(io::IndexKind::point_tree, io::ScalarType::float32, io::MetricId::l2, 3, 0);
  for (std::uint32_t part = 0; part < 1500; ++part) {
    std::vector<unsigned char> values(1 + part % 97);
    for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<unsigned char>(part * 7 + i);
    w.add_values(io::SectionType::ids, part, 1, values);
  }
  w.write(path);
  CHECK(file_bytes(path) == w.bytes());
  const auto file = io::IndexFile::open(path);  // every checksum verified
  REQUIRE(file->info().sections.size() == 1500);
  const io::SectionEntry* last = file->find(io::SectionType::ids, 1499);
  REQUIRE(last);
  CHECK(last->length == 1 + 1499 % 97);
}

TEST_CASE("index: a process killed mid-save leaves the old file intact", "[index][errors]") {
  TempDir tmp;
  const std::string path = tmp.file("tree.kdx");
  SmallIndex small;
  io::save(path, small.tree);
  const std::vector<unsigned char> before = file_bytes(path);
  const auto big = kdspace_test::make_points<float>(Shape::uniform, 20000, 3, 2);
  const PointTree<float> bigger(big.data(), 20000, 3);

  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // The file size limit's signal kills the child part way through the write, like a crash.
    struct rlimit limit {};
    getrlimit(RLIMIT_FSIZE, &limit);
    limit.rlim_cur = 100000;
    setrlimit(RLIMIT_FSIZE, &limit);
    signal(SIGXFSZ, SIG_DFL);
    try {
      io::save(path, bigger);
    } catch (...) {
    }
    _exit(0);  // not reached when the signal kills it
  }
  int status = 0;
  REQUIRE(waitpid(child, &status, 0) == child);
  CHECK(WIFSIGNALED(status));
  CHECK(file_bytes(path) == before);
  require_same_answers(io::load_point_tree<float>(path), small.tree, small.queries);
  // Saving again works, and replaces the file whole.
  io::save(path, bigger);
  REQUIRE(io::load_point_tree<float>(path).size() == 20000);
}

// Where the file is not in the page cache, Linux reads a mapping advised MADV_HUGEPAGE back in 2 MiB
// folios, which later loads map with one entry each (kdspace-index-bench times loads after eviction).
TEST_CASE("index: a mapped load advises huge pages for a file of 2 MiB or more, and answers the same",
          "[index]") {
  TempDir tmp;
  const std::string path = tmp.file("tree.kdx");
  const std::size_t n = 200000;  // 2.4 MB of points, 0.8 MB of order
  const PointTree<float> built = saved_tree(path, Shape::uniform, n, 31);
  REQUIRE(fs::file_size(path) >= (std::size_t{2} << 20));
  const auto mapped = io::load_point_tree<float>(path);
  const auto read = io::load_point_tree<float>(path, io::LoadMode::read);
#if defined(__linux__)
  if (fs::exists("/sys/kernel/mm/transparent_hugepage/enabled")) {
    CHECK(kdspace_test::advised_for_huge_pages(mapped.parts().points.data()));
    CHECK_FALSE(kdspace_test::advised_for_huge_pages(read.parts().points.data()));
  }
#endif
  const auto queries = kdspace_test::make_points<float>(Shape::uniform, 200, 3, 32);
  require_same_answers(mapped, built, queries);
  require_same_answers(read, built, queries);
}

TEST_CASE("index: a mapped tree stays valid when the file is saved over", "[index]") {
  TempDir tmp;
  const std::string path = tmp.file("tree.kdx");
  SmallIndex small;
  io::save(path, small.tree);
  const auto mapped = io::load_point_tree<float>(path);
  const auto other = kdspace_test::make_points<float>(Shape::uniform, 500, 3, 9);
  io::save(path, PointTree<float>(other.data(), 500, 3));
  require_same_answers(mapped, small.tree, small.queries);
  REQUIRE(io::load_point_tree<float>(path).size() == 500);
}
