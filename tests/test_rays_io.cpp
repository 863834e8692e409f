// Tests of the ray module's files (kdspace/io/scene.hpp): round trips, and one test per malformed
// file checking that the message names the file, the record and the problem.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/scene.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "support.hpp"

namespace fs = std::filesystem;
using Catch::Contains;
using Catch::StartsWith;
using kdspace::Box3f;
using kdspace::Hit;
using kdspace::Ray;
namespace io = kdspace::io;

namespace {

class TempDir : public kdspace_test::ScratchDir {
 public:
  TempDir() : ScratchDir("kdspace-rays-io-test-") {}
};

/// Writes raw bytes: a uint64 header followed by floats, as a hand-made file.
void write_raw(const std::string& path, std::uint64_t header, const std::vector<float>& values,
               std::size_t extra = 0) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(&header), sizeof header);
  out.write(reinterpret_cast<const char*>(values.data()),
            static_cast<std::streamsize>(values.size() * sizeof(float)));
  for (std::size_t i = 0; i < extra; ++i) out.put('\0');
}

std::vector<float> unit_boxes(std::size_t n) {
  std::vector<float> v(6 * n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) v[6 * i + 3] = v[6 * i + 4] = v[6 * i + 5] = 1;
  return v;
}

bool same_boxes(const std::vector<Box3f>& a, const std::vector<Box3f>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Box3f)) == 0;
}

}  // namespace

TEST_CASE("rays io: boxes, rays and hits round-trip bit for bit", "[rays][io]") {
  TempDir dir;
  const std::vector<Box3f> boxes = kdspace::generate_boxes(1000, kdspace::SceneKind::clustered, 1);
  io::write_boxes(dir.file("scene.boxes"), boxes);
  CHECK(same_boxes(io::read_boxes(dir.file("scene.boxes")), boxes));
  CHECK(fs::file_size(dir.file("scene.boxes")) == 8 + 24 * boxes.size());

  std::vector<Ray> rays = kdspace::random_rays(500, kdspace::BoxTree(boxes).bounds(), 2);
  rays[3].direction = {-0.0f, 0.0f, 1.0f};  // signed zeros survive
  io::write_rays(dir.file("cam.rays"), rays);
  const std::vector<Ray> rays_back = io::read_rays(dir.file("cam.rays"));
  REQUIRE(rays_back.size() == rays.size());
  CHECK(std::memcmp(rays_back.data(), rays.data(), rays.size() * sizeof(Ray)) == 0);
  CHECK(std::signbit(rays_back[3].direction[0]));

  const std::vector<Hit> hits = kdspace::BoxTree(boxes).closest_hit_batch(rays);
  io::write_hits(dir.file("out.hits"), hits);
  const std::vector<Hit> hits_back = io::read_hits(dir.file("out.hits"));
  REQUIRE(hits_back.size() == hits.size());
  for (std::size_t i = 0; i < hits.size(); ++i) {
    CHECK(hits_back[i].box == hits[i].box);
    CHECK(std::memcmp(&hits_back[i].t, &hits[i].t, sizeof(float)) == 0);
  }
  CHECK(fs::file_size(dir.file("out.hits")) == 8 + 8 * hits.size());
}

TEST_CASE("rays io: a miss is stored as box -1 and t = +inf", "[rays][io]") {
  TempDir dir;
  io::write_hits(dir.file("h.hits"), std::vector<Hit>{Hit{}, Hit{4, 2.5f}});
  std::ifstream in(dir.file("h.hits"), std::ios::binary);
  char bytes[24];
  in.read(bytes, 24);
  std::uint64_t count;
  std::int32_t box;
  float t;
  std::memcpy(&count, bytes, 8);
  std::memcpy(&box, bytes + 8, 4);
  std::memcpy(&t, bytes + 12, 4);
  CHECK(count == 2);
  CHECK(box == -1);
  CHECK(std::isinf(t));
  std::memcpy(&box, bytes + 16, 4);
  std::memcpy(&t, bytes + 20, 4);
  CHECK(box == 4);
  CHECK(t == 2.5f);
}

TEST_CASE("rays io: files with a count of zero are valid and empty", "[rays][io]") {
  TempDir dir;
  io::write_boxes(dir.file("none.boxes"), std::vector<Box3f>{});
  io::write_rays(dir.file("none.rays"), std::vector<Ray>{});
  io::write_hits(dir.file("none.hits"), std::vector<Hit>{});
  CHECK(io::read_boxes(dir.file("none.boxes")).empty());
  CHECK(io::read_rays(dir.file("none.rays")).empty());
  CHECK(io::read_hits(dir.file("none.hits")).empty());
}

TEST_CASE("rays io: an empty file is an error", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("empty.boxes");
  std::ofstream(path).close();
  CHECK_THROWS_WITH(io::read_boxes(path), path + ": empty file: expected a uint64 count of boxes");
  CHECK_THROWS_WITH(io::read_rays(path), StartsWith(path + ": empty file"));
  CHECK_THROWS_WITH(io::read_hits(path), StartsWith(path + ": empty file"));
}

