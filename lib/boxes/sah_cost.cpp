// The SAH cost model (see sah_cost.hpp). The sweep is kept out of line so that both exact SAH builds
// run the very same arithmetic and therefore choose the very same planes.
#include "sah_cost.hpp"

namespace kdspace::detail {

namespace {
double extent(const Box3f& b, int axis) {
  return static_cast<double>(b.hi[axis]) - static_cast<double>(b.lo[axis]);
}
}  // namespace

CellMeasure::CellMeasure(HitProbability probability, const Box3f& cell) : probability_(probability) {
  int extended = 0;
  for (int a = 0; a < 3; ++a) {
    has_extent_[a] = extent(cell, a) > 0;
    extended += has_extent_[a] ? 1 : 0;
  }
  use_length_ = probability_ == HitProbability::surface_area && extended < 2;
  whole_ = (*this)(cell);
}

double CellMeasure::operator()(const Box3f& sub) const {
  const double ex = extent(sub, 0), ey = extent(sub, 1), ez = extent(sub, 2);
  if (probability_ == HitProbability::volume) {
    double v = 1;
    if (has_extent_[0]) v *= ex;
    if (has_extent_[1]) v *= ey;
    if (has_extent_[2]) v *= ez;
    return v;
  }
  if (use_length_) return ex + ey + ez;
  // Half the surface area: the factor 2 cancels in every ratio.
  return ex * ey + ey * ez + ez * ex;
}

SahCostModel::SahCostModel(const BoxBuildParams& params, const Box3f& cell)
    : cell_(cell),
      k_t_(params.K_t),
      k_i_(params.K_i),
      empty_factor_(1.0 - static_cast<double>(params.empty_bonus)) {
  const CellMeasure measure(params.probability, cell);
  if (!(measure.whole() > 0)) return;  // a single point: no plane lies inside it
  for (int k = 0; k < 3; ++k) {
    // Two samples of the affine function w -> measure(part of width w): at w = 0 and w = extent.
    Box3f part = cell;
    part.hi[k] = part.lo[k];
    const double at_zero = measure(part);
    const double width = extent(cell, k);
    fixed_[k] = at_zero / measure.whole();
    per_width_[k] = width > 0 ? (measure.whole() - at_zero) / width / measure.whole() : 0.0;
  }
}

void sweep_axis(const Event* events, std::size_t count, int axis, std::size_t n, const Box3f& cell,
                const SahCostModel& model, std::optional<SplitCandidate>& best, std::size_t before,
                std::size_t gone) {
  // Boxes entirely left of the plane, entirely right, and lying in it; a box that straddles the
  // plane counts on both sides. Boxes ending at the plane are left of it, boxes starting at it right.
  std::size_t n_left = before, n_right = n - gone;
  std::size_t i = 0;
  while (i < count) {
    const Event& first = events[i];
    const float p = first.position();
    std::size_t of_type[3] = {0, 0, 0};  // ending at p, lying in p, starting at p
    do {
      ++of_type[events[i].type()];
      ++i;
    } while (i < count && events[i].same_position(first));
    const std::size_t ending = of_type[Event::end], lying = of_type[Event::planar],
                      starting = of_type[Event::start];
    n_right -= ending + lying;
    if (inside_cell(cell, axis, p)) {
      // The cost alone first; the candidate is made only when it wins (same arithmetic, same cost).
      const double cost = model.cost_of(axis, p, n_left, n_right, lying);
      if (!best || cost <= best->cost) {
        const SplitCandidate c = model.evaluate(axis, p, n_left, n_right, lying);
        if (!best || c.better_than(*best)) best = c;
      }
    }
    n_left += starting + lying;
  }
}

}  // namespace kdspace::detail
