// The descent of the BoxTree ray traversal: from a node, with the ray's interval [t_entry, t_exit]
// in its cell, down to a leaf, pushing the far children the ray may still need (traverse.cpp pops
// them). Havran's near/far step (TA^B_rec), without a branch on the ray: for random rays each
// choice is a coin toss for the branch predictor. Both children's nodes are read as soon as a node
// is known (the left is the next node, the right at right_child()), before the ray's plane
// parameter; the next node, the far child's push and the new interval are selects, and only the
// leaf-or-inner test ends the loop.
//
// Two forms with the same arithmetic, comparisons and choices, so the same leaf, pushes and node
// count: descend (any Real, integer selects) and, with AVX2, descend_avx (float; the node kept in
// a vector register, the ray's origin and reciprocal on the node's axis picked by a lane
// permutation on the axis bits, the next node a blend on the comparison's mask). In descend the
// chain from one node to the next runs through a load indexed by the axis, the plane parameter, a
// compare, integer masks and a move back to a vector register; descend_avx keeps it in vector
// registers (tests/test_rays.cpp checks the two against each other).
#pragma once

#include <cstdint>
#include <cstring>
#include <type_traits>

#include "kdspace/boxes/box_tree.hpp"
#include "traversal_ray.hpp"

namespace kdspace::detail {

/// A pending far child and the ray's interval in its cell: 12 bytes in float.
template <class Real>
struct StackEntry {
  std::uint32_t node;
  Real t_entry, t_exit;
};

/// A node's two words as one integer (word low, info high), and back: for selects between nodes.
inline std::uint64_t node_bits(const BoxNode& node) {
  static_assert(sizeof(BoxNode) == sizeof(std::uint64_t), "BoxNode: two 32-bit words");
  return node.word | static_cast<std::uint64_t>(node.info) << 32;
}
inline BoxNode node_of_bits(std::uint64_t bits) {
  BoxNode node;
  node.word = static_cast<std::uint32_t>(bits);
  node.info = static_cast<std::uint32_t>(bits >> 32);
  return node;
}

/// Bit a: the ray runs towards -a.
template <class Real>
inline std::uint32_t negative_axes(const TraversalRay<Real>& r) {
  return r.negative[0] | r.negative[1] << 1 | r.negative[2] << 2;
}

/// From node `index` to a leaf (returned), the ray in [t_entry, t_exit] in the node's cell; the far
/// children to visit later are written to stack[top..] (top advanced), and every node entered,
/// the leaf included, is counted in `visited`.
template <class Real>
inline BoxNode descend(const BoxNode* nodes, std::uint32_t index, Real t_entry, Real t_exit,
                       const TraversalRay<Real>& r, StackEntry<Real>* stack, std::size_t& top,
                       std::uint64_t& visited) {
  const std::uint32_t negative = negative_axes(r);
  const Real entry_low = widen_down(t_entry);
  BoxNode node = nodes[index];
  while (!node.is_leaf()) {
    ++visited;
    const int axis = node.axis();
    const std::uint32_t right = node.right_child();
    const std::uint64_t left_bits = node_bits(nodes[index + 1]), right_bits = node_bits(nodes[right]);
    const std::uint32_t towards_negative = (negative >> axis) & 1u;
    std::uint32_t near, far;
    order_children(index, right, towards_negative, near, far);
    const std::uint64_t node_differ = (left_bits ^ right_bits) & (0ull - towards_negative);
    const std::uint64_t near_bits = left_bits ^ node_differ, far_bits = right_bits ^ node_differ;
    // The ray crosses the plane at t_split. On a parallel axis the reciprocal is +-inf: t_split is
    // +inf (the ray stays on the near side), -inf (on the far side) or NaN (it lies in the plane).
    const Real t_split = (static_cast<Real>(node.split()) - r.origin[axis]) * r.inverse[axis];
    // The ray crossed the plane before entering the cell: the far child alone, over the same
    // interval. Else the near child over [t_entry, min(t_split, t_exit)], and the far child pushed
    // unless the ray leaves the cell before the plane. A NaN t_split is neither: both children over
    // the same interval. The interval comparisons are widened (traversal_ray.hpp).
    const std::uint32_t far_only = t_split < entry_low;
    const auto push = (far_only ^ 1u) & static_cast<std::uint32_t>(!(t_split > widen_up(t_exit)));
    stack[top] = StackEntry<Real>{far, t_split > t_entry ? t_split : t_entry, t_exit};
    top += push;
    index = near ^ ((near ^ far) & (0u - far_only));
    node = node_of_bits(near_bits ^ ((near_bits ^ far_bits) & (0ull - far_only)));
    const Real near_exit = t_split < t_exit ? t_split : t_exit;
    t_exit = far_only ? t_exit : near_exit;
  }
  ++visited;
  return node;
}

#if defined(KDSPACE_AVX2_DISPATCH)
/// The ray for descend_avx: lane a of origin and inverse holds axis a (lane 3 repeats axis 2), and
/// lane a of negative is all ones when the ray runs towards -a.
struct DescentRay {
  __m128 origin, inverse, negative;
};

__attribute__((target("avx2"))) inline DescentRay descent_ray(const TraversalRay<float>& r) {
  DescentRay d;
  d.origin = _mm_setr_ps(r.origin[0], r.origin[1], r.origin[2], r.origin[2]);
  d.inverse = _mm_setr_ps(r.inverse[0], r.inverse[1], r.inverse[2], r.inverse[2]);
  d.negative =
      _mm_castsi128_ps(_mm_setr_epi32(-static_cast<int>(r.negative[0]), -static_cast<int>(r.negative[1]),
                                      -static_cast<int>(r.negative[2]), 0));
  return d;
}

/// A node's two words in the low half of a register (split lane 0, info lane 1).
__attribute__((target("avx2"))) inline __m128 load_node(const BoxNode* node) {
  return _mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(node)));
}

