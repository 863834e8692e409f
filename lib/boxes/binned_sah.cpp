// Min-max binning (see binned_sah.hpp).
#include "binned_sah.hpp"

#include <algorithm>
#include <array>
#include <cstdint>

namespace kdspace::detail {

namespace {

/// Bin boundaries over one axis of a cell: boundary k = lo + k * extent / bins, k = 0 .. bins.
/// In double: the extent of a float cell may overflow float.
struct Bins {
  double lo = 0, scale = 0;  ///< scale = bins / extent; 0 for a flat axis
  bool extended = false;

  Bins(const Box3f& cell, int axis) : lo(cell.lo[axis]) {
    const double extent = static_cast<double>(cell.hi[axis]) - lo;
    extended = extent > 0;
    scale = extended ? sah_bins / extent : 0.0;
  }
  /// The bin of a coordinate inside the cell (its upper face in the last bin).
  int of(float x) const {
    const auto b = static_cast<int>((static_cast<double>(x) - lo) * scale);
    return std::min(std::max(b, 0), sah_bins - 1);
  }
  float boundary(int k) const { return static_cast<float>(lo + k / scale); }
};

/// The exact SAH plane on `axis` among the box faces in [w_lo, w_hi], by the sweep of the exact
/// builds over the events in that window alone (counting the boxes that begin or end before it).
void refine(const std::vector<BoxRef>& refs, const Box3f& cell, const SahCostModel& model, int axis,
            float w_lo, float w_hi, std::optional<SplitCandidate>& best) {
  std::vector<Event> events;
  std::size_t before = 0, gone = 0;
  for (std::size_t r = 0; r < refs.size(); ++r) {
    const float lo = refs[r].bounds.lo[axis], hi = refs[r].bounds.hi[axis];
    before += lo < w_lo ? 1 : 0;
    gone += hi < w_lo ? 1 : 0;
    const auto ref = static_cast<std::uint32_t>(r);
    if (lo == hi) {
      if (w_lo <= lo && lo <= w_hi) events.emplace_back(lo, ref, Event::planar);
      continue;
    }
    if (w_lo <= lo && lo <= w_hi) events.emplace_back(lo, ref, Event::start);
    if (w_lo <= hi && hi <= w_hi) events.emplace_back(hi, ref, Event::end);
  }
  std::sort(events.begin(), events.end());
  sweep_axis(events.data(), events.size(), axis, refs.size(), cell, model, best, before, gone);
}

}  // namespace

std::optional<SplitCandidate> binned_split(const std::vector<BoxRef>& refs, const Box3f& cell,
                                           const SahCostModel& model) {
  const std::array<Bins, 3> bins{Bins(cell, 0), Bins(cell, 1), Bins(cell, 2)};
  std::array<std::array<std::uint32_t, sah_bins>, 3> starts{}, ends{};
  for (const BoxRef& r : refs)
    for (int a = 0; a < 3; ++a) {
      ++starts[a][bins[a].of(r.bounds.lo[a])];
      ++ends[a][bins[a].of(r.bounds.hi[a])];
    }

  std::optional<SplitCandidate> best;
  int best_boundary = 0;
  for (int a = 0; a < 3; ++a) {
    if (!bins[a].extended) continue;
    // At the boundary below bin j: boxes starting in a lower bin are left of it (or straddle it),
    // boxes ending in bin j or above are right of it.
    std::size_t n_left = 0, n_right = refs.size();
    float previous = cell.lo[a];
    for (int j = 1; j < sah_bins; ++j) {
      n_left += starts[a][j - 1];
      n_right -= ends[a][j - 1];
      const float position = bins[a].boundary(j);
      if (!(previous < position && inside_cell(cell, a, position))) continue;
      previous = position;
      const double cost = model.cost_of(a, position, n_left, n_right, 0);
      if (!best || cost < best->cost) {
        best = model.evaluate(a, position, n_left, n_right, 0);
        best_boundary = j;
      }
    }
  }
  if (!best) return best;

  // The boundary is a guess: box faces cluster on planes that no boundary hits (boxes on a grid,
  // voxels), and a plane through a face separates where one beside it cuts every box. So the exact
  // sweep chooses among the faces of the two bins around the best boundary.
  const int axis = best->split.axis;
  std::optional<SplitCandidate> refined;
  refine(refs, cell, model, axis, bins[axis].boundary(best_boundary - 1),
         bins[axis].boundary(best_boundary + 1), refined);
  if (refined) best = refined;
  return best;
}

}  // namespace kdspace::detail