TEST_CASE("rays io: a header cut short is an error", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("short.boxes");
  std::ofstream(path, std::ios::binary).write("\x01\x00\x00", 3);
  CHECK_THROWS_WITH(io::read_boxes(path), path + ": truncated header: 3 bytes, expected 8");
}

TEST_CASE("rays io: a truncated file is an error naming both sizes", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("cut.boxes");
  write_raw(path, 100, unit_boxes(41));
  CHECK_THROWS_WITH(io::read_boxes(path), path +
                                              ": truncated: header says 100 boxes (2408 bytes), file has " +
                                              std::to_string(8 + 41 * 24) + " bytes");
  std::vector<float> part = unit_boxes(2);
  part.pop_back();  // a record cut in the middle
  write_raw(path, 2, part);
  CHECK_THROWS_WITH(io::read_boxes(path), StartsWith(path + ": truncated: header says 2 boxes"));
}

TEST_CASE("rays io: a header claiming an absurd count fails before allocating", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("huge.rays");
  write_raw(path, std::uint64_t{1} << 62, unit_boxes(1));
  CHECK_THROWS_WITH(io::read_rays(path),
                    StartsWith(path + ": truncated: header says 4611686018427387904 rays"));
  write_raw(path, std::numeric_limits<std::uint64_t>::max(), unit_boxes(1));
  CHECK_THROWS_WITH(io::read_rays(path), Contains("(too many)"));
}

TEST_CASE("rays io: trailing bytes after the records are an error", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("long.boxes");
  write_raw(path, 2, unit_boxes(3));
  CHECK_THROWS_WITH(
      io::read_boxes(path),
      path + ": oversized: header says 2 boxes (56 bytes), file has 80 bytes (24 bytes too many)");
  write_raw(path, 1, unit_boxes(1), 5);
  CHECK_THROWS_WITH(io::read_boxes(path), Contains("(5 bytes too many)"));
}

TEST_CASE("rays io: a box with min > max names the box, 1-based, and the axis", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("bad.boxes");
  std::vector<float> v = unit_boxes(20);
  v[11 * 6 + 0] = 3;  // box 12: min x 3, max x 1
  write_raw(path, 20, v);
  CHECK_THROWS_WITH(io::read_boxes(path), path + ": box 12: min x 3 > max x 1");
}

TEST_CASE("rays io: non-finite coordinates name the record and the coordinate", "[rays][io]") {
  TempDir dir;
  const std::string boxes = dir.file("nan.boxes");
  std::vector<float> v = unit_boxes(5);
  v[2 * 6 + 4] = std::numeric_limits<float>::quiet_NaN();
  write_raw(boxes, 5, v);
  CHECK_THROWS_WITH(io::read_boxes(boxes), boxes + ": box 3: max y is nan");
  v[2 * 6 + 4] = -std::numeric_limits<float>::infinity();
  write_raw(boxes, 5, v);
  CHECK_THROWS_WITH(io::read_boxes(boxes), boxes + ": box 3: max y is -inf");

  const std::string rays = dir.file("nan.rays");
  std::vector<float> r{0, 0, 0, 1, 0, 0, 0, std::numeric_limits<float>::infinity(), 0, 1, 0, 0};
  write_raw(rays, 2, r);
  CHECK_THROWS_WITH(io::read_rays(rays), rays + ": ray 2: origin y is inf");
}

TEST_CASE("rays io: a zero direction names the ray", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("zero.rays");
  write_raw(path, 3, {0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 1, 5, 5, 5, -0.0f, 0, -0.0f});
  CHECK_THROWS_WITH(io::read_rays(path), path + ": ray 3: direction is zero");
}

TEST_CASE("rays io: a hit with a box index below -1 is an error", "[rays][io]") {
  TempDir dir;
  const std::string path = dir.file("bad.hits");
  io::write_hits(path, std::vector<Hit>{Hit{0, 1}, Hit{-7, 1}});
  CHECK_THROWS_WITH(io::read_hits(path), path + ": hit 2: box index -7 is negative");
}

TEST_CASE("rays io: missing files, directories and unwritable paths are errors naming the path",
          "[rays][io]") {
  TempDir dir;
  const std::string missing = dir.file("missing.boxes");
  CHECK_THROWS_WITH(io::read_boxes(missing), StartsWith(missing + ": cannot open"));
  fs::create_directories(dir.file("folder.boxes"));
  CHECK_THROWS_WITH(io::read_boxes(dir.file("folder.boxes")), dir.file("folder.boxes") + ": is a directory");
  const std::string unwritable = dir.file("no/such/dir/out.hits");
  CHECK_THROWS_WITH(io::write_hits(unwritable, std::vector<Hit>{Hit{}}),
                    StartsWith(unwritable + ": cannot open"));
}
