// First contact of a moving box (kdspace/collide/contact.hpp): the ray traversal of the BoxTree
// (Havran's near/far order with an explicit stack of (node, t_entry, t_exit), as in
// lib/rays/traverse.cpp), run on the Minkowski-grown scene without building it.
//
// At a split plane p on an axis the box moves along, the moving box touches the lower closed cell
// while its lower face is at or below p, for t up to (p - lo) / motion when it moves up, and the upper
// cell once its upper face reaches p, from (p - hi) / motion: the plane seen by the grown boxes is the
// slab [p - hi, p - lo], and the two children's time intervals overlap by the box's extent. On an
// axis it does not move along it touches each side for all t or for none. The near child is searched
// first; the far one is kept while it could still hold a contact no later than the best so far
// (equality matters for the tie rule). Interval ends are widened by a relative margin far above double
// rounding, so no leaf that holds the winning box is skipped: the answer is that of testing every box
// (brute_force_first_contact), bit for bit.
#include "kdspace/collide/contact.hpp"

#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "kdspace/collide/detail/contact_window.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "tree_access.hpp"

namespace kdspace {

namespace {

using detail::contact_window;
using detail::NodeId;
using detail::PreparedMotion;
using detail::TreeAccess;

/// Relative widening of interval ends: 2^-40, some 8000 ulps of double, yet 2^-16 of a float ulp.
constexpr double time_margin = 1.0 / 1099511627776.0;

/// t moved later or earlier by the margin (infinities stay as they are).
double later(double t) {
  return t >= 0 ? t * (1 + time_margin) : t * (1 - time_margin);
}
double earlier(double t) {
  return t >= 0 ? t * (1 - time_margin) : t * (1 + time_margin);
}

struct StackEntry {
  NodeId node;
  double t_entry, t_exit;
};

/// t rounded to float; a contact beyond the float range reports the largest finite float.
float to_float_t(double t) {
  constexpr double largest = std::numeric_limits<float>::max();
  return static_cast<float>(t > largest ? largest : t);
}

/// What is wrong with a moving box and its motion, or "".
std::string moving_problem(const Box3f& box, const Vec3f& motion) {
  const std::string problem = box_problem(box);
  if (!problem.empty()) return problem;
  constexpr const char* axis_name[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(motion[a]))
      return std::string("motion ") + axis_name[a] + " is " + std::to_string(motion[a]);
  return {};
}

void check_t_max(float t_max) {
  if (!(t_max >= 0)) throw Error("t_max must be >= 0 (or +inf), got " + std::to_string(t_max));
}

Contact first_contact_in(const TreeAccess& tree, const Box3f& moving, const Vec3f& motion, double t_max,
                         CollideStats& stats) {
  ++stats.queries;
  if (tree.empty()) return Contact{};
  const PreparedMotion m(moving, motion);
  double t_entry = 0, t_exit = t_max;
  if (!contact_window(tree.root_cell(), m, t_entry, t_exit)) return Contact{};
  t_entry = earlier(t_entry);
  t_exit = later(t_exit);

  double best_t = t_max;
  std::int32_t best_box = Contact::none;
  std::array<StackEntry, max_box_tree_depth + 2> stack;
  std::size_t top = 0;
  stack[top++] = StackEntry{TreeAccess::root(), t_entry, t_exit};
  while (top > 0) {
    const StackEntry entry = stack[--top];
    if (entry.t_entry > best_t) continue;  // every contact in this cell is later than the best
    NodeId node = entry.node;
    t_entry = entry.t_entry;
    t_exit = entry.t_exit;
    for (;;) {
      ++stats.nodes_visited;
      if (tree.is_leaf(node)) {
        const std::uint32_t count = tree.leaf_size(node);
        const std::uint32_t* ids = tree.leaf_ids(node);
        const auto boxes = tree.leaf_boxes(node);
        stats.boxes_tested += count;
        for (std::uint32_t i = 0; i < count; ++i) {
          double t_enter = 0, t_leave = best_t;
          if (!contact_window(boxes[i], m, t_enter, t_leave)) continue;
          const auto box = static_cast<std::int32_t>(ids[i]);
          if (t_enter < best_t || best_box == Contact::none || box < best_box) {
            best_t = t_enter;
            best_box = box;
          }
        }
        break;
      }
      const int axis = tree.axis(node);
      const double split = tree.split(node);
      const NodeId lower = tree.left(node), upper = tree.right(node);
      if (m.still[axis]) {
        // The box never moves across the plane: it touches one side, or both when it straddles it.
        const bool touches_lower = m.lo[axis] <= split, touches_upper = m.hi[axis] >= split;
        if (touches_lower && touches_upper) {
          stack[top++] = StackEntry{upper, t_entry, t_exit};
          node = lower;
        } else {
          node = touches_lower ? lower : upper;
        }
        continue;
      }
      // Moving up: the lower cell is touched until t_a, the upper one from t_b (t_b <= t_a).
      // Moving down: the upper cell until t_b, the lower one from t_a.
      const double t_a = (split - m.lo[axis]) * m.inverse[axis];
      const double t_b = (split - m.hi[axis]) * m.inverse[axis];
      const bool down = m.negative[axis];
      const NodeId near = down ? upper : lower, far = down ? lower : upper;
      const double near_until = down ? t_b : t_a, far_from = down ? t_a : t_b;
      const double near_exit = std::min(t_exit, later(near_until));
      const double far_entry = std::max(t_entry, earlier(far_from));
      const bool visit_near = near_exit >= t_entry, visit_far = far_entry <= t_exit;
      if (visit_near && visit_far) {
        stack[top++] = StackEntry{far, far_entry, t_exit};
        node = near;
        t_exit = near_exit;
      } else if (visit_near) {
        node = near;
        t_exit = near_exit;
      } else if (visit_far) {
        node = far;
        t_entry = far_entry;
      } else {
        break;  // cannot happen: the far child's interval starts before the near one's ends
      }
    }
  }
  if (best_box == Contact::none) return Contact{};
  return Contact{best_box, to_float_t(best_t)};
}

}  // namespace

Contact first_contact(const BoxTree& tree, const Box3f& moving, const Vec3f& motion, float t_max,
                      CollideStats* stats) {
  const std::string problem = moving_problem(moving, motion);
  if (!problem.empty()) throw Error("moving box: " + problem);
  check_t_max(t_max);
  CollideStats local;
  const Contact c = first_contact_in(TreeAccess(tree), moving, motion, t_max, local);
  if (stats) *stats += local;
  return c;
}

std::vector<Contact> first_contact_batch(const BoxTree& tree, const MovingBox* moving, std::size_t n,
                                         float t_max, unsigned threads, CollideStats* stats) {
  if (n > 0 && moving == nullptr) throw Error("moving boxes: null pointer");
  for (std::size_t i = 0; i < n; ++i) {
    const std::string problem = moving_problem(moving[i].box, moving[i].motion);
    if (!problem.empty()) throw Error("moving box " + std::to_string(i + 1) + ": " + problem);
  }
  check_t_max(t_max);
  const TreeAccess access(tree);
  std::vector<Contact> contacts(n);
  const unsigned workers = detail::resolve_threads(threads);
  std::vector<CollideStats> per_worker(workers);
  detail::parallel_for(n, workers, 256, [&](std::size_t begin, std::size_t end, unsigned worker) {
    for (std::size_t i = begin; i < end; ++i)
      contacts[i] = first_contact_in(access, moving[i].box, moving[i].motion, t_max, per_worker[worker]);
  });
  if (stats)
    for (const CollideStats& s : per_worker) *stats += s;
  return contacts;
}

}  // namespace kdspace
