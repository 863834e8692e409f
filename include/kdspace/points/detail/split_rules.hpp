// Split rules as small policies. The builder asks an axis rule for the axis and a position rule for
// the plane; it then moves the node's points to their sides in one pass (builder.hpp). Adding a rule
// means adding one struct here and one case in with_split_rules().
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "kdspace/points/params.hpp"

namespace kdspace::detail {

/// What a rule may look at: the node's points (contiguous rows), their exact bounds and the node's
/// cell (the region of space the node stands for), all per axis.
template <class T>
struct NodeView {
  const T* rows;  ///< row-major coordinates of the node's points
  std::size_t count;
  std::size_t dim;
  const T* point_lo;  ///< bounds of the node's points
  const T* point_hi;
  const T* cell_lo;  ///< the node's cell
  const T* cell_hi;
  std::size_t depth;
  T* scratch;  ///< room for `count` values, for rules that select (null for the others)

  T coord(std::size_t i, std::size_t axis) const { return rows[i * dim + axis]; }
};

/// A split: points with coordinate below `value` go left, above it right, and of those equal to it
/// the first `equal_left` (in row order) go left, the rest right.
template <class T>
struct Plane {
  T value;
  std::size_t equal_left;
};
inline constexpr std::size_t all_equal_left = std::numeric_limits<std::size_t>::max();

// ---- axis rules (only called when the node's points are not all identical) ----------------------

struct CycleAxis {
  template <class T>
  static std::size_t choose(const NodeView<T>& in) {
    for (std::size_t step = 0; step < in.dim; ++step) {
      const std::size_t axis = (in.depth + step) % in.dim;
      if (in.point_hi[axis] > in.point_lo[axis]) return axis;  // skip axes on which the node is flat
    }
    return in.depth % in.dim;
  }
};

struct MaxSpreadAxis {
  template <class T>
  static std::size_t choose(const NodeView<T>& in) {
    std::size_t best = 0;
    T best_spread = in.point_hi[0] - in.point_lo[0];
    for (std::size_t a = 1; a < in.dim; ++a) {
      const T spread = in.point_hi[a] - in.point_lo[a];
      if (spread > best_spread) best = a, best_spread = spread;
    }
    return best;
  }
};

// ---- position rules (the axis is never flat: point_lo[axis] < point_hi[axis]) -------------------

/// The middle of [lo, hi], without overflow when hi - lo exceeds the largest finite value.
template <class T>
T middle_of(T lo, T hi) {
  return lo / 2 + hi / 2;
}

/// Object median: the left side gets the count / 2 smallest coordinates. The selection
/// (std::nth_element: introselect, so sorted or gridded input never goes quadratic) runs on a
/// contiguous copy of the one coordinate, not on (coordinate, index) pairs; ties at the median are
/// shared out in row order so that the sides are exactly count / 2 and count - count / 2.
struct MedianPosition {
  static constexpr bool needs_scratch = true;
  template <class T>
  static Plane<T> split(const NodeView<T>& in, std::size_t axis) {
    const std::size_t half = in.count / 2;
    T* keys = in.scratch;
    for (std::size_t i = 0; i < in.count; ++i) keys[i] = in.coord(i, axis);
    std::nth_element(keys, keys + half, keys + in.count);
    const T median = keys[half];
    std::size_t below = 0;  // keys[0, half) are <= median; those below it go left whatever their order
    for (std::size_t i = 0; i < half; ++i) below += keys[i] < median ? 1 : 0;
    return {median, half - below};
  }
};

/// Spatial middle of the cell; one side may be empty (the search never enters an empty child).
struct MiddlePosition {
  static constexpr bool needs_scratch = false;
  template <class T>
  static Plane<T> split(const NodeView<T>& in, std::size_t axis) {
    return {middle_of(in.cell_lo[axis], in.cell_hi[axis]), 0};
  }
};

/// Middle of the cell; when all points fall on one side, the plane slides to the nearest point so
/// that each side keeps at least one (Maneewongvatana & Mount, 1999).
struct SlidingMidpointPosition {
  static constexpr bool needs_scratch = false;
  template <class T>
  static Plane<T> split(const NodeView<T>& in, std::size_t axis) {
    const T plane = middle_of(in.cell_lo[axis], in.cell_hi[axis]);
    if (plane <= in.point_lo[axis]) return {in.point_lo[axis], all_equal_left};  // the lowest points go left
    if (plane > in.point_hi[axis]) return {in.point_hi[axis], 0};                // the highest go right
    return {plane, 0};
  }
};

/// Middle of the node's points' extent along the axis (their bounding box, not the cell): both sides
/// always keep points, the cells hug the data (a scan's points lie on surfaces, with empty space
/// between), and the plane is known before the points are touched, so the split is one pass.
struct MidpointPosition {
  static constexpr bool needs_scratch = false;
  template <class T>
  static Plane<T> split(const NodeView<T>& in, std::size_t axis) {
    const T lo = in.point_lo[axis], hi = in.point_hi[axis];
    const T plane = middle_of(lo, hi);
    // lo and hi adjacent floats: the middle rounds to lo, and "below lo" would be empty.
    return plane > lo ? Plane<T>{plane, 0} : Plane<T>{lo, all_equal_left};
  }
};

/// Calls f(AxisRuleType{}, PositionRuleType{}) with the policy types the parameters name.
template <class F>
decltype(auto) with_split_rules(const BuildParams& params, F&& f) {
  auto with_position = [&](auto axis_rule) -> decltype(auto) {
    switch (params.position) {
      case PositionRule::middle:
        return f(axis_rule, MiddlePosition{});
      case PositionRule::sliding_midpoint:
        return f(axis_rule, SlidingMidpointPosition{});
      case PositionRule::midpoint:
        return f(axis_rule, MidpointPosition{});
      case PositionRule::median:
        break;
    }
    return f(axis_rule, MedianPosition{});
  };
  if (params.axis == AxisRule::cycle) return with_position(CycleAxis{});
  return with_position(MaxSpreadAxis{});
}

}  // namespace kdspace::detail
