// Overlap queries and overlapping pairs on a BoxTree (kdspace/collide/overlap.hpp): each is a rule
// applied at the leaves that one of the shared traversals (traversal.hpp) reaches.
#include "kdspace/collide/overlap.hpp"

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/rays/ray.hpp"
#include "pair_sort.hpp"
#include "traversal.hpp"
#include "tree_access.hpp"

namespace kdspace {

namespace {

using detail::NodeAndCell;
using detail::NodeId;
using detail::owns;
using detail::pair_point;
using detail::TreeAccess;

/// Queries handed to a thread at a time.
constexpr std::size_t query_chunk = 64;

void check_query(const Box3f& query, const std::string& where) {
  const std::string problem = box_problem(query);
  if (!problem.empty()) throw Error(where + ": " + problem);
}

/// The rule of an overlap query at a leaf: the leaf's boxes that overlap the query and whose pair
/// point with it the leaf owns.
void overlapping_in_leaf(const TreeAccess& tree, NodeId leaf, const Box3f& cell, const Box3f& query,
                         std::vector<std::uint32_t>& ids, CollideStats& stats) {
  const std::uint32_t count = tree.leaf_size(leaf);
  const std::uint32_t* leaf_ids = tree.leaf_ids(leaf);
  const auto boxes = tree.leaf_boxes(leaf);
  stats.boxes_tested += count;
  for (std::uint32_t i = 0; i < count; ++i) {
    const Box3f& b = boxes[i];
    if (query.overlaps(b) && owns(cell, b, pair_point(query, b))) ids.push_back(leaf_ids[i]);
  }
}

/// The rule shared by the pair searches: box b, met in a leaf of cell `cell`, against every box of
/// `leaf` (cell `leaf_cell`, maybe of another tree); emit(id) for each box that overlaps b where
/// both leaves own the pair point.
template <class Emit>
void pair_with_leaf(const Box3f& b, const Box3f& cell, const TreeAccess& tree, NodeId leaf,
                    const Box3f& leaf_cell, CollideStats& stats, Emit&& emit) {
  const std::uint32_t count = tree.leaf_size(leaf);
  const std::uint32_t* ids = tree.leaf_ids(leaf);
  const auto boxes = tree.leaf_boxes(leaf);
  stats.boxes_tested += count;
  for (std::uint32_t y = 0; y < count; ++y) {
    const Box3f& by = boxes[y];
    if (!b.overlaps(by)) continue;
    const auto c = pair_point(b, by);
    if (owns(cell, b, c) && owns(leaf_cell, by, c)) emit(ids[y]);
  }
}

void overlapping_into(const TreeAccess& tree, const Box3f& query, std::vector<std::uint32_t>& ids,
                      CollideStats& stats) {
  ++stats.queries;
  detail::for_each_leaf_touching(tree, query, stats.nodes_visited, [&](NodeId leaf, const Box3f& cell) {
    overlapping_in_leaf(tree, leaf, cell, query, ids, stats);
  });
  std::sort(ids.begin(), ids.end());
}

// ---- pairs within one set -------------------------------------------------------------------------

/// The region where a box of a leaf may meet boxes of the leaves to the right of its own that it
/// shares no leaf with: its faces that lie on the leaf's upper faces (inside the scene). Empty when
/// it has none: then all its partners share a leaf with it. With one such face, the face; with more,
/// the whole box.
bool beyond_region(const Box3f& box, const Box3f& cell, const Box3f& root, Box3f& region) {
  int faces = 0, axis = 0;
  for (int a = 0; a < 3; ++a)
    if (box.hi[a] == cell.hi[a] && cell.hi[a] < root.hi[a]) {
      ++faces;
      axis = a;
    }
  if (faces == 0) return false;
  region = box;
  if (faces == 1) region.lo[axis] = box.hi[axis];
  return true;
}

/// The pairs of one leaf: every two of its boxes whose pair point the leaf owns for both; and for a
/// box on the leaf's upper faces, its partners in leaves to the right that the leaf does not share
/// with it (a pair of boxes that only touch, in a plane that one of them ends on). A pair whose
/// owning leaves differ is found from the box in the leaf of smaller rank (the box that ends on the
/// plane of their lowest common ancestor), so it is found once.
/// `boxes` is scratch: the leaf's boxes are read out of its blocks once, for the all-against-all loop.
void pairs_of_leaf(const TreeAccess& tree, const NodeAndCell& leaf, std::vector<IndexPair>& out,
                   std::vector<Box3f>& boxes, CollideStats& stats) {
  const std::uint32_t count = tree.leaf_size(leaf.node);
  const std::uint32_t* ids = tree.leaf_ids(leaf.node);
  const auto leaf_boxes = tree.leaf_boxes(leaf.node);
  boxes.resize(count);
  for (std::uint32_t i = 0; i < count; ++i) boxes[i] = leaf_boxes[i];
  const Box3f& cell = leaf.cell;
  for (std::uint32_t x = 0; x < count; ++x) {
    const Box3f& bx = boxes[x];
    for (std::uint32_t y = x + 1; y < count; ++y) {
      const Box3f& by = boxes[y];
      if (!bx.overlaps(by)) continue;
      const auto c = pair_point(bx, by);
      if (owns(cell, bx, c) && owns(cell, by, c)) out.push_back({ids[x], ids[y]});  // ids ascending
    }
    stats.boxes_tested += count - x - 1;

    Box3f region;
    if (!beyond_region(bx, cell, tree.root_cell(), region)) continue;
    const NodeId rank = tree.leaf_rank(leaf.node);
    detail::for_each_leaf_touching(
        tree, region, stats.nodes_visited, [&](NodeId other, const Box3f& other_cell) {
          if (tree.leaf_rank(other) <= rank) return;
          pair_with_leaf(bx, cell, tree, other, other_cell, stats, [&](std::uint32_t id) {
            out.push_back({std::min(ids[x], id), std::max(ids[x], id)});
          });
        });
  }
}

/// The pairs of a leaf of one tree and a leaf of another: each box of the first that reaches the
/// second's cell, against the second's boxes.
void pairs_of_leaf_pair(const TreeAccess& ta, const NodeAndCell& a, const TreeAccess& tb,
                        const NodeAndCell& b, std::vector<IndexPair>& out, CollideStats& stats) {
  const std::uint32_t count = ta.leaf_size(a.node);
  const std::uint32_t* ids = ta.leaf_ids(a.node);
  const auto boxes = ta.leaf_boxes(a.node);
  for (std::uint32_t x = 0; x < count; ++x) {
    const Box3f& bx = boxes[x];
    if (!bx.overlaps(b.cell)) continue;
    pair_with_leaf(bx, a.cell, tb, b.node, b.cell, stats, [&](std::uint32_t id) {
      out.push_back({ids[x], id});
    });
  }
}

}  // namespace

std::vector<std::uint32_t> overlapping(const BoxTree& tree, const Box3f& query, CollideStats* stats) {
  check_query(query, "query box");
  CollideStats local;
  std::vector<std::uint32_t> ids;
  overlapping_into(TreeAccess(tree), query, ids, local);
  if (stats) *stats += local;
  return ids;
}

OverlapLists overlapping_batch(const BoxTree& tree, const Box3f* queries, std::size_t n, unsigned threads,
                               CollideStats* stats) {
  if (n > 0 && queries == nullptr) throw Error("queries: null pointer");
  for (std::size_t q = 0; q < n; ++q) check_query(queries[q], "query " + std::to_string(q + 1));
  const TreeAccess access(tree);
  const unsigned workers = detail::resolve_threads(threads);

  // Each run of queries a thread takes keeps its answers together; the runs are joined in order.
  struct Run {
    std::size_t begin;
    std::vector<std::uint32_t> ids;
  };
  std::vector<std::vector<Run>> runs(workers);
  std::vector<CollideStats> per_worker(workers);
  std::vector<std::size_t> counts(n);
  detail::parallel_for(n, workers, query_chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
    Run run{begin, {}};
    std::vector<std::uint32_t> ids;
    for (std::size_t q = begin; q < end; ++q) {
      ids.clear();
      overlapping_into(access, queries[q], ids, per_worker[worker]);
      counts[q] = ids.size();
      run.ids.insert(run.ids.end(), ids.begin(), ids.end());
    }
    runs[worker].push_back(std::move(run));
  });

