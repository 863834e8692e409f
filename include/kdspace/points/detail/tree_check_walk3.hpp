// The node walk of a loaded 3-D float point tree's check (tree_check.hpp) as one AVX2 loop: the cell
// in two registers (x y z and a spare lane), each inner node's cell on a stack of its own, and each
// leaf's points tested against the cell inline. It decides exactly what TreeChecker's visit() and
// visit_leaf() decide for such a tree and returns false where they would throw; the checker then
// walks the same subtree again with visit() to name the problem (the tests run both, and
// `baseline_without_avx2_index` the baseline alone).
#pragma once

#include <cstddef>
#include <cstdint>

#include "kdspace/detail/check_companion.hpp"
#include "kdspace/points/detail/node.hpp"
#include "kdspace/points/detail/tree_check_kernels.hpp"

namespace kdspace::detail {

/// What a walk of one subtree reads and where it stands: the same figures as TreeChecker's Walk.
struct Walk3 {
  const PointNode<float>* nodes = nullptr;
  std::size_t node_count = 0;            // the nodes the walk may read lie below this one
  const float* points = nullptr;         // n rows of 3 floats
  const std::uint32_t* order = nullptr;  // n values
  std::size_t n = 0;
  CheckCompanion* companion = nullptr;
  std::size_t piece = 0;                        // the companion's piece the walk reads
  std::size_t rows_array = 0, nodes_array = 0;  // the companion's numbers for rows and nodes
  std::size_t next_node = 0, next_point = 0, rows_ready = 0, nodes_ready = 0;
  std::size_t depth = 0, leaves = 0;  // deepest leaf so far, leaves so far
};

#if defined(KDSPACE_AVX2_DISPATCH)

/// Walks the subtree whose root is w.next_node, at `depth`, in the cell lo / hi (x y z, then any),
/// as TreeChecker::visit() does, for a 3-D float tree: the same checks, the same calls to the
/// companion, the same figures in `w` on success. Returns false where visit() would throw (w is then
/// left part way). MaxDepth: the deepest node the search accepts.
template <std::size_t MaxDepth>
__attribute__((target("avx2"))) bool walk3_avx2(Walk3& w, std::size_t depth, const float* cell_lo,
                                                const float* cell_hi) {
  // An inner node on the way down to the node being visited: its own cell, and its depth.
  struct Frame {
    __m128 lo, hi;
    std::uint32_t id, depth;
  };
  Frame stack[MaxDepth + 1];  // one frame a level: depth is checked before a frame is pushed
  std::size_t top = 0;
  const PointNode<float>* nodes = w.nodes;
  const std::size_t node_count = w.node_count, n = w.n, first_node = w.next_node;
  if (node_count > ~std::uint32_t{0}) return false;  // frames keep node ids in 32 bits
  CheckCompanion* const companion = w.companion;
  const __m128i lanes = _mm_setr_epi32(0, 1, 2, 3);
  const auto on_axis = [lanes](std::uint32_t axis) {  // all ones in lane `axis`
    return _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_set1_epi32(static_cast<int>(axis)), lanes));
  };
  __m128 lo = _mm_loadu_ps(cell_lo), hi = _mm_loadu_ps(cell_hi);
  std::size_t id = first_node, next_point = w.next_point, deepest = w.depth;
  // Without a companion everything is ready.
  constexpr std::size_t all = ~std::size_t{0};
  std::size_t rows_ready = companion ? w.rows_ready : all, nodes_ready = companion ? w.nodes_ready : all;
  // Nodes below `readable` are in the array and ready to read.
  std::size_t readable = nodes_ready < node_count ? nodes_ready : node_count;
  // A node deeper than MaxDepth fails: the subtree's root here, any other below an inner node at
  // MaxDepth or deeper, which fails when it is met (so no frame is pushed past the stack's end).
  if (depth > MaxDepth) return false;
  for (;;) {
    if (id >= readable) {
      if (id >= node_count) return false;
      nodes_ready = companion->ready(w.nodes_array, w.piece, id + 1);
      readable = nodes_ready < node_count ? nodes_ready : node_count;
    }
    const PointNode<float>& node = nodes[id];
    if (!node.is_leaf()) {  // down its left side, in the cell below left_max
      const std::uint32_t axis = node.axis();
      if (axis >= 3 || !(node.left_max <= node.right_min) || depth >= MaxDepth)
        return false;  // false too when either bound is NaN
      stack[top++] = {lo, hi, static_cast<std::uint32_t>(id), static_cast<std::uint32_t>(depth)};
      hi = _mm_blendv_ps(hi, _mm_min_ps(hi, _mm_set1_ps(node.left_max)), on_axis(axis));
      ++id;
      ++depth;
      continue;
    }
    // Its points must start where the last leaf's ended, and end by n (first == next_point <= n, and
    // count < 2^30: no overflow).
    const std::size_t first = node.first(), count = node.count();
    if (first != next_point) return false;
    next_point += count;
    if (next_point > n) return false;
    deepest = depth > deepest ? depth : deepest;
    if (next_point > rows_ready) rows_ready = companion->ready(w.rows_array, w.piece, next_point);
    const float* rows = w.points + 3 * first;
    if (!points3_in_cell_avx2(rows, count, lo, hi)) return false;
    if (node.all_identical())
      for (std::size_t i = 1; i < count; ++i)
        if (!(rows[3 * i] == rows[0]) || !(rows[3 * i + 1] == rows[1]) || !(rows[3 * i + 2] == rows[2]) ||
            !(w.order[first + i - 1] < w.order[first + i]))
          return false;
    ++id;
    // Up to the nearest node whose right side is still to come: its right child must be next.
    if (top == 0) break;
    const Frame& up = stack[--top];
    const PointNode<float>& parent = nodes[up.id];
    if (parent.right_child() != id) return false;
    lo = _mm_blendv_ps(up.lo, _mm_max_ps(up.lo, _mm_set1_ps(parent.right_min)), on_axis(parent.axis()));
    hi = up.hi;
    depth = up.depth + 1;
  }
  w.next_node = id;
  w.next_point = next_point;
  w.rows_ready = rows_ready;
  w.nodes_ready = nodes_ready;
  w.depth = deepest;
  w.leaves += (id - first_node + 1) / 2;  // every inner node of the subtree has two children
  return true;
}

#endif

}  // namespace kdspace::detail
