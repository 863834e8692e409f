// BoxTree: input checks, the choice of build, and the statistics of the built tree.
#include "kdspace/boxes/box_tree.hpp"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "build_common.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
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

namespace {

[[noreturn]] void fail_parts(const std::string& what) {
  throw Error("box tree: " + what);
}

constexpr std::size_t prefetch_references = 64;

// The references of the leaf `leaf` ([first, first + padded), its count of them real): ascending
// boxes in range, the padding repeating the last, and the leaf blocks equal to the boxes they copy
// (the traversal tests a leaf's boxes from those copies). Marks each box in `referenced` (a bit a box).
void check_leaf(const BoxTreeParts& p, std::size_t leaf_id, std::size_t first, std::size_t count,
                std::uint64_t* referenced) {
  const std::size_t n = p.boxes.size(), refs = p.references.size(), padded = (count + 3) / 4 * 4;
  auto leaf = [leaf_id] { return "leaf " + std::to_string(leaf_id) + ": "; };
  if (first % 4 != 0 || first > refs || padded > refs - first) fail_parts(leaf() + "references out of place");
  const std::uint32_t* ids = p.references.data() + first;
  const Box3f* boxes = p.boxes.data();
  for (std::size_t i = 0; i < padded; ++i) {
    // The boxes named by the references lie anywhere: fetch the box of a reference 64 ahead, both of
    // its bytes' cache lines (a 24-byte box straddles two in a quarter of the cases). Against 16 ahead
    // and its first line only: 1e6 uniform boxes, the check's processor time 26.6 -> 16.6 ms.
    if (first + i + prefetch_references < refs && n > 0) {
      const auto* ahead =
          reinterpret_cast<const char*>(boxes + std::min<std::size_t>(ids[i + prefetch_references], n - 1));
      __builtin_prefetch(ahead);
      __builtin_prefetch(ahead + sizeof(Box3f) - 1);
    }
    const std::uint32_t id = ids[i];
    if (id >= n)
      fail_parts(leaf() + "reference names box " + std::to_string(id) + " of " + std::to_string(n));
    if (i < count ? i > 0 && id <= ids[i - 1] : id != ids[count - 1])
      fail_parts(leaf() +
                 (i < count ? "references not ascending" : "padding does not repeat the last reference"));
    referenced[id >> 6] |= std::uint64_t{1} << (id & 63);
    const LeafBlock& block = p.blocks[(first + i) / 4];
    const Box3f& b = boxes[id];
    const std::size_t lane = i % 4;
    for (int a = 0; a < 3; ++a)
      if (!(block.plane[a][lane] == b.lo[a] && block.plane[3 + a][lane] == b.hi[a]))
        fail_parts(leaf() + "leaf block " + std::to_string((first + i) / 4) + " lane " +
                   std::to_string(lane) + " differs from box " + std::to_string(id));
  }
}

// Depth first, every node once (left child next to its parent, right child where the left subtree
// ends), leaf ranges tiling the references as the layout pads them (detail::lay_out), no leaf deeper
// than the traversal's stack allows, finite splits. Calls leaf(id, first, count) for each leaf in
// order; returns the depth of the deepest leaf.
template <class Leaf>
std::size_t check_nodes(const BoxTreeParts& p, Leaf&& leaf) {
  struct Pending {
    std::size_t id, parent, depth;
  };
  const std::size_t refs = p.references.size();
  std::vector<Pending> stack{{0, 0, 0}};
  std::size_t next = 0, next_ref = 0, depth = 0;
  while (!stack.empty()) {
    const Pending at = stack.back();
    stack.pop_back();
    auto where = [&at] { return "node " + std::to_string(at.parent) + ": "; };
    if (at.id != next || next >= p.nodes.size())
      fail_parts(where() + "child " + std::to_string(at.id) + ", expected " + std::to_string(next) + " (of " +
                 std::to_string(p.nodes.size()) + " nodes)");
    if (at.depth > max_box_tree_depth)
      fail_parts(where() + "deeper than " + std::to_string(max_box_tree_depth));
    const BoxNode& node = p.nodes[next++];
    if (node.is_leaf()) {
      const std::size_t count = node.count(), padded = (count + 3) / 4 * 4;
      if (node.first() != next_ref || padded > refs - next_ref)
        fail_parts("leaf " + std::to_string(at.id) + ": references out of place");
      leaf(at.id, next_ref, count);
      next_ref += padded;
      depth = std::max(depth, at.depth);
      continue;
    }
    if (!std::isfinite(node.split())) fail_parts("node " + std::to_string(at.id) + ": split is not finite");
    stack.push_back({node.right_child(), at.id, at.depth + 1});
    stack.push_back({at.id + 1, at.id, at.depth + 1});
  }
  if (next != p.nodes.size() || next_ref != refs) fail_parts("nodes or references not reached from the root");
  return depth;
}

// Whether boxes [begin, end) lie inside `bounds` (finite and ordered), each min at most its max: with
// finite bounds no NaN or infinity passes, so this is box_problem's rule and the bounds' at once.
bool boxes_inside(const Box3f* boxes, std::size_t begin, std::size_t end, const Box3f& bounds) {
  unsigned ok = 1;
  for (std::size_t i = begin; i < end; ++i)
    for (int a = 0; a < 3; ++a)
      ok &= static_cast<unsigned>(bounds.lo[a] <= boxes[i].lo[a]) &
            static_cast<unsigned>(boxes[i].lo[a] <= boxes[i].hi[a]) &
            static_cast<unsigned>(boxes[i].hi[a] <= bounds.hi[a]);
  return ok != 0;
}

bool all_referenced(const std::vector<std::uint64_t>& referenced, std::size_t n) {
  std::uint64_t missing = 0;
  for (std::size_t w = 0; w < n / 64; ++w) missing |= ~referenced[w];
  if (n % 64 != 0) missing |= ~referenced[n / 64] & ((std::uint64_t{1} << (n % 64)) - 1);
  return missing == 0;
}

// The check of parts from outside, on one thread, in the order that names the first problem.
std::size_t check_parts_on_one_thread(const BoxTreeParts& p) {
  const std::size_t n = p.boxes.size();
  for (std::size_t i = 0; i < n; ++i) {
    const std::string problem = box_problem(p.boxes[i]);  // empty (no allocation) for a sound box
    if (!problem.empty()) fail_parts("box " + std::to_string(i + 1) + ": " + problem);
  }
  std::vector<std::uint64_t> referenced(n / 64 + 1, 0);
  const std::size_t depth = check_nodes(p, [&](std::size_t id, std::size_t first, std::size_t count) {
    check_leaf(p, id, first, count, referenced.data());
  });
  // The root cell: the union of the boxes, or more after a refit (it keeps the cells the planes were
  // made in); it must hold every box.
  if (n > 0) {
    if (!box_problem(p.bounds).empty()) fail_parts("bounds: " + box_problem(p.bounds));
    for (std::size_t i = 0; i < n; ++i)
      if (!boxes_inside(p.boxes.data(), i, i + 1, p.bounds))
        fail_parts("box " + std::to_string(i + 1) + " lies outside the bounds");
  }
  // Every box meets the root cell (the union of the boxes), so some leaf holds it.
  for (std::size_t i = 0; i < n; ++i)
    if (!(referenced[i >> 6] >> (i & 63) & 1u)) fail_parts("box " + std::to_string(i + 1) + " is in no leaf");
  return depth;
}

/// Trees of at least this many references are checked on two threads (a thread's start costs tens of
/// microseconds, a reference's check a few nanoseconds).
constexpr std::size_t parallel_box_check = std::size_t{1} << 16;

// The same checks on two threads: each takes half of the boxes, then the leaves of half of the node
// array (a linear scan: the leaves in node order are those of the depth-first walk, which thread 0
// checks besides), each with its own marks of the boxes referenced; then both help the companion.
// Any problem throws, and the caller starts over on one thread, whose message names it.
std::size_t check_parts_on_two_threads(const BoxTreeParts& p) {
  const std::size_t n = p.boxes.size(), refs = p.references.size(), nodes = p.nodes.size();
  if (!box_problem(p.bounds).empty()) fail_parts("bounds");
  const std::size_t middle_node = nodes / 2;
  std::size_t middle_ref = refs;  // where thread 1's references begin: at its first leaf
  for (std::size_t v = middle_node; v < nodes; ++v)
    if (p.nodes[v].is_leaf()) {
      middle_ref = std::min<std::size_t>(p.nodes[v].first(), refs);
      break;
    }
  detail::CheckCompanion* companion = p.companion;
  if (companion) {
    companion->pieces(detail::box_check_boxes, {0, n / 2});
    companion->pieces(detail::box_check_references, {0, middle_ref});
  }
  std::vector<std::uint64_t> referenced[2];
  std::size_t depth = 0;
  auto share = [&](int w) {
    const auto piece = static_cast<std::size_t>(w);  // the companion's piece of each array: the thread's half
    // Boxes: a block at a time, as the companion makes them ready.
    const std::size_t box_end = w == 0 ? n / 2 : n;
    for (std::size_t i = w == 0 ? 0 : n / 2; i < box_end;) {
      const std::size_t ready =
          companion ? std::clamp(companion->ready(detail::box_check_boxes, piece, i + 1), i + 1, box_end)
                    : box_end;
      if (!boxes_inside(p.boxes.data(), i, ready, p.bounds)) fail_parts("a box");
      i = ready;
    }
    if (w == 0) depth = check_nodes(p, [](std::size_t, std::size_t, std::size_t) {});
    referenced[w].assign(n / 64 + 1, 0);
    std::size_t ready = 0;
    for (std::size_t v = w == 0 ? 0 : middle_node, end = w == 0 ? middle_node : nodes; v < end; ++v) {
      const BoxNode& node = p.nodes[v];
      if (!node.is_leaf()) continue;
      const std::size_t first = node.first(), count = node.count(), padded = (count + 3) / 4 * 4;
      if (companion && first + padded > ready)
        ready = companion->ready(detail::box_check_references, piece, first + padded);
      check_leaf(p, v, first, count, referenced[w].data());
    }
    if (companion) companion->help();
  };
  detail::fork_join([&] { share(1); }, [&] { share(0); });
  for (std::size_t w = 0; w < referenced[0].size(); ++w) referenced[0][w] |= referenced[1][w];
  if (!all_referenced(referenced[0], n)) fail_parts("a box in no leaf");
  return depth;
}

}  // namespace

