// BoxTree: input checks, the choice of build, and the statistics of the built tree.
#include "kdspace/boxes/box_tree.hpp"

#include <charconv>
#include <chrono>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "build_common.hpp"
#include "kdspace/error.hpp"
#include "layout.hpp"
#include "sah_cost.hpp"

namespace kdspace {

namespace {

constexpr const char* axis_name[3] = {"x", "y", "z"};

/// The shortest text that reads back as v: "3", "0.1", "nan", "-inf".
std::string number(float v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

std::string not_finite(const char* what, int axis, float v) {
  return std::string(what) + " " + axis_name[axis] + " is " + number(v);
}

void check_params(const BoxBuildParams& p) {
  if (!(std::isfinite(p.K_t) && p.K_t >= 0))
    throw Error("K_t must be a finite number >= 0, got " + number(p.K_t));
  if (!(std::isfinite(p.K_i) && p.K_i > 0))
    throw Error("K_i must be a finite number > 0, got " + number(p.K_i));
  if (!(p.empty_bonus >= 0 && p.empty_bonus < 1))
    throw Error("empty_bonus must be in [0, 1), got " + number(p.empty_bonus));
  if (p.max_depth > max_box_tree_depth)
    throw Error("max_depth must be at most " + std::to_string(max_box_tree_depth) + ", got " +
                std::to_string(p.max_depth));
  if (p.method != BoxBuildMethod::sah && p.method != BoxBuildMethod::sah_nlogn && p.leaf_size == 0)
    throw Error("leaf_size must be at least 1");
  if (!(p.max_references_per_box >= 1) || std::isinf(p.max_references_per_box))
    throw Error("max_references_per_box must be a finite number >= 1, got " +
                number(p.max_references_per_box));
}

/// S_maxProf when the caller leaves it to us: round(8 + 1.3 log2 N) (pbrt's rule).
std::size_t automatic_max_depth(std::size_t n) {
  if (n <= 1) return 8;
  const double d = std::round(8.0 + 1.3 * std::log2(static_cast<double>(n)));
  return std::min<std::size_t>(max_box_tree_depth, static_cast<std::size_t>(d));
}

}  // namespace

std::string box_problem(const Box3f& box) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(box.lo[a])) return not_finite("min", a, box.lo[a]);
    if (!std::isfinite(box.hi[a])) return not_finite("max", a, box.hi[a]);
  }
  for (int a = 0; a < 3; ++a)
    if (box.lo[a] > box.hi[a])
      return std::string("min ") + axis_name[a] + " " + number(box.lo[a]) + " > max " + axis_name[a] + " " +
             number(box.hi[a]);
  return {};
}

std::string ray_problem(const Ray& ray) {
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(ray.origin[a])) return not_finite("origin", a, ray.origin[a]);
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(ray.direction[a])) return not_finite("direction", a, ray.direction[a]);
  if (ray.direction[0] == 0 && ray.direction[1] == 0 && ray.direction[2] == 0) return "direction is zero";
  return {};
}

namespace detail {

void check_boxes(const Box3f* boxes, std::size_t n) {
  // Every box is referenced by at least one leaf, and references are counted in 30 bits.
  if (n >= (std::size_t{1} << 30))
    throw Error("too many boxes: " + std::to_string(n) + " (at most 2^30 - 1)");
  if (n > 0 && boxes == nullptr) throw Error("boxes: null pointer");
  for (std::size_t i = 0; i < n; ++i) {
    const std::string problem = box_problem(boxes[i]);
    if (!problem.empty()) throw Error("box " + std::to_string(i + 1) + ": " + problem);
  }
}

}  // namespace detail

BoxTree::BoxTree(const std::vector<Box3f>& boxes, const BoxBuildParams& params)
    : BoxTree(boxes.data(), boxes.size(), params) {}

BoxTree::BoxTree(const Box3f* boxes, std::size_t n, const BoxBuildParams& params) : params_(params) {
  check_params(params);
  detail::check_boxes(boxes, n);

  const auto start = std::chrono::steady_clock::now();
  std::vector<Box3f> copy(boxes, boxes + n);
  boxes_ = detail::Storage<Box3f>(copy);
  compute_bounds();

  const std::size_t max_depth = params.max_depth == 0 ? automatic_max_depth(n) : params.max_depth;
  detail::TreeWriter out;
  if (n == 0) {
    out.add_leaf({}, 0);
  } else {
    switch (params.method) {
      case BoxBuildMethod::median:
        detail::build_median(copy, bounds_, params, max_depth, out);
        break;
      case BoxBuildMethod::sah:
        detail::build_sah(copy, bounds_, params, max_depth, out);
        break;
      case BoxBuildMethod::sah_nlogn:
        detail::build_sah_nlogn(copy, bounds_, params, max_depth, out);
        break;
      case BoxBuildMethod::binned:
        detail::build_binned(copy, bounds_, params, max_depth, out);
        break;
    }
  }
  detail::TreeLayout layout = detail::lay_out(out, copy);
  nodes_ = detail::Storage<BoxNode>(std::move(layout.nodes));
  references_ = detail::Storage<std::uint32_t>(std::move(layout.references));
  blocks_ = detail::Storage<LeafBlock>(std::move(layout.blocks));
  stats_.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  stats_.depth = out.depth;
  stats_.max_depth = max_depth;
  compute_stats();
}

