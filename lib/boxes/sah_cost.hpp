// The SAH cost model shared by both SAH builds and by the tree statistics.
//
// Both exact builds must pick the very same plane, so both sweep their candidates with one function
// (sweep_axis in sah_cost.cpp, compiled once), which computes the cost of a candidate from exact
// inputs: the cell, the plane and three counts. Ties between planes of equal cost go to the smaller
// axis, then the smaller position.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
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

/// The cost units of testing n boxes: the traversal tests a leaf's boxes four at a time (LeafBlock),
/// so a leaf of 1 to 4 boxes costs one test, of 5 to 8 two, and so on.
inline double box_tests(std::size_t n) {
  return static_cast<double>((n + 3) / 4);
}

/// Evaluates candidate planes of one node (the SAH of W&H 2006, with planar events), with the cost
/// of a leaf counted in tests of four boxes (box_tests).
class SahCostModel {
 public:
  SahCostModel(const BoxBuildParams& params, const Box3f& cell);

  /// The cost of the plane at `position`: the cheaper placement of the n_planar boxes lying in it
  /// (evaluate() says which).
  double cost_of(int axis, float position, std::size_t n_left, std::size_t n_right,
                 std::size_t n_planar) const {
    double p_left, p_right;
    probabilities(axis, position, p_left, p_right);
    const double cost_left = cost(p_left, p_right, n_left + n_planar, n_right);
    if (n_planar == 0) return cost_left;
    const double cost_right = cost(p_left, p_right, n_left, n_right + n_planar);
    return cost_left <= cost_right ? cost_left : cost_right;
  }

  /// The cheaper of the two placements of the n_planar boxes lying in the plane, with its cost:
  /// cost(n_left + n_planar, n_right) or cost(n_left, n_right + n_planar); left on a tie.
  SplitCandidate evaluate(int axis, float position, std::size_t n_left, std::size_t n_right,
                          std::size_t n_planar) const {
    double p_left, p_right;
    probabilities(axis, position, p_left, p_right);
    const double cost_left = cost(p_left, p_right, n_left + n_planar, n_right);
    const double cost_right = n_planar == 0 ? cost_left : cost(p_left, p_right, n_left, n_right + n_planar);
    SplitCandidate c;
    c.split.axis = axis;
    c.split.position = position;
    c.split.planar_left = cost_left <= cost_right;
    c.cost = c.split.planar_left ? cost_left : cost_right;
    c.split.n_left = n_left + (c.split.planar_left ? n_planar : 0);
    c.split.n_right = n_right + (c.split.planar_left ? 0 : n_planar);
    return c;
  }

  /// The cost of not splitting: K_i * box_tests(n).
  double leaf_cost(std::size_t n) const { return k_i_ * box_tests(n); }

 private:
  void probabilities(int axis, float position, double& p_left, double& p_right) const {
    const double w_left = static_cast<double>(position) - static_cast<double>(cell_.lo[axis]);
    const double w_right = static_cast<double>(cell_.hi[axis]) - static_cast<double>(position);
    p_left = fixed_[axis] + per_width_[axis] * w_left;
    p_right = fixed_[axis] + per_width_[axis] * w_right;
  }
  double cost(double p_left, double p_right, std::size_t n_left, std::size_t n_right) const {
    const double lambda = (n_left == 0 || n_right == 0) ? empty_factor_ : 1.0;
    return lambda * (k_t_ + k_i_ * (p_left * box_tests(n_left) + p_right * box_tests(n_right)));
  }

  Box3f cell_;
  /// The measure of the part of the cell of width w along axis k is fixed_[k] + per_width_[k] * w,
  /// both divided by the cell's measure: every measure used is affine in the split axis's extent.
  double fixed_[3] = {0, 0, 0};
  double per_width_[3] = {0, 0, 0};
  double k_t_, k_i_, empty_factor_;
};

/// A boundary of a clipped box along one axis (an "event" of W&H 2006), packed in one 64-bit key
/// that sorts by (position, type, reference): at one position the ends come first, then the flat
/// boxes, then the starts. 8 bytes, one integer comparison: the builds sort and move hundreds of
/// millions of them.
struct Event {
  enum Type : std::uint32_t { end = 0, planar = 1, start = 2 };

  /// Bits 32-63: the position as an integer of the same order (-0 taken as +0); bits 30-31: the
  /// type; bits 0-29: the reference's position in its node's list.
  std::uint64_t key;

  Event(float pos, std::uint32_t ref, Type type)
      : key(static_cast<std::uint64_t>(ordered_bits(pos)) << 32 | static_cast<std::uint64_t>(type) << 30 |
            ref) {}
  float position() const {
    const auto u = static_cast<std::uint32_t>(key >> 32);
    const std::uint32_t bits = (u & 0x80000000u) ? u ^ 0x80000000u : ~u;
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
  }
  std::uint32_t ref() const { return static_cast<std::uint32_t>(key) & 0x3fffffffu; }
  Type type() const { return static_cast<Type>((static_cast<std::uint32_t>(key) >> 30) & 3u); }
  /// True when both lie at the same position.
  bool same_position(const Event& o) const { return (key >> 32) == (o.key >> 32); }
  /// The same event for the reference's new position in a child's list.
  Event moved_to(std::uint32_t ref) const {
    Event e = *this;
    e.key = (key & ~std::uint64_t{0x3fffffffu}) | ref;
    return e;
  }

  friend bool operator<(const Event& a, const Event& b) { return a.key < b.key; }

 private:
  /// The bits of f, flipped so that unsigned integer order is float order.
  static std::uint32_t ordered_bits(float f) {
    f += 0.0f;  // -0 becomes +0: the two are one position
    std::uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    return (bits & 0x80000000u) ? ~bits : bits | 0x80000000u;
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
/// in `best` (the incremental sweep of W&H 2006, over one dimension). Only planes strictly inside
/// the cell are candidates. The events may be those of a window of positions only: then `before`
/// boxes begin before the window's first event and `gone` end before it (a flat box counts in both).
void sweep_axis(const Event* events, std::size_t count, int axis, std::size_t n, const Box3f& cell,
                const SahCostModel& model, std::optional<SplitCandidate>& best, std::size_t before = 0,
                std::size_t gone = 0);

/// The split a SAH build makes, or none when no candidate costs less than a leaf.
inline std::optional<Split> accept_split(const std::optional<SplitCandidate>& best, const SahCostModel& model,
                                         std::size_t n) {
  if (best && best->cost < model.leaf_cost(n)) return best->split;
  return std::nullopt;
}

}  // namespace kdspace::detail