  std::vector<Run> ordered;
  for (auto& list : runs)
    for (Run& run : list) ordered.push_back(std::move(run));
  std::sort(ordered.begin(), ordered.end(), [](const Run& x, const Run& y) { return x.begin < y.begin; });
  OverlapLists lists;
  lists.offsets.resize(n + 1);
  for (std::size_t q = 0; q < n; ++q) lists.offsets[q + 1] = lists.offsets[q] + counts[q];
  lists.ids.reserve(lists.offsets[n]);
  for (const Run& run : ordered) lists.ids.insert(lists.ids.end(), run.ids.begin(), run.ids.end());
  if (stats)
    for (const CollideStats& s : per_worker) *stats += s;
  return lists;
}

std::vector<IndexPair> overlapping_pairs(const BoxTree& tree, unsigned threads, CollideStats* stats) {
  const TreeAccess access(tree);
  std::vector<NodeAndCell> leaves;
  detail::for_each_leaf(access, [&](NodeId leaf, const Box3f& cell) {
    if (access.leaf_size(leaf) > 0) leaves.push_back({leaf, cell});
  });
  const unsigned workers = detail::resolve_threads(threads);
  std::vector<std::vector<IndexPair>> found(workers);
  std::vector<CollideStats> per_worker(workers);
  std::vector<std::vector<Box3f>> scratch(workers);
  constexpr std::size_t leaves_per_chunk = 64;
  detail::parallel_for(leaves.size(), workers, leaves_per_chunk,
                       [&](std::size_t begin, std::size_t end, unsigned worker) {
                         for (std::size_t l = begin; l < end; ++l)
                           pairs_of_leaf(access, leaves[l], found[worker], scratch[worker], per_worker[worker]);
                       });
  if (stats) {
    ++stats->queries;
    stats->nodes_visited += tree.node_count();  // the walk to the leaves
    for (const CollideStats& s : per_worker) *stats += s;
  }
  return detail::merge_and_sort(found, tree.size());
}

