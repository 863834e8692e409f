// Index files of the point indexes: the checks and parameters shared by PointTree and
// DynamicPointTree (whose save and load are templates in kdspace/io/index.hpp), and PointForest's
// save and load.
#include <cmath>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"

namespace kdspace::io {
namespace detail {

std::string with_article(const std::string& noun) {
  return (noun.find_first_of("aeiou") == 0 ? "an " : "a ") + noun;
}

void expect_header(const IndexFile& file, const std::vector<IndexKind>& kinds, ScalarType scalar,
                   MetricId metric, std::size_t dim) {
  const IndexInfo& info = file.info();
  bool kind_ok = false;
  for (IndexKind k : kinds) kind_ok = kind_ok || info.kind == k;
  if (!kind_ok)
    file.fail("holds " + with_article(name_of(info.kind)) + ", not " + with_article(name_of(kinds.front())));
  if (info.scalar != scalar)
    file.fail(std::string("holds ") + name_of(info.scalar) + " coordinates, expected " + name_of(scalar));
  if (info.metric != metric)
    file.fail(std::string("is built for metric ") + name_of(info.metric) + ", expected " + name_of(metric));
  if (info.dim == 0 || info.dim > info.file_bytes)
    file.fail("dimension " + std::to_string(info.dim) + " is impossible");
  if (dim != 0 && info.dim != dim)
    file.fail("dimension " + std::to_string(info.dim) + ", expected " + std::to_string(dim));
}

std::vector<std::uint64_t> point_tree_params(const BuildParams& p, double metric_parameter) {
  const std::uint64_t position = p.position == PositionRule::median             ? 0
                                 : p.position == PositionRule::middle           ? 1
                                 : p.position == PositionRule::sliding_midpoint ? 2
                                                                                : 3;
  return {p.axis == AxisRule::cycle ? 0u : 1u, position, p.leaf_size, p.max_depth, word_of(metric_parameter)};
}

double read_metric_parameter(const IndexFile& file) {
  return double_of(file.words(SectionType::params, 0, 1, 5)[4]);
}

BuildParams read_point_tree_params(const IndexFile& file) {
  const std::vector<std::uint64_t> w = file.words(SectionType::params, 0, 1, 5);
  if (w[0] > 1 || w[1] > 3 || w[2] == 0 || w[2] > (std::uint64_t{1} << 30) || w[3] > 256)
    file.fail("build parameters out of range (axis " + std::to_string(w[0]) + ", position " +
              std::to_string(w[1]) + ", leaf size " + std::to_string(w[2]) + ", max depth " +
              std::to_string(w[3]) + ")");
  BuildParams p;
  p.axis = w[0] == 0 ? AxisRule::cycle : AxisRule::max_spread;
  p.position = w[1] == 0   ? PositionRule::median
               : w[1] == 1 ? PositionRule::middle
               : w[1] == 2 ? PositionRule::sliding_midpoint
                           : PositionRule::midpoint;
  p.leaf_size = static_cast<std::size_t>(w[2]);
  p.max_depth = static_cast<std::size_t>(w[3]);
  return p;
}

std::size_t level_for(std::size_t n, std::size_t base_capacity) {
  std::size_t level = 0;
  while ((base_capacity << level) < n) ++level;
  return level;
}

}  // namespace detail

// ---- PointForest ---------------------------------------------------------------------------------------
// Sections: params (the ForestParams, the projected dimensions, the stored search setting), mean,
// projection, points (T) or point bytes, ids (original index of each row), per tree t its nodes
// and order, and the neighbour graph when the forest has one.

namespace {

/// The forest's node array is stored as the forest keeps it. Layout 1: {float left_max; float
/// right_min; uint32 link; uint32 info}.
constexpr std::uint32_t forest_node_layout = 1;
static_assert(sizeof(PointForest<float>::Node) == 16, "PointForest::Node changed: update forest_node_layout");

// Version 2 of the params section: version 1's 13 words, then the graph's parameters, the width of
// its lists (0: no graph) and the stored ef.
constexpr std::uint32_t forest_params_version = 2;
constexpr std::size_t forest_param_words = 19;

std::uint64_t word_of_graph_mode(GraphMode mode) {
  return mode == GraphMode::automatic ? 0 : mode == GraphMode::on ? 1 : 2;
}

}  // namespace

template <class T>
void save(const std::string& path, const PointForest<T>& forest, const ForestSearchParams* search) {
  const typename PointForest<T>::Parts p = forest.parts();
  const ForestParams& f = p.params;
  IndexWriter w(IndexKind::point_forest, detail::scalar_of<T>(), MetricId::l2, p.dim, p.ids.size());
  w.add_words(SectionType::params, 0, forest_params_version,
              {f.trees, f.leaf_size, f.pca ? 1u : 0u, f.projected_dims, word_of(f.variance_share),
               f.compact ? 1u : 0u, f.candidate_axes, f.variance_sample, f.pca_sample, f.seed,
               p.projected_dims, search ? search->checks : 0, search ? search->trees : 0,
               word_of_graph_mode(f.graph), f.graph_degree, f.graph_build_ef, word_of(f.graph_alpha), p.graph_degree,
               search ? search->ef : 0});
  w.add(SectionType::mean, 0, 1, p.mean.data(), p.mean.size());
  w.add(SectionType::projection, 0, 1, p.projection.data(), p.projection.size());
  if (!p.bytes.empty())
    w.add(SectionType::point_bytes, 0, 1, p.bytes.data(), p.bytes.size());
  else
    w.add(SectionType::points, 0, 1, p.points.data(), p.points.size());
  w.add(SectionType::ids, 0, 1, p.ids.data(), p.ids.size());
  for (std::uint32_t t = 0; t < p.nodes.size(); ++t) {
    w.add(SectionType::nodes, t, forest_node_layout, p.nodes[t].data(), p.nodes[t].size());
    w.add(SectionType::order, t, 1, p.orders[t].data(), p.orders[t].size());
  }
  if (p.graph_degree != 0) w.add(SectionType::graph, 0, 1, p.graph_links.data(), p.graph_links.size());
  w.write(path);
}

template <class T>
PointForest<T> load_point_forest(const std::shared_ptr<const IndexFile>& file, ForestSearchParams* search) {
  detail::expect_header(*file, {IndexKind::point_forest}, detail::scalar_of<T>(), MetricId::l2, 0);
  const std::vector<std::uint64_t> w = file->words(SectionType::params, 0, forest_params_version, forest_param_words);
  if (w[0] == 0 || w[0] > 1024 || w[2] > 1 || w[5] > 1 || w[12] > w[0] || w[13] > 2 || w[14] > 1024 ||
      w[15] > (std::uint64_t{1} << 30) || w[17] > 1024)
    file->fail("forest parameters out of range");
  typename PointForest<T>::Parts p;
  ForestParams& f = p.params;
  f.trees = static_cast<std::size_t>(w[0]);
  f.leaf_size = static_cast<std::size_t>(w[1]);
  f.pca = w[2] == 1;
  f.projected_dims = static_cast<std::size_t>(w[3]);
  f.variance_share = double_of(w[4]);
  f.compact = w[5] == 1;
  f.candidate_axes = static_cast<std::size_t>(w[6]);
  f.variance_sample = static_cast<std::size_t>(w[7]);
  f.pca_sample = static_cast<std::size_t>(w[8]);
  f.seed = w[9];
  p.projected_dims = static_cast<std::size_t>(std::min<std::uint64_t>(w[10], 1u << 20));
  f.graph = w[13] == 0 ? GraphMode::automatic : w[13] == 1 ? GraphMode::on : GraphMode::off;
  f.graph_degree = static_cast<std::size_t>(w[14]);
  f.graph_build_ef = static_cast<std::size_t>(w[15]);
  f.graph_alpha = double_of(w[16]);
  p.graph_degree = static_cast<std::size_t>(w[17]);
  if (w[18] != 0 && w[17] == 0) file->fail("stores a graph search (ef " + std::to_string(w[18]) + ") but no graph");
  if (search)
    *search = ForestSearchParams{static_cast<std::size_t>(w[11]), static_cast<std::size_t>(w[12]),
                                 static_cast<std::size_t>(w[18])};
  p.dim = static_cast<std::size_t>(file->info().dim);
  const auto mean = file->array<double>(SectionType::mean, 0, 1);
  const auto projection = file->array<double>(SectionType::projection, 0, 1);
  p.mean.assign(mean.begin(), mean.end());
  p.projection.assign(projection.begin(), projection.end());
  if (file->find(SectionType::point_bytes))
    p.bytes = file->array<std::uint8_t>(SectionType::point_bytes, 0, 1);
  else
    p.points = file->array<T>(SectionType::points, 0, 1);
  p.ids = file->array<std::uint32_t>(SectionType::ids, 0, 1);
  if (p.ids.size() != file->info().count)
    file->fail("the header says " + std::to_string(file->info().count) + " points, the forest holds " +
               std::to_string(p.ids.size()));
  for (std::uint32_t t = 0; t < f.trees; ++t) {
    p.nodes.push_back(file->array<typename PointForest<T>::Node>(SectionType::nodes, t, forest_node_layout));
    p.orders.push_back(file->array<std::uint32_t>(SectionType::order, t, 1));
  }
  if (p.graph_degree != 0) p.graph_links = file->array<std::uint32_t>(SectionType::graph, 0, 1);
  else if (file->find(SectionType::graph)) file->fail("holds a graph section, but its parameters say no graph");
  p.backing = file;
  try {
    return PointForest<T>(std::move(p));
  } catch (const Error& e) {
    file->fail(e.what());
  }
}

template void save<float>(const std::string&, const PointForest<float>&, const ForestSearchParams*);
template void save<double>(const std::string&, const PointForest<double>&, const ForestSearchParams*);
template PointForest<float> load_point_forest<float>(const std::shared_ptr<const IndexFile>&,
                                                     ForestSearchParams*);
template PointForest<double> load_point_forest<double>(const std::shared_ptr<const IndexFile>&,
                                                       ForestSearchParams*);

}  // namespace kdspace::io