BoxTree::BoxTree(BoxTreeParts p) : params_(p.params) {
  try {
    check_params(p.params);
  } catch (const Error& e) {
    fail_parts(e.what());
  }
  const std::size_t n = p.boxes.size();
  if (n >= (std::size_t{1} << 30)) fail_parts("too many boxes: " + std::to_string(n));
  if (p.max_depth > max_box_tree_depth)
    fail_parts("depth cap " + std::to_string(p.max_depth) + " above " + std::to_string(max_box_tree_depth));
  const std::size_t refs = p.references.size();
  if (p.nodes.size() >= (std::size_t{1} << 28) || refs >= (std::size_t{1} << 30))
    fail_parts("more than 2^28 nodes or 2^30 references");
  if (refs % 4 != 0 || p.blocks.size() != refs / 4)
    fail_parts(std::to_string(refs) + " references and " + std::to_string(p.blocks.size()) +
               " leaf blocks: one block per 4 references expected");
  std::size_t depth = 0;
  bool checked = false;
  if (refs >= parallel_box_check && n > 0) {
    try {
      depth = check_parts_on_two_threads(p);
      checked = true;
    } catch (const Error&) {
      // Something is wrong: the one-thread check below names the first problem, as it finds it.
    }
  }
  if (!checked) {
    depth = check_parts_on_one_thread(p);
    if (p.companion) p.companion->help();
  }
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
