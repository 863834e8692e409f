// The binned build: a cheap tree for scenes that are rebuilt often (moving boxes, collisions).
//
// Two steps, neither of which copies boxes from node to node:
//   1. Planes, from the boxes' centres, reordered in place as in a point kd-tree. At each node: the
//      axis of largest spread of the centres; along it the boxes' faces counted in 32 bins over that
//      spread (min-max binning, Shevtsov, Soupikov & Kapustin 2007, "Highly parallel fast kd-tree
//      construction for interactive ray tracing of dynamic scenes"); the plane at the bin boundary
//      that minimises n_left^2 + n_right^2, the box-box tests of the two children were they leaves:
//      it balances them, and a box the plane cuts counts on both sides, so planes go between boxes
//      where they can. The centres below the plane go to the lower child.
//      A node becomes a leaf when the centres in it are leaf_size or fewer (S_minObj), at max_depth
//      (S_maxProf), or when the best plane would cut more than half of its boxes (boxes larger
//      than the cells: splitting would copy them into both children again and again).
//   2. Boxes. Every box is sent down the planes to every leaf it overlaps (route.hpp): one descent a
//      box and a counting sort by leaf, the same step as BoxTree::refit.
// If the leaves would hold more than max_references_per_box references a box, the planes are made
// again with leaves four times larger, until they fit (one leaf always does).
#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "build_common.hpp"
#include "route.hpp"

namespace kdspace::detail {

namespace {

/// A box as the plane step sees it, reordered in place: its centre and half extents (computed once;
/// the faces are needed only to count them in bins, where rounding does not matter), and its index.
struct Item {
  float centre[3];
  float half[3];
  std::uint32_t id;
};

/// The bounds of the centres of items[first, last).
struct CentreBounds {
  float lo[3], hi[3];
};

/// Bins of the plane search. 32 places a plane within 1/32 of the centres' spread of the best
/// boundary; more bins found no better trees on the benchmark scenes.
constexpr int bin_count = 32;

/// Below this many boxes a node is split at the middle of its centres' spread, without counting:
/// the counting pass costs more there than the better plane saves (measured on the benchmark scenes).
constexpr std::size_t small_node = 128;

/// Step 1: the planes of the tree over items[begin, end) in `cell`, depth first into `nodes` (leaves
/// left empty for route_boxes to fill).
class PlaneBuilder {
 public:
  PlaneBuilder(std::vector<Item>& items, std::size_t leaf_size, std::size_t max_depth,
               std::vector<BuiltNode>& nodes)
      : items_(items), leaf_size_(leaf_size), max_depth_(max_depth), nodes_(nodes) {}

  std::size_t deepest_leaf = 0;

  void build_all(const Box3f& cell) {
    if (items_.empty()) {
      nodes_.emplace_back();
      return;
    }
    build(0, items_.size(), cell, bounds_of(items_.data(), items_.data() + items_.size()), 0);
  }

 private:
  void build(std::size_t begin, std::size_t end, const Box3f& cell, const CentreBounds& centres,
             std::size_t depth) {
    int axis = 0;
    float plane = 0;
    std::size_t middle = 0;
    CentreBounds lower_centres, upper_centres;
    if (end - begin <= leaf_size_ || depth >= max_depth_ ||
        !choose(begin, end, cell, centres, axis, plane, middle, lower_centres, upper_centres)) {
      nodes_.emplace_back();
      deepest_leaf = std::max(deepest_leaf, depth);
      return;
    }
    const std::size_t self = nodes_.size();
    BuiltNode inner;
    inner.axis = static_cast<std::int8_t>(axis);
    inner.split = plane;
    nodes_.push_back(inner);
    Box3f lower = cell, upper = cell;
    lower.hi[axis] = plane;
    upper.lo[axis] = plane;
    build(begin, middle, lower, lower_centres, depth + 1);
    nodes_[self].right = static_cast<std::uint32_t>(nodes_.size());
    build(middle, end, upper, upper_centres, depth + 1);
  }

