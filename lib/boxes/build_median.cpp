// The median build: the classic kd-tree rule. The split axis cycles with depth (x, y, z, x, ...) and
// the plane lies at the spatial middle of the cell or at the lower face of the median box; a node with
// at most leaf_size boxes (S_minObj) or at max_depth (S_maxProf) becomes a leaf.
#include <algorithm>
#include <optional>
#include <utility>
#include <vector>

#include "build_common.hpp"

namespace kdspace::detail {

namespace {

/// A split that would leave the children holding together more than this many times the node's
/// boxes is refused (the axis is skipped). Without it a cell crowded by boxes larger than itself
/// would copy nearly all of them into both children at every level down to max_depth: 2^depth
/// copies. 1.5 lets half of the boxes straddle, which well spread scenes never exceed.
constexpr double max_reference_growth = 1.5;

class MedianMethod {
 public:
  using Work = std::vector<BoxRef>;

  explicit MedianMethod(const BoxBuildParams& params) : params_(params) {}

  std::optional<Split> choose_split(const Work& refs, const Box3f& cell, std::size_t depth) const {
    if (refs.size() <= params_.leaf_size) return std::nullopt;
    for (std::size_t attempt = 0; attempt < 3; ++attempt) {
      const int axis = static_cast<int>((depth + attempt) % 3);
      if (!(cell.lo[axis] < cell.hi[axis])) continue;
      Split s;
      s.axis = axis;
      s.position = plane_position(refs, cell, axis);
      if (!inside_cell(cell, axis, s.position)) continue;  // cell too thin to split in floats
      if (useful(refs, s)) return s;                       // sets s.n_left, s.n_right
    }
    return std::nullopt;
  }

  std::pair<Work, Work> partition(Work&& refs, const Box3f& /*cell*/, const Split& s) const {
    std::pair<Work, Work> children;
    split_references(refs, s, children.first, children.second);
    Work().swap(refs);
    return children;
  }

  std::vector<std::uint32_t> box_ids(const Work& refs) const {
    std::vector<std::uint32_t> ids(refs.size());
    for (std::size_t i = 0; i < refs.size(); ++i) ids[i] = refs[i].box;
    return ids;
  }
  std::size_t size(const Work& refs) const { return refs.size(); }

 private:
  float plane_position(const Work& refs, const Box3f& cell, int axis) const {
    // Halves first: hi - lo may overflow for coordinates near the float range.
    const float middle = 0.5f * cell.lo[axis] + 0.5f * cell.hi[axis];
    if (params_.median_position == MedianPosition::middle) return middle;
    // The median box, in the order of the (clipped) lower faces; the plane at its lower face puts it
    // and the boxes above it on the right. (A plane through the median box's centre would cut that
    // box, and a node of two boxes would then be split again and again without separating them.)
    std::vector<float> lower(refs.size());
    for (std::size_t i = 0; i < refs.size(); ++i) lower[i] = refs[i].bounds.lo[axis];
    const auto mid = lower.begin() + static_cast<std::ptrdiff_t>(lower.size() / 2);
    std::nth_element(lower.begin(), mid, lower.end());
    // The median face on the cell boundary (e.g. half the boxes start there): fall back to the middle.
    return inside_cell(cell, axis, *mid) ? *mid : middle;
  }

  static bool useful(const Work& refs, Split& s) {
    std::size_t n_left = 0, n_right = 0;
    for (const BoxRef& r : refs) {
      const Side side = classify(r.bounds, s);
      n_left += side != Side::right ? 1 : 0;
      n_right += side != Side::left ? 1 : 0;
    }
    s.n_left = n_left;
    s.n_right = n_right;
    const std::size_t n = refs.size();
    if (n_left == n && n_right == n) return false;  // separates nothing
    return static_cast<double>(n_left + n_right) <= max_reference_growth * static_cast<double>(n);
  }

  const BoxBuildParams& params_;
};

}  // namespace

void build_median(const std::vector<Box3f>& boxes, const Box3f& bounds, const BoxBuildParams& params,
                  std::size_t max_depth, TreeWriter& out) {
  const MedianMethod method(params);
  build_subtree(method, root_references(boxes), bounds, 0, max_depth, root_budget(params, boxes.size()), out,
                build_threads(params) - 1);
}

}  // namespace kdspace::detail
