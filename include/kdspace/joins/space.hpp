// The space distances are measured in: ordinary space (FlatSpace) or a torus with a period on some
// axes (TorusSpace, periodic boundaries). Each gives the internal distance of two points and, for two
// axis-aligned boxes, a lower and an upper bound on the internal distance of any point of one to any
// point of the other.
//
// Exactness without a margin. Every value here is combined over the axes by combine_axes (metric.hpp),
// the order internal_distance uses. A bound's term on each axis is computed with the same rounded
// operations as a point pair's term, from box corners instead of coordinates; as rounding is monotone,
// the bound's term is no larger (lower bound) or no smaller (upper bound) than the point pair's term,
// and so is their combination. A pair of cells is therefore pruned, or counted whole, by comparing its
// bound with a radius or a k-th distance directly, and never loses or adds a point, even at equal
// distances. (This relies on IEEE arithmetic without contraction into fused multiply-adds. GCC in
// ISO C++ mode, -std=c++17, does not contract; Clang contracts within one expression where FMA is
// enabled, so each term and each addition is a call of its own: metric.hpp's term and accumulate.)
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"

namespace kdspace::detail {

// std::max and std::min by value (the same results, NaN included), which compilers turn into vector
// max and min instructions more readily than the standard ones, which return references.
template <class T>
T larger(T a, T b) {
  return a < b ? b : a;
}
template <class T>
T smaller(T a, T b) {
  return b < a ? b : a;
}

/// larger() for one value, as a max instruction where there is one: the compiler made a branch of
/// larger() in the cells' bounds, where which side is larger is as good as random (callgrind
/// --branch-sim, 2e5 uniform 3-D points: 12.49e6 -> 11.75e6 mispredictions in a self-join k = 10,
/// 3.02e6 -> 2.84e6 in pairs within r). maxsd(b, a) is b > a ? b : a, which is larger(a, b), NaN
/// included. (Not in the loops over blocks: those become vector max instructions by themselves.)
template <class T>
T larger_one(T a, T b) {
#if defined(__SSE2__)
  if constexpr (std::is_same_v<T, double>) return _mm_cvtsd_f64(_mm_max_sd(_mm_set_sd(b), _mm_set_sd(a)));
  if constexpr (std::is_same_v<T, float>) return _mm_cvtss_f32(_mm_max_ss(_mm_set_ss(b), _mm_set_ss(a)));
#endif
  return larger(a, b);
}

/// Ordinary space, axis by axis: the coordinate difference, and the gap and span of two intervals.
/// For a in [alo, ahi] and b in [blo, bhi]: b - a >= blo - ahi, so fl(b - a) >= fl(blo - ahi), and
/// likewise the other way; so |fl(a - b)| lies between the gap (0 where the intervals overlap) and
/// the widest span.
struct FlatAxes {
  template <class T>
  T difference(T a, T b, std::size_t) const {
    return a - b;
  }
  template <class T>
  T lower(T alo, T ahi, T blo, T bhi, std::size_t) const {
    return larger_one(larger_one(blo - ahi, alo - bhi), T(0));
  }
  template <class T>
  T upper(T alo, T ahi, T blo, T bhi, std::size_t) const {
    return larger(bhi - alo, ahi - blo);
  }
  /// lower(x, x, blo, bhi) up to its sign: x less the nearest coordinate of the interval. (The same
  /// magnitude: fl(x - blo) = -fl(blo - x).) Written with a clamp, which becomes vector min and max.
  template <class T>
  T lower_from_point(T x, T blo, T bhi, std::size_t) const {
    return x - smaller(larger(x, blo), bhi);
  }
};

/// A torus: on axis i with period L (points in [0, L)) the coordinate difference d counts as
/// min(|d|, L - |d|), as in SciPy's cKDTree with `boxsize`. Axes that are not periodic have L = +inf,
/// where the same formula gives |d| (and, with |d| = inf, smaller() keeps |d| against inf - inf = NaN),
/// so a torus without periodic axes gives the flat values bit for bit (Metric::term(|d|) is
/// Metric::term(d)). With gap g and span u of the plain intervals, g <= |d| <= u, so
/// fl(L - |d|) >= fl(L - u), and the wrapped difference is at least min(g, L - u) and at most
/// min(u, L - g).
template <class T>
struct TorusAxes {
  const T* period;  ///< dim values: L, or +inf

  T difference(T a, T b, std::size_t i) const {
    const T d = std::abs(a - b);
    return smaller(d, period[i] - d);
  }
  T lower(T alo, T ahi, T blo, T bhi, std::size_t i) const {
    return smaller(FlatAxes{}.lower(alo, ahi, blo, bhi, i), period[i] - FlatAxes{}.upper(alo, ahi, blo, bhi, i));
  }
  T upper(T alo, T ahi, T blo, T bhi, std::size_t i) const {
    return smaller(FlatAxes{}.upper(alo, ahi, blo, bhi, i), period[i] - FlatAxes{}.lower(alo, ahi, blo, bhi, i));
  }
  T lower_from_point(T x, T blo, T bhi, std::size_t i) const {
    const T gap = std::abs(FlatAxes{}.lower_from_point(x, blo, bhi, i));
    return smaller(gap, period[i] - FlatAxes{}.upper(x, x, blo, bhi, i));
  }
};

/// Distances and bounds of a metric over the axes of a space (FlatAxes or TorusAxes), each combined
/// by combine_axes in the order of internal_distance.
template <class Metric, class Axes>
struct Space : Axes {
  /// The internal distance of two points (for FlatAxes: internal_distance itself).
  template <class T>
  T distance(const T* a, const T* b, std::size_t dim) const {
    return combine_axes<Metric, T>(dim, [&](std::size_t i) { return Metric::term(this->difference(a[i], b[i], i)); });
  }

