// Saving indexes to .kdx files and loading them back (the file format: io/index_file.hpp).
//
//   kdspace::io::save("points.kdx", tree);                      // PointTree, DynamicPointTree,
//                                                               // PointForest, BoxTree; atomic
//   auto tree = kdspace::io::load_point_tree<float>("points.kdx");   // memory-mapped
//   auto copy = kdspace::io::load_point_tree<float>("points.kdx", kdspace::io::LoadMode::read);
//   auto dyn  = kdspace::io::load_dynamic_point_tree<float>("points.kdx");  // either kind of tree file
//   auto forest = kdspace::io::load_point_forest<float>("forest.kdx");
//   auto boxes  = kdspace::io::load_box_tree("scene.kdx");
//
// A loaded index answers exactly as the one that was saved. Loaded by memory-mapping (the default),
// its arrays are the file's pages: loading costs a check of the file (every checksum, then the
// structure), not a copy, and the index keeps the mapping alive. The file must not be changed in
// place while mapped; saving over it is safe (save() writes a new file and renames it, so the
// mapping keeps the old one). Every problem throws kdspace::Error("PATH: what is wrong").
//
// To answer before every checksum is verified (what `kdspace knn --index` does), ask for it:
//
//   kdspace::io::PendingChecksums pending;
//   auto tree = kdspace::io::load_point_tree_deferred<float>(
//       kdspace::io::IndexFile::open(path, kdspace::io::LoadMode::map, kdspace::io::Checksums::deferred),
//       kdspace::Verify::safety, 2, &pending);   // returns once the structure is checked
//   ... queries (safe whatever the bytes) ...
//   pending.wait();                              // throws if a section is damaged: then drop them
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "kdspace/io/index_file.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/dynamic_point_tree.hpp"
#include "kdspace/points/point_forest.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace::io {

namespace detail {

template <class T>
constexpr ScalarType scalar_of() {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "float or double");
  return std::is_same_v<T, float> ? ScalarType::float32 : ScalarType::float64;
}

template <class Metric>
constexpr MetricId metric_of() {
  static_assert(std::is_same_v<Metric, L2> || std::is_same_v<Metric, L1> || std::is_same_v<Metric, Linf> ||
                    std::is_same_v<Metric, Minkowski>,
                "index files hold the metrics L2, L1, Linf and Minkowski");
  if constexpr (std::is_same_v<Metric, L2>)
    return MetricId::l2;
  else if constexpr (std::is_same_v<Metric, L1>)
    return MetricId::l1;
  else if constexpr (std::is_same_v<Metric, Linf>)
    return MetricId::linf;
  else
    return MetricId::minkowski;
}

/// The metric's parameter, as stored in the params section: Minkowski's order p, else 0.
template <class Metric>
double metric_parameter(const Metric& metric) {
  if constexpr (std::is_same_v<Metric, Minkowski>)
    return metric.p;
  else
    return 0;
}

/// The point tree's node array is stored as the tree keeps it. Layout 1: PointNode<T> =
/// {T left_max; T right_min; uint32 link; uint32 info}. A change of PointNode must bump this number
/// (the asserts below stop the build until it is looked at).
inline constexpr std::uint32_t point_node_layout = 1;
static_assert(sizeof(kdspace::detail::PointNode<float>) == 16 &&
                  sizeof(kdspace::detail::PointNode<double>) == 24,
              "PointNode changed: update point_node_layout and the loader");
static_assert(offsetof(kdspace::detail::PointNode<float>, link) == 8 &&
                  offsetof(kdspace::detail::PointNode<float>, info) == 12,
              "PointNode changed: update point_node_layout and the loader");

/// Throws Error("PATH: ...") unless the file holds one of `kinds`, with that scalar type and metric,
/// and (dim != 0) that dimension.
void expect_header(const IndexFile& file, const std::vector<IndexKind>& kinds, ScalarType scalar,
                   MetricId metric, std::size_t dim);
/// "a point tree", "an updatable point tree".
std::string with_article(const std::string& noun);
/// The point tree's build parameters as params words, and back (checked).
std::vector<std::uint64_t> point_tree_params(const BuildParams& params, double metric_parameter);
BuildParams read_point_tree_params(const IndexFile& file);
/// The metric's parameter stored with a point tree (0 when it has none).
double read_metric_parameter(const IndexFile& file);

