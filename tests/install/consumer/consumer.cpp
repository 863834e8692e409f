// Builds a tree from the installed kdspace, answers one query, checks it against brute force.
#include <kdspace/kdspace.hpp>

#include <cstdio>
#include <vector>

int main() {
  std::vector<float> points;
  for (int i = 0; i < 100; ++i) {
    points.push_back(static_cast<float>(i % 10));
    points.push_back(static_cast<float>(i / 10));
  }
  kdspace::PointTree<float> tree(points.data(), 100, 2);
  const float query[2] = {3.2f, 4.9f};
  const auto found = tree.knn(query, 3);
  const auto expected = kdspace::brute_force_knn(points.data(), 100, 2, query, 3);
  if (found.size() != 3 || !(found[0] == expected[0] && found[1] == expected[1] && found[2] == expected[2])) {
    std::printf("consumer: wrong answer\n");
    return 1;
  }
  std::printf("consumer: nearest to (3.2, 4.9) is point %u at distance %.4f (kdspace %s)\n", found[0].index,
              static_cast<double>(found[0].distance), kdspace::version);
  return 0;
}
