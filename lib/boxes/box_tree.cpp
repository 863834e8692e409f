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
  boxes_.assign(boxes, boxes + n);
  for (int a = 0; a < 3; ++a) {
    bounds_.lo[a] = std::numeric_limits<float>::infinity();
    bounds_.hi[a] = -std::numeric_limits<float>::infinity();
  }
  for (const Box3f& b : boxes_)
    for (int a = 0; a < 3; ++a) {
      bounds_.lo[a] = std::min(bounds_.lo[a], b.lo[a]);
      bounds_.hi[a] = std::max(bounds_.hi[a], b.hi[a]);
    }
  for (int a = 0; a < 3; ++a)
    if (!(std::abs(bounds_.lo[a]) <= float_trace_limit && std::abs(bounds_.hi[a]) <= float_trace_limit))
      float_range_ = false;

  const std::size_t max_depth = params.max_depth == 0 ? automatic_max_depth(n) : params.max_depth;
  detail::TreeWriter out;
  if (n == 0) {
    out.add_leaf({}, 0);
  } else {
    switch (params.method) {
      case BoxBuildMethod::median:
        detail::build_median(boxes_, bounds_, params, max_depth, out);
        break;
      case BoxBuildMethod::sah:
        detail::build_sah(boxes_, bounds_, params, max_depth, out);
        break;
      case BoxBuildMethod::sah_nlogn:
        detail::build_sah_nlogn(boxes_, bounds_, params, max_depth, out);
        break;
      case BoxBuildMethod::binned:
        detail::build_binned(boxes_, bounds_, params, max_depth, out);
        break;
    }
  }
  detail::TreeLayout layout = detail::lay_out(out, boxes_);
  nodes_ = std::move(layout.nodes);
  references_ = std::move(layout.references);
  blocks_ = std::move(layout.blocks);
  stats_.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  stats_.depth = out.depth;
  stats_.max_depth = max_depth;
  compute_stats();
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
