// The SAH build in O(N log^2 N): at every node the candidate planes of each axis are generated from
// the node's clipped boxes and sorted anew (the O(N log^2 N) build of W&H 2006). It is the
// reference for the O(N log N) build, which must make exactly the same tree.
#include <algorithm>
#include <optional>
#include <utility>
#include <vector>

#include "build_common.hpp"
#include "sah_cost.hpp"

namespace kdspace::detail {

namespace {

class SahMethod {
 public:
  using Work = std::vector<BoxRef>;

  explicit SahMethod(const BoxBuildParams& params) : params_(params) {}

  std::optional<Split> choose_split(const Work& refs, const Box3f& cell, std::size_t /*depth*/) const {
    const SahCostModel model(params_, cell);
    std::optional<SplitCandidate> best;
    std::vector<Event> events;
    events.reserve(2 * refs.size());
    for (int axis = 0; axis < 3; ++axis) {
      if (!(cell.lo[axis] < cell.hi[axis])) continue;  // a flat axis has no plane inside the cell
      events.clear();
      for (std::size_t r = 0; r < refs.size(); ++r)
        add_events(events, refs[r].bounds, axis, static_cast<std::uint32_t>(r));
      std::sort(events.begin(), events.end());
      sweep_axis(events.data(), events.size(), axis, refs.size(), cell, model, best);
    }
    return accept_split(best, model, refs.size());
  }

  std::pair<Work, Work> partition(Work&& refs, const Box3f& /*cell*/, const Split& s) const {
    std::pair<Work, Work> children;
    split_references(refs, s, children.first, children.second);
    Work().swap(refs);  // free the parent's list before the children recurse
    return children;
  }

  std::vector<std::uint32_t> box_ids(const Work& refs) const {
    std::vector<std::uint32_t> ids(refs.size());
    for (std::size_t i = 0; i < refs.size(); ++i) ids[i] = refs[i].box;
    return ids;
  }
  std::size_t size(const Work& refs) const { return refs.size(); }

 private:
  const BoxBuildParams& params_;
};

}  // namespace

void build_sah(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
               std::size_t max_depth, TreeWriter& out) {
  const SahMethod method(params);
  build_subtree(method, root_references(boxes), bounds, 0, max_depth, root_budget(params, boxes.size()), out,
                build_threads(params) - 1);
}

}  // namespace kdspace::detail
