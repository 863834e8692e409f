// The boxes of the faces of a mesh in OFF format (Object File Format, as CGAL's example meshes are
// stored): one box per face, the bounds of its vertices. For kdspace-collide-bench.
#pragma once

#include <algorithm>
#include <cstddef>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "kdspace/box.hpp"

namespace bench {

/// Reads an OFF file ("OFF", then "vertices faces edges", the vertices, then each face as "k i1 ..
/// ik"); throws std::runtime_error naming the file and what is wrong.
inline std::vector<kdspace::Box3f> read_off_face_boxes(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  // The words of the file without comments.
  std::stringstream words;
  for (std::string line; std::getline(in, line);) words << line.substr(0, line.find('#')) << '\n';
  std::string magic;
  words >> magic;
  if (magic != "OFF") throw std::runtime_error(path + ": not an OFF file (first word '" + magic + "')");
  std::size_t vertices = 0, faces = 0, edges = 0;
  if (!(words >> vertices >> faces >> edges)) throw std::runtime_error(path + ": bad counts line");
  std::vector<float> xyz(3 * vertices);
  for (float& v : xyz)
    if (!(words >> v)) throw std::runtime_error(path + ": truncated vertex list");
  std::vector<kdspace::Box3f> boxes;
  boxes.reserve(faces);
  for (std::size_t f = 0; f < faces; ++f) {
    std::size_t k = 0;
    if (!(words >> k) || k == 0) throw std::runtime_error(path + ": bad face " + std::to_string(f + 1));
    kdspace::Box3f box;
    for (std::size_t j = 0; j < k; ++j) {
      std::size_t v = 0;
      if (!(words >> v) || v >= vertices)
        throw std::runtime_error(path + ": face " + std::to_string(f + 1) + ": bad vertex index");
      for (int a = 0; a < 3; ++a) {
        const float c = xyz[3 * v + static_cast<std::size_t>(a)];
        box.lo[a] = j == 0 ? c : std::min(box.lo[a], c);
        box.hi[a] = j == 0 ? c : std::max(box.hi[a], c);
      }
    }
    boxes.push_back(box);
    std::string rest;
    std::getline(words, rest);  // colours, if any
  }
  return boxes;
}

}  // namespace bench
