// Ray traversal of the BoxTree: Havran's recursive near/far algorithm (TA^B_rec in his thesis
// "Heuristic Ray Shooting Algorithms", 2000), written with an explicit stack of (node, t_entry, t_exit).
//
// A node is entered with the interval [t_entry, t_exit] over which the ray lies in its cell. The ray
// crosses the split plane at t_split; the child on the side the ray comes from (the near child) is
// visited first, over [t_entry, t_split], and the far child afterwards, over [t_split, t_exit], only
// when the ray reaches it inside the cell. A box may be referenced by several leaves and its hit may
// lie beyond the leaf being tested, so the search goes on while a pending node could still hold a
// hit no farther than the best one (t_entry <= best t; equality matters for the tie rule).
//
// Robustness:
//   - everything is computed in double, from float data: t = (plane - origin) * (1 / direction);
//     the slab test of a box uses the same expression as the split planes, so a box face that is also
//     a split plane gives bitwise the same t in both.
//   - a zero direction component (+0 or -0) is never divided by: the ray stays on one side of a plane
//     on that axis, or lies in it and then visits both children over the same interval.
//   - the split parameter is widened by a relative margin far above double rounding, so a hit at the
//     boundary between two cells is seen from both.
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/rays/detail/slab.hpp"

namespace kdspace {

namespace {

/// Relative widening of t_split: 2^-40, some 8000 ulps of double, yet 2^-16 of a float ulp.
constexpr double split_margin = 1.0 / 1099511627776.0;

using detail::clip_to_box;
using detail::PreparedRay;

/// t rounded to float; a hit beyond the float range reports the largest finite float.
inline float to_float_t(double t) {
  constexpr double largest = std::numeric_limits<float>::max();
  return static_cast<float>(t > largest ? largest : t);
}

struct StackEntry {
  std::uint32_t node;
  double t_entry, t_exit;
};

void check_range(float t_min, float t_max) {
  if (!std::isfinite(t_min)) throw Error("t_min must be finite, got " + std::to_string(t_min));
  if (std::isnan(t_max)) throw Error("t_max must not be NaN");
  if (t_min > t_max)
    throw Error("t_min " + std::to_string(t_min) + " exceeds t_max " + std::to_string(t_max));
}

void check_ray(const Ray& ray) {
  const std::string problem = ray_problem(ray);
  if (!problem.empty()) throw Error("ray: " + problem);
}

}  // namespace

template <bool AnyHit>
Hit BoxTree::trace(const Ray& ray, double t_min, double t_max, RayStats& stats) const {
  ++stats.rays;
  Hit none;
  if (boxes_.empty()) return none;
  const PreparedRay r(ray);

  double t_entry = t_min, t_exit = t_max;
  if (!clip_to_box(bounds_, r, t_entry, t_exit)) return none;
  t_entry -= std::abs(t_entry) * split_margin;
  t_exit += std::abs(t_exit) * split_margin;

  double best_t = t_max;
  std::int32_t best_box = Hit::none;
  std::array<StackEntry, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = StackEntry{0, t_entry, t_exit};

  while (top > 0) {
    const StackEntry entry = stack[--top];
    if (entry.t_entry > best_t) continue;  // every hit in this cell is farther than the best
    std::uint32_t index = entry.node;
    t_entry = entry.t_entry;
    t_exit = entry.t_exit;
    for (;;) {
      ++stats.nodes_visited;
      const BoxNode& node = nodes_[index];
      if (node.is_leaf()) {
        const std::uint32_t* ids = references_.data() + node.first();
        const Box3f* leaf_boxes = leaf_boxes_.data() + node.first();
        for (std::uint32_t i = 0; i < node.count(); ++i) {
          ++stats.boxes_tested;
          const auto box = static_cast<std::int32_t>(ids[i]);
          double t_near = t_min, t_far = best_t;
          if (!clip_to_box(leaf_boxes[i], r, t_near, t_far)) continue;
          if constexpr (AnyHit) {
            return Hit{box, to_float_t(t_near)};
          } else {
            if (t_near < best_t || best_box == Hit::none || box < best_box) {
              best_t = t_near;
              best_box = box;
            }
          }
        }
        break;
      }
      const int axis = node.axis();
      const double split = node.split();
      const std::uint32_t left = index + 1, right = node.right_child();
      if (r.parallel[axis]) {
        // The ray never crosses the plane: one side, or both when it lies in the plane.
        if (r.origin[axis] < split) {
          index = left;
        } else if (r.origin[axis] > split) {
          index = right;
        } else {
          stack[top++] = StackEntry{right, t_entry, t_exit};
          index = left;
        }
        continue;
      }
      // The near child holds the ray for t < t_split: the left one when the ray moves towards +axis.
      const std::uint32_t near = r.negative[axis] ? right : left;
      const std::uint32_t far = r.negative[axis] ? left : right;
      const double t_split = (split - r.origin[axis]) * r.inverse[axis];
      const double margin = std::abs(t_split) * split_margin;
      const double split_lo = t_split - margin, split_hi = t_split + margin;
      if (split_lo > t_exit) {
        index = near;  // the ray leaves the cell before reaching the plane
      } else if (split_hi < t_entry) {
        index = far;  // the ray crossed the plane before entering the cell
      } else {
        stack[top++] = StackEntry{far, std::max(t_entry, split_lo), t_exit};
        index = near;
        t_exit = std::min(t_exit, split_hi);
      }
    }
  }
  if (best_box == Hit::none) return none;
  return Hit{best_box, to_float_t(best_t)};
}

Hit BoxTree::closest_hit(const Ray& ray, float t_min, float t_max, RayStats* stats) const {
  check_ray(ray);
  check_range(t_min, t_max);
  RayStats local;
  const Hit h = trace<false>(ray, t_min, t_max, local);
  if (stats) *stats += local;
  return h;
}

Hit BoxTree::any_hit(const Ray& ray, float t_min, float t_max, RayStats* stats) const {
  check_ray(ray);
  check_range(t_min, t_max);
  RayStats local;
  const Hit h = trace<true>(ray, t_min, t_max, local);
  if (stats) *stats += local;
  return h;
}

template <bool AnyHit>
std::vector<Hit> BoxTree::trace_batch(const Ray* rays, std::size_t n, unsigned threads,
                                      RayStats* stats) const {
  if (n > 0 && rays == nullptr) throw Error("rays: null pointer");
  for (std::size_t i = 0; i < n; ++i) {
    const std::string problem = ray_problem(rays[i]);
    if (!problem.empty()) throw Error("ray " + std::to_string(i + 1) + ": " + problem);
  }
  std::vector<Hit> hits(n);
  const unsigned workers = detail::resolve_threads(threads);
  std::vector<RayStats> per_worker(workers);
  const double inf = std::numeric_limits<double>::infinity();
  detail::parallel_for(n, workers, 256, [&](std::size_t begin, std::size_t end, unsigned worker) {
    RayStats local;
    for (std::size_t i = begin; i < end; ++i) hits[i] = trace<AnyHit>(rays[i], 0.0, inf, local);
    per_worker[worker] += local;
  });
  if (stats)
    for (const RayStats& s : per_worker) *stats += s;
  return hits;
}

std::vector<Hit> BoxTree::closest_hit_batch(const Ray* rays, std::size_t n, unsigned threads,
                                            RayStats* stats) const {
  return trace_batch<false>(rays, n, threads, stats);
}

std::vector<Hit> BoxTree::any_hit_batch(const Ray* rays, std::size_t n, unsigned threads,
                                        RayStats* stats) const {
  return trace_batch<true>(rays, n, threads, stats);
}

}  // namespace kdspace
