// Minimal readers for the real 3-D point sets of the joins benchmark (scans and meshes shipped in
// Debian's libcgal-demo package): the vertex coordinates of a .ply (ascii or binary little-endian;
// x, y, z of any numeric type, other vertex properties skipped), an .off (ascii) or an .xyz file.
// Only what the benchmark needs; a failure throws std::runtime_error naming the file.
#pragma once

#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace bench {

/// n x 3 coordinates, row-major.
struct Cloud {
  std::size_t n = 0;
  std::vector<double> xyz;
};

inline std::runtime_error bad_file(const std::string& path, const std::string& what) {
  return std::runtime_error(path + ": " + what);
}

inline std::size_t ply_type_size(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" || type == "float32") return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

inline double ply_value(const unsigned char* p, const std::string& type) {
  if (type == "float" || type == "float32") { float v; std::memcpy(&v, p, 4); return v; }
  if (type == "double" || type == "float64") { double v; std::memcpy(&v, p, 8); return v; }
  if (type == "int" || type == "int32") { std::int32_t v; std::memcpy(&v, p, 4); return v; }
  if (type == "uint" || type == "uint32") { std::uint32_t v; std::memcpy(&v, p, 4); return v; }
  if (type == "short" || type == "int16") { std::int16_t v; std::memcpy(&v, p, 2); return v; }
  if (type == "ushort" || type == "uint16") { std::uint16_t v; std::memcpy(&v, p, 2); return v; }
  if (type == "char" || type == "int8") return static_cast<std::int8_t>(*p);
  return *p;
}

inline Cloud read_ply(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw bad_file(path, "cannot open");
  std::string line, format;
  std::vector<std::string> names, types;
  std::size_t vertices = 0;
  bool in_vertex = false;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream words(line);
    std::string word;
    words >> word;
    if (word == "format") words >> format;
    if (word == "element") {
      std::string element;
      words >> element;
      in_vertex = element == "vertex";
      if (in_vertex) words >> vertices;
      else if (vertices == 0) throw bad_file(path, "vertices are not the first element");
    }
    if (word == "property" && in_vertex) {
      std::string type, name;
      words >> type >> name;
      if (type == "list") throw bad_file(path, "list property in vertices");
      types.push_back(type);
      names.push_back(name);
    }
    if (word == "end_header") break;
  }
  int axis_of[3] = {-1, -1, -1};
  for (std::size_t i = 0; i < names.size(); ++i)
    for (int a = 0; a < 3; ++a)
      if (names[i] == std::string(1, static_cast<char>('x' + a))) axis_of[a] = static_cast<int>(i);
  if (axis_of[0] < 0 || axis_of[1] < 0 || axis_of[2] < 0) throw bad_file(path, "no x, y, z vertex properties");
  Cloud cloud;
  cloud.n = vertices;
  cloud.xyz.resize(vertices * 3);
  if (format == "ascii") {
    std::vector<double> row(names.size());
    for (std::size_t v = 0; v < vertices; ++v) {
      for (double& x : row)
        if (!(in >> x)) throw bad_file(path, "truncated at vertex " + std::to_string(v + 1));
      for (int a = 0; a < 3; ++a) cloud.xyz[v * 3 + a] = row[axis_of[a]];
    }
  } else if (format == "binary_little_endian") {
    std::vector<std::size_t> offset(names.size() + 1, 0);
    for (std::size_t i = 0; i < names.size(); ++i) {
      const std::size_t size = ply_type_size(types[i]);
      if (size == 0) throw bad_file(path, "unknown property type " + types[i]);
      offset[i + 1] = offset[i] + size;
    }
    std::vector<unsigned char> record(offset.back());
    for (std::size_t v = 0; v < vertices; ++v) {
      if (!in.read(reinterpret_cast<char*>(record.data()), static_cast<std::streamsize>(record.size())))
        throw bad_file(path, "truncated at vertex " + std::to_string(v + 1));
      for (int a = 0; a < 3; ++a) cloud.xyz[v * 3 + a] = ply_value(record.data() + offset[axis_of[a]], types[axis_of[a]]);
    }
  } else {
    throw bad_file(path, "unsupported PLY format '" + format + "'");
  }
  return cloud;
}

/// .off: "OFF", then "V F E", then V lines of x y z.
inline Cloud read_off(const std::string& path) {
  std::ifstream in(path);
  std::string magic;
  std::size_t vertices = 0, faces = 0, edges = 0;
  if (!(in >> magic) || magic != "OFF" || !(in >> vertices >> faces >> edges)) throw bad_file(path, "not an OFF file");
  Cloud cloud;
  cloud.n = vertices;
  cloud.xyz.resize(vertices * 3);
  for (double& x : cloud.xyz)
    if (!(in >> x)) throw bad_file(path, "truncated");
  return cloud;
}

inline Cloud read_cloud(const std::string& path) {
  const auto ends_with = [&](const char* ext) {
    const std::size_t m = std::strlen(ext);
    return path.size() >= m && path.compare(path.size() - m, m, ext) == 0;
  };
  if (ends_with(".ply")) return read_ply(path);
  if (ends_with(".off")) return read_off(path);
  throw bad_file(path, "unknown extension (.ply or .off)");
}

}  // namespace bench