/// descend<float> with the node in a vector register; `d` is descent_ray(r).
__attribute__((target("avx2"))) inline BoxNode descend_avx(const BoxNode* nodes, std::uint32_t index,
                                                           float t_entry, float t_exit,
                                                           const TraversalRay<float>& r, const DescentRay& d,
                                                           StackEntry<float>* stack, std::size_t& top,
                                                           std::uint64_t& visited) {
  const std::uint32_t negative = negative_axes(r);
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 relative = _mm_set1_ps(Widening<float>::relative);
  const __m128 absolute = _mm_set1_ps(Widening<float>::absolute);
  const __m128 entry = _mm_set1_ps(t_entry), entry_low = _mm_set1_ps(widen_down(t_entry));
  __m128 exit = _mm_set1_ps(t_exit);
  __m128 node = load_node(nodes + index);
  auto info = static_cast<std::uint32_t>(_mm_extract_epi32(_mm_castps_si128(node), 1));
  while ((info & 3u) != BoxNode::leaf_tag) {
    ++visited;
    const std::uint32_t right = info >> 2;
    const __m128 left_node = load_node(nodes + index + 1), right_node = load_node(nodes + right);
    // vpermilps reads the low two bits of each lane of its control: the axis, in info.
    const __m128i axis_control = _mm_castps_si128(_mm_shuffle_ps(node, node, 0x55));
    const __m128 towards_negative = _mm_permutevar_ps(d.negative, axis_control);
    const __m128 near_node = _mm_blendv_ps(left_node, right_node, towards_negative);
    const __m128 far_node = _mm_blendv_ps(right_node, left_node, towards_negative);
    const __m128 split = _mm_shuffle_ps(node, node, 0x00);
    const __m128 t_split = _mm_mul_ps(_mm_sub_ps(split, _mm_permutevar_ps(d.origin, axis_control)),
                                      _mm_permutevar_ps(d.inverse, axis_control));
    // As in descend: CMPLTPS is false for NaN, CMPNGTPS true; widen_up's operations in its order.
    const __m128 far_only = _mm_cmplt_ps(t_split, entry_low);
    const __m128 exit_high =
        _mm_add_ps(exit, _mm_add_ps(_mm_mul_ps(_mm_and_ps(exit, magnitude), relative), absolute));
    const __m128 reaches_far = _mm_cmpngt_ps(t_split, exit_high);
    const auto far_only_bit = static_cast<std::uint32_t>(_mm_movemask_ps(far_only) & 1);
    const auto push = static_cast<std::uint32_t>(_mm_movemask_ps(_mm_andnot_ps(far_only, reaches_far)) & 1);
    std::uint32_t near, far;
    order_children(index, right, (negative >> (info & 3u)) & 1u, near, far);
    // MAXSS and MINSS return their second operand when either is NaN, as descend's selects do.
    stack[top] = StackEntry<float>{far, _mm_cvtss_f32(_mm_max_ss(t_split, entry)), _mm_cvtss_f32(exit)};
    top += push;
    index = near ^ ((near ^ far) & (0u - far_only_bit));
    node = _mm_blendv_ps(near_node, far_node, far_only);
    exit = _mm_blendv_ps(_mm_min_ps(t_split, exit), exit, far_only);
    info = static_cast<std::uint32_t>(_mm_extract_epi32(_mm_castps_si128(node), 1));
  }
  ++visited;
  std::uint64_t bits;  // the node's eight bytes (_mm_cvtsi128_si64 exists on x86-64 only)
  _mm_storel_epi64(reinterpret_cast<__m128i*>(&bits), _mm_castps_si128(node));
  return node_of_bits(bits);
}
#endif

/// What a descent needs of the ray besides TraversalRay: descent_ray(r) for descend_avx (float, with
/// AVX2), nothing otherwise.
struct NoDescentRay {};
#if defined(KDSPACE_AVX2_DISPATCH)
template <class Real>
using DescentRayOf = std::conditional_t<std::is_same_v<Real, float>, DescentRay, NoDescentRay>;
#else
template <class Real>
using DescentRayOf = NoDescentRay;
#endif

}  // namespace kdspace::detail
