// MovingScene (kdspace/collide/moving_scene.hpp): the tree refitted or rebuilt each frame, and the
// pairs found again or updated for the moved boxes only.
#include "kdspace/collide/moving_scene.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <string>
#include <utility>

#include "kdspace/collide/overlap.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/rays/ray.hpp"
#include "pair_sort.hpp"
#include "traversal.hpp"
#include "tree_access.hpp"

namespace kdspace {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// The box-box tests of pairs within leaves: the sum over leaves of their references squared.
double leaf_test_cost(const BoxTree& tree) {
  const detail::TreeAccess access(tree);
  double cost = 0;
  for (detail::NodeId node = 0; node < access.node_count(); ++node)
    if (access.is_leaf(node)) {
      const double count = access.leaf_size(node);
      cost += count * count;
    }
  return cost;
}

bool same_box(const Box3f& a, const Box3f& b) {
  return std::memcmp(&a, &b, sizeof(Box3f)) == 0;
}

}  // namespace

MovingScene::MovingScene(const MovingSceneParams& params) : params_(params) {
  if (!(params.rebuild_factor >= 1)) throw Error("rebuild_factor must be at least 1");
  if (!(params.incremental_share >= 0 && params.incremental_share <= 1))
    throw Error("incremental_share must be in [0, 1]");
}
MovingScene::~MovingScene() = default;
MovingScene::MovingScene(MovingScene&&) noexcept = default;
MovingScene& MovingScene::operator=(MovingScene&&) noexcept = default;

const BoxTree& MovingScene::tree() const {
  if (!tree_) throw Error("MovingScene: no tree before the first step");
  return *tree_;
}

const std::vector<IndexPair>& MovingScene::step(const Box3f* boxes, std::size_t n) {
  if (n > 0 && boxes == nullptr) throw Error("boxes: null pointer");
  FrameStats stats;
  stats.frame = stats_.frame + 1;
  stats.boxes = n;

  // Boxes are checked by the tree: all of them by a build or a full refit, the moved ones by a
  // partial refit (the others are, bit for bit, boxes it has accepted before).
  const auto update_start = Clock::now();
  const bool same_count = tree_ && previous_.size() == n;
  moved_.clear();
  if (same_count)
    for (std::size_t i = 0; i < n; ++i)
      if (!same_box(boxes[i], previous_[i])) moved_.push_back(static_cast<std::uint32_t>(i));
  stats.moved = same_count ? moved_.size() : n;
  const bool few_moved =
      same_count && static_cast<double>(moved_.size()) <= params_.incremental_share * static_cast<double>(n);

  if (!same_count || (params_.update == TreeUpdate::rebuild && !moved_.empty())) {
    rebuild(boxes, n);
    stats.rebuilt = true;
  } else if (!moved_.empty()) {
    // Few moved: refit those only. Many: send every box down once, which costs less per box than
    // merging the moved boxes' references into the leaves' lists.
    const bool refitted =
        few_moved ? tree_->refit(boxes, moved_.data(), moved_.size()) : tree_->refit(boxes, n);
    if (!refitted || leaf_test_cost(*tree_) > params_.rebuild_factor * built_cost_) {
      rebuild(boxes, n);
      stats.rebuilt = true;
    }
  }
  if (same_count) {
    for (const std::uint32_t i : moved_) previous_[i] = boxes[i];
  } else {
    previous_.assign(boxes, boxes + n);
  }
  stats.update_s = seconds_since(update_start);

  const auto pairs_start = Clock::now();
  if (few_moved) {
    if (!moved_.empty()) find_pairs_of_moved(boxes);  // else the pairs stand
    stats.incremental = true;
  } else {
    find_all_pairs();
  }
  stats.pairs_s = seconds_since(pairs_start);
  stats.pairs = pairs_.size();
  stats_ = stats;
  return pairs_;
}

void MovingScene::rebuild(const Box3f* boxes, std::size_t n) {
  tree_ = std::make_unique<BoxTree>(boxes, n, params_.build);
  built_cost_ = leaf_test_cost(*tree_);
}

void MovingScene::find_all_pairs() {
  pairs_ = overlapping_pairs(*tree_, params_.threads);
}

void MovingScene::find_pairs_of_moved(const Box3f* boxes) {
  // Pairs of two unmoved boxes stand; every pair with a moved box is found by that box's query (by
  // the smaller one's when both moved).
  is_moved_.assign(previous_.size(), 0);
  for (const std::uint32_t i : moved_) is_moved_[i] = 1;
  pairs_.erase(std::remove_if(pairs_.begin(), pairs_.end(),
                              [&](const IndexPair& p) { return is_moved_[p.a] || is_moved_[p.b]; }),
               pairs_.end());

  const OverlapLists partners = overlapping_batch(
      *tree_,
      [&] {
        std::vector<Box3f> queries(moved_.size());
        for (std::size_t k = 0; k < moved_.size(); ++k) queries[k] = boxes[moved_[k]];
        return queries;
      }(),
      params_.threads);
  fresh_.clear();
  for (std::size_t k = 0; k < moved_.size(); ++k) {
    const std::uint32_t i = moved_[k];
    for (const std::uint32_t j : partners.row(k))
      if (j != i && (!is_moved_[j] || j > i)) fresh_.push_back({std::min(i, j), std::max(i, j)});
  }
  detail::sort_pairs(fresh_, previous_.size());
  merged_.resize(pairs_.size() + fresh_.size());
  std::merge(pairs_.begin(), pairs_.end(), fresh_.begin(), fresh_.end(), merged_.begin());
  pairs_.swap(merged_);
}

}  // namespace kdspace