/// The metric a point tree file was saved with.
template <class Metric>
Metric metric_from(const IndexFile& file) {
  if constexpr (std::is_same_v<Metric, Minkowski>) {
    try {
      return Minkowski(read_metric_parameter(file));
    } catch (const Error& e) {
      file.fail(e.what());
    }
  } else {
    (void)file;
    return Metric{};
  }
}

template <class T>
void add_tree_sections(IndexWriter& w, const kdspace::detail::PointTreeParts<T>& p, std::uint32_t part) {
  w.add(SectionType::nodes, part, point_node_layout, p.nodes.data(), p.nodes.size());
  w.add(SectionType::points, part, 1, p.points.data(), p.points.size());
  w.add(SectionType::order, part, 1, p.order.data(), p.order.size());
  std::vector<T> bounds = p.root_lo;
  bounds.insert(bounds.end(), p.root_hi.begin(), p.root_hi.end());
  w.add_values(SectionType::bounds, part, 1, std::move(bounds));
}

template <class T>
kdspace::detail::PointTreeParts<T> tree_sections(const std::shared_ptr<const IndexFile>& file,
                                                 std::uint32_t part, const BuildParams& params) {
  kdspace::detail::PointTreeParts<T> p;
  p.dim = static_cast<std::size_t>(file->info().dim);
  p.params = params;
  p.nodes = file->array<kdspace::detail::PointNode<T>>(SectionType::nodes, part, point_node_layout);
  p.points = file->array<T>(SectionType::points, part, 1);
  p.order = file->array<std::uint32_t>(SectionType::order, part, 1);
  const auto bounds = file->array<T>(SectionType::bounds, part, 1, 2 * p.dim);
  p.root_lo.assign(bounds.begin(), bounds.begin() + p.dim);
  p.root_hi.assign(bounds.begin() + p.dim, bounds.end());
  p.backing = file;
  return p;
}

/// The smallest level of a DynamicPointTree whose parts may hold n points.
std::size_t level_for(std::size_t n, std::size_t base_capacity);

}  // namespace detail

/// Runs load(file) (one of the loaders below that take an IndexFile) on a file opened with
/// Checksums::deferred, while a second thread checks the file's checksums; when load is done, the
/// calling thread takes its share of what is left of them (IndexFile::ChecksumPass), so that the
/// two threads share the whole work. The structural checks are safe on any bytes. A checksum error
/// wins over load's (it explains any other). The loaders that take a path work this way, but for the
/// point tree's and the box tree's, whose checks share their own threads with the checksums
/// (load_point_tree_deferred, load_box_tree_deferred).
template <class Load>
auto load_with_checksums(const std::shared_ptr<const IndexFile>& file, Load load) {
  IndexFile::ChecksumPass checksums(*file);
  std::optional<decltype(load(file))> result;
  std::exception_ptr load_error;
  kdspace::detail::fork_join([&checksums] { checksums.run(); },
                             [&] {
                               try {
                                 result.emplace(load(file));
                               } catch (...) {
                                 load_error = std::current_exception();
                               }
                               checksums.run();
                             });
  checksums.finish();
  if (load_error) std::rethrow_exception(load_error);
  return std::move(*result);
}