  /// distance(a, p_j) for Count points stored by column: axis i of point j at columns[i * stride + j].
  template <std::size_t Count, class T>
  std::array<T, Count> distances(const T* a, const T* columns, std::size_t stride, std::size_t dim) const {
    return combine_axes_many<Metric, Count, T>(dim, [&](std::size_t i, std::size_t j) {
      return Metric::term(this->difference(a[i], columns[i * stride + j], i));
    });
  }

  /// No larger than the distance of any point of box A = [alo, ahi] to any point of box B.
  template <class T>
  T lower(const T* alo, const T* ahi, const T* blo, const T* bhi, std::size_t dim) const {
    return combine_axes<Metric, T>(dim, [&](std::size_t i) { return Metric::term(Axes::lower(alo[i], ahi[i], blo[i], bhi[i], i)); });
  }

  /// lower() for Count points (boxes of one point) stored by column, to box B.
  template <std::size_t Count, class T>
  std::array<T, Count> lower_many(const T* columns, std::size_t stride, const T* blo, const T* bhi, std::size_t dim) const {
    return combine_axes_many<Metric, Count, T>(dim, [&](std::size_t i, std::size_t j) {
      return Metric::term(Axes::lower_from_point(columns[i * stride + j], blo[i], bhi[i], i));
    });
  }

  /// No smaller than the distance of any point of A to any point of B.
  template <class T>
  T upper(const T* alo, const T* ahi, const T* blo, const T* bhi, std::size_t dim) const {
    return combine_axes<Metric, T>(dim, [&](std::size_t i) { return Metric::term(Axes::upper(alo[i], ahi[i], blo[i], bhi[i], i)); });
  }
};

template <class Metric>
using FlatSpace = Space<Metric, FlatAxes>;
template <class Metric, class T>
using TorusSpace = Space<Metric, TorusAxes<T>>;

/// The period of each axis from a box size given by the user: one value for every axis, or one per
/// axis; 0 means "not periodic" (as in SciPy). Empty when no axis is periodic. Throws Error for a
/// negative, NaN or infinite size, a size T cannot hold, or a count that is neither 1 nor dim.
template <class T>
std::vector<T> periods_from_boxsize(const std::vector<double>& boxsize, std::size_t dim) {
  if (boxsize.empty()) return {};
  if (boxsize.size() != 1 && boxsize.size() != dim)
    throw Error("boxsize has " + std::to_string(boxsize.size()) + " values; give one, or one per axis (" +
                std::to_string(dim) + ")");
  std::vector<T> period(dim, std::numeric_limits<T>::infinity());
  bool any = false;
  for (std::size_t i = 0; i < dim; ++i) {
    const double size = boxsize[boxsize.size() == 1 ? 0 : i];
    if (!(size >= 0) || !std::isfinite(size))
      throw Error("boxsize of axis " + std::to_string(i + 1) + " must be a finite number >= 0 (0: not periodic), got " +
                  std::to_string(size));
    if (size > static_cast<double>(std::numeric_limits<T>::max()))
      throw Error("boxsize of axis " + std::to_string(i + 1) + " is beyond the range of the points' type");
    if (size > 0) {
      period[i] = static_cast<T>(size);
      any = true;
    }
  }
  if (!any) return {};
  return period;
}

/// "row R: coordinate A = v lies outside the periodic box [0, L)" (row and axis 0-based here,
/// 1-based in the message).
template <class T>
Error outside_box(std::size_t row, std::size_t axis, T value, T period) {
  return Error("row " + std::to_string(row + 1) + ": coordinate " + std::to_string(axis + 1) + " = " +
               std::to_string(value) + " lies outside the periodic box [0, " + std::to_string(period) + ")");
}

/// Whether a coordinate lies in [0, L) on a periodic axis; any finite coordinate on another (L = +inf).
template <class T>
bool inside_period(T v, T period) {
  return std::isinf(period) || (v >= 0 && v < period);
}

/// Checks that every point lies in [0, L) on each periodic axis; else outside_box for the first.
template <class T>
void check_in_box(const T* rows, std::size_t n, std::size_t dim, const std::vector<T>& period) {
  if (period.empty()) return;
  for (std::size_t r = 0; r < n; ++r)
    for (std::size_t a = 0; a < dim; ++a)
      if (!inside_period(rows[r * dim + a], period[a])) throw outside_box(r, a, rows[r * dim + a], period[a]);
}

}  // namespace kdspace::detail
