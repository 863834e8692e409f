// Reading and writing the files of the ray module: .boxes, .rays and .hits (little-endian).
//
//   .boxes  uint64 N, then N records of 6 float32: min x, min y, min z, max x, max y, max z
//   .rays   uint64 M, then M records of 6 float32: origin x y z, direction x y z
//   .hits   uint64 M, then M records of int32 box index (-1 for a miss) and float32 t (+inf for a miss)
//
// The readers check the header against the file size before allocating anything, then every record.
// Every problem throws kdspace::Error whose message starts with the path and, for a bad record, its
// 1-based position: "scene.boxes: box 12: min x 3 > max x 1", "cam.rays: ray 5: direction is zero",
// "scene.boxes: truncated: header says 100 boxes (2408 bytes), file has 1000 bytes".
// A file of zero bytes is an error; a header with count 0 is a valid, empty file.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace::io {

/// Boxes with finite coordinates and min <= max on every axis.
std::vector<Box3f> read_boxes(const std::string& path);
/// Rays with finite coordinates and non-zero directions.
std::vector<Ray> read_rays(const std::string& path);
/// Hits with box index >= -1 (t is not checked).
std::vector<Hit> read_hits(const std::string& path);

/// The writers store what they are given, unchecked (so that tests can make bad files), atomically:
/// into a temporary file in the same folder, renamed to `path` once complete.
void write_boxes(const std::string& path, const Box3f* boxes, std::size_t n);
void write_boxes(const std::string& path, const std::vector<Box3f>& boxes);
void write_rays(const std::string& path, const Ray* rays, std::size_t n);
void write_rays(const std::string& path, const std::vector<Ray>& rays);
void write_hits(const std::string& path, const Hit* hits, std::size_t n);
void write_hits(const std::string& path, const std::vector<Hit>& hits);

}  // namespace kdspace::io