namespace detail {
template <class Load>
auto load_checked(const std::string& path, LoadMode mode, Load load) {
  return load_with_checksums(IndexFile::open(path, mode, Checksums::deferred), load);
}

/// The readers of a point tree's check (kdspace::detail::check_rows, check_nodes): the sections it
/// reads front to back, row by row and node by node.
inline std::vector<SectionChecksums::Reader> point_tree_readers(const IndexFile& file,
                                                                std::size_t row_bytes) {
  const SectionEntry* nodes = file.find(SectionType::nodes);
  return {{kdspace::detail::check_rows, file.find(SectionType::points), row_bytes},
          {kdspace::detail::check_rows, file.find(SectionType::order), sizeof(std::uint32_t)},
          {kdspace::detail::check_nodes, nodes, nodes ? nodes->item_bytes : 1}};
}

/// Runs load(companion), a loader whose structural check takes the file's checksums on its own threads
/// (a SectionChecksums over the sections it reads, `readers`), then judges the checksums; a damaged
/// section explains any other problem: its message wins.
template <class Load>
auto load_beside_checksums(const IndexFile& file, const std::vector<SectionChecksums::Reader>& readers,
                           Load load) {
  SectionChecksums checksums(file, readers);
  std::optional<decltype(load(&checksums))> result;
  try {
    result.emplace(load(&checksums));
  } catch (...) {
    checksums.finish();
    throw;
  }
  checksums.finish();
  return std::move(*result);
}

template <class T, int Dim, class Metric>
PointTree<T, Dim, Metric> point_tree_of(const std::shared_ptr<const IndexFile>& file,
                                        kdspace::detail::CheckCompanion* companion, Verify verify,
                                        unsigned threads = 2) {
  detail::expect_header(*file, {IndexKind::point_tree}, detail::scalar_of<T>(), detail::metric_of<Metric>(),
                        Dim == Dynamic ? 0 : static_cast<std::size_t>(Dim));
  auto parts = detail::tree_sections<T>(file, 0, detail::read_point_tree_params(*file));
  if (parts.order.size() != file->info().count)
    file->fail("the header says " + std::to_string(file->info().count) + " points, the tree holds " +
               std::to_string(parts.order.size()));
  parts.companion = companion;
  parts.check_threads = threads;
  parts.verify = verify;
  try {
    return PointTree<T, Dim, Metric>(std::move(parts), detail::metric_from<Metric>(*file));
  } catch (const Error& e) {
    file->fail(e.what());
  }
}
}  // namespace detail

// ---- PointTree ---------------------------------------------------------------------------------------

template <class T, int Dim, class Metric>
void save(const std::string& path, const PointTree<T, Dim, Metric>& tree) {
  const auto parts = tree.parts();
  IndexWriter w(IndexKind::point_tree, detail::scalar_of<T>(), detail::metric_of<Metric>(), tree.dim(),
                tree.size());
  w.add_words(SectionType::params, 0, 1, detail::point_tree_params(parts.params, detail::metric_parameter(tree.metric())));
  detail::add_tree_sections(w, parts, 0);
  w.write(path);
}

/// `verify` (params.hpp): Verify::safety checks what keeps every query in bounds, Verify::full also
/// that the answers are brute force's over the file's points whoever wrote it (a pass over every
/// coordinate; for files from elsewhere). The checksums are verified either way.
template <class T, int Dim = Dynamic, class Metric = L2>
PointTree<T, Dim, Metric> load_point_tree(const std::shared_ptr<const IndexFile>& file,
                                          Verify verify = Verify::safety) {
  return detail::point_tree_of<T, Dim, Metric>(file, nullptr, verify);
}

/// Loads a point tree from a file opened with Checksums::deferred, whose checksums its structural check
/// takes on its own threads (what load_point_tree(path) does once it has opened the file). `threads`:
/// 1 checks on the calling thread alone; 2 or more on that many threads for a tree of 131,072 points or
/// more (kdspace::detail::parallel_tree_check), which take its subtrees in turn, each checksumming the
/// bytes it reads; 0 on as many as pay for their start (kdspace::detail::check_threads_that_pay: 4 for
/// the 18 MB of 1e6 3-D float points, never more than the hardware has).
///
/// With `pending` and Verify::safety, the load leaves the checksums to `pending` (PendingChecksums:
/// wait() before an answer is used) and returns once the tree is safe to query. The check runs without
/// them, reading the nodes and the order alone (a third of 3-D float points' file); then they start
/// on a thread of their own (where `threads` is 2 or more, or 0 and two pay for their start).
template <class T, int Dim = Dynamic, class Metric = L2>
PointTree<T, Dim, Metric> load_point_tree_deferred(const std::shared_ptr<const IndexFile>& file,
                                                   Verify verify = Verify::safety, unsigned threads = 2,
                                                   PendingChecksums* pending = nullptr) {
  if (pending && verify == Verify::safety) {
    const unsigned all =
        kdspace::detail::check_threads_for(threads, static_cast<std::size_t>(file->info().file_bytes));
    PointTree<T, Dim, Metric> tree = [&] {
      try {
        return detail::point_tree_of<T, Dim, Metric>(file, nullptr, verify, threads);
      } catch (const Error&) {
        pending->start(file, false);
        pending->wait();  // a damaged section explains the problem: its message wins
        throw;
      }
    }();
    pending->start(file, all >= 2);
    return tree;
  }
  return detail::load_beside_checksums(
      *file, detail::point_tree_readers(*file, static_cast<std::size_t>(file->info().dim) * sizeof(T)),
      [&](kdspace::detail::CheckCompanion* checksums) {
        return detail::point_tree_of<T, Dim, Metric>(file, checksums, verify, threads);
      });
}

