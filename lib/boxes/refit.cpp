// BoxTree::refit: the same split planes, the boxes sent down them again (route.hpp).
#include <algorithm>
#include <chrono>
#include <cstring>
#include <string>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "build_common.hpp"
#include "layout.hpp"
#include "route.hpp"

namespace kdspace {

namespace {

/// Grows `cell` to hold b.
void include(Box3f& cell, const Box3f& b) {
  for (int a = 0; a < 3; ++a) {
    cell.lo[a] = std::min(cell.lo[a], b.lo[a]);
    cell.hi[a] = std::max(cell.hi[a], b.hi[a]);
  }
}

/// The tree's nodes as a build writes them (leaves left empty, for route_boxes to fill).
std::vector<detail::BuiltNode> planes_of(const detail::Storage<BoxNode>& nodes) {
  std::vector<detail::BuiltNode> built(nodes.size());
  for (std::size_t i = 0; i < nodes.size(); ++i)
    if (!nodes[i].is_leaf()) {
      built[i].axis = static_cast<std::int8_t>(nodes[i].axis());
      built[i].split = nodes[i].split();
      built[i].right = nodes[i].right_child();
    }
  return built;
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

void BoxTree::own(std::vector<Box3f> boxes, detail::TreeLayout&& layout) {
  boxes_ = detail::Storage<Box3f>(std::move(boxes));
  nodes_ = detail::Storage<BoxNode>(std::move(layout.nodes));
  references_ = detail::Storage<std::uint32_t>(std::move(layout.references));
  blocks_ = detail::Storage<LeafBlock>(std::move(layout.blocks));
  backing_.reset();  // nothing is borrowed any more
}

bool BoxTree::refit(const Box3f* boxes, std::size_t n) {
  detail::check_boxes(boxes, n);
  const auto start = std::chrono::steady_clock::now();
  const auto budget =
      static_cast<std::size_t>(static_cast<double>(params_.max_references_per_box) * static_cast<double>(n));
  detail::TreeWriter routed;
  routed.nodes = planes_of(nodes_);
  if (!detail::route_boxes(routed.nodes, boxes, n, budget, routed.references)) return false;
  std::vector<Box3f> moved_boxes = boxes_.release();
  moved_boxes.assign(boxes, boxes + n);
  // The root cell keeps the old cells, so that every plane stays strictly inside its cell.
  Box3f bounds = bounds_;
  for (const Box3f& b : moved_boxes) include(bounds, b);
  set_bounds(bounds);
  // Laid out into the tree's own vectors: a refit every frame allocates no new leaf storage (a
  // tree loaded from a mapped file copies its arrays on its first refit, and owns them after).
  detail::TreeLayout layout{nodes_.release(), references_.release(), blocks_.release()};
  detail::lay_out(routed, moved_boxes, layout);
  own(std::move(moved_boxes), std::move(layout));
  count_leaves();
  stats_.build_seconds = seconds_since(start);
  return true;
}

// Only the leaves that a moved box leaves or enters change: the others' (padded) references and leaf
// blocks are copied over in runs, and only the changed leaves are merged (their unmoved references,
// in order, with the moved boxes that now reach them) and written again (detail::write_leaf).
bool BoxTree::refit(const Box3f* boxes, const std::uint32_t* moved, std::size_t m) {
  if (m > 0 && (boxes == nullptr || moved == nullptr)) throw Error("refit: null pointer");
  for (std::size_t k = 0; k < m; ++k) {
    if (moved[k] >= boxes_.size())
      throw Error("refit: moved box " + std::to_string(moved[k]) + " out of range (" +
                  std::to_string(boxes_.size()) + " boxes)");
    if (k > 0 && moved[k] <= moved[k - 1]) throw Error("refit: moved boxes must be strictly ascending");
    const std::string problem = box_problem(boxes[moved[k]]);
    if (!problem.empty()) throw Error("box " + std::to_string(moved[k] + 1) + ": " + problem);
  }
  const auto start = std::chrono::steady_clock::now();

  // The leaves the moved boxes leave (from their old boxes) and enter (new boxes), and what enters.
  std::vector<char> changed(nodes_.size(), 0);
  std::vector<std::uint32_t> entering_leaf, entering_box, entering_count(nodes_.size(), 0);
  for (std::size_t k = 0; k < m; ++k) {
    detail::for_each_leaf_of(nodes_, boxes_[moved[k]], [&](std::uint32_t leaf) { changed[leaf] = 1; });
    detail::for_each_leaf_of(nodes_, boxes[moved[k]], [&](std::uint32_t leaf) {
      changed[leaf] = 1;
      entering_leaf.push_back(leaf);
      entering_box.push_back(moved[k]);
      ++entering_count[leaf];
    });
  }
  // What enters, grouped by leaf in ascending box order (a stable counting sort).
  std::vector<std::uint32_t> entering_first(nodes_.size() + 1, 0);
  for (std::size_t node = 0; node < nodes_.size(); ++node)
    entering_first[node + 1] = entering_first[node] + entering_count[node];
  std::vector<std::uint32_t> entering(entering_box.size());
  {
    std::vector<std::uint32_t> next(entering_first.begin(), entering_first.end() - 1);
    for (std::size_t e = 0; e < entering_box.size(); ++e)
      entering[next[entering_leaf[e]]++] = entering_box[e];
  }
  std::vector<char> moved_flag(boxes_.size(), 0);
  for (std::size_t k = 0; k < m; ++k) moved_flag[moved[k]] = 1;
  auto is_moved = [&](std::uint32_t box) { return moved_flag[box] != 0; };

  // The new size of every leaf, and so where each one starts (a multiple of 4).
  std::vector<BoxNode> nodes(nodes_.begin(), nodes_.end());
  std::size_t total = 0, padded_total = 0;
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    const BoxNode& at = nodes_[node];
    if (!at.is_leaf()) continue;
    std::size_t count = at.count();
    if (changed[node]) {
      const std::uint32_t* ref = references_.data() + at.first();
      count = entering_count[node];
      for (std::uint32_t r = 0; r < at.count(); ++r) count += is_moved(ref[r]) ? 0 : 1;
    }
    if (total + count > detail::reference_limit) return false;
    nodes[node] = BoxNode::leaf(static_cast<std::uint32_t>(padded_total), static_cast<std::uint32_t>(count));
    total += count;
    padded_total += detail::padded_size(count);
  }
  const double budget =
      static_cast<double>(params_.max_references_per_box) * static_cast<double>(boxes_.size());
  if (static_cast<double>(total) > budget) return false;

  // The boxes take their new places first: the changed leaves' blocks are written from them.
  std::vector<Box3f> moved_boxes = boxes_.release();
  Box3f bounds = bounds_;
  for (std::size_t k = 0; k < m; ++k) {
    moved_boxes[moved[k]] = boxes[moved[k]];
    include(bounds, boxes[moved[k]]);
  }
  set_bounds(bounds);
  // Runs of unchanged leaves are copied as they are (they are contiguous in both layouts, references
  // and blocks alike); changed leaves are merged and written again.
  std::vector<std::uint32_t> references(padded_total);
  std::vector<LeafBlock> blocks(padded_total / 4);
  std::vector<std::uint32_t> merged;
  std::size_t run_old = 0, run_new = 0, run_length = 0;
  auto copy_run = [&] {
    std::copy_n(references_.data() + run_old, run_length, references.data() + run_new);
    std::copy_n(blocks_.data() + run_old / 4, run_length / 4, blocks.data() + run_new / 4);
    run_length = 0;
  };
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    const BoxNode& at = nodes_[node];
    if (!at.is_leaf()) continue;
    if (!changed[node]) {
      if (run_length == 0) {
        run_old = at.first();
        run_new = nodes[node].first();
      }
      run_length += detail::padded_size(at.count());
      continue;
    }
    copy_run();
    merged.clear();
    const std::uint32_t *old_ref = references_.data() + at.first(), *old_end = old_ref + at.count();
    const std::uint32_t* new_ref = entering.data() + entering_first[node];
    const std::uint32_t* new_end = entering.data() + entering_first[node + 1];
    for (;;) {
      while (old_ref < old_end && is_moved(*old_ref)) ++old_ref;
      const bool old_left = old_ref < old_end, new_left = new_ref < new_end;
      if (!old_left && !new_left) break;
      if (old_left && (!new_left || *old_ref < *new_ref))
        merged.push_back(*old_ref++);
      else
        merged.push_back(*new_ref++);
    }
    const std::uint32_t first = nodes[node].first();
    detail::write_leaf(merged.data(), static_cast<std::uint32_t>(merged.size()), moved_boxes.data(),
                       references.data() + first, blocks.data() + first / 4);
  }
  copy_run();

  own(std::move(moved_boxes), detail::TreeLayout{std::move(nodes), std::move(references), std::move(blocks)});
  count_leaves();
  stats_.build_seconds = seconds_since(start);
  return true;
}

}  // namespace kdspace
