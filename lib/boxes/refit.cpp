// BoxTree::refit: the same split planes, the boxes sent down them again (route.hpp).
#include <algorithm>
#include <chrono>
#include <string>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "route.hpp"

namespace kdspace {

namespace {

void check_boxes(const Box3f* boxes, std::size_t n) {
  if (n >= (std::size_t{1} << 30)) throw Error("too many boxes: " + std::to_string(n) + " (at most 2^30 - 1)");
  if (n > 0 && boxes == nullptr) throw Error("boxes: null pointer");
  for (std::size_t i = 0; i < n; ++i) {
    const std::string problem = box_problem(boxes[i]);
    if (!problem.empty()) throw Error("box " + std::to_string(i + 1) + ": " + problem);
  }
}

/// Grows `cell` to hold b.
void include(Box3f& cell, const Box3f& b) {
  for (int a = 0; a < 3; ++a) {
    cell.lo[a] = std::min(cell.lo[a], b.lo[a]);
    cell.hi[a] = std::max(cell.hi[a], b.hi[a]);
  }
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

bool BoxTree::refit(const Box3f* boxes, std::size_t n) {
  check_boxes(boxes, n);
  const auto start = std::chrono::steady_clock::now();
  const auto budget =
      static_cast<std::size_t>(static_cast<double>(params_.max_references_per_box) * static_cast<double>(n));
  if (!detail::route_boxes(nodes_, boxes, n, budget, references_)) return false;
  boxes_.assign(boxes, boxes + n);
  // The root cell keeps the old cells, so that every plane stays strictly inside its cell.
  for (const Box3f& b : boxes_) include(bounds_, b);
  after_refit(seconds_since(start));
  return true;
}

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
  const auto budget = static_cast<std::size_t>(static_cast<double>(params_.max_references_per_box) *
                                               static_cast<double>(boxes_.size()));
  if (!detail::route_moved_boxes(nodes_, boxes, boxes_.size(), moved, m, budget, references_)) return false;
  for (std::size_t k = 0; k < m; ++k) {
    boxes_[moved[k]] = boxes[moved[k]];
    include(bounds_, boxes[moved[k]]);
  }
  after_refit(seconds_since(start));
  return true;
}

void BoxTree::after_refit(double seconds) {
  leaf_boxes_.resize(references_.size());
  for (std::size_t r = 0; r < references_.size(); ++r) leaf_boxes_[r] = boxes_[references_[r]];
  stats_.build_seconds = seconds;
  compute_stats();
}

}  // namespace kdspace
