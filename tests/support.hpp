// Helpers shared by several test files (tests/test_*.cpp): data generators for the point-tree tests,
// scene helpers for the ray tests, and a scratch directory for the file tests.
#ifndef KDSPACE_TESTS_SUPPORT_HPP
#define KDSPACE_TESTS_SUPPORT_HPP

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/point_tree.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/scene_gen.hpp"

namespace kdspace_test {

using kdspace::AxisRule;
using kdspace::PositionRule;

// ---- point data (test_point_tree_exact.cpp, test_flann_validation.cpp) -----------------------------

enum class Shape { uniform, clustered, duplicates, grid, identical, flat, sorted_x };

inline const char* name(Shape s) {
  switch (s) {
    case Shape::uniform:
      return "uniform";
    case Shape::clustered:
      return "clustered";
    case Shape::duplicates:
      return "duplicate-heavy";
    case Shape::grid:
      return "integer grid";
    case Shape::identical:
      return "all identical";
    case Shape::flat:
      return "flat axes";
    case Shape::sorted_x:
      return "sorted along x";
  }
  return "?";
}

inline const char* name(AxisRule a) {
  return a == AxisRule::cycle ? "cycle" : "max_spread";
}

inline const char* name(PositionRule p) {
  switch (p) {
    case PositionRule::median:
      return "median";
    case PositionRule::middle:
      return "middle";
    case PositionRule::sliding_midpoint:
      return "sliding_midpoint";
    case PositionRule::midpoint:
      return "midpoint";
  }
  return "?";
}

template <class T>
const char* type_name() {
  return sizeof(T) == sizeof(float) ? "float" : "double";
}

/// n points of `dim` coordinates, row-major, of the given shape; the same seed gives the same points.
template <class T>
std::vector<T> make_points(Shape shape, std::size_t n, std::size_t dim, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<T> pts(n * dim);
  switch (shape) {
    case Shape::uniform:
      for (auto& v : pts) v = static_cast<T>(unit(rng));
      break;
    case Shape::clustered: {
      // Six Gaussian blobs of very different weights and widths, centres spread over [-10, 10].
      const std::size_t blobs = 6;
      std::vector<double> centres(blobs * dim);
      for (auto& c : centres) c = 10.0 * unit(rng);
      const double sigma[blobs] = {0.01, 0.05, 0.1, 0.2, 0.3, 0.02};
      std::discrete_distribution<std::size_t> pick({1, 2, 4, 8, 16, 32});
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t b = pick(rng);
        std::normal_distribution<double> noise(0.0, sigma[b]);
        for (std::size_t a = 0; a < dim; ++a)
          pts[i * dim + a] = static_cast<T>(centres[b * dim + a] + noise(rng));
      }
      break;
    }
    case Shape::duplicates: {
      // Every point is one of 16 distinct points.
      const std::size_t pool = 16;
      std::vector<T> distinct(pool * dim);
      for (auto& v : distinct) v = static_cast<T>(unit(rng));
      std::uniform_int_distribution<std::size_t> pick(0, pool - 1);
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t p = pick(rng);
        std::copy_n(distinct.begin() + static_cast<std::ptrdiff_t>(p * dim), dim,
                    pts.begin() + static_cast<std::ptrdiff_t>(i * dim));
      }
      break;
    }
    case Shape::grid: {
      std::uniform_int_distribution<int> cell(0, 6);
      for (auto& v : pts) v = static_cast<T>(cell(rng));
      break;
    }
    case Shape::identical: {
      std::vector<T> p(dim);
      for (auto& v : p) v = static_cast<T>(unit(rng));
      for (std::size_t i = 0; i < n; ++i)
        std::copy(p.begin(), p.end(), pts.begin() + static_cast<std::ptrdiff_t>(i * dim));
      break;
    }
    case Shape::flat:
      // Uniform, but every third axis (1, 4, 7, ...) is constant, and from 8-D on the last one too.
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t a = 0; a < dim; ++a) {
          T v = static_cast<T>(unit(rng));
          if (a % 3 == 1) v = T(0.25);
          if (dim >= 8 && a + 1 == dim) v = T(-3);
          pts[i * dim + a] = v;
        }
      break;
    case Shape::sorted_x: {
      std::vector<T> raw(n * dim);
      for (auto& v : raw) v = static_cast<T>(unit(rng));
      std::vector<std::size_t> order(n);
      std::iota(order.begin(), order.end(), std::size_t{0});
      std::stable_sort(order.begin(), order.end(),
                       [&](std::size_t i, std::size_t j) { return raw[i * dim] < raw[j * dim]; });
      for (std::size_t i = 0; i < n; ++i)
        std::copy_n(raw.begin() + static_cast<std::ptrdiff_t>(order[i] * dim), dim,
                    pts.begin() + static_cast<std::ptrdiff_t>(i * dim));
      break;
    }
  }
  return pts;
}

