// Split rules as small policies. The builder asks an axis rule for the axis and a position rule to
// partition the node's points; adding a rule means adding one struct here and one case in
// with_split_rules().
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "kdspace/points/params.hpp"

namespace kdspace::detail {

/// A coordinate and the node-local index of its point.
template <class T>
struct Keyed {
  T key;
  std::uint32_t index;
};

/// What a rule may look at: the node's points, the bounds of those points and the node's cell, all
/// per axis. The rule reorders the node-local indices [first, last) (0 .. count-1 into `coords`); the
/// builder then moves the rows themselves.
template <class T>
struct SplitInput {
  const T* coords;  ///< row-major coordinates of the node's points
  std::size_t dim;
  std::uint32_t* first;  ///< node-local indices [first, last), reordered by the position rule
  std::uint32_t* last;
  const T* point_lo;  ///< bounds of the node's points
  const T* point_hi;
  const T* cell_lo;  ///< the node's cell (the region of space the node stands for)
  const T* cell_hi;
  std::size_t depth;
  Keyed<T>* keyed;  ///< scratch for (last - first) entries, for rules that select on copied keys

  T coord(std::uint32_t i, std::size_t axis) const { return coords[std::size_t{i} * dim + axis]; }
};

/// The result of a position rule: [first, first + left_count) go left, the rest right; `plane` is
/// the splitting coordinate, which bounds the left and right cells.
template <class T>
struct Partition {
  std::size_t left_count;
  T plane;
};

// ---- axis rules (only called when the node's points are not all identical) ----------------------

struct CycleAxis {
  template <class T>
  static std::size_t choose(const SplitInput<T>& in) {
    for (std::size_t step = 0; step < in.dim; ++step) {
      const std::size_t axis = (in.depth + step) % in.dim;
      if (in.point_hi[axis] > in.point_lo[axis]) return axis;  // skip axes on which the node is flat
    }
    return in.depth % in.dim;
  }
};

struct MaxSpreadAxis {
  template <class T>
  static std::size_t choose(const SplitInput<T>& in) {
    std::size_t best = 0;
    T best_spread = in.point_hi[0] - in.point_lo[0];
    for (std::size_t a = 1; a < in.dim; ++a) {
      const T spread = in.point_hi[a] - in.point_lo[a];
      if (spread > best_spread) best = a, best_spread = spread;
    }
    return best;
  }
};

// ---- position rules --------------------------------------------------------------------------

/// Object median: std::nth_element (introselect), so sorted or gridded input never goes quadratic.
/// The selection runs on a contiguous copy of (coordinate, index) pairs, not on coordinates read
/// through the index array at every comparison.
struct MedianPosition {
  template <class T>
  static Partition<T> split(const SplitInput<T>& in, std::size_t axis) {
    const std::size_t n = static_cast<std::size_t>(in.last - in.first);
    Keyed<T>* keyed = in.keyed;
    for (std::size_t i = 0; i < n; ++i) keyed[i] = {in.coord(in.first[i], axis), in.first[i]};
    Keyed<T>* mid = keyed + n / 2;
    std::nth_element(keyed, mid, keyed + n, [](const Keyed<T>& a, const Keyed<T>& b) { return a.key < b.key; });
    for (std::size_t i = 0; i < n; ++i) in.first[i] = keyed[i].index;
    return {n / 2, mid->key};
  }
};

template <class T>
std::size_t partition_below(const SplitInput<T>& in, std::size_t axis, T plane) {
  std::uint32_t* cut =
      std::partition(in.first, in.last, [&](std::uint32_t i) { return in.coord(i, axis) < plane; });
  return static_cast<std::size_t>(cut - in.first);
}

/// The middle of [lo, hi], without overflow when hi - lo exceeds the largest finite value.
template <class T>
T middle_of(T lo, T hi) {
  return lo / 2 + hi / 2;
}

/// Spatial middle of the cell; one side may be empty (the search never enters an empty child).
struct MiddlePosition {
  template <class T>
  static Partition<T> split(const SplitInput<T>& in, std::size_t axis) {
    const T plane = middle_of(in.cell_lo[axis], in.cell_hi[axis]);
    return {partition_below(in, axis, plane), plane};
  }
};

/// Middle of the cell; when all points fall on one side, the plane slides to the nearest point so
/// that each side keeps at least one (Maneewongvatana & Mount, 1999).
struct SlidingMidpointPosition {
  template <class T>
  static Partition<T> split(const SplitInput<T>& in, std::size_t axis) {
    T plane = middle_of(in.cell_lo[axis], in.cell_hi[axis]);
    // The axis is not flat, so point_lo < point_hi and each slid partition leaves both sides non-empty.
    if (plane <= in.point_lo[axis]) {
      plane = in.point_lo[axis];  // everything is right of the middle: keep the lowest points left
      auto cut = std::partition(in.first, in.last, [&](std::uint32_t i) { return in.coord(i, axis) <= plane; });
      return {static_cast<std::size_t>(cut - in.first), plane};
    }
    if (plane > in.point_hi[axis]) plane = in.point_hi[axis];  // everything is left: highest go right
    return {partition_below(in, axis, plane), plane};
  }
};

/// Calls f(AxisRuleType{}, PositionRuleType{}) with the policy types the parameters name.
template <class F>
decltype(auto) with_split_rules(const BuildParams& params, F&& f) {
  auto with_position = [&](auto axis_rule) -> decltype(auto) {
    switch (params.position) {
      case PositionRule::middle: return f(axis_rule, MiddlePosition{});
      case PositionRule::sliding_midpoint: return f(axis_rule, SlidingMidpointPosition{});
      case PositionRule::median: break;
    }
    return f(axis_rule, MedianPosition{});
  };
  if (params.axis == AxisRule::cycle) return with_position(CycleAxis{});
  return with_position(MaxSpreadAxis{});
}

}  // namespace kdspace::detail
