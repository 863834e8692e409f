// Tests of the benchmarks' reader of real scans and meshes (bench/real_data/mesh_io.hpp): each
// format read from a small hand-made file, and bad files giving an Error that says where.
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "../bench/real_data/mesh_io.hpp"
#include "support.hpp"

using Catch::Contains;
using kdspace::bench::Mesh;
using kdspace::bench::read_mesh;

namespace {

class TempDir : public kdspace_test::ScratchDir {
 public:
  TempDir() : ScratchDir("kdspace-mesh-io-test-") {}
};

std::string write(const TempDir& dir, const std::string& name, const std::string& bytes) {
  const std::string path = dir.file(name);
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

template <class V>
void append(std::string& bytes, V value) {
  char raw[sizeof value];
  std::memcpy(raw, &value, sizeof value);
  bytes.append(raw, sizeof value);
}

std::string error_of(const std::string& path) {
  try {
    read_mesh(path);
  } catch (const kdspace::Error& e) {
    return e.what();
  }
  FAIL_CHECK("no kdspace::Error for " << path);
  return "";
}

using Vertices = std::vector<std::array<float, 3>>;
using Triangles = std::vector<std::array<std::uint32_t, 3>>;

}  // namespace

TEST_CASE("mesh_io reads OFF: comments, counts on the keyword line, colours, polygons fanned", "[io][mesh]") {
  TempDir dir;
  const std::string path = write(dir, "quad.off",
                                 "COFF 4 1 0  # a quad\n"
                                 "0 0 0 255 0 0\n1 0 0\n\n1 1 0\n0 1 0.5\n"
                                 "4 0 1 2 3  10 20 30\n");
  const Mesh mesh = read_mesh(path);
  CHECK(mesh.name == "quad");
  CHECK(mesh.vertices == Vertices{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.5f}});
  CHECK(mesh.triangles == Triangles{{0, 1, 2}, {0, 2, 3}});
}

TEST_CASE("mesh_io reads ascii PLY with extra properties and elements", "[io][mesh]") {
  TempDir dir;
  const std::string path =
      write(dir, "t.PLY",
            "ply\nformat ascii 1.0\ncomment made by hand\n"
            "element vertex 3\nproperty float y\nproperty float x\nproperty uchar red\n"
            "property double z\n"
            "element face 1\nproperty list uchar int vertex_indices\nproperty int flags\n"
            "element edge 1\nproperty int a\nproperty int b\nend_header\n"
            "1 2 7 3\n4 5 7 6\n-1 -2 7 -3e0\n3 2 1 0 9\n0 1\n");
  const Mesh mesh = read_mesh(path);
  CHECK(mesh.vertices == Vertices{{2, 1, 3}, {5, 4, 6}, {-2, -1, -3}});
  CHECK(mesh.triangles == Triangles{{2, 1, 0}});
}

TEST_CASE("mesh_io reads binary little-endian PLY with double coordinates and int lists", "[io][mesh]") {
  TempDir dir;
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\n"
      "property double z\nproperty int label\nelement face 1\nproperty list uchar uint "
      "vertex_index\nend_header\n";
  for (int v = 0; v < 4; ++v) {
    append(bytes, 0.5 * v);
    append(bytes, -1.0 * v);
    append(bytes, 596648.0625);
    append(bytes, std::int32_t{v});
  }
  append(bytes, std::uint8_t{4});
  for (std::uint32_t v : {3u, 2u, 1u, 0u}) append(bytes, v);
  const Mesh mesh = read_mesh(write(dir, "b.ply", bytes));
  CHECK(mesh.vertices ==
        Vertices{
            {0, 0, 596648.0625f}, {0.5f, -1, 596648.0625f}, {1, -2, 596648.0625f}, {1.5f, -3, 596648.0625f}});
  CHECK(mesh.triangles == Triangles{{3, 2, 1}, {3, 1, 0}});

  SECTION("a file that ends inside the data names the byte") {
    const std::string cut = write(dir, "cut.ply", bytes.substr(0, bytes.size() - 3));
    CHECK_THAT(error_of(cut), Contains(cut + ": byte") && Contains("ends inside the data"));
  }
  SECTION("a count larger than the file is refused before reading") {
    std::string lie = bytes;
    lie.replace(lie.find("vertex 4"), 8, "vertex 400000000");
    CHECK_THAT(error_of(write(dir, "lie.ply", lie)), Contains("more than the file can hold"));
  }
}

TEST_CASE("mesh_io reads points from .xyz and .pts, skipping a count line", "[io][mesh]") {
  TempDir dir;
  const Mesh xyz = read_mesh(write(dir, "s.xyz", "1 2 3 0 0 1\n# comment\n4 5 6 0 1 0\n"));
  CHECK(xyz.vertices == Vertices{{1, 2, 3}, {4, 5, 6}});
  CHECK(xyz.triangles.empty());
  const Mesh pts = read_mesh(write(dir, "s.pts", "2\n1 2 3 100 7 7 7\n4 5 +6 100 7 7 7\n"));
  CHECK(pts.vertices == Vertices{{1, 2, 3}, {4, 5, 6}});
}

