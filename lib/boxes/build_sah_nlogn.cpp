// The SAH build in O(N log N) (Wald & Havran 2006, "On building fast kd-trees for ray tracing, and
// on doing that in O(N log N)"), with min-max binning near the root.
//
// A node holding more than BoxBuildParams::binning_threshold boxes places its plane by min-max
// binning (binned_sah.hpp): one pass over its boxes, no sorting. Once a node holds fewer, its events
// (box boundaries) are sorted per axis, once, and the exact algorithm of W&H takes over: a node sweeps
// its three sorted lists to find the cheapest plane (linear), classifies its boxes as left only,
// right only or both, and hands each child its events in order:
//   - the events of one-sided boxes are filtered from the parent's lists, which keeps them sorted;
//   - the boxes that straddle the plane are clipped to each child cell and their new events sorted
//     (there are only about sqrt(n) of them in practice) and merged in.
// Each level of the tree thus costs time linear in its references, and the whole build O(N log N).
// With binning off (threshold 0) it evaluates exactly the candidates of the O(N log^2 N) build with
// the same counts and the same cost function, so both make the same tree.
#include <algorithm>
#include <array>
#include <optional>
#include <utility>
#include <vector>

#include "binned_sah.hpp"
#include "build_common.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "sah_cost.hpp"

namespace kdspace::detail {

namespace {

/// The boxes of a node and, once it is small enough for the exact sweep, their events.
struct NodeEvents {
  std::vector<BoxRef> refs;
  std::array<std::vector<Event>, 3> events;  ///< per axis, sorted; empty while the node is binned
  bool exact = false;                        ///< events hold the refs' boundaries
};

class SahNlognMethod {
 public:
  using Work = NodeEvents;

  explicit SahNlognMethod(const BoxBuildParams& params) : params_(params) {}

  std::optional<Split> choose_split(const Work& work, const Box3f& cell, std::size_t /*depth*/) const {
    const SahCostModel model(params_, cell);
    std::optional<SplitCandidate> best;
    if (!work.exact) {
      best = binned_split(work.refs, cell, model);
    } else {
      for (int axis = 0; axis < 3; ++axis) {
        if (!(cell.lo[axis] < cell.hi[axis])) continue;  // a flat axis has no plane inside the cell
        const std::vector<Event>& e = work.events[axis];
        sweep_axis(e.data(), e.size(), axis, work.refs.size(), cell, model, best);
      }
    }
    return accept_split(best, model, work.refs.size());
  }

  std::pair<Work, Work> partition(Work&& parent, const Box3f& cell, const Split& s) const {
    if (parent.exact) return partition_events(std::move(parent), cell, s);
    std::pair<Work, Work> children;
    split_references(parent.refs, s, children.first.refs, children.second.refs);
    std::vector<BoxRef>().swap(parent.refs);
    for (Work* child : {&children.first, &children.second})
      if (!binned(child->refs.size())) sort_events(*child, 1);
    return children;
  }

  std::vector<std::uint32_t> box_ids(const Work& work) const {
    std::vector<std::uint32_t> ids(work.refs.size());
    for (std::size_t i = 0; i < work.refs.size(); ++i) ids[i] = work.refs[i].box;
    return ids;
  }
  std::size_t size(const Work& work) const { return work.refs.size(); }

  /// The root: every box, its events sorted when the root is small enough for the exact sweep.
  Work root(const std::vector<Box3f>& boxes, unsigned threads) const {
    Work w;
    w.refs = root_references(boxes);
    if (!binned(w.refs.size())) sort_events(w, threads);
    return w;
  }

 private:
  /// True when a node of n boxes places its plane by binning.
  bool binned(std::size_t n) const { return params_.binning_threshold != 0 && n > params_.binning_threshold; }

