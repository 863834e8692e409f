// Readers of real 3-D scans and meshes for the benchmarks: .off, .ply (ascii and binary
// little-endian), .xyz/.pts/.pwn (points), .stl (binary and ascii) and .las (uncompressed LIDAR).
//
// The data come from Debian packages that bench/real_data/fetch.sh downloads and unpacks (CGAL's
// demo data, assimp's test models); read_real_meshes() reads what fetch.sh listed. Header only, so
// a bench or a test includes it without linking anything but the kdspace library (for Error).
//
// Every malformed file gives a kdspace::Error naming the file and where: "FILE: row R: ..." in a
// text file (R counts lines from 1), "FILE: byte B: ..." in a binary one. Nothing reads past the
// end of the file, and no count read from a header is trusted before the file's size is checked.
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <kdspace/error.hpp>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace kdspace::bench {

/// A triangle mesh, or a point set when `triangles` is empty (scans: .xyz, .pts, .las, PLY without
/// faces). Polygons are fanned into triangles (v0, vi, vi+1); indices refer to `vertices`.
struct Mesh {
  std::string name;  // the file's name without folder and extension
  std::vector<std::array<float, 3>> vertices;
  std::vector<std::array<std::uint32_t, 3>> triangles;
};

namespace mesh_io_detail {

[[noreturn]] inline void fail_row(const std::string& path, std::size_t row, const std::string& what) {
  throw Error(path + ": row " + std::to_string(row) + ": " + what);
}
[[noreturn]] inline void fail_byte(const std::string& path, std::size_t byte, const std::string& what) {
  throw Error(path + ": byte " + std::to_string(byte) + ": " + what);
}

inline std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (in.bad()) throw Error(path + ": read error");
  return bytes.str();
}

inline std::string lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

inline std::string extension_of(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return lower(path.substr(dot + 1));
}

inline std::string stem_of(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
  const std::size_t dot = name.find_last_of('.');
  return dot == std::string::npos || dot == 0 ? name : name.substr(0, dot);
}

/// Lines of a text file, with their numbers, split into whitespace-separated tokens on demand.
class TextLines {
 public:
  TextLines(const std::string& path, std::string_view text) : path_(path), text_(text) {}

  /// The next line that holds something other than blanks or a '#' comment; false at the end.
  bool next(std::string_view& line) {
    while (pos_ < text_.size()) {
      const std::size_t end = std::min(text_.find('\n', pos_), text_.size());
      line = text_.substr(pos_, end - pos_);
      pos_ = end + 1;
      ++row_;
      const std::size_t hash = line.find('#');
      if (hash != std::string_view::npos) line = line.substr(0, hash);
      if (line.find_first_not_of(" \t\r\f\v") != std::string_view::npos) return true;
    }
    return false;
  }
  std::size_t row() const { return row_; }
  const std::string& path() const { return path_; }
  std::size_t offset() const { return std::min(pos_, text_.size()); }

 private:
  const std::string& path_;
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t row_ = 0;
};

inline std::vector<std::string_view> tokens_of(std::string_view line) {
  std::vector<std::string_view> tokens;
  std::size_t pos = 0;
  while (true) {
    pos = line.find_first_not_of(" \t\r\f\v", pos);
    if (pos == std::string_view::npos) break;
    std::size_t end = line.find_first_of(" \t\r\f\v", pos);
    if (end == std::string_view::npos) end = line.size();
    tokens.push_back(line.substr(pos, end - pos));
    pos = end;
  }
  return tokens;
}

/// A finite number, or false. Accepts a leading '+', which std::from_chars does not.
inline bool parse_double(std::string_view token, double& value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto result = std::from_chars(token.data(), end, value);
  return result.ec == std::errc() && result.ptr == end && std::isfinite(value);
}

inline double number_at(const TextLines& lines, std::string_view token, const char* what) {
  double value = 0;
  if (!parse_double(token, value))
    fail_row(lines.path(), lines.row(), std::string("bad ") + what + " '" + std::string(token) + "'");
  return value;
}

/// A non-negative integer below `limit`, or an error naming what it is.
inline std::uint64_t count_at(const TextLines& lines, std::string_view token, const char* what,
                              std::uint64_t limit) {
  std::uint64_t value = 0;
  const char* end = token.data() + token.size();
  const auto result = std::from_chars(token.data(), end, value);
  if (result.ec != std::errc() || result.ptr != end || value >= limit)
    fail_row(lines.path(), lines.row(), std::string("bad ") + what + " '" + std::string(token) + "'");
  return value;
}

/// A coordinate as float; a value beyond float's range is an error, not an infinity.
inline float to_float_coordinate(double value, bool& ok) {
  ok = std::isfinite(value) && std::fabs(value) <= static_cast<double>(std::numeric_limits<float>::max());
  return static_cast<float>(value);
}

inline std::array<float, 3> point_at(const TextLines& lines, std::string_view x, std::string_view y,
                                     std::string_view z) {
  const double xyz[3] = {number_at(lines, x, "x"), number_at(lines, y, "y"), number_at(lines, z, "z")};
  std::array<float, 3> point{};
  for (int axis = 0; axis < 3; ++axis) {
    bool ok = true;
    point[axis] = to_float_coordinate(xyz[axis], ok);
    if (!ok) fail_row(lines.path(), lines.row(), "coordinate beyond float range");
  }
  return point;
}

/// Fans polygon (indices[0], indices[i], indices[i+1]) into `triangles`.
inline void fan(const std::vector<std::uint32_t>& polygon,
                std::vector<std::array<std::uint32_t, 3>>& triangles) {
  for (std::size_t i = 1; i + 1 < polygon.size(); ++i)
    triangles.push_back({polygon[0], polygon[i], polygon[i + 1]});
}

// Counts in headers must fit in memory before anything is allocated; a text vertex takes at
// least 6 bytes ("0 0 0\n"), a face at least 8, so a count above the file size is a lie.
inline void check_count_fits(const TextLines& lines, std::uint64_t count, std::size_t bytes_each,
                             std::size_t file_size, const char* what) {
  if (count > file_size / bytes_each)
    fail_row(lines.path(), lines.row(),
             std::string(what) + " count " + std::to_string(count) + " is more than the file can hold");
}

// ---- OFF ---------------------------------------------------------------------------------------
// "OFF" (or COFF, NOFF, ... any keyword ending in OFF), "nv nf ne", nv vertex lines (x y z, then
// anything: colours, normals), nf face lines "n i0 ... i(n-1) [colour]".
inline Mesh read_off(const std::string& path, const std::string& text) {
  TextLines lines(path, text);
  std::string_view line;
  if (!lines.next(line)) throw Error(path + ": empty file, expected an OFF header");
  std::vector<std::string_view> tokens = tokens_of(line);
  const std::string keyword(tokens.front());
  if (keyword.size() < 3 || keyword.compare(keyword.size() - 3, 3, "OFF") != 0 ||
      keyword.find("4") != std::string::npos)
    fail_row(path, lines.row(), "expected the keyword OFF, found '" + keyword + "'");
  tokens.erase(tokens.begin());
  if (tokens.empty()) {
    if (!lines.next(line)) fail_row(path, lines.row(), "missing the vertex and face counts");
    tokens = tokens_of(line);
  }
  if (tokens.size() < 2) fail_row(path, lines.row(), "expected 'vertices faces edges'");
  const std::uint64_t limit = std::numeric_limits<std::uint32_t>::max();
  const std::uint64_t vertex_count = count_at(lines, tokens[0], "vertex count", limit);
  const std::uint64_t face_count = count_at(lines, tokens[1], "face count", limit);
  check_count_fits(lines, vertex_count, 6, text.size(), "vertex");
  check_count_fits(lines, face_count, 8, text.size(), "face");

  Mesh mesh;
  mesh.vertices.reserve(vertex_count);
  for (std::uint64_t v = 0; v < vertex_count; ++v) {
    if (!lines.next(line))
      fail_row(path, lines.row(),
               "file ends after " + std::to_string(v) + " of " + std::to_string(vertex_count) + " vertices");
    tokens = tokens_of(line);
    if (tokens.size() < 3) fail_row(path, lines.row(), "a vertex needs x y z");
    mesh.vertices.push_back(point_at(lines, tokens[0], tokens[1], tokens[2]));
  }
  std::vector<std::uint32_t> polygon;
  for (std::uint64_t f = 0; f < face_count; ++f) {
    if (!lines.next(line))
      fail_row(path, lines.row(),
               "file ends after " + std::to_string(f) + " of " + std::to_string(face_count) + " faces");
    tokens = tokens_of(line);
    const std::uint64_t corners = count_at(lines, tokens[0], "face size", tokens.size());
    if (corners < 3) fail_row(path, lines.row(), "a face needs at least 3 vertices");
    polygon.clear();
    for (std::uint64_t c = 1; c <= corners; ++c)
      polygon.push_back(static_cast<std::uint32_t>(count_at(lines, tokens[c], "vertex index", vertex_count)));
    fan(polygon, mesh.triangles);
  }
  return mesh;
}

// ---- XYZ / PTS ---------------------------------------------------------------------------------
// One point a line: x y z, then anything (normals, colours, intensity). A first line holding a
// single number is a point count (the .pts convention) and is skipped.
inline Mesh read_xyz(const std::string& path, const std::string& text) {
  TextLines lines(path, text);
  std::string_view line;
  Mesh mesh;
  bool first = true;
  while (lines.next(line)) {
    const std::vector<std::string_view> tokens = tokens_of(line);
    if (first && tokens.size() == 1) {
      count_at(lines, tokens[0], "point count", std::numeric_limits<std::uint64_t>::max());
      first = false;
      continue;
    }
    first = false;
    if (tokens.size() < 3) fail_row(path, lines.row(), "a point needs x y z");
    mesh.vertices.push_back(point_at(lines, tokens[0], tokens[1], tokens[2]));
  }
  if (mesh.vertices.empty()) throw Error(path + ": no points");
  return mesh;
}

// ---- binary helpers ----------------------------------------------------------------------------
/// Little-endian value of type V at `offset`; the caller has checked the bounds.
template <class V>
V load_le(const std::string& bytes, std::size_t offset) {
  static_assert(std::is_trivially_copyable<V>::value, "plain values only");
  V value;
  std::memcpy(&value, bytes.data() + offset, sizeof(V));
  return value;  // x86/ARM little-endian hosts; a big-endian host would need a byte swap here
}

// ---- PLY ---------------------------------------------------------------------------------------
enum class PlyType { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

inline bool ply_type_of(std::string_view name, PlyType& type) {
  static const std::pair<const char*, PlyType> names[] = {
      {"char", PlyType::int8},      {"int8", PlyType::int8},       {"uchar", PlyType::uint8},
      {"uint8", PlyType::uint8},    {"short", PlyType::int16},     {"int16", PlyType::int16},
      {"ushort", PlyType::uint16},  {"uint16", PlyType::uint16},   {"int", PlyType::int32},
      {"int32", PlyType::int32},    {"uint", PlyType::uint32},     {"uint32", PlyType::uint32},
      {"float", PlyType::float32},  {"float32", PlyType::float32}, {"double", PlyType::float64},
      {"float64", PlyType::float64}};
  for (const auto& entry : names)
    if (name == entry.first) {
      type = entry.second;
      return true;
    }
  return false;
}

inline std::size_t ply_size_of(PlyType type) {
  switch (type) {
    case PlyType::int8:
    case PlyType::uint8:
      return 1;
    case PlyType::int16:
    case PlyType::uint16:
      return 2;
    case PlyType::int32:
    case PlyType::uint32:
    case PlyType::float32:
      return 4;
    case PlyType::float64:
      return 8;
  }
  return 0;
}

inline double ply_load(const std::string& bytes, std::size_t offset, PlyType type) {
  switch (type) {
    case PlyType::int8:
      return load_le<std::int8_t>(bytes, offset);
    case PlyType::uint8:
      return load_le<std::uint8_t>(bytes, offset);
    case PlyType::int16:
      return load_le<std::int16_t>(bytes, offset);
    case PlyType::uint16:
      return load_le<std::uint16_t>(bytes, offset);
    case PlyType::int32:
      return load_le<std::int32_t>(bytes, offset);
    case PlyType::uint32:
      return load_le<std::uint32_t>(bytes, offset);
    case PlyType::float32:
      return load_le<float>(bytes, offset);
    case PlyType::float64:
      return load_le<double>(bytes, offset);
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::float32;  // the value's type, or the list items' type
  bool is_list = false;
  PlyType count_type = PlyType::uint8;  // lists only
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

/// Reads one value of a PLY element: ascii (next token of the current row) or binary.
class PlyValues {
 public:
  PlyValues(const std::string& path, const std::string& text, bool binary, std::size_t body_offset,
            std::size_t header_rows)
      : path_(path),
        text_(text),
        binary_(binary),
        offset_(body_offset),
        lines_(path, std::string_view(text).substr(body_offset)),
        header_rows_(header_rows) {}

  /// Starts the next element instance: in ascii, the next non-empty line.
  void begin_instance() {
    if (binary_) return;
    std::string_view line;
    if (!lines_.next(line))
      throw Error(path_ + ": row " + std::to_string(row()) + ": file ends inside the data");
    tokens_ = tokens_of(line);
    token_ = 0;
  }
  /// Ends an instance: in ascii, the row must hold nothing more.
  void end_instance() {
    if (!binary_ && token_ != tokens_.size()) fail_row(path_, row(), "more values than the header declares");
  }
  double value(PlyType type) {
    if (binary_) {
      const std::size_t size = ply_size_of(type);
      if (text_.size() - offset_ < size) fail_byte(path_, offset_, "file ends inside the data");
      const double v = ply_load(text_, offset_, type);
      offset_ += size;
      return v;
    }
    if (token_ >= tokens_.size()) fail_row(path_, row(), "fewer values than the header declares");
    double v = 0;
    if (!parse_double(tokens_[token_], v))
      fail_row(path_, row(), "bad value '" + std::string(tokens_[token_]) + "'");
    ++token_;
    return v;
  }
  bool binary() const { return binary_; }
  std::size_t row() const { return header_rows_ + lines_.row(); }
  std::size_t byte() const { return offset_; }
  /// Where the reader stands, for error messages.
  std::string where() const {
    return binary_ ? "byte " + std::to_string(offset_) : "row " + std::to_string(row());
  }

 private:
  const std::string& path_;
  const std::string& text_;
  bool binary_;
  std::size_t offset_;
  TextLines lines_;
  std::size_t header_rows_;
  std::vector<std::string_view> tokens_;
  std::size_t token_ = 0;
};

inline Mesh read_ply(const std::string& path, const std::string& text) {
  TextLines header(path, text);
  std::string_view line;
  if (!header.next(line) || tokens_of(line) != std::vector<std::string_view>{"ply"})
    fail_row(path, header.row(), "not a PLY file (no 'ply' line)");
  bool binary = false;
  bool have_format = false;
  std::vector<PlyElement> elements;
  bool ended = false;
  while (header.next(line)) {
    const std::vector<std::string_view> tokens = tokens_of(line);
    const std::string_view keyword = tokens[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") {
      ended = true;
      break;
    }
    if (keyword == "format") {
      if (tokens.size() < 2) fail_row(path, header.row(), "format line without a format");
      if (tokens[1] == "ascii")
        binary = false;
      else if (tokens[1] == "binary_little_endian")
        binary = true;
      else
        fail_row(path, header.row(), "unsupported PLY format '" + std::string(tokens[1]) + "'");
      have_format = true;
    } else if (keyword == "element") {
      if (tokens.size() != 3) fail_row(path, header.row(), "expected 'element NAME COUNT'");
      elements.push_back(
          {std::string(tokens[1]),
           count_at(header, tokens[2], "element count", std::numeric_limits<std::uint32_t>::max()),
           {}});
    } else if (keyword == "property") {
      if (elements.empty()) fail_row(path, header.row(), "property before any element");
      PlyProperty property;
      const bool list = tokens.size() == 5 && tokens[1] == "list";
      if (!list && tokens.size() != 3)
        fail_row(path, header.row(), "expected 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME'");
      if (list) {
        property.is_list = true;
        if (!ply_type_of(tokens[2], property.count_type) || !ply_type_of(tokens[3], property.type))
          fail_row(path, header.row(), "unknown property type");
        if (property.count_type == PlyType::float32 || property.count_type == PlyType::float64)
          fail_row(path, header.row(), "a list count must be an integer type");
        property.name = std::string(tokens[4]);
      } else {
        if (!ply_type_of(tokens[1], property.type))
          fail_row(path, header.row(), "unknown property type '" + std::string(tokens[1]) + "'");
        property.name = std::string(tokens[2]);
      }
      elements.back().properties.push_back(property);
    } else {
      fail_row(path, header.row(), "unknown header line '" + std::string(keyword) + "'");
    }
  }
  if (!ended) throw Error(path + ": no end_header line");
  if (!have_format) throw Error(path + ": no format line");

  // The body starts after the end_header line's newline.
  const std::size_t body = header.offset();
  const std::size_t body_bytes = text.size() - std::min(body, text.size());
  Mesh mesh;
  PlyValues values(path, text, binary, std::min(body, text.size()), header.row());
  bool have_vertices = false;
  std::vector<std::uint32_t> polygon;
  for (const PlyElement& element : elements) {
    const bool is_vertex = element.name == "vertex";
    const bool is_face = element.name == "face";
    int xyz_index[3] = {-1, -1, -1};
    int face_list = -1;
    std::size_t bytes_each = 0;
    for (std::size_t p = 0; p < element.properties.size(); ++p) {
      const PlyProperty& property = element.properties[p];
      bytes_each += property.is_list ? ply_size_of(property.count_type) : ply_size_of(property.type);
      if (is_vertex && !property.is_list)
        for (int axis = 0; axis < 3; ++axis)
          if (property.name == std::string(1, static_cast<char>('x' + axis)))
            xyz_index[axis] = static_cast<int>(p);
      if (is_face && property.is_list &&
          (property.name == "vertex_indices" || property.name == "vertex_index"))
        face_list = static_cast<int>(p);
    }
    // Each instance takes at least one byte (binary) or two (a value and a newline, ascii).
    if (element.count > body_bytes / std::max<std::size_t>(binary ? bytes_each : 2, 1))
      throw Error(path + ": element '" + element.name + "' count " + std::to_string(element.count) +
                  " is more than the file can hold");
    if (is_vertex) {
      if (xyz_index[0] < 0 || xyz_index[1] < 0 || xyz_index[2] < 0)
        throw Error(path + ": the vertex element has no x, y and z properties");
      have_vertices = true;
      mesh.vertices.reserve(element.count);
    }
    if (is_face && !have_vertices) throw Error(path + ": faces come before the vertices");
    for (std::uint64_t instance = 0; instance < element.count; ++instance) {
      values.begin_instance();
      std::array<float, 3> point{};
      for (std::size_t p = 0; p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        if (!property.is_list) {
          const double v = values.value(property.type);
          for (int axis = 0; axis < 3; ++axis)
            if (xyz_index[axis] == static_cast<int>(p)) {
              bool ok = true;
              point[axis] = to_float_coordinate(v, ok);
              if (!ok)
                throw Error(path + ": " + values.where() + ": coordinate not finite or beyond float range");
            }
          continue;
        }
        const std::string where = values.where();
        const double length = values.value(property.count_type);
        if (length < 0 || length > 1e6)
          throw Error(path + ": " + where + ": bad list length " + std::to_string(length));
        const bool is_polygon = static_cast<int>(p) == face_list;
        polygon.clear();
        for (std::size_t i = 0; i < static_cast<std::size_t>(length); ++i) {
          const double index = values.value(property.type);
          if (!is_polygon) continue;
          if (!(index >= 0) || index >= static_cast<double>(mesh.vertices.size()) ||
              index != std::floor(index))
            throw Error(path + ": " + values.where() + ": vertex index " + std::to_string(index) +
                        " out of range");
          polygon.push_back(static_cast<std::uint32_t>(index));
        }
        if (is_polygon) {
          if (polygon.size() < 3) throw Error(path + ": " + where + ": a face needs at least 3 vertices");
          fan(polygon, mesh.triangles);
        }
      }
      values.end_instance();
      if (is_vertex) mesh.vertices.push_back(point);
    }
  }
  if (!have_vertices) throw Error(path + ": no vertex element");
  return mesh;
}

// ---- STL ---------------------------------------------------------------------------------------
/// Merges equal corners into one vertex, so an STL mesh has shared vertices like the other formats
/// (an STL file repeats each vertex in every triangle around it).
class VertexMerger {
 public:
  explicit VertexMerger(Mesh& mesh) : mesh_(mesh) {}
  std::uint32_t index_of(const std::array<float, 3>& point) {
    std::array<std::uint32_t, 3> bits{};
    for (int axis = 0; axis < 3; ++axis) {
      const float coordinate = point[axis] == 0.0f ? 0.0f : point[axis];  // -0 and +0 are one vertex
      std::memcpy(&bits[axis], &coordinate, sizeof(float));
    }
    const std::uint64_t key_low = (static_cast<std::uint64_t>(bits[0]) << 32) | bits[1];
    auto [it, inserted] =
        index_.try_emplace(Key{key_low, bits[2]}, static_cast<std::uint32_t>(mesh_.vertices.size()));
    if (inserted) mesh_.vertices.push_back(point);
    return it->second;
  }

 private:
  struct Key {
    std::uint64_t xy;
    std::uint32_t z;
    bool operator==(const Key& other) const { return xy == other.xy && z == other.z; }
  };
  struct KeyHash {
    std::size_t operator()(const Key& key) const {
      return std::hash<std::uint64_t>()(key.xy * 0x9E3779B97F4A7C15ull ^ key.z);
    }
  };
  Mesh& mesh_;
  std::unordered_map<Key, std::uint32_t, KeyHash> index_;
};

inline Mesh read_stl(const std::string& path, const std::string& bytes) {
  Mesh mesh;
  VertexMerger merger(mesh);
  // Binary: 80-byte header, uint32 count, then 50 bytes a triangle (normal, 3 corners, attribute).
  // Some binary files start with "solid" too, so the size decides first.
  if (bytes.size() >= 84) {
    const std::uint64_t count = load_le<std::uint32_t>(bytes, 80);
    if (84 + 50 * count == bytes.size()) {
      for (std::uint64_t t = 0; t < count; ++t) {
        const std::size_t at = static_cast<std::size_t>(84 + 50 * t);
        std::array<std::uint32_t, 3> triangle{};
        for (int corner = 0; corner < 3; ++corner) {
          std::array<float, 3> point{};
          for (int axis = 0; axis < 3; ++axis) {
            point[axis] = load_le<float>(
                bytes, at + 12 + 12 * static_cast<std::size_t>(corner) + 4 * static_cast<std::size_t>(axis));
            if (!std::isfinite(point[axis]))
              fail_byte(path, at, "triangle " + std::to_string(t) + " has a coordinate that is not finite");
          }
          triangle[corner] = merger.index_of(point);
        }
        mesh.triangles.push_back(triangle);
      }
      return mesh;
    }
  }
  TextLines lines(path, bytes);
  std::string_view line;
  if (!lines.next(line) || tokens_of(line)[0] != "solid")
    throw Error(path +
                ": neither a binary STL (size != 84 + 50 x triangle count) nor an ascii one (no 'solid')");
  std::vector<std::uint32_t> facet;
  while (lines.next(line)) {
    const std::vector<std::string_view> tokens = tokens_of(line);
    if (tokens[0] == "vertex") {
      if (tokens.size() != 4) fail_row(path, lines.row(), "expected 'vertex x y z'");
      facet.push_back(merger.index_of(point_at(lines, tokens[1], tokens[2], tokens[3])));
    } else if (tokens[0] == "endloop") {
      if (facet.size() < 3) fail_row(path, lines.row(), "a facet needs at least 3 vertices");
      fan(facet, mesh.triangles);
      facet.clear();
    } else if (tokens[0] != "facet" && tokens[0] != "outer" && tokens[0] != "endfacet" &&
               tokens[0] != "endsolid" && tokens[0] != "solid") {
      fail_row(path, lines.row(), "unexpected '" + std::string(tokens[0]) + "'");
    }
  }
  if (!facet.empty()) throw Error(path + ": file ends inside a facet");
  if (mesh.triangles.empty()) throw Error(path + ": no facets");
  return mesh;
}

// ---- LAS ---------------------------------------------------------------------------------------
// ASPRS LAS 1.0-1.4, uncompressed (not .laz). Each point record starts with int32 X, Y, Z; the
// coordinate is X * scale + offset. The points are kept relative to the header's offset (the
// scaled integers alone), because the offset is often a UTM position of 10^5..10^6 metres where
// float would keep only centimetres.
inline Mesh read_las(const std::string& path, const std::string& bytes) {
  if (bytes.size() < 227 || bytes.compare(0, 4, "LASF") != 0)
    throw Error(path + ": not a LAS file (no LASF header)");
  const std::size_t data_offset = load_le<std::uint32_t>(bytes, 96);
  const std::size_t record_length = load_le<std::uint16_t>(bytes, 105);
  std::uint64_t count = load_le<std::uint32_t>(bytes, 107);
  const unsigned version_minor = static_cast<unsigned char>(bytes[25]);
  if (count == 0 && version_minor >= 4 && bytes.size() >= 255) count = load_le<std::uint64_t>(bytes, 247);
  const std::uint8_t format = static_cast<std::uint8_t>(bytes[104]);
  if (format & 0x80) fail_byte(path, 104, "compressed LAS (LAZ) is not supported");
  if (record_length < 12)
    fail_byte(path, 105, "point record length " + std::to_string(record_length) + " is shorter than X, Y, Z");
  if (data_offset > bytes.size() || count > (bytes.size() - data_offset) / record_length)
    fail_byte(path, 107, "point count " + std::to_string(count) + " is more than the file holds");
  const double scale[3] = {load_le<double>(bytes, 131), load_le<double>(bytes, 139),
                           load_le<double>(bytes, 147)};
  for (double s : scale)
    if (!std::isfinite(s) || s == 0) fail_byte(path, 131, "bad scale factor");
  Mesh mesh;
  mesh.vertices.reserve(count);
  for (std::uint64_t p = 0; p < count; ++p) {
    const std::size_t at = static_cast<std::size_t>(data_offset + p * record_length);
    std::array<float, 3> point{};
    for (int axis = 0; axis < 3; ++axis) {
      bool ok = true;
      point[axis] = to_float_coordinate(
          load_le<std::int32_t>(bytes, at + 4 * static_cast<std::size_t>(axis)) * scale[axis], ok);
      if (!ok) fail_byte(path, at, "coordinate beyond float range");
    }
    mesh.vertices.push_back(point);
  }
  if (mesh.vertices.empty()) throw Error(path + ": no points");
  return mesh;
}

}  // namespace mesh_io_detail

/// Reads a mesh or point set, the format chosen by the file's extension (case-insensitive).
inline Mesh read_mesh(const std::string& path) {
  namespace d = mesh_io_detail;
  const std::string extension = d::extension_of(path);
  const std::string bytes = d::read_file(path);
  Mesh mesh;
  if (extension == "off")
    mesh = d::read_off(path, bytes);
  else if (extension == "ply")
    mesh = d::read_ply(path, bytes);
  else if (extension == "xyz" || extension == "pts" || extension == "pwn")
    mesh = d::read_xyz(path, bytes);
  else if (extension == "stl")
    mesh = d::read_stl(path, bytes);
  else if (extension == "las")
    mesh = d::read_las(path, bytes);
  else
    throw Error(path + ": unknown mesh format '." + extension + "' (off, ply, xyz, pts, pwn, stl, las)");
  if (mesh.vertices.empty()) throw Error(path + ": no vertices");
  mesh.name = d::stem_of(path);
  return mesh;
}

/// Reads every file listed in DIR/real_data.txt (written by bench/real_data/fetch.sh DIR): one path
/// a line, relative to DIR; '#' starts a comment. An error in any file is an error.
inline std::vector<Mesh> read_real_meshes(const std::string& dir) {
  namespace d = mesh_io_detail;
  const std::string list_path = dir + "/real_data.txt";
  std::ifstream list(list_path);
  if (!list) throw Error(list_path + ": cannot open (run bench/real_data/fetch.sh " + dir + " first)");
  std::vector<Mesh> meshes;
  std::string line;
  while (std::getline(list, line)) {
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    const std::vector<std::string_view> tokens = d::tokens_of(line);
    if (tokens.empty()) continue;
    meshes.push_back(read_mesh(dir + "/" + std::string(tokens[0])));
  }
  if (meshes.empty()) throw Error(list_path + ": lists no files");
  return meshes;
}

}  // namespace kdspace::bench