/// nq queries: random in the data's bounding box grown by a quarter, every third one a data point,
/// every seventh far outside.
template <class T>
std::vector<T> make_queries(const std::vector<T>& pts, std::size_t n, std::size_t dim, std::size_t nq,
                            std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<T> lo(pts.begin(), pts.begin() + static_cast<std::ptrdiff_t>(dim)), hi = lo;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a) {
      lo[a] = std::min(lo[a], pts[i * dim + a]);
      hi[a] = std::max(hi[a], pts[i * dim + a]);
    }
  std::vector<T> q(nq * dim);
  for (std::size_t j = 0; j < nq; ++j) {
    const std::size_t on = std::uniform_int_distribution<std::size_t>(0, n - 1)(rng);
    for (std::size_t a = 0; a < dim; ++a) {
      const double span = static_cast<double>(hi[a]) - static_cast<double>(lo[a]);
      const double mid = static_cast<double>(lo[a]) / 2 + static_cast<double>(hi[a]) / 2;
      double v = mid + std::uniform_real_distribution<double>(-0.625, 0.625)(rng) * span;
      if (j % 3 == 1) v = static_cast<double>(pts[on * dim + a]);
      if (j % 7 == 5) v = mid + 50 * (span + 1);
      q[j * dim + a] = static_cast<T>(v);
    }
  }
  return q;
}

/// The first difference between a batch answer and brute_force_knn over every query (ids and
/// distances, rank by rank), described for a failure message; "" when they are the same.
template <class Metric = kdspace::L2, class T>
std::string differs_from_brute_force(const kdspace::NeighborLists<T>& batch, const std::vector<T>& pts,
                                     std::size_t n, std::size_t dim, const std::vector<T>& queries, std::size_t k) {
  const std::size_t nq = queries.size() / dim;
  for (std::size_t q = 0; q < nq; ++q) {
    const auto expected = kdspace::brute_force_knn<Metric>(pts.data(), n, dim, queries.data() + q * dim, k);
    const auto row = batch.row(q);
    if (row.size() != k) return "query " + std::to_string(q) + ": " + std::to_string(row.size()) + " results";
    for (std::size_t i = 0; i < k; ++i)
      if (!(row[i] == expected[i])) {
        std::ostringstream out;
        out.precision(10);
        out << "query " << q << " rank " << i << ": got index " << row[i].index << " at " << row[i].distance
            << ", brute force index " << expected[i].index << " at " << expected[i].distance;
        return out.str();
      }
  }
  return "";
}

// ---- scenes (test_rays.cpp, test_rays_build.cpp) ------------------------------------------------

using Rng = std::mt19937;

inline float uniform(Rng& rng, float lo, float hi) {
  return std::uniform_real_distribution<float>(lo, hi)(rng);
}
inline int uniform_int(Rng& rng, int lo, int hi) {
  return std::uniform_int_distribution<int>(lo, hi)(rng);
}

inline kdspace::Box3f box_of(float x0, float y0, float z0, float x1, float y1, float z1) {
  kdspace::Box3f b;
  b.lo = {x0, y0, z0};
  b.hi = {x1, y1, z1};
  return b;
}

// ---- collision scenes (test_collide*.cpp) -------------------------------------------------------

enum class CollisionScene { uniform, clustered, overlapping, flat, face_sharing, mixed_sizes, identical, points };

inline const char* name(CollisionScene s) {
  switch (s) {
    case CollisionScene::uniform:
      return "uniform";
    case CollisionScene::clustered:
      return "clustered";
    case CollisionScene::overlapping:
      return "heavily overlapping";
    case CollisionScene::flat:
      return "flat and coplanar";
    case CollisionScene::face_sharing:
      return "face-sharing cubes";
    case CollisionScene::mixed_sizes:
      return "mixed sizes";
    case CollisionScene::identical:
      return "all identical";
    case CollisionScene::points:
      return "points on a grid";
  }
  return "?";
}

inline const CollisionScene all_collision_scenes[] = {
    CollisionScene::uniform,      CollisionScene::clustered,   CollisionScene::overlapping,
    CollisionScene::flat,         CollisionScene::face_sharing, CollisionScene::mixed_sizes,
    CollisionScene::identical,    CollisionScene::points};

