// Generated scenes and rays. The generator and every conversion are our own (SplitMix64, integer to
// float by scaling, square roots only), so a seed gives the same data on every platform.
#include "kdspace/rays/scene_gen.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "kdspace/error.hpp"

namespace kdspace {

namespace {

/// SplitMix64 (Steele, Lea & Flood 2014): small, fast, and good enough for test data.
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed * 0x9e3779b97f4a7c15ull + 0x632be59bd9b4e019ull) {}
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  /// Uniform in [0, 1), 53 random bits.
  double uniform() { return static_cast<double>(next() >> 11) * (1.0 / 9007199254740992.0); }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// Approximately standard normal: the sum of 4 uniforms, centred and scaled (Irwin-Hall), which
  /// needs no transcendental function and so is the same everywhere.
  double normal() { return (uniform() + uniform() + uniform() + uniform() - 2.0) * std::sqrt(3.0); }

 private:
  std::uint64_t state_;
};

Box3f box_around(const std::array<double, 3>& centre, const std::array<double, 3>& size) {
  Box3f b;
  for (int a = 0; a < 3; ++a) {
    const double lo = std::clamp(centre[a] - 0.5 * size[a], 0.0, 1.0);
    const double hi = std::clamp(centre[a] + 0.5 * size[a], 0.0, 1.0);
    b.lo[a] = static_cast<float>(lo);
    b.hi[a] = std::max(b.lo[a], static_cast<float>(hi));
  }
  return b;
}

std::array<double, 3> normalized(std::array<double, 3> v) {
  const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (double& c : v) c /= len;
  return v;
}

std::array<double, 3> cross(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

std::array<double, 3> to_double(const std::array<float, 3>& v) {
  return {v[0], v[1], v[2]};
}

}  // namespace

std::vector<Box3f> generate_boxes(std::size_t n, SceneKind kind, std::uint32_t seed) {
  Random rng(seed);
  std::vector<Box3f> boxes;
  boxes.reserve(n);
  if (n == 0) return boxes;
  // Mean spacing of n points in the unit cube; boxes of about this size overlap a little.
  const double spacing = std::cbrt(1.0 / static_cast<double>(n));
  if (kind == SceneKind::uniform) {
    for (std::size_t i = 0; i < n; ++i) {
      const std::array<double, 3> centre{rng.uniform(), rng.uniform(), rng.uniform()};
      const std::array<double, 3> size{spacing * rng.uniform(0.2, 1.5), spacing * rng.uniform(0.2, 1.5),
                                       spacing * rng.uniform(0.2, 1.5)};
      boxes.push_back(box_around(centre, size));
    }
    return boxes;
  }
  // Clustered: about sqrt(n) / 4 clusters of random weight and spread.
  const std::size_t clusters =
      std::max<std::size_t>(1, static_cast<std::size_t>(std::sqrt(static_cast<double>(n)) / 4));
  struct Cluster {
    std::array<double, 3> centre;
    double spread;
    double box_size;
  };
  std::vector<Cluster> cs(clusters);
  std::vector<double> cumulative(clusters);
  double total = 0;
  for (std::size_t c = 0; c < clusters; ++c) {
    cs[c].centre = {rng.uniform(0.1, 0.9), rng.uniform(0.1, 0.9), rng.uniform(0.1, 0.9)};
    cs[c].spread = rng.uniform(0.01, 0.08);
    total += rng.uniform(0.2, 1.0);
    cumulative[c] = total;
  }
  for (std::size_t c = 0; c < clusters; ++c) {
    // Boxes of a cluster about as large as the spacing of its expected share of points.
    const double share = (cumulative[c] - (c ? cumulative[c - 1] : 0.0)) / total * static_cast<double>(n);
    cs[c].box_size = 2.0 * cs[c].spread * std::cbrt(1.0 / std::max(1.0, share));
  }
  for (std::size_t i = 0; i < n; ++i) {
    const double pick = rng.uniform() * total;
    const std::size_t c = std::min<std::size_t>(
        clusters - 1, static_cast<std::size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), pick) -
                                               cumulative.begin()));
    const Cluster& cl = cs[c];
    const std::array<double, 3> centre{cl.centre[0] + cl.spread * rng.normal(),
                                       cl.centre[1] + cl.spread * rng.normal(),
                                       cl.centre[2] + cl.spread * rng.normal()};
    const std::array<double, 3> size{cl.box_size * rng.uniform(0.2, 1.5), cl.box_size * rng.uniform(0.2, 1.5),
                                     cl.box_size * rng.uniform(0.2, 1.5)};
    boxes.push_back(box_around(centre, size));
  }
  return boxes;
}

