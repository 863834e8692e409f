// The SAH cost model (see sah_cost.hpp). Kept out of line so that both SAH builds run the very same
// arithmetic and therefore choose the very same planes.
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

double SahCostModel::leaf_cost(std::size_t n) const {
  return k_i_ * static_cast<double>(n);
}

double SahCostModel::cost(double p_left, double p_right, std::size_t n_left, std::size_t n_right) const {
  const double lambda = (n_left == 0 || n_right == 0) ? empty_factor_ : 1.0;
  return lambda *
         (k_t_ + k_i_ * (p_left * static_cast<double>(n_left) + p_right * static_cast<double>(n_right)));
}

SplitCandidate SahCostModel::evaluate(int axis, float position, std::size_t n_left, std::size_t n_right,
                                      std::size_t n_planar) const {
  const double w_left = static_cast<double>(position) - static_cast<double>(cell_.lo[axis]);
  const double w_right = static_cast<double>(cell_.hi[axis]) - static_cast<double>(position);
  const double p_left = fixed_[axis] + per_width_[axis] * w_left;
  const double p_right = fixed_[axis] + per_width_[axis] * w_right;
  const double cost_left = cost(p_left, p_right, n_left + n_planar, n_right);
  const double cost_right = cost(p_left, p_right, n_left, n_right + n_planar);
  SplitCandidate c;
  c.split.axis = axis;
  c.split.position = position;
  c.split.planar_left = cost_left <= cost_right;
  c.cost = c.split.planar_left ? cost_left : cost_right;
  c.split.n_left = n_left + (c.split.planar_left ? n_planar : 0);
  c.split.n_right = n_right + (c.split.planar_left ? 0 : n_planar);
  return c;
}

void sweep_axis(const Event* events, std::size_t count, int axis, std::size_t n, const Box3f& cell,
                const SahCostModel& model, std::optional<SplitCandidate>& best) {
  // Boxes entirely left of the plane, entirely right, and lying in it; a box that straddles the
  // plane counts on both sides. Boxes ending at the plane are left of it, boxes starting at it right.
  std::size_t n_left = 0, n_right = n;
  std::size_t i = 0;
  while (i < count) {
    const float p = events[i].position;
    std::size_t ending = 0, lying = 0, starting = 0;
    while (i < count && events[i].position == p && events[i].type() == Event::end) ++ending, ++i;
    while (i < count && events[i].position == p && events[i].type() == Event::planar) ++lying, ++i;
    while (i < count && events[i].position == p && events[i].type() == Event::start) ++starting, ++i;
    n_right -= ending + lying;
    if (inside_cell(cell, axis, p)) {
      const SplitCandidate c = model.evaluate(axis, p, n_left, n_right, lying);
      if (!best || c.better_than(*best)) best = c;
    }
    n_left += starting + lying;
  }
}

}  // namespace kdspace::detail
