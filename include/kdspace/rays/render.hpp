// render_image: a shaded picture of a box scene, traced through a BoxTree.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/scene_gen.hpp"

namespace kdspace {

struct RenderParams {
  std::size_t width = 800;
  std::size_t height = 600;
  /// Cast a shadow ray (any_hit) from every visible point towards the light.
  bool shadows = true;
  /// Threads; 0 = all hardware threads. The image does not depend on it.
  unsigned threads = 0;
  /// When not empty, one colour a box (RGB in [0, 1]), used instead of the colour of its index.
  std::vector<std::array<float, 3>> box_colours;
};

/// An RGB image, 3 bytes a pixel, rows from the top.
struct Image {
  std::size_t width = 0;
  std::size_t height = 0;
  std::vector<std::uint8_t> rgb;
};

/// Renders the tree's boxes: each box in its own colour (a hash of its index), Lambert shading from
/// the normal of the face hit and a light above the camera's left shoulder, a little ambient light,
/// and shadows; the background is a vertical grey gradient.
Image render_image(const BoxTree& tree, const Camera& camera, const RenderParams& params = {});

/// The same from fit_camera(tree.bounds(), width / height).
Image render_image(const BoxTree& tree, const RenderParams& params = {});

}  // namespace kdspace