template <class T, int Dim = Dynamic, class Metric = L2>
PointTree<T, Dim, Metric> load_point_tree(const std::string& path, LoadMode mode = LoadMode::map,
                                          Verify verify = Verify::safety, unsigned threads = 2) {
  return load_point_tree_deferred<T, Dim, Metric>(IndexFile::open(path, mode, Checksums::deferred), verify,
                                                  threads);
}

// ---- DynamicPointTree ----------------------------------------------------------------------------------
// Sections: params; dynamic_state (uint64 words: the next id, the base capacity, the number P of
// parts, each part's level, the number of buffered points); for each part p < P its nodes, points,
// order and bounds (as a PointTree's), ids, and removed (when some are); and for the buffer, when it
// holds points, points and ids of part P.

template <class T, int Dim, class Metric>
void save(const std::string& path, const DynamicPointTree<T, Dim, Metric>& tree) {
  const auto parts = tree.parts();  // one snapshot, kept alive until written
  std::size_t live = parts.buffer_ids.size();
  for (const auto& p : parts.parts) live += p.ids.size() - p.removed.size();
  IndexWriter w(IndexKind::dynamic_point_tree, detail::scalar_of<T>(), detail::metric_of<Metric>(),
                tree.dim(), live);
  w.add_words(SectionType::params, 0, 1, detail::point_tree_params(parts.params, detail::metric_parameter(tree.metric())));
  std::vector<std::uint64_t> state{parts.next_id, parts.base_capacity, parts.parts.size()};
  for (const auto& p : parts.parts) state.push_back(p.level);
  state.push_back(parts.buffer_ids.size());
  w.add_words(SectionType::dynamic_state, 0, 1, std::move(state));
  for (std::uint32_t i = 0; i < parts.parts.size(); ++i) {
    const auto& p = parts.parts[i];
    detail::add_tree_sections(w, p.tree, i);
    w.add(SectionType::ids, i, 1, p.ids.data(), p.ids.size());
    if (!p.removed.empty()) w.add(SectionType::removed, i, 1, p.removed.data(), p.removed.size());
  }
  if (!parts.buffer_ids.empty()) {
    const auto buffer_part = static_cast<std::uint32_t>(parts.parts.size());
    w.add(SectionType::points, buffer_part, 1, parts.buffer_rows.data(), parts.buffer_rows.size());
    w.add(SectionType::ids, buffer_part, 1, parts.buffer_ids.data(), parts.buffer_ids.size());
  }
  w.write(path);
}