void BoxTree::compute_bounds() {
  Box3f all;
  for (int a = 0; a < 3; ++a) {
    all.lo[a] = std::numeric_limits<float>::infinity();
    all.hi[a] = -std::numeric_limits<float>::infinity();
  }
  for (const Box3f& b : boxes_)
    for (int a = 0; a < 3; ++a) {
      all.lo[a] = std::min(all.lo[a], b.lo[a]);
      all.hi[a] = std::max(all.hi[a], b.hi[a]);
    }
  set_bounds(all);
}

void BoxTree::set_bounds(const Box3f& bounds) {
  bounds_ = bounds;
  float_range_ = true;
  for (int a = 0; a < 3; ++a)
    if (!(std::abs(bounds_.lo[a]) <= float_trace_limit && std::abs(bounds_.hi[a]) <= float_trace_limit))
      float_range_ = false;
}

BoxTree::BoxTree(BoxTreeParts p) : params_(p.params) {
  auto fail = [](const std::string& what) { throw Error("box tree: " + what); };
  try {
    check_params(p.params);
  } catch (const Error& e) {
    fail(e.what());
  }
  const std::size_t n = p.boxes.size();
  if (n >= (std::size_t{1} << 30)) fail("too many boxes: " + std::to_string(n));
  if (p.max_depth > max_box_tree_depth)
    fail("depth cap " + std::to_string(p.max_depth) + " above " + std::to_string(max_box_tree_depth));
  for (std::size_t i = 0; i < n; ++i) {
    const std::string problem = box_problem(p.boxes[i]);  // empty (no allocation) for a sound box
    if (!problem.empty()) fail("box " + std::to_string(i + 1) + ": " + problem);
  }
  const std::size_t refs = p.references.size();
  if (p.nodes.size() >= (std::size_t{1} << 28) || refs >= (std::size_t{1} << 30))
    fail("more than 2^28 nodes or 2^30 references");
  if (refs % 4 != 0 || p.blocks.size() != refs / 4)
    fail(std::to_string(refs) + " references and " + std::to_string(p.blocks.size()) +
         " leaf blocks: one block per 4 references expected");
  // Depth first, every node once (left child next to its parent, right child where the left subtree
  // ends), leaf ranges tiling the references as the layout pads them (detail::lay_out), no leaf
  // deeper than the traversal's stack allows.
  struct Pending {
    std::size_t id, parent, depth;
  };
  std::vector<Pending> stack{{0, 0, 0}};
  std::vector<bool> referenced(n, false);
  std::size_t next = 0, next_ref = 0, depth = 0;
  while (!stack.empty()) {
    const Pending at = stack.back();
    stack.pop_back();
    auto where = [&at] { return "node " + std::to_string(at.parent) + ": "; };
    if (at.id != next || next >= p.nodes.size())
      fail(where() + "child " + std::to_string(at.id) + ", expected " + std::to_string(next) + " (of " +
           std::to_string(p.nodes.size()) + " nodes)");
    if (at.depth > max_box_tree_depth) fail(where() + "deeper than " + std::to_string(max_box_tree_depth));
    const BoxNode& node = p.nodes[next++];
    if (node.is_leaf()) {
      const std::size_t count = node.count(), padded = (count + 3) / 4 * 4;
      auto leaf = [&at] { return "leaf " + std::to_string(at.id) + ": "; };
      if (node.first() != next_ref || padded > refs - next_ref) fail(leaf() + "references out of place");
      const std::uint32_t* ids = p.references.data() + next_ref;
      for (std::size_t i = 0; i < padded; ++i) {
        // The boxes named by the references lie anywhere: fetch the box of a reference 16 ahead.
        if (next_ref + i + 16 < refs && n > 0)
          __builtin_prefetch(p.boxes.data() + std::min<std::size_t>(ids[i + 16], n - 1));
        const std::uint32_t id = ids[i];
        if (id >= n) fail(leaf() + "reference names box " + std::to_string(id) + " of " + std::to_string(n));
        if (i < count ? i > 0 && id <= ids[i - 1] : id != ids[count - 1])
          fail(leaf() +
               (i < count ? "references not ascending" : "padding does not repeat the last reference"));
        referenced[id] = true;
        // The traversal tests a leaf's boxes from their copies in the blocks: each copy must be its box.
        const LeafBlock& block = p.blocks[(next_ref + i) / 4];
        const Box3f& b = p.boxes[id];
        const std::size_t lane = i % 4;
        for (int a = 0; a < 3; ++a)
          if (!(block.plane[a][lane] == b.lo[a] && block.plane[3 + a][lane] == b.hi[a]))
            fail(leaf() + "leaf block " + std::to_string((next_ref + i) / 4) + " lane " +
                 std::to_string(lane) + " differs from box " + std::to_string(id));
      }
      next_ref += padded;
      depth = std::max(depth, at.depth);
      continue;
    }
    if (!std::isfinite(node.split())) fail("node " + std::to_string(at.id) + ": split is not finite");
    stack.push_back({node.right_child(), at.id, at.depth + 1});
    stack.push_back({at.id + 1, at.id, at.depth + 1});
  }
  if (next != p.nodes.size() || next_ref != refs) fail("nodes or references not reached from the root");
  // The root cell: the union of the boxes, or more after a refit (it keeps the cells the planes were
  // made in); it must hold every box.
  if (n > 0) {
    if (!box_problem(p.bounds).empty()) fail("bounds: " + box_problem(p.bounds));
    for (std::size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a)
        if (!(p.bounds.lo[a] <= p.boxes[i].lo[a] && p.boxes[i].hi[a] <= p.bounds.hi[a]))
          fail("box " + std::to_string(i + 1) + " lies outside the bounds");
  }
  // Every box meets the root cell (the union of the boxes), so some leaf holds it.
  for (std::size_t i = 0; i < n; ++i)
    if (!referenced[i]) fail("box " + std::to_string(i + 1) + " is in no leaf");
  boxes_ = std::move(p.boxes);
  nodes_ = std::move(p.nodes);
  references_ = std::move(p.references);
  blocks_ = std::move(p.blocks);
  backing_ = std::move(p.backing);
  if (n > 0)
    set_bounds(p.bounds);
  else
    compute_bounds();
  stats_.depth = depth;
  stats_.max_depth = p.max_depth;
  compute_stats();
}

