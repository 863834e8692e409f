// Fuzz target of the index file reader (kdspace/io/index_file.hpp) and every loader behind it
// (kdspace/io/index.hpp). The first input byte chooses how the rest is read: even, as it is (the
// checksums stop nearly every change); odd, with its checksums recomputed first, so that the
// structural checks of the loaders meet the changed bytes. Whatever loads is then queried, so that a
// structure the checks let through would show as a sanitizer report.
#include <cstdint>
#include <limits>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"

namespace {

namespace io = kdspace::io;
using File = std::shared_ptr<const io::IndexFile>;

// A few queries at the points' corner and beyond: k-NN, radius, box.
template <class Tree>
void query(const Tree& tree) {
  using T = typename Tree::Scalar;
  std::vector<T> q(tree.dim(), T(0.25)), lo(tree.dim(), T(-1)), hi(tree.dim(), T(1));
  if (tree.size() == 0) return;
  tree.knn(q.data(), std::min<std::size_t>(3, tree.size()));
  tree.radius(q.data(), T(0.5), 10);
  tree.box(lo.data(), hi.data());
}

template <class T, class Metric>
void load_trees(const File& file) {  // the metric (Minkowski's p) comes from the file
  if (file->info().kind == io::IndexKind::point_tree)
    query(io::load_point_tree<T, kdspace::Dynamic, Metric>(file));
  auto dynamic = io::load_dynamic_point_tree<T, kdspace::Dynamic, Metric>(file);
  query(dynamic);
  std::vector<T> row(dynamic.dim(), T(0.5));
  dynamic.insert(row.data(), 1);  // updates run on loaded parts too
  if (dynamic.contains(0)) dynamic.remove(0);
  query(dynamic);
}

template <class T>
void load_forest(const File& file) {
  const auto forest = io::load_point_forest<T>(file);
  std::vector<T> q(forest.dim(), T(3));
  forest.knn(q.data(), std::min<std::size_t>(2, forest.size()), {kdspace::unlimited_checks, 0});
  if (forest.has_graph()) forest.knn(q.data(), std::min<std::size_t>(2, forest.size()), {kdspace::unlimited_checks, 0, 4});
}

void load(const File& file) {
  const io::IndexInfo& info = file->info();
  const bool wide = info.scalar == io::ScalarType::float64;
  switch (info.kind) {
    case io::IndexKind::point_tree:
    case io::IndexKind::dynamic_point_tree:
      if (info.metric == io::MetricId::l1)
        wide ? load_trees<double, kdspace::L1>(file) : load_trees<float, kdspace::L1>(file);
      else if (info.metric == io::MetricId::linf)
        wide ? load_trees<double, kdspace::Linf>(file) : load_trees<float, kdspace::Linf>(file);
      else if (info.metric == io::MetricId::minkowski)
        wide ? load_trees<double, kdspace::Minkowski>(file) : load_trees<float, kdspace::Minkowski>(file);
      else
        wide ? load_trees<double, kdspace::L2>(file) : load_trees<float, kdspace::L2>(file);
      break;
    case io::IndexKind::point_forest:
      wide ? load_forest<double>(file) : load_forest<float>(file);
      break;
    case io::IndexKind::box_tree: {
      const kdspace::BoxTree tree = io::load_box_tree(file);
      tree.closest_hit(kdspace::Ray{{-1, 0.5f, 0.5f}, {1, 0.01f, 0.02f}});
      tree.any_hit(kdspace::Ray{{0.5f, 0.5f, 2}, {0, 0, -1}});
      break;
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  std::vector<unsigned char> bytes(data + 1, data + size);
  if (data[0] & 1) io::reseal_index_bytes(bytes);
  try {
    load(io::IndexFile::from_bytes(bytes.data(), bytes.size(), "fuzz.kdx"));
  } catch (const kdspace::Error&) {
  }
  return 0;
}