std::vector<Ray> random_rays(std::size_t m, const Box3f& bounds, std::uint32_t seed) {
  Random rng(static_cast<std::uint64_t>(seed) ^ 0x5bd1e995u);
  std::vector<Ray> rays(m);
  for (Ray& r : rays) {
    for (int a = 0; a < 3; ++a) {
      const double lo = bounds.lo[a], hi = bounds.hi[a], grow = 0.1 * (hi - lo);
      r.origin[a] = static_cast<float>(rng.uniform(lo - grow, hi + grow));
    }
    // Uniform on the sphere: a uniform point of the unit ball (by rejection), normalised.
    std::array<double, 3> d{};
    double len2 = 0;
    do {
      d = {rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
      len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    } while (len2 > 1 || len2 < 1e-6);
    d = normalized(d);
    for (int a = 0; a < 3; ++a) r.direction[a] = static_cast<float>(d[a]);
  }
  return rays;
}

Camera fit_camera(const Box3f& bounds, double aspect) {
  Camera cam;
  std::array<double, 3> centre{}, half{};
  for (int a = 0; a < 3; ++a) {
    const bool empty = !(bounds.lo[a] <= bounds.hi[a]);
    centre[a] = empty ? 0.0 : 0.5 * (static_cast<double>(bounds.lo[a]) + bounds.hi[a]);
    half[a] = empty ? 0.5 : 0.5 * (static_cast<double>(bounds.hi[a]) - bounds.lo[a]);
  }
  double radius = std::sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2]);
  if (!(radius > 0)) radius = 1;
  const double pi = 3.14159265358979323846;
  const double half_fov = 0.5 * cam.vertical_fov_degrees * pi / 180.0;
  // The bounding sphere fits the narrower of the two fields of view, with 5% to spare.
  const double half_fov_x = std::atan(std::tan(half_fov) * (aspect > 0 ? aspect : 1.0));
  const double distance = 1.05 * radius / std::sin(std::min(half_fov, half_fov_x));
  const std::array<double, 3> towards_eye = normalized({1.0, -1.4, 0.9});
  for (int a = 0; a < 3; ++a) {
    cam.target[a] = static_cast<float>(centre[a]);
    cam.eye[a] = static_cast<float>(centre[a] + distance * towards_eye[a]);
  }
  cam.up = {0, 0, 1};
  return cam;
}

std::vector<Ray> primary_rays(const Camera& camera, std::size_t width, std::size_t height,
                              std::size_t first_row, std::size_t row_count) {
  if (width == 0 || height == 0) throw Error("image size must be at least 1 x 1");
  if (!(camera.vertical_fov_degrees > 0 && camera.vertical_fov_degrees < 180))
    throw Error("camera: vertical field of view must be in (0, 180) degrees");
  const std::array<double, 3> eye = to_double(camera.eye), target = to_double(camera.target);
  std::array<double, 3> forward{target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]};
  if (forward[0] == 0 && forward[1] == 0 && forward[2] == 0) throw Error("camera: eye and target coincide");
  forward = normalized(forward);
  std::array<double, 3> right = cross(forward, to_double(camera.up));
  const double right_len = std::sqrt(right[0] * right[0] + right[1] * right[1] + right[2] * right[2]);
  if (!(right_len > 1e-9)) throw Error("camera: up is parallel to the view direction");
  right = normalized(right);
  const std::array<double, 3> up = cross(right, forward);
  const double pi = 3.14159265358979323846;
  const double half_h = std::tan(0.5 * camera.vertical_fov_degrees * pi / 180.0);
  const double half_w = half_h * static_cast<double>(width) / static_cast<double>(height);

  const std::size_t begin = std::min(first_row, height);
  const std::size_t end = begin + std::min(row_count, height - begin);
  std::vector<Ray> rays((end - begin) * width);
  for (std::size_t y = begin; y < end; ++y)
    for (std::size_t x = 0; x < width; ++x) {
      const double u = ((static_cast<double>(x) + 0.5) / static_cast<double>(width) * 2.0 - 1.0) * half_w;
      const double v = (1.0 - (static_cast<double>(y) + 0.5) / static_cast<double>(height) * 2.0) * half_h;
      const std::array<double, 3> d =
          normalized({forward[0] + u * right[0] + v * up[0], forward[1] + u * right[1] + v * up[1],
                      forward[2] + u * right[2] + v * up[2]});
      Ray& r = rays[(y - begin) * width + x];
      r.origin = camera.eye;
      for (int a = 0; a < 3; ++a) r.direction[a] = static_cast<float>(d[a]);
    }
  return rays;
}

}  // namespace kdspace