TEST_CASE("mesh_io reads binary and ascii STL, merging shared corners", "[io][mesh]") {
  TempDir dir;
  const float corners[2][3][3] = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{1, 0, 0}, {1, 1, 0}, {0, 1, 0}}};
  std::string bytes = "solid but binary";  // binary files may start with "solid" too
  bytes.resize(80, ' ');
  append(bytes, std::uint32_t{2});
  for (const auto& triangle : corners) {
    for (int i = 0; i < 3; ++i) append(bytes, 0.0f);  // normal
    for (const auto& corner : triangle)
      for (float c : corner) append(bytes, c);
    append(bytes, std::uint16_t{0});
  }
  const Vertices vertices{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  const Triangles triangles{{0, 1, 2}, {1, 3, 2}};
  const Mesh binary = read_mesh(write(dir, "b.stl", bytes));
  CHECK(binary.vertices == vertices);
  CHECK(binary.triangles == triangles);

  std::string text = "solid square\n";
  for (const auto& triangle : corners) {
    text += "facet normal 0 0 1\n outer loop\n";
    for (const auto& corner : triangle)
      text += "  vertex " + std::to_string(corner[0]) + " " + std::to_string(corner[1]) + " " +
              std::to_string(corner[2]) + "\n";
    text += " endloop\nendfacet\n";
  }
  text += "endsolid square\n";
  const Mesh ascii = read_mesh(write(dir, "a.stl", text));
  CHECK(ascii.vertices == vertices);
  CHECK(ascii.triangles == triangles);
}

TEST_CASE("mesh_io reads uncompressed LAS points relative to the header's offset", "[io][mesh]") {
  TempDir dir;
  std::string bytes(227, '\0');
  std::memcpy(&bytes[0], "LASF", 4);
  bytes[24] = 1;
  bytes[25] = 2;
  const auto put = [&bytes](std::size_t at, auto value) { std::memcpy(&bytes[at], &value, sizeof value); };
  put(96, std::uint32_t{227});  // point data offset
  bytes[104] = 0;               // point format 0
  put(105, std::uint16_t{20});  // record length
  put(107, std::uint32_t{2});   // points
  put(131, 0.01);
  put(139, 0.01);
  put(147, 0.5);
  put(155, 548875.0);  // offsets: not added
  for (std::int32_t p = 0; p < 2; ++p) {
    std::string record(20, '\0');
    const std::int32_t xyz[3] = {100 * (p + 1), -50, 3};
    std::memcpy(&record[0], xyz, sizeof xyz);
    bytes += record;
  }
  const Mesh mesh = read_mesh(write(dir, "tile.las", bytes));
  CHECK(mesh.vertices == Vertices{{1, -0.5f, 1.5f}, {2, -0.5f, 1.5f}});

  put(107, std::uint32_t{3});
  CHECK_THAT(error_of(write(dir, "short.las", bytes)), Contains("point count 3 is more than the file holds"));
}

TEST_CASE("mesh_io errors name the file and the row", "[io][mesh]") {
  TempDir dir;
  const std::string bad_index = write(dir, "i.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  CHECK_THAT(error_of(bad_index), Contains(bad_index + ": row 6: bad vertex index '3'"));
  const std::string short_off = write(dir, "s.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n");
  CHECK_THAT(error_of(short_off), Contains("file ends after 2 of 3 vertices"));
  const std::string nan = write(dir, "n.xyz", "1 2 3\n1 nan 3\n");
  CHECK_THAT(error_of(nan), Contains(nan + ": row 2: bad y 'nan'"));
  const std::string huge = write(dir, "h.xyz", "1 2 1e300\n");
  CHECK_THAT(error_of(huge), Contains(huge + ": row 1: coordinate beyond float range"));
  const std::string two = write(dir, "t.xyz", "1 2 3\n1 2\n");
  CHECK_THAT(error_of(two), Contains(two + ": row 2: a point needs x y z"));
  const std::string ply =
      write(dir, "p.ply",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n");
  CHECK_THAT(error_of(ply), Contains("no x, y and z"));
  const std::string big_endian = write(dir, "e.ply", "ply\nformat binary_big_endian 1.0\nend_header\n");
  CHECK_THAT(error_of(big_endian), Contains(big_endian + ": row 2: unsupported PLY format"));
  const std::string extra = write(dir, "x.ply",
                                  "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float "
                                  "y\nproperty float z\nend_header\n1 2 3 4\n");
  CHECK_THAT(error_of(extra), Contains(extra + ": row 8: more values than the header declares"));
  const std::string stl = write(dir, "x.stl", "not an stl");
  CHECK_THAT(error_of(stl), Contains("neither a binary STL"));
  CHECK_THAT(error_of(write(dir, "x.obj", "v 0 0 0\n")), Contains("unknown mesh format '.obj'"));
  CHECK_THAT(error_of(dir.file("missing.off")), Contains("cannot open"));
}

TEST_CASE("read_real_meshes reads the files its list names", "[io][mesh]") {
  TempDir dir;
  write(dir, "a.xyz", "0 0 0\n1 1 1\n");
  write(dir, "b.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  write(dir, "real_data.txt", "# list\na.xyz\n\nb.off  # a mesh\n");
  const std::vector<Mesh> meshes = kdspace::bench::read_real_meshes(dir.file(""));
  REQUIRE(meshes.size() == 2);
  CHECK(meshes[0].name == "a");
  CHECK(meshes[1].triangles.size() == 1);
}