/// n boxes of the given kind; the same seed gives the same boxes.
///   uniform, clustered   the ray module's generated scenes (a few overlaps a box)
///   overlapping          boxes a third of the scene wide: every box overlaps a large share of the rest
///   flat                 boxes of zero thickness on one axis, on coarse grid coordinates: many
///                        coplanar, touching along faces and edges, lying in each other's planes
///   face_sharing         cubes of side 1 or 2 at integer positions: neighbours share faces, edges,
///                        corners exactly
///   mixed_sizes          sizes over three orders of magnitude
///   identical            one box n times
///   points               zero-size boxes on a small integer grid: many coincide
inline std::vector<kdspace::Box3f> make_collision_scene(CollisionScene kind, std::size_t n, std::uint32_t seed) {
  Rng rng(seed);
  std::vector<kdspace::Box3f> boxes(n);
  switch (kind) {
    case CollisionScene::uniform:
      return kdspace::generate_boxes(n, kdspace::SceneKind::uniform, seed);
    case CollisionScene::clustered:
      return kdspace::generate_boxes(n, kdspace::SceneKind::clustered, seed);
    case CollisionScene::overlapping:
      for (kdspace::Box3f& b : boxes)
        for (int a = 0; a < 3; ++a) {
          b.lo[a] = uniform(rng, 0, 0.7f);
          b.hi[a] = b.lo[a] + uniform(rng, 0.1f, 0.3f);
        }
      break;
    case CollisionScene::flat: {
      const int cells = std::max(2, static_cast<int>(std::cbrt(static_cast<double>(n))));
      for (kdspace::Box3f& b : boxes) {
        const int flat_axis = uniform_int(rng, 0, 2);
        for (int a = 0; a < 3; ++a) {
          b.lo[a] = 0.25f * static_cast<float>(uniform_int(rng, 0, 4 * cells));
          b.hi[a] = a == flat_axis ? b.lo[a] : b.lo[a] + 0.25f * static_cast<float>(uniform_int(rng, 1, 6));
        }
      }
      break;
    }
    case CollisionScene::face_sharing: {
      const int cells = std::max(2, static_cast<int>(std::cbrt(static_cast<double>(n)) * 1.3));
      for (kdspace::Box3f& b : boxes) {
        const float side = uniform_int(rng, 0, 3) == 0 ? 2.0f : 1.0f;
        for (int a = 0; a < 3; ++a) {
          b.lo[a] = static_cast<float>(uniform_int(rng, 0, cells));
          b.hi[a] = b.lo[a] + side;
        }
      }
      break;
    }
    case CollisionScene::mixed_sizes:
      for (kdspace::Box3f& b : boxes) {
        const float scale = std::pow(10.0f, uniform(rng, -2, 1));
        for (int a = 0; a < 3; ++a) {
          b.lo[a] = uniform(rng, -10, 10);
          b.hi[a] = b.lo[a] + scale * uniform(rng, 0.05f, 1);
        }
      }
      break;
    case CollisionScene::identical: {
      const kdspace::Box3f one = box_of(0.5f, -1, 2, 1.5f, 0, 2.25f);
      std::fill(boxes.begin(), boxes.end(), one);
      break;
    }
    case CollisionScene::points:
      for (kdspace::Box3f& b : boxes) {
        for (int a = 0; a < 3; ++a) b.lo[a] = b.hi[a] = static_cast<float>(uniform_int(rng, 0, 7));
      }
      break;
  }
  return boxes;
}

// ---- files (test_io.cpp, test_rays_io.cpp, test_index_*.cpp) ---------------------------------------

/// A scratch directory for one test, removed afterwards: <base>/<prefix><process id>, where base is
/// the temporary directory, or (in_memory) /dev/shm where there is one: for tests that write many
/// small files, which a disk file system may flush one by one.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& prefix, bool in_memory = false)
      : dir_((in_memory && std::filesystem::is_directory("/dev/shm") ? std::filesystem::path("/dev/shm")
                                                                      : std::filesystem::temp_directory_path()) /
             (prefix + std::to_string(::getpid()))) {
    std::filesystem::create_directories(dir_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;

  std::string file(const std::string& name) const { return (dir_ / name).string(); }
  std::string path() const { return dir_.string(); }

 private:
  std::filesystem::path dir_;
};

/// The whole content of a file ({} when it cannot be opened).
inline std::vector<unsigned char> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<unsigned char>(std::istreambuf_iterator<char>(in), {});
}

/// Replaces a file's content.
inline void write_bytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace kdspace_test

#endif  // KDSPACE_TESTS_SUPPORT_HPP
