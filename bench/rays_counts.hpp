// Work per ray inside a BoxTree, counted by walking its public arrays (nodes(), references(), box())
// in the order of the library's traversal (Havran's near/far, TA^B_rec; lib/rays/traverse.cpp), in
// double and without the float traversal's widening: the leaves a ray enters, how many of them are
// empty, the box references it tests and how many distinct boxes those are (a box straddling a
// plane is referenced by the leaves on both sides and may be tested again in each). For
// kdspace-rays-bench --counts, which sets these beside the boxes Embree's BVH hands its user-geometry
// callback, to tell whether the tree (references, leaf size, where the SAH cuts) or the cost of each
// node step and box test is what separates the two.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/detail/slab.hpp"

namespace kdspace::bench {

/// Sums over the rays walked.
struct TreeWalkCounts {
  std::uint64_t rays = 0;
  std::uint64_t inner_nodes = 0;       ///< inner nodes entered
  std::uint64_t leaves = 0;            ///< leaves entered
  std::uint64_t empty_leaves = 0;      ///< leaves entered that hold no box
  std::uint64_t references = 0;        ///< box references tested (a box in two leaves counts twice)
  std::uint64_t distinct_boxes = 0;    ///< different boxes among them
  std::uint64_t rays_hitting = 0;      ///< rays with a hit
  std::uint64_t leaves_after_hit = 0;  ///< leaves entered after the ray had a hit (which failed to end it)
};

/// Walks `ray` over [t_min, t_max] (closest hit) through `tree` and adds what it did to `counts`.
/// `seen` is scratch of tree.size() flags, all false on entry and on return.
inline void walk_closest_hit(const BoxTree& tree, const Ray& ray, double t_min, double t_max,
                             TreeWalkCounts& counts, std::vector<bool>& seen) {
  ++counts.rays;
  if (tree.size() == 0) return;
  const detail::PreparedRay r(ray);
  double t_entry = t_min, t_exit = t_max;
  if (!detail::clip_to_box(tree.bounds(), r, t_entry, t_exit)) return;
  struct Entry {
    std::uint32_t node;
    double t_entry, t_exit;
  };
  std::vector<Entry> stack{{0, t_entry, t_exit}};
  std::vector<std::uint32_t> tested;
  double best_t = t_max;
  bool hit = false;
  while (!stack.empty()) {
    const Entry e = stack.back();
    stack.pop_back();
    if (e.t_entry > best_t) continue;
    std::uint32_t index = e.node;
    t_entry = e.t_entry;
    t_exit = e.t_exit;
    for (;;) {
      const BoxNode node = tree.nodes()[index];
      if (node.is_leaf()) {
        ++counts.leaves;
        counts.empty_leaves += node.count() == 0;
        counts.leaves_after_hit += hit;
        const std::uint32_t* ids = tree.leaf_references(node);
        for (std::uint32_t k = 0; k < node.count(); ++k) {
          ++counts.references;
          if (!seen[ids[k]]) {
            seen[ids[k]] = true;
            tested.push_back(ids[k]);
          }
          double t_near = t_min, t_far = best_t;
          if (detail::clip_to_box(tree.box(ids[k]), r, t_near, t_far)) {
            best_t = std::min(best_t, t_near);
            hit = true;
          }
        }
        break;
      }
      ++counts.inner_nodes;
      const int axis = node.axis();
      const bool negative = r.negative[axis];
      const std::uint32_t near = negative ? node.right_child() : index + 1,
                          far = negative ? index + 1 : node.right_child();
      if (r.parallel[axis]) {
        // In the plane: both children; else the side the origin lies on.
        const double split = node.split();
        if (r.origin[axis] == split) {
          stack.push_back({far, t_entry, t_exit});
          index = near;
        } else {
          index = (r.origin[axis] < split) ? index + 1 : node.right_child();
        }
        continue;
      }
      const double t_split = (static_cast<double>(node.split()) - r.origin[axis]) * r.inverse[axis];
      if (t_split < t_entry) {
        index = far;
      } else if (t_split > t_exit) {
        index = near;
      } else {
        stack.push_back({far, t_split, t_exit});
        index = near;
        t_exit = t_split;
      }
    }
  }
  counts.rays_hitting += hit;
  counts.distinct_boxes += tested.size();
  for (const std::uint32_t b : tested) seen[b] = false;
}

}  // namespace kdspace::bench
