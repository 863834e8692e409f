// Feature-vector search: find, for each query descriptor, its 5 nearest base descriptors.
//
//   feature_search BASE.fvecs QUERY.fvecs        (also .bvecs, .csv, .npy)
//
// Without arguments it makes 20,000 random 128-D descriptors (like SIFT) and 5 queries.
#include <kdspace/io/vectors.hpp>
#include <kdspace/kdspace.hpp>

#include <cstdio>
#include <random>

int main(int argc, char** argv) try {
  kdspace::io::Matrix<float> base, queries;
  if (argc == 3) {
    base = kdspace::io::read_points<float>(argv[1]);
    queries = kdspace::io::read_points<float>(argv[2]);
  } else {
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> byte(0, 255);  // SIFT components are small integers
    for (auto* m : {&base, &queries}) {
      m->cols = 128;
      m->rows = m == &base ? 20000 : 5;
      m->data.resize(m->rows * m->cols);
      for (auto& v : m->data) v = static_cast<float>(byte(rng));
    }
  }
  if (queries.cols != base.cols) {
    std::fprintf(stderr, "queries have dimension %zu, base has %zu\n", queries.cols, base.cols);
    return 1;
  }
  kdspace::PointTree<float> tree(base.data.data(), base.rows, base.cols);
  const auto answers = tree.knn_batch(queries.data.data(), queries.rows, 5);
  for (std::size_t q = 0; q < answers.rows() && q < 10; ++q) {
    std::printf("query %zu:", q);
    for (const auto& n : answers.row(q)) std::printf("  %u (%.1f)", n.index, static_cast<double>(n.distance));
    std::printf("\n");
  }
  return 0;
} catch (const kdspace::Error& e) {
  std::fprintf(stderr, "feature_search: %s\n", e.what());
  return 1;
}
