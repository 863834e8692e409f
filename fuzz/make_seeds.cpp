// kdspace-fuzz-seeds DIR: writes small valid files of every format the fuzz targets read into
// DIR/<target>/, the seed corpus of each target (made by the build, so nothing binary is committed).
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "kdspace/io/index.hpp"
#include "kdspace/io/pairs.hpp"
#include "kdspace/io/scene.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/rays/scene_gen.hpp"

namespace fs = std::filesystem;
namespace io = kdspace::io;

namespace {

fs::path root;

std::string seed(const std::string& target, const std::string& name) {
  fs::create_directories(root / target);
  return (root / target / name).string();
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary) << text;
}

template <class T>
io::Matrix<T> grid(std::size_t rows, std::size_t cols, bool integers) {
  io::Matrix<T> m{rows, cols, {}};
  for (std::size_t i = 0; i < rows * cols; ++i)
    m.data.push_back(integers ? T((i * 37) % 256) : T((double(i) - 7) / 3));
  return m;
}

std::vector<float> points(std::size_t n, std::size_t dim) {
  std::vector<float> p(n * dim);
  std::uint32_t state = 12345;
  for (auto& v : p) v = float((state = state * 1664525u + 1013904223u) >> 8) / float(1 << 24);
  return p;
}

// An index file prefixed by the byte that tells fuzz_index to read it as it is (0) or resealed (1).
void index_seeds(const std::string& name, const std::string& saved) {
  std::ifstream in(saved, std::ios::binary);
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  for (char mode : {'\0', '\1'}) {
    std::ofstream out(seed("index", name + (mode ? "-resealed" : "") + ".bin"), std::ios::binary);
    out.put(mode);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  fs::remove(saved);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: kdspace-fuzz-seeds DIR\n");
    return 2;
  }
  root = argv[1];
  try {
    io::write_points(seed("fvecs", "a.fvecs"), grid<float>(4, 3, false));
    io::write_points(seed("fvecs", "b.fvecs"), grid<float>(1, 7, false));
    io::write_points(seed("ivecs", "a.ivecs"), grid<float>(4, 3, true));
    io::write_points(seed("bvecs", "a.bvecs"), grid<float>(5, 8, true));
    io::write_points(seed("csv", "a.csv"), grid<double>(4, 3, false));
    write_text(seed("csv", "header.csv"), "x, y\n1.5, -2\n3e2,\t4\r\n-inf,nan\n\n");
    io::write_points(seed("npy", "f4.npy"), grid<float>(3, 4, false));
    io::write_points(seed("npy", "f8.npy"), grid<double>(2, 2, false));
    const std::string dict = "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3), }\n";
    std::string v2("\x93NUMPY\x02\x00", 8);
    for (int i = 0; i < 4; ++i) v2 += static_cast<char>((dict.size() >> (8 * i)) & 0xff);
    write_text(seed("npy", "v2-u1.npy"), v2 + dict + "\x01\x02\x03\x04\x05\x06");
    // fuzz_read_part: a first byte (the format: csv fvecs npy bvecs ivecs, plus 5 x (parts - 1)), then
    // a file of that format.
    const char* const read_part_formats[] = {"csv/header.csv", "fvecs/a.fvecs", "npy/f4.npy", "bvecs/a.bvecs",
                                             "ivecs/a.ivecs"};
    for (int format = 0; format < 5; ++format) {
      std::ifstream in(root / read_part_formats[format], std::ios::binary);
      const std::string bytes((std::istreambuf_iterator<char>(in)), {});
      write_text(seed("read_part", std::to_string(format) + ".bin"),
                 std::string(1, char(format + 5 * 2)) + bytes);
    }
    const auto boxes = kdspace::generate_boxes(6, kdspace::SceneKind::clustered, 1);
    io::write_boxes(seed("boxes", "a.boxes"), boxes);
    const auto rays = kdspace::random_rays(5, kdspace::Box3f{{0, 0, 0}, {1, 1, 1}}, 2);
    io::write_rays(seed("rays", "a.rays"), rays);
    io::write_hits(seed("hits", "a.hits"), kdspace::BoxTree(boxes).closest_hit_batch(rays));
    io::write_pairs(seed("pairs", "empty.pairs"), std::vector<kdspace::IndexPair>{});
    io::write_pairs(seed("pairs", "three.pairs"), std::vector<kdspace::IndexPair>{{0, 1}, {0, 2}, {3, 1}});

    const std::string tmp = (root / "saved.kdx").string();
    const auto p3 = points(24, 3);
    kdspace::BuildParams params;
    params.leaf_size = 3;
    io::save(tmp, kdspace::PointTree<float>(p3.data(), 24, 3, params));
    index_seeds("tree", tmp);
    const std::vector<double> p2(p3.begin(), p3.begin() + 40);
    io::save(tmp, kdspace::PointTree<double, kdspace::Dynamic, kdspace::L1>(p2.data(), 20, 2, params));
    index_seeds("tree-double-l1", tmp);
    io::save(tmp, kdspace::PointTree<double, kdspace::Dynamic, kdspace::Minkowski>(p2.data(), 20, 2, params,
                                                                                  kdspace::Minkowski(3)));
    index_seeds("tree-minkowski", tmp);
    kdspace::DynamicPointTree<float> dynamic(3, params, 4);
    for (std::size_t i = 0; i < 24; i += 6) dynamic.insert(p3.data() + i * 3, 6);
    const kdspace::Index gone[] = {1, 7, 20};
    dynamic.remove(gone, 3);
    dynamic.insert(p3.data(), 2);  // waits in the buffer
    io::save(tmp, dynamic);
    index_seeds("dynamic", tmp);
    kdspace::ForestParams forest;
    forest.trees = 2;
    forest.leaf_size = 3;
    const auto p5 = points(20, 5);
    io::save(tmp, kdspace::PointForest<float>(p5.data(), 20, 5, forest));
    index_seeds("forest", tmp);
    std::vector<float> bytes(20 * 4);
    for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = float((i * 53) % 256);
    forest.graph = kdspace::GraphMode::on;  // the graph section too
    forest.graph_degree = 4;
    const kdspace::ForestSearchParams tuned{12, 1, 6};
    io::save(tmp, kdspace::PointForest<float>(bytes.data(), 20, 4, forest), &tuned);
    index_seeds("forest-bytes", tmp);
    io::save(tmp, kdspace::BoxTree(boxes));
    index_seeds("boxes", tmp);
  } catch (const kdspace::Error& e) {
    std::fprintf(stderr, "kdspace-fuzz-seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
