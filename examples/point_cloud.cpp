// 3-D point cloud: neighbours within a radius and points inside a box, with a compile-time dimension.
#include <kdspace/kdspace.hpp>

#include <cmath>
#include <cstdio>
#include <vector>

int main() {
  // A sphere of radius 1 sampled on a latitude/longitude grid.
  const double pi = std::acos(-1.0);
  std::vector<double> cloud;
  for (int i = 0; i < 200; ++i)
    for (int j = 0; j < 400; ++j) {
      const double theta = pi * (i + 0.5) / 200, phi = 2 * pi * j / 400;
      cloud.insert(cloud.end(), {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)});
    }
  kdspace::PointTree<double, 3> tree(cloud.data(), cloud.size() / 3, 3);

  const double north_pole[3] = {0, 0, 1};
  const auto cap = tree.radius(north_pole, 0.1);  // a true distance, not squared
  std::printf("%zu points within 0.1 of the north pole; the nearest at %.5f\n", cap.size(), cap.front().distance);

  const double lo[3] = {0.9, -0.1, -0.1}, hi[3] = {1.0, 0.1, 0.1};
  std::printf("%zu points in the box [0.9,1]x[-0.1,0.1]x[-0.1,0.1]\n", tree.box(lo, hi).size());
  std::printf("tree: %zu points, depth %zu, %zu leaves, %zu bytes besides the points\n", tree.size(), tree.depth(),
              tree.leaf_count(), tree.index_bytes());
  return 0;
}
