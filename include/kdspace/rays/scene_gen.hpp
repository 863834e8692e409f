// Generated scenes and rays: test data, benchmarks and the demo, reproducible from a seed.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace {

enum class SceneKind {
  uniform,    ///< centres uniform in the unit cube, sizes up to about twice the mean spacing
  clustered,  ///< Gaussian clusters of small boxes, cluster sizes and spreads varying, in the unit cube
};

/// n boxes of the given kind inside [0, 1]^3, the same for the same (n, kind, seed) on every
/// platform (own generator and conversions, no std::*_distribution).
std::vector<Box3f> generate_boxes(std::size_t n, SceneKind kind, std::uint32_t seed);

/// m rays with origins uniform in `bounds` grown by 10% on every side and directions uniform on the
/// unit sphere.
std::vector<Ray> random_rays(std::size_t m, const Box3f& bounds, std::uint32_t seed);

/// A pinhole camera.
struct Camera {
  std::array<float, 3> eye{0, 0, 1};
  std::array<float, 3> target{0, 0, 0};
  std::array<float, 3> up{0, 0, 1};
  float vertical_fov_degrees = 40;
};

/// A camera that sees all of `bounds` from a diagonal direction (from +x, -y, +z, above the scene),
/// for an image of the given width / height.
Camera fit_camera(const Box3f& bounds, double aspect);

/// One ray through the centre of each pixel of a width x height image, row by row from the top left,
/// for the rows [first_row, first_row + row_count) (clamped to the image): row_count * width rays.
/// The directions are unit vectors. Throws Error for width or height 0 or a degenerate camera
/// (eye = target, up parallel to the view direction, fov outside (0, 180)).
std::vector<Ray> primary_rays(const Camera& camera, std::size_t width, std::size_t height,
                              std::size_t first_row = 0,
                              std::size_t row_count = static_cast<std::size_t>(-1));

}  // namespace kdspace
