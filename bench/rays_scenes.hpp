// Box scenes made from real meshes for kdspace-rays-bench: the bounding boxes of a mesh's triangles
// (thin, elongated, overlapping boxes along a surface, the case synthetic scenes hide), and the
// voxels a mesh's surface passes through (unit cubes sharing faces on a grid: coplanar faces and
// ties everywhere). Meshes come from bench/real_data/mesh_io.hpp.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/box.hpp"
#include "real_data/mesh_io.hpp"

namespace kdspace::bench {

/// The bounding box of each triangle, in the mesh's order. Degenerate triangles give flat boxes,
/// segments or points, which the tree takes as they are.
inline std::vector<Box3f> triangle_boxes(const Mesh& mesh) {
  std::vector<Box3f> boxes;
  boxes.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    Box3f b;
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min({mesh.vertices[t[0]][a], mesh.vertices[t[1]][a], mesh.vertices[t[2]][a]});
      b.hi[a] = std::max({mesh.vertices[t[0]][a], mesh.vertices[t[1]][a], mesh.vertices[t[2]][a]});
    }
    boxes.push_back(b);
  }
  return boxes;
}

/// The voxels of a grid of `resolution` cells along the mesh's longest side (cubic cells) that its
/// surface passes through, as boxes, in x-major order. Found by sampling each triangle at spacing
/// below a third of a cell (barycentric lattice), so a voxel the surface only grazes may be missed;
/// neighbouring voxels share their faces exactly (both are computed as lo + i * cell).
inline std::vector<Box3f> surface_voxels(const Mesh& mesh, std::size_t resolution) {
  std::vector<Box3f> voxels;
  if (mesh.triangles.empty() || resolution == 0) return voxels;
  std::array<double, 3> lo{}, hi{};
  for (int a = 0; a < 3; ++a) {
    lo[a] = hi[a] = mesh.vertices[mesh.triangles[0][0]][a];
  }
  for (const auto& t : mesh.triangles)
    for (const std::uint32_t v : t)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], static_cast<double>(mesh.vertices[v][a]));
        hi[a] = std::max(hi[a], static_cast<double>(mesh.vertices[v][a]));
      }
  const double side = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  if (!(side > 0)) return voxels;
  const double cell = side / static_cast<double>(resolution);
  std::array<std::size_t, 3> cells{};
  for (int a = 0; a < 3; ++a)
    cells[a] = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil((hi[a] - lo[a]) / cell)));
  std::vector<bool> occupied(cells[0] * cells[1] * cells[2], false);
  auto mark = [&](const std::array<double, 3>& p) {
    std::size_t index = 0;
    for (int a = 0; a < 3; ++a) {
      const auto i = static_cast<std::size_t>(std::max(0.0, (p[a] - lo[a]) / cell));
      index = index * cells[a] + std::min(i, cells[a] - 1);
    }
    occupied[index] = true;
  };
  for (const auto& t : mesh.triangles) {
    std::array<std::array<double, 3>, 3> v{};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) v[k][a] = mesh.vertices[t[k]][a];
    double longest = 0;
    for (int k = 0; k < 3; ++k) {
      const auto& p = v[k];
      const auto& q = v[(k + 1) % 3];
      longest = std::max(longest, std::sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                                            (p[2] - q[2]) * (p[2] - q[2])));
    }
    const auto steps = static_cast<int>(std::ceil(3 * longest / cell)) + 1;
    for (int i = 0; i <= steps; ++i)
      for (int j = 0; i + j <= steps; ++j) {
        const double u = static_cast<double>(i) / steps, w = static_cast<double>(j) / steps;
        std::array<double, 3> p{};
        for (int a = 0; a < 3; ++a) p[a] = v[0][a] + u * (v[1][a] - v[0][a]) + w * (v[2][a] - v[0][a]);
        mark(p);
      }
  }
  for (std::size_t x = 0; x < cells[0]; ++x)
    for (std::size_t y = 0; y < cells[1]; ++y)
      for (std::size_t z = 0; z < cells[2]; ++z) {
        if (!occupied[(x * cells[1] + y) * cells[2] + z]) continue;
        const std::array<std::size_t, 3> i{x, y, z};
        Box3f b;
        for (int a = 0; a < 3; ++a) {
          b.lo[a] = static_cast<float>(lo[a] + static_cast<double>(i[a]) * cell);
          b.hi[a] = static_cast<float>(lo[a] + static_cast<double>(i[a] + 1) * cell);
        }
        voxels.push_back(b);
      }
  return voxels;
}

}  // namespace kdspace::bench