  static CentreBounds bounds_of(const Item* first, const Item* last) {
    CentreBounds b;
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::numeric_limits<float>::infinity();
      b.hi[a] = -std::numeric_limits<float>::infinity();
    }
    for (const Item* it = first; it < last; ++it) include(b, *it);
    return b;
  }
  static void include(CentreBounds& b, const Item& item) {
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], item.centre[a]);
      b.hi[a] = std::max(b.hi[a], item.centre[a]);
    }
  }

  /// The plane of a node (see the top of the file): false when it should be a leaf. On success the
  /// items are partitioned: [begin, middle) have centres below the plane, [middle, end) at or above
  /// it; and the bounds of the centres of each side are known.
  bool choose(std::size_t begin, std::size_t end, const Box3f& cell, const CentreBounds& centres, int& axis,
              float& plane, std::size_t& middle, CentreBounds& lower_centres, CentreBounds& upper_centres) {
    axis = 0;
    for (int a = 1; a < 3; ++a)
      if (static_cast<double>(centres.hi[a]) - centres.lo[a] >
          static_cast<double>(centres.hi[axis]) - centres.lo[axis])
        axis = a;
    const double lo = centres.lo[axis], hi = centres.hi[axis];
    if (!(lo < hi)) return false;  // all centres coincide
    Item* first = items_.data() + begin;
    Item* last = items_.data() + end;
    const std::size_t n = end - begin;

    if (n <= small_node) {
      plane = static_cast<float>(0.5 * lo + 0.5 * hi);
      if (!(lo < plane)) plane = static_cast<float>(hi);
      if (!inside_cell(cell, axis, plane)) return false;
      return partition(first, last, axis, plane, middle, lower_centres, upper_centres);
    }
    const auto scale = static_cast<float>(bin_count / (hi - lo));
    const auto low = static_cast<float>(lo);
    std::array<std::uint32_t, bin_count> centre_bins{}, starts{}, ends{};
    const int ax = axis;
    auto bin_of = [low, scale](float x) {
      return std::clamp(static_cast<int>((x - low) * scale), 0, bin_count - 1);
    };
    for (const Item* it = first; it < last; ++it) {
      ++centre_bins[bin_of(it->centre[ax])];
      ++starts[bin_of(it->centre[ax] - it->half[ax])];
      ++ends[bin_of(it->centre[ax] + it->half[ax])];
    }
    // Boundary j lies between bins j - 1 and j: centres below it go to the lower child; boxes that
    // start below it reach the lower cell, boxes that end above it the upper one.
    double best_cost = std::numeric_limits<double>::infinity();
    int best = 0;
    std::size_t below = 0, n_lower = 0, n_upper = n, best_cut = 0;
    for (int j = 1; j < bin_count; ++j) {
      below += centre_bins[j - 1];
      n_lower += starts[j - 1];
      n_upper -= ends[j - 1];
      if (below == 0 || below == n) continue;
      const double cost = static_cast<double>(n_lower) * static_cast<double>(n_lower) +
                          static_cast<double>(n_upper) * static_cast<double>(n_upper);
      if (cost < best_cost) {
        best_cost = cost;
        best = j;
        best_cut = n_lower + n_upper > n ? n_lower + n_upper - n : 0;
      }
    }
    if (best == 0 || 2 * best_cut > n) return false;  // (see partition)
    plane = static_cast<float>(lo + (hi - lo) * best / bin_count);
    if (!inside_cell(cell, ax, plane)) return false;

    return partition(first, last, axis, plane, middle, lower_centres, upper_centres);
  }

  /// Partitions by centre, gathering each side's centre bounds on the way. False (a leaf) when one
  /// side is empty, or when the plane cuts more than half of the boxes: boxes larger than the cells,
  /// which splitting would only copy into both children again and again.
  bool partition(Item* first, Item* last, int ax, float plane, std::size_t& middle,
                 CentreBounds& lower_centres, CentreBounds& upper_centres) {
    lower_centres = bounds_of(first, first);
    upper_centres = lower_centres;
    Item* split = first;
    std::size_t cut = 0;
    for (Item* it = first; it < last; ++it) {
      const float c = it->centre[ax], h = it->half[ax];
      if (c < plane) {
        cut += c + h > plane;
        include(lower_centres, *it);
        std::swap(*it, *split++);
      } else {
        cut += c - h < plane;
        include(upper_centres, *it);
      }
    }
    if (split == first || split == last) return false;
    if (2 * cut > static_cast<std::size_t>(last - first)) return false;
    middle = static_cast<std::size_t>(split - items_.data());
    return true;
  }

  std::vector<Item>& items_;
  std::size_t leaf_size_;
  std::size_t max_depth_;
  std::vector<BuiltNode>& nodes_;
};

}  // namespace

void build_binned(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
                  std::size_t max_depth, TreeWriter& out) {
  const auto budget = static_cast<std::size_t>(root_budget(params, boxes.size()));
  std::vector<Item> items(boxes.size());
  for (std::size_t leaf_size = params.leaf_size;; leaf_size *= 4) {
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      const Box3f& b = boxes[i];
      Item& item = items[i];
      for (int a = 0; a < 3; ++a) {
        item.centre[a] = 0.5f * b.lo[a] + 0.5f * b.hi[a];
        item.half[a] = 0.5f * b.hi[a] - 0.5f * b.lo[a];
      }
      item.id = static_cast<std::uint32_t>(i);
    }
    out.nodes.clear();
    PlaneBuilder planes(items, leaf_size, max_depth, out.nodes);
    planes.build_all(bounds);
    out.depth = planes.deepest_leaf;
    if (route_boxes(out.nodes, boxes.data(), boxes.size(), budget, out.references)) return;
  }
}

}  // namespace kdspace::detail