BoxTreeParts BoxTree::parts() const {
  BoxTreeParts p;
  p.params = params_;
  p.max_depth = stats_.max_depth;
  p.boxes = detail::Storage<Box3f>::borrow(boxes_.data(), boxes_.size());
  p.nodes = detail::Storage<BoxNode>::borrow(nodes_.data(), nodes_.size());
  p.references = detail::Storage<std::uint32_t>::borrow(references_.data(), references_.size());
  p.blocks = detail::Storage<LeafBlock>::borrow(blocks_.data(), blocks_.size());
  p.bounds = bounds_;
  p.backing = backing_;
  return p;
}

void BoxTree::count_leaves() {
  stats_.boxes = boxes_.size();
  stats_.nodes = nodes_.size();
  stats_.references = 0;
  stats_.leaves = stats_.empty_leaves = stats_.max_leaf_size = 0;
  for (const BoxNode& node : nodes_)
    if (node.is_leaf()) {
      ++stats_.leaves;
      stats_.references += node.count();
      stats_.empty_leaves += node.count() == 0 ? 1 : 0;
      stats_.max_leaf_size = std::max<std::size_t>(stats_.max_leaf_size, node.count());
    }
  stats_.references_per_box =
      boxes_.empty() ? 0 : static_cast<double>(stats_.references) / static_cast<double>(boxes_.size());
}

void BoxTree::compute_stats() {
  count_leaves();
  if (boxes_.empty()) return;
  // Walk the tree with each node's cell to weigh it by P(cell | scene) (the SAH tree cost, W&H 2006).
  const detail::CellMeasure measure(HitProbability::surface_area, bounds_);
  const double whole = measure.whole();
  struct Item {
    std::uint32_t node;
    Box3f cell;
  };
  std::vector<Item> stack{{0, bounds_}};
  double cost = 0;
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    const BoxNode& node = nodes_[item.node];
    const double p = whole > 0 ? measure(item.cell) / whole : 1.0;
    if (node.is_leaf()) {
      cost += static_cast<double>(params_.K_i) * detail::box_tests(node.count()) * p;
    } else {
      cost += static_cast<double>(params_.K_t) * p;
      Box3f left = item.cell, right = item.cell;
      left.hi[node.axis()] = node.split();
      right.lo[node.axis()] = node.split();
      stack.push_back({item.node + 1, left});
      stack.push_back({node.right_child(), right});
    }
  }
  stats_.sah_cost = cost;
}

}  // namespace kdspace
