// The compact node of the point tree: 16 bytes for float, 24 for double.
#pragma once

#include <cstdint>

namespace kdspace::detail {

/// Nodes are stored depth first: an inner node's left child is the next node, its right child is
/// at `link`. Instead of one split value an inner node keeps the two tight bounds along its axis
/// (left_max: the largest coordinate in the left subtree, right_min: the smallest in the right),
/// so the gap between the children is never searched.
/// A leaf holds the points [link, link + count) of the leaf-ordered copy.
template <class T>
struct PointNode {
  static constexpr std::uint32_t leaf_bit = 0x80000000u;
  static constexpr std::uint32_t identical_bit = 0x40000000u;  ///< leaf whose points all coincide
  static constexpr std::uint32_t count_mask = 0x3fffffffu;

  T left_max;
  T right_min;
  std::uint32_t link;  ///< right child (inner) or first point (leaf)
  std::uint32_t info;  ///< axis (inner) or leaf_bit | identical_bit? | count (leaf)

  bool is_leaf() const { return (info & leaf_bit) != 0; }
  bool all_identical() const { return (info & identical_bit) != 0; }
  std::uint32_t axis() const { return info; }
  std::uint32_t count() const { return info & count_mask; }
  std::uint32_t first() const { return link; }
  std::uint32_t right_child() const { return link; }
};

}  // namespace kdspace::detail