/// Loads a DynamicPointTree, or a PointTree file as one (its indices become the ids; the next id is
/// the number of points).
template <class T, int Dim = Dynamic, class Metric = L2>
DynamicPointTree<T, Dim, Metric> load_dynamic_point_tree(const std::shared_ptr<const IndexFile>& file) {
  using Dyn = DynamicPointTree<T, Dim, Metric>;
  detail::expect_header(*file, {IndexKind::point_tree, IndexKind::dynamic_point_tree}, detail::scalar_of<T>(),
                        detail::metric_of<Metric>(), Dim == Dynamic ? 0 : static_cast<std::size_t>(Dim));
  kdspace::detail::DynamicTreeParts<T> parts;
  parts.dim = static_cast<std::size_t>(file->info().dim);
  parts.params = detail::read_point_tree_params(*file);
  parts.backing = file;
  if (file->info().kind == IndexKind::point_tree) {
    kdspace::detail::DynamicPartParts<T> p;
    p.tree = detail::tree_sections<T>(file, 0, parts.params);
    std::vector<Index> ids(p.tree.order.size());
    for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = static_cast<Index>(i);
    p.ids = kdspace::detail::Storage<Index>(std::move(ids));
    p.level = detail::level_for(p.tree.order.size(), parts.base_capacity);
    parts.next_id = p.tree.order.size();
    parts.parts.push_back(std::move(p));
  } else {
    const std::vector<std::uint64_t> state = file->words(SectionType::dynamic_state, 0, 1, 4);
    const std::uint64_t part_count = state[2];
    if (part_count > max_sections || state.size() != 4 + part_count || state[1] == 0 || state[1] > (1u << 30))
      file->fail("dynamic state is inconsistent (" + std::to_string(part_count) + " parts in " +
                 std::to_string(state.size()) + " words, base capacity " + std::to_string(state[1]) + ")");
    parts.next_id = state[0];
    parts.base_capacity = static_cast<std::size_t>(state[1]);
    for (std::uint32_t i = 0; i < part_count; ++i) {
      kdspace::detail::DynamicPartParts<T> p;
      p.tree = detail::tree_sections<T>(file, i, parts.params);
      p.ids = file->array<Index>(SectionType::ids, i, 1);
      if (file->find(SectionType::removed, i))
        p.removed = file->array<std::uint32_t>(SectionType::removed, i, 1);
      p.level = static_cast<std::size_t>(std::min<std::uint64_t>(state[3 + i], 1u << 20));
      parts.parts.push_back(std::move(p));
    }
    if (state.back() > 0) {
      const auto buffer_part = static_cast<std::uint32_t>(part_count);
      const auto buffered = static_cast<std::size_t>(std::min<std::uint64_t>(state.back(), 1u << 30));
      parts.buffer_ids = file->array<Index>(SectionType::ids, buffer_part, 1, buffered);
      parts.buffer_rows = file->array<T>(SectionType::points, buffer_part, 1);
    }
  }
  try {
    Dyn tree(std::move(parts), detail::metric_from<Metric>(*file));
    if (tree.size() != file->info().count)
      file->fail("the header says " + std::to_string(file->info().count) + " points, the index holds " +
                 std::to_string(tree.size()));
    return tree;
  } catch (const Error& e) {
    const std::string what = e.what();
    if (what.rfind(file->path() + ": ", 0) == 0) throw;
    file->fail(what);
  }
}

template <class T, int Dim = Dynamic, class Metric = L2>
DynamicPointTree<T, Dim, Metric> load_dynamic_point_tree(const std::string& path,
                                                         LoadMode mode = LoadMode::map) {
  return detail::load_checked(path, mode, [](const std::shared_ptr<const IndexFile>& file) {
    return load_dynamic_point_tree<T, Dim, Metric>(file);
  });
}

// ---- PointForest and BoxTree (compiled in the library) --------------------------------------------------

/// Saves a forest; `search`, when given, is stored as the setting to search it with (a tuned one).
template <class T>
void save(const std::string& path, const PointForest<T>& forest, const ForestSearchParams* search = nullptr);
/// Loads a forest; `search`, when given, receives the stored search setting (checks and ef 0 when none).
template <class T>
PointForest<T> load_point_forest(const std::shared_ptr<const IndexFile>& file,
                                 ForestSearchParams* search = nullptr);
template <class T>
PointForest<T> load_point_forest(const std::string& path, LoadMode mode = LoadMode::map,
                                 ForestSearchParams* search = nullptr) {
  return detail::load_checked(path, mode, [search](const std::shared_ptr<const IndexFile>& file) {
    return load_point_forest<T>(file, search);
  });
}

void save(const std::string& path, const BoxTree& tree);
BoxTree load_box_tree(const std::shared_ptr<const IndexFile>& file);
/// Loads a box tree from a file opened with Checksums::deferred, whose checksums its structural check
/// takes on its own threads (two for a large tree).
BoxTree load_box_tree_deferred(const std::shared_ptr<const IndexFile>& file);
inline BoxTree load_box_tree(const std::string& path, LoadMode mode = LoadMode::map) {
  return load_box_tree_deferred(IndexFile::open(path, mode, Checksums::deferred));
}

extern template void save<float>(const std::string&, const PointForest<float>&, const ForestSearchParams*);
extern template void save<double>(const std::string&, const PointForest<double>&, const ForestSearchParams*);
extern template PointForest<float> load_point_forest<float>(const std::shared_ptr<const IndexFile>&,
                                                            ForestSearchParams*);
extern template PointForest<double> load_point_forest<double>(const std::shared_ptr<const IndexFile>&,
                                                              ForestSearchParams*);

}  // namespace kdspace::io
