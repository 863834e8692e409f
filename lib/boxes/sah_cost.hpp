// The SAH cost model shared by both SAH builds and by the tree statistics.
//
// Both builds must pick the very same plane, so the cost of a candidate is computed in one place
// (sah_cost.cpp, not inlined into either build) from exact inputs: the cell, the plane and three
// counts. Ties between planes of equal cost go to the smaller axis, then the smaller position.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "build_common.hpp"
#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"

namespace kdspace::detail {

/// A candidate plane with its cost, ordered by (cost, axis, position).
struct SplitCandidate {
  double cost = 0;
  Split split;

  bool better_than(const SplitCandidate& o) const {
    if (cost != o.cost) return cost < o.cost;
    if (split.axis != o.split.axis) return split.axis < o.split.axis;
    return split.position < o.split.position;
  }
};

/// The measure (surface area or volume) of cells, made safe for flat cells.
///
/// P(sub | V) = measure(sub) / measure(V). When the scene or a node is flat the plain formula gives
/// 0 / 0, so the measure of a node and of its parts is taken over the axes on which the node has
/// extent: for volume, the product of the non-zero extents (the area of a flat cell, the length of
/// a thin one); for surface area, the length (sum of extents) of a cell flat on two axes. The two
/// parts of a split keep the parent's flat axes (planes lie strictly inside), so the ratio is always
/// between commensurable measures.
class CellMeasure {
 public:
  CellMeasure(HitProbability probability, const Box3f& cell);
  /// The measure of `sub` (a part of the cell this was made for); > 0 when the cell's is.
  double operator()(const Box3f& sub) const;
  /// The measure of the cell itself; 0 only for a cell that is a single point.
  double whole() const { return whole_; }

 private:
  HitProbability probability_;
  bool use_length_ = false;  ///< surface area of a cell flat on two axes: use its length instead
  bool has_extent_[3] = {false, false, false};
  double whole_ = 0;
};

/// Evaluates candidate planes of one node (the SAH of W&H 2006, with planar events).
class SahCostModel {
 public:
  SahCostModel(const BoxBuildParams& params, const Box3f& cell);

  /// The cheaper of the two placements of the n_planar boxes lying in the plane, with its cost:
  /// cost(n_left + n_planar, n_right) or cost(n_left, n_right + n_planar); left on a tie.
  SplitCandidate evaluate(int axis, float position, std::size_t n_left, std::size_t n_right,
                          std::size_t n_planar) const;

  /// The cost of not splitting: K_i * n.
  double leaf_cost(std::size_t n) const;

 private:
  double cost(double p_left, double p_right, std::size_t n_left, std::size_t n_right) const;

  Box3f cell_;
  /// The measure of the part of the cell of width w along axis k is fixed_[k] + per_width_[k] * w,
  /// both divided by the cell's measure: every measure used is affine in the split axis's extent.
  double fixed_[3] = {0, 0, 0};
  double per_width_[3] = {0, 0, 0};
  double k_t_, k_i_, empty_factor_;
};

/// A boundary of a clipped box along one axis (an "event" of W&H 2006). Sorted by (position, type):
/// at one position the ends come first, then the flat boxes, then the starts, which is the order the
/// sweep needs to count the boxes on each side of a plane.
/// 8 bytes: the builds move hundreds of millions of them.
struct Event {
  enum Type : std::uint32_t { end = 0, planar = 1, start = 2 };

  float position;
  std::uint32_t ref_and_type;  ///< bits 0-29: the reference's position in its node's list; 30-31: type

  Event(float pos, std::uint32_t ref, Type type) : position(pos), ref_and_type(ref | (type << 30)) {}
  std::uint32_t ref() const { return ref_and_type & 0x3fffffffu; }
  Type type() const { return static_cast<Type>(ref_and_type >> 30); }
  /// The same event for the reference's new position in a child's list.
  Event moved_to(std::uint32_t ref) const { return Event(position, ref, type()); }

  friend bool operator<(const Event& a, const Event& b) {
    return a.position < b.position || (a.position == b.position && a.type() < b.type());
  }
};

/// Appends the events of one reference along `axis`: one planar event for a flat extent, else a
/// start and an end.
inline void add_events(std::vector<Event>& out, const Box3f& bounds, int axis, std::uint32_t ref) {
  const float lo = bounds.lo[axis], hi = bounds.hi[axis];
  if (lo == hi) {
    out.emplace_back(lo, ref, Event::planar);
  } else {
    out.emplace_back(lo, ref, Event::start);
    out.emplace_back(hi, ref, Event::end);
  }
}

/// Sweeps the sorted events of one axis of a node holding n boxes and keeps the best candidate plane
/// in `best` (the incremental sweep of W&H 2006, over one dimension). Only planes strictly inside the cell
/// are candidates.
void sweep_axis(const Event* events, std::size_t count, int axis, std::size_t n, const Box3f& cell,
                const SahCostModel& model, std::optional<SplitCandidate>& best);

/// The split a SAH build makes, or none when no candidate costs less than a leaf.
inline std::optional<Split> accept_split(const std::optional<SplitCandidate>& best, const SahCostModel& model,
                                         std::size_t n) {
  if (best && best->cost < model.leaf_cost(n)) return best->split;
  return std::nullopt;
}

}  // namespace kdspace::detail
