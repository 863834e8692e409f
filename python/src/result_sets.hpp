// The result sets the Python module adds to the library's (kdspace/points/detail/result_sets.hpp):
// each is the rule of one SciPy query, run by PointTree::query_with over the tree's one traversal.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "kdspace/points/detail/result_sets.hpp"

namespace kdspace::python {

/// The largest value below `limit`: keeping dist <= below(limit) keeps dist < limit. SciPy's
/// distance_upper_bound is strict (a neighbour exactly at the bound is left out), and a distance that
/// overflowed to +inf is never a neighbour, as in SciPy (inf < inf is false).
template <class S>
S strictly_below(S limit) {
  return std::nextafter(limit, -std::numeric_limits<S>::infinity());
}

/// Every candidate within a closed limit, in the order the traversal offers them (no sort).
template <class S>
class Within {
 public:
  Within(S limit, std::vector<detail::Candidate<S>>& storage) : limit_(limit), found_(storage) {
    found_.clear();
  }
  S bound() const { return limit_; }
  bool full() const { return false; }
  bool offer(S dist, std::uint32_t index) {
    if (!(dist <= limit_)) return false;
    found_.push_back({dist, index});
    return true;
  }

 private:
  S limit_;
  std::vector<detail::Candidate<S>>& found_;
};

/// Counts the candidates within a closed limit, keeping none.
template <class S>
class CountWithin {
 public:
  explicit CountWithin(S limit) : limit_(limit) {}
  S bound() const { return limit_; }
  bool full() const { return false; }
  bool offer(S dist, std::uint32_t) {
    if (!(dist <= limit_)) return false;
    ++count_;
    return true;
  }
  std::size_t count() const { return count_; }

 private:
  S limit_;
  std::size_t count_ = 0;
};

/// Pair counts at many radii from one search: a candidate within the largest radius adds its weight
/// (1 unweighted) to the bin of the first radius it is within; the caller sums the bins. `radii` are
/// internal distances, ascending, distinct.
template <class S, class Count>
class RadiusHistogram {
 public:
  RadiusHistogram(const std::vector<S>& radii, const double* weights, Count* bins)
      : radii_(radii), weights_(weights), bins_(bins) {}
  S bound() const { return radii_.back(); }
  bool full() const { return false; }
  bool offer(S dist, std::uint32_t index) {
    if (!(dist <= radii_.back())) return false;
    const std::size_t bin =
        static_cast<std::size_t>(std::lower_bound(radii_.begin(), radii_.end(), dist) - radii_.begin());
    if constexpr (std::is_floating_point_v<Count>)
      bins_[bin] += weights_ ? weights_[index] : 1.0;
    else
      bins_[bin] += 1;
    return true;
  }

 private:
  const std::vector<S>& radii_;
  const double* weights_;  // by the tree's own point index; null: every point weighs 1
  Count* bins_;
};

}  // namespace kdspace::python