std::vector<IndexPair> overlapping_pairs(const BoxTree& tree, const BoxTree& other, unsigned threads,
                                         CollideStats* stats) {
  const TreeAccess ta(tree), tb(other);
  const unsigned workers = detail::resolve_threads(threads);
  // Several tasks a thread, so that an uneven split still keeps the threads busy.
  const std::vector<detail::NodePair> tasks =
      detail::node_pair_tasks(ta, tb, workers == 1 ? 1 : 16 * workers);
  std::vector<std::vector<IndexPair>> found(workers);
  std::vector<CollideStats> per_worker(workers);
  detail::parallel_for(tasks.size(), workers, 1, [&](std::size_t begin, std::size_t end, unsigned worker) {
    std::vector<IndexPair>& out = found[worker];
    CollideStats& local = per_worker[worker];
    for (std::size_t t = begin; t < end; ++t)
      detail::for_each_leaf_pair(ta, tb, tasks[t], local.nodes_visited,
                                 [&](NodeId leaf_a, const Box3f& cell_a, NodeId leaf_b, const Box3f& cell_b) {
                                   pairs_of_leaf_pair(ta, {leaf_a, cell_a}, tb, {leaf_b, cell_b}, out, local);
                                 });
  });
  if (stats) {
    ++stats->queries;
    for (const CollideStats& s : per_worker) *stats += s;
  }
  return detail::merge_and_sort(found, tree.size());
}

}  // namespace kdspace
