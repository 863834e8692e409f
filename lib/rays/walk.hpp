// One ray's walk through the BoxTree from a pending cell: Havran's recursive near/far traversal
// (TA^B_rec) with an explicit stack, its descents in descent.hpp, each leaf's boxes through the float
// filter (traversal_ray.hpp) and then the exact double test (slab.hpp). traverse.cpp walks a ray from
// the root; the ray streams of trace_stream.cpp walk a ray from a deeper cell once too few rays share
// it. Either way the walk makes the decisions of the whole single traversal below that cell, so the
// answers and the counts are those of single traces.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <optional>

#include "descent.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/detail/slab.hpp"
#include "kdspace/rays/ray.hpp"
#include "traversal_ray.hpp"

namespace kdspace::detail {

/// The arrays a walk reads.
struct BoxTreeView {
  const BoxNode* nodes;
  const LeafBlock* blocks;             ///< blocks[r / 4] holds the box of references[r] in lane r % 4
  const std::uint32_t* references;
};

inline BoxTreeView view_of(const BoxTree& tree) {
  return BoxTreeView{tree.nodes().data(), tree.leaf_blocks().data(), tree.references().data()};
}

/// A ray's best hit so far: t in double (the hit rule's), the box (Hit::none before the first), and
/// t rounded up to Real (the bound the traversal's float comparisons use).
template <class Real>
struct BestHit {
  double t;
  std::int32_t box = Hit::none;
  Real bound;

  explicit BestHit(float t_max) : t(t_max), bound(static_cast<Real>(t_max)) {}
  Hit hit() const { return box == Hit::none ? Hit{} : Hit{box, to_float_t(t)}; }
};

/// Where box `box`, hit at t when `hit`, comes before the best hit so far (best_t, best_box: a
/// smaller t, or the same t and a smaller index), makes it the best and `bound` t rounded up to
/// Real. Without a branch on the outcome (select_bits): whether a box that passed the filter is
/// hit, and hit before the best, is a coin toss that a branch mispredicted about once per exact
/// test.
template <class Real>
inline void keep_if_closer(bool hit, double t, std::int32_t box, double& best_t, std::int32_t& best_box,
                           Real& bound) {
  const bool take = hit & ((t < best_t) | (best_box == Hit::none) | (box < best_box));
  best_t = select_bits(take, t, best_t);
  best_box = select_bits(take, box, best_box);
  bound = select_bits(take, round_up<Real>(t), bound);
}

/// Tests the leaf `node`'s boxes against the ray over [t_min, best.t], keeping the closest hit
/// (equal t: the smaller box index) in `best`; with AnyHit, true as soon as one box is hit (then
/// `best` holds it). `exact` is the ray in double, made when the first box needs it.
template <class Real, bool AnyHit, bool Wide>
inline bool test_leaf(const BoxTreeView& tree, const BoxNode& node, const Ray& ray, const TraversalRay<Real>& r,
                      float t_min, std::optional<PreparedRay>& exact, BestHit<Real>& best, RayStats& stats) {
  constexpr std::uint32_t step_blocks = Wide ? 2 : 1;  // leaf blocks tested together
  const std::uint32_t count = node.count();
  stats.boxes_tested += count;
  const LeafBlock* blocks = tree.blocks + node.first() / 4;
  const std::uint32_t* ids = tree.references + node.first();
  const Real t_low = static_cast<Real>(t_min);
  // The filter's steps of up to 64 boxes first, all against the bound at their start, then the
  // double tests of the boxes they let through: one branch on the outcome per 64 boxes instead of
  // per step.
  for (std::uint32_t first = 0; first < count; first += 64) {
    const std::uint32_t end = std::min<std::uint32_t>(count, first + 64);
    std::uint64_t passed = 0;
    for (std::uint32_t done = first; done < end; done += 4 * step_blocks)
      passed |= std::uint64_t{leaf_step_candidates<Real, Wide>(blocks + done / 4, count - done, r, t_low, best.bound)}
                << (done - first);
    passed &= end - first == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << (end - first)) - 1;
    while (passed != 0) {
      const std::uint32_t lane = first + static_cast<std::uint32_t>(__builtin_ctzll(passed));
      passed &= passed - 1;
      double t_near = t_min, t_far = best.t;
      if (!exact) exact.emplace(ray);
      const bool hit = clip_to_box(box_in_lane(blocks[lane / 4], lane % 4), *exact, t_near, t_far);
      const auto box = static_cast<std::int32_t>(ids[lane]);
      if constexpr (AnyHit) {
        if (!hit) continue;
        best.t = t_near;
        best.box = box;
        return true;
      } else {
        keep_if_closer(hit, t_near, box, best.t, best.box, best.bound);
      }
    }
  }
  return false;
}

/// Walks the ray through the subtree of `start.node`, entered over [start.t_entry, start.t_exit],
/// keeping its best hit in `best` (which may hold a hit found elsewhere: cells beyond it are not
/// entered). With AnyHit it stops at the first box hit. `descent` is descent_ray(r) (Wide only).
template <class Real, bool AnyHit, bool Wide>
inline void walk(const BoxTreeView& tree, const Ray& ray, const TraversalRay<Real>& r,
                 [[maybe_unused]] const DescentRayOf<Real>& descent, StackEntry<Real> start, float t_min,
                 BestHit<Real>& best, RayStats& stats) {
  std::optional<PreparedRay> exact;
  std::array<StackEntry<Real>, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = start;
  while (top > 0) {
    const StackEntry<Real> entry = stack[--top];
    if (widen_down(entry.t_entry) > best.bound) continue;  // every hit in it is farther
    std::uint64_t visited = 0;
    BoxNode node;
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (Wide)
      node = descend_avx(tree.nodes, entry.node, entry.t_entry, entry.t_exit, r, descent, stack.data(), top,
                         visited);
    else
#endif
      node = descend(tree.nodes, entry.node, entry.t_entry, entry.t_exit, r, stack.data(), top, visited);
    stats.nodes_visited += visited;
    if (test_leaf<Real, AnyHit, Wide>(tree, node, ray, r, t_min, exact, best, stats)) return;
  }
}

}  // namespace kdspace::detail
