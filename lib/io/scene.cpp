// The files of the ray module: .boxes, .rays, .hits (see kdspace/io/scene.hpp).
#include "kdspace/io/scene.hpp"

#include <string>

#include "kdspace/error.hpp"
#include "record_file.hpp"

namespace kdspace::io {
namespace {

static_assert(sizeof(Box3f) == 24 && sizeof(Ray) == 24,
              "a box and a ray are 6 packed floats, as in the files");

using detail::fail;
using detail::read_records;
using detail::write_records;

}  // namespace

std::vector<Box3f> read_boxes(const std::string& path) {
  std::vector<Box3f> boxes = read_records<Box3f>(path, "boxes");
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const std::string problem = box_problem(boxes[i]);
    if (!problem.empty()) fail(path, "box " + std::to_string(i + 1) + ": " + problem);
  }
  return boxes;
}

std::vector<Ray> read_rays(const std::string& path) {
  std::vector<Ray> rays = read_records<Ray>(path, "rays");
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const std::string problem = ray_problem(rays[i]);
    if (!problem.empty()) fail(path, "ray " + std::to_string(i + 1) + ": " + problem);
  }
  return rays;
}

std::vector<Hit> read_hits(const std::string& path) {
  static_assert(sizeof(Hit) == 8, "a hit is int32 + float32, as in the file");
  std::vector<Hit> hits = read_records<Hit>(path, "hits");
  for (std::size_t i = 0; i < hits.size(); ++i)
    if (hits[i].box < Hit::none)
      fail(path,
           "hit " + std::to_string(i + 1) + ": box index " + std::to_string(hits[i].box) + " is negative");
  return hits;
}

void write_boxes(const std::string& path, const Box3f* boxes, std::size_t n) {
  write_records(path, boxes, n);
}
void write_boxes(const std::string& path, const std::vector<Box3f>& boxes) {
  write_records(path, boxes.data(), boxes.size());
}
void write_rays(const std::string& path, const Ray* rays, std::size_t n) {
  write_records(path, rays, n);
}
void write_rays(const std::string& path, const std::vector<Ray>& rays) {
  write_records(path, rays.data(), rays.size());
}
void write_hits(const std::string& path, const Hit* hits, std::size_t n) {
  write_records(path, hits, n);
}
void write_hits(const std::string& path, const std::vector<Hit>& hits) {
  write_records(path, hits.data(), hits.size());
}

}  // namespace kdspace::io