  /// Makes the events of every reference and sorts them per axis (the three axes at once when
  /// threads allow).
  static void sort_events(Work& w, unsigned threads) {
    auto sort_axis = [&w](int axis) {
      std::vector<Event>& events = w.events[axis];
      events.reserve(2 * w.refs.size());
      for (std::size_t r = 0; r < w.refs.size(); ++r)
        add_events(events, w.refs[r].bounds, axis, static_cast<std::uint32_t>(r));
      std::sort(events.begin(), events.end());
    };
    w.exact = true;
    parallel_for(3, threads < 2 || w.refs.size() < 4096 ? 1 : threads, 1,
                 [&](std::size_t begin, std::size_t end, unsigned) {
                   for (std::size_t axis = begin; axis < end; ++axis) sort_axis(static_cast<int>(axis));
                 });
  }

  /// The exact partition: each child's events from the parent's, still sorted (see the top).
  std::pair<Work, Work> partition_events(Work&& parent, const Box3f& /*cell*/, const Split& s) const {
    const std::size_t n = parent.refs.size();
    std::vector<Side> side(n);
    std::vector<std::uint32_t> child_index(n);  // position in its child's list, for one-sided boxes
    std::pair<Work, Work> children;
    Work& left = children.first;
    Work& right = children.second;
    std::size_t straddling = 0;
    for (std::size_t r = 0; r < n; ++r) {
      side[r] = classify(parent.refs[r].bounds, s);
      if (side[r] == Side::left) {
        child_index[r] = static_cast<std::uint32_t>(left.refs.size());
        left.refs.push_back(parent.refs[r]);
      } else if (side[r] == Side::right) {
        child_index[r] = static_cast<std::uint32_t>(right.refs.size());
        right.refs.push_back(parent.refs[r]);
      } else {
        ++straddling;
      }
    }
    const std::size_t left_single = left.refs.size(), right_single = right.refs.size();

    // Straddling boxes, clipped to each child cell (their new lists start after the one-sided ones).
    left.refs.reserve(left_single + straddling);
    right.refs.reserve(right_single + straddling);
    for (std::size_t r = 0; r < n; ++r) {
      if (side[r] != Side::both) continue;
      BoxRef l = parent.refs[r], rr = parent.refs[r];
      l.bounds.hi[s.axis] = s.position;
      rr.bounds.lo[s.axis] = s.position;
      left.refs.push_back(l);
      right.refs.push_back(rr);
    }
    std::vector<BoxRef>().swap(parent.refs);

    for (int axis = 0; axis < 3; ++axis) {
      std::vector<Event>& from = parent.events[axis];
      std::vector<Event>& to_left = left.events[axis];
      std::vector<Event>& to_right = right.events[axis];
      to_left.reserve(2 * left.refs.size());
      to_right.reserve(2 * right.refs.size());
      for (const Event& e : from) {
        const std::uint32_t ref = e.ref();
        if (side[ref] == Side::left)
          to_left.push_back(e.moved_to(child_index[ref]));
        else if (side[ref] == Side::right)
          to_right.push_back(e.moved_to(child_index[ref]));
      }
      std::vector<Event>().swap(from);
      merge_new_events(to_left, left.refs, left_single, axis);
      merge_new_events(to_right, right.refs, right_single, axis);
    }
    left.exact = right.exact = true;
    return children;
  }

  /// Sorts the events of refs[first ..) along `axis` and merges them into the sorted `events`.
  static void merge_new_events(std::vector<Event>& events, const std::vector<BoxRef>& refs, std::size_t first,
                               int axis) {
    const std::size_t old_size = events.size();
    for (std::size_t r = first; r < refs.size(); ++r)
      add_events(events, refs[r].bounds, axis, static_cast<std::uint32_t>(r));
    const auto middle = events.begin() + static_cast<std::ptrdiff_t>(old_size);
    std::sort(middle, events.end());
    std::inplace_merge(events.begin(), middle, events.end());
  }

  const BoxBuildParams& params_;
};

}  // namespace

void build_sah_nlogn(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
                     std::size_t max_depth, TreeWriter& out) {
  const SahNlognMethod method(params);
  build_subtree(method, method.root(boxes, build_threads(params)), bounds, 0, max_depth,
                root_budget(params, boxes.size()), out, build_threads(params) - 1);
}

}  // namespace kdspace::detail
