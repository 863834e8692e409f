// The files of the ray module: .boxes, .rays, .hits (see kdspace/io/scene.hpp).
#include "kdspace/io/scene.hpp"

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <system_error>

#include "kdspace/error.hpp"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "kdspace's scene file I/O copies little-endian file data straight into memory"
#endif

namespace kdspace::io {
namespace {

static_assert(sizeof(Box3f) == 24 && sizeof(Ray) == 24,
              "a box and a ray are 6 packed floats, as in the files");

constexpr std::uint64_t header_bytes = 8;

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw Error(path + ": " + what);
}

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

/// The record count of a file of `record_bytes`-byte records, checked against the file's size.
/// `noun` names a record in messages ("boxes").
std::uint64_t open_and_count(const std::string& path, File& file, std::uint64_t record_bytes,
                             const char* noun) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory");
  file.reset(std::fopen(path.c_str(), "rb"));
  if (!file) fail(path, std::string("cannot open: ") + std::strerror(errno));
  if (std::fseek(file.get(), 0, SEEK_END) != 0) fail(path, "cannot seek (not a regular file?)");
  const long end = std::ftell(file.get());
  if (end < 0) fail(path, "cannot tell the file size (not a regular file?)");
  std::rewind(file.get());
  const auto size = static_cast<std::uint64_t>(end);
  if (size == 0) fail(path, std::string("empty file: expected a uint64 count of ") + noun);
  if (size < header_bytes)
    fail(path,
         "truncated header: " + std::to_string(size) + " bytes, expected " + std::to_string(header_bytes));
  unsigned char head[header_bytes];
  if (std::fread(head, 1, header_bytes, file.get()) != header_bytes) fail(path, "read error in the header");
  std::uint64_t count = 0;
  std::memcpy(&count, head, sizeof count);
  const std::uint64_t payload = size - header_bytes;
  // Compare by division first: count * record_bytes may overflow for a corrupt header.
  if (count > payload / record_bytes || count * record_bytes != payload) {
    const bool fits = count <= (std::numeric_limits<std::uint64_t>::max() - header_bytes) / record_bytes;
    const std::string expected = fits ? " (" + std::to_string(header_bytes + count * record_bytes) + " bytes)"
                                      : std::string(" (too many)");
    const std::string says = "header says " + std::to_string(count) + " " + noun + expected + ", file has " +
                             std::to_string(size) + " bytes";
    if (count > payload / record_bytes) fail(path, "truncated: " + says);
    fail(path,
         "oversized: " + says + " (" + std::to_string(payload - count * record_bytes) + " bytes too many)");
  }
  if (count > std::numeric_limits<std::size_t>::max() / record_bytes) fail(path, "file too large");
  return count;
}

template <class Record>
std::vector<Record> read_records(const std::string& path, const char* noun) {
  File file;
  const std::uint64_t count = open_and_count(path, file, sizeof(Record), noun);
  std::vector<Record> records(static_cast<std::size_t>(count));
  if (count > 0 && std::fread(records.data(), sizeof(Record), records.size(), file.get()) != records.size())
    fail(path, "read error");
  return records;
}

template <class Record>
void write_records(const std::string& path, const Record* records, std::size_t n) {
  if (n > 0 && records == nullptr) fail(path, "nothing to write: null pointer");
  File file(std::fopen(path.c_str(), "wb"));
  if (!file) fail(path, std::string("cannot open for writing: ") + std::strerror(errno));
  const std::uint64_t count = n;
  unsigned char head[header_bytes];
  std::memcpy(head, &count, sizeof count);
  bool ok = std::fwrite(head, 1, header_bytes, file.get()) == header_bytes;
  if (ok && n > 0) ok = std::fwrite(records, sizeof(Record), n, file.get()) == n;
  std::FILE* raw = file.release();
  if (std::fclose(raw) != 0) ok = false;
  if (!ok) fail(path, std::string("write error: ") + std::strerror(errno));
}

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
