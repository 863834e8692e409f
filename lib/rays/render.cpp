// render_image: primary rays through a BoxTree, shaded by the face they hit.
#include "kdspace/rays/render.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"

namespace kdspace {

namespace {

using Vec3 = std::array<double, 3>;

Vec3 normalized(Vec3 v) {
  const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (double& c : v) c /= len;
  return v;
}

double dot(const Vec3& a, const Vec3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/// The outward normal of the face of `box` that the ray hits at point p: the face p lies closest to,
/// turned towards the ray (a flat box shows the face that looks at the camera).
Vec3 face_normal(const Box3f& box, const Vec3& p, const Ray& ray) {
  int best_axis = 0;
  double best_distance = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (ray.direction[a] == 0) continue;  // a ray never enters through a face parallel to it
    const double face = ray.direction[a] > 0 ? box.lo[a] : box.hi[a];
    const double distance = std::abs(p[a] - face);
    if (distance < best_distance) {
      best_distance = distance;
      best_axis = a;
    }
  }
  Vec3 n{0, 0, 0};
  n[best_axis] = ray.direction[best_axis] > 0 ? -1.0 : 1.0;
  return n;
}

/// A colour per box: the index hashed (Murmur3's finaliser) to a hue, at fixed saturation and value.
Vec3 box_colour(std::uint32_t index) {
  std::uint32_t h = index;
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  const double hue = static_cast<double>(h % 3600u) / 600.0;  // [0, 6)
  const double s = 0.55, v = 0.95;
  const double f = hue - std::floor(hue);
  const double p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  switch (static_cast<int>(hue)) {
    case 0:
      return {v, t, p};
    case 1:
      return {q, v, p};
    case 2:
      return {p, v, t};
    case 3:
      return {p, q, v};
    case 4:
      return {t, p, v};
    default:
      return {v, p, q};
  }
}

std::uint8_t to_byte(double c) {
  return static_cast<std::uint8_t>(std::lround(std::clamp(c, 0.0, 1.0) * 255.0));
}

}  // namespace

Image render_image(const BoxTree& tree, const RenderParams& params) {
  const double aspect =
      params.height ? static_cast<double>(params.width) / static_cast<double>(params.height) : 1.0;
  return render_image(tree, fit_camera(tree.bounds(), aspect), params);
}

Image render_image(const BoxTree& tree, const Camera& camera, const RenderParams& params) {
  if (params.width == 0 || params.height == 0) throw Error("image size must be at least 1 x 1");
  if (params.width > 1u << 15 || params.height > 1u << 15)
    throw Error("image size must be at most 32768 x 32768");
  if (!params.box_colours.empty() && params.box_colours.size() != tree.size())
    throw Error("box_colours: " + std::to_string(params.box_colours.size()) + " colours for " +
                std::to_string(tree.size()) + " boxes");
  Image image;
  image.width = params.width;
  image.height = params.height;
  image.rgb.assign(params.width * params.height * 3, 0);

  // The light sits above the camera's left shoulder.
  const Vec3 forward = normalized({static_cast<double>(camera.target[0]) - camera.eye[0],
                                   static_cast<double>(camera.target[1]) - camera.eye[1],
                                   static_cast<double>(camera.target[2]) - camera.eye[2]});
  const Vec3 world_up{camera.up[0], camera.up[1], camera.up[2]};
  const Vec3 right = normalized({forward[1] * world_up[2] - forward[2] * world_up[1],
                                 forward[2] * world_up[0] - forward[0] * world_up[2],
                                 forward[0] * world_up[1] - forward[1] * world_up[0]});
  Vec3 light{};
  for (int a = 0; a < 3; ++a) light[a] = -forward[a] - 0.6 * right[a] + 0.9 * world_up[a];
  light = normalized(light);

  // Shadow rays start a little off the surface so that they do not hit the box they leave.
  double diagonal = 0;
  for (int a = 0; a < 3; ++a) {
    const double e = static_cast<double>(tree.bounds().hi[a]) - tree.bounds().lo[a];
    diagonal += e > 0 ? e * e : 0;
  }
  const double offset = 1e-4 * std::max(std::sqrt(diagonal), 1e-6);
  constexpr double ambient = 0.18;

  constexpr std::size_t rows_per_chunk = 8;
  const std::size_t chunks = (params.height + rows_per_chunk - 1) / rows_per_chunk;
  detail::parallel_for(chunks, params.threads, 1, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t chunk = begin; chunk < end; ++chunk) {
      const std::size_t first_row = chunk * rows_per_chunk;
      const std::vector<Ray> rays =
          primary_rays(camera, params.width, params.height, first_row, rows_per_chunk);
      for (std::size_t i = 0; i < rays.size(); ++i) {
        const std::size_t pixel = first_row * params.width + i;
        const std::size_t row = pixel / params.width;
        const Ray& ray = rays[i];
        const Hit hit = tree.closest_hit(ray);
        Vec3 colour;
        if (!hit.hit()) {
          const double shade = 0.88 - 0.25 * static_cast<double>(row) / static_cast<double>(params.height);
          colour = {shade, shade, shade + 0.03};
        } else {
          const auto box = static_cast<std::size_t>(hit.box);
          Vec3 p{};
          for (int a = 0; a < 3; ++a) p[a] = ray.origin[a] + static_cast<double>(hit.t) * ray.direction[a];
          const Vec3 n = face_normal(tree.box(box), p, ray);
          double diffuse = std::max(0.0, dot(n, light));
          if (diffuse > 0 && params.shadows) {
            Ray shadow;
            for (int a = 0; a < 3; ++a) {
              shadow.origin[a] = static_cast<float>(p[a] + offset * n[a]);
              shadow.direction[a] = static_cast<float>(light[a]);
            }
            if (tree.any_hit(shadow).hit()) diffuse = 0;
          }
          const Vec3 base = params.box_colours.empty()
                                ? box_colour(static_cast<std::uint32_t>(box))
                                : Vec3{params.box_colours[box][0], params.box_colours[box][1],
                                       params.box_colours[box][2]};
          for (int a = 0; a < 3; ++a) colour[a] = base[a] * (ambient + (1 - ambient) * diffuse);
        }
        for (int c = 0; c < 3; ++c) image.rgb[pixel * 3 + c] = to_byte(colour[c]);
      }
    }
  });
  return image;
}

}  // namespace kdspace
