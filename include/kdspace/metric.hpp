// Metrics: L2 (Euclidean), L1 (Manhattan), Linf (Chebyshev), and Minkowski of any order p >= 1.
//
// The tree never works with true distances inside: it works with an "internal" distance, a monotone
// function of the true one that is cheap to accumulate axis by axis (the squared distance for L2, the
// distance itself for L1 and Linf). Users only ever see true distances: radii go in through
// to_internal() and results come out through to_distance().
//
// A metric is a set of static functions:
//   term(diff)                 the contribution of one axis, from the coordinate difference
//   accumulate(acc, term)      how contributions combine (a sum, or a maximum for Linf)
//   replace(bound, old, new)   the bound after one axis's contribution grows from `old` to `new`
//                              (the incremental cell distance of Arya & Mount: only one axis changes
//                              when the search steps into a child cell)
//   to_distance / to_internal  the monotone map between internal and true distances
// Because combining is a function of its own (not a fixed sum), L-infinity works like the others.
//
// L2, L1 and Linf have only static functions; Minkowski holds its order p, so the tree keeps a metric
// object and calls its functions through it (metric.term(diff)). The same code serves both kinds.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <string>

#include "kdspace/error.hpp"

namespace kdspace {

struct L2 {
  static constexpr const char* name = "l2";
  template <class T>
  static T term(T diff) { return diff * diff; }
  template <class T>
  static T accumulate(T acc, T t) { return acc + t; }
  template <class T>
  static T replace(T bound, T old_term, T new_term) { return bound - old_term + new_term; }
  template <class T>
  static T to_distance(T internal) { return std::sqrt(internal); }
  template <class T>
  static T to_internal(T distance) { return distance * distance; }
};

struct L1 {
  static constexpr const char* name = "l1";
  template <class T>
  static T term(T diff) { return std::abs(diff); }
  template <class T>
  static T accumulate(T acc, T t) { return acc + t; }
  template <class T>
  static T replace(T bound, T old_term, T new_term) { return bound - old_term + new_term; }
  template <class T>
  static T to_distance(T internal) { return internal; }
  template <class T>
  static T to_internal(T distance) { return distance; }
};

struct Linf {
  static constexpr const char* name = "linf";
  template <class T>
  static T term(T diff) { return std::abs(diff); }
  template <class T>
  static T accumulate(T acc, T t) { return std::max(acc, t); }
  // In a child cell the axis's contribution can only grow, so the maximum simply takes it in.
  template <class T>
  static T replace(T bound, T /*old_term*/, T new_term) { return std::max(bound, new_term); }
  template <class T>
  static T to_distance(T internal) { return internal; }
  template <class T>
  static T to_internal(T distance) { return distance; }
};

/// Minkowski distance of order p, 1 <= p < infinity, chosen at run time: (sum |x_i - y_i|^p)^(1/p).
/// L1, L2 and Linf have their own, faster types; this one serves every other order.
///
/// The internal distance is sum |x_i - y_i|^p: each term by std::pow in double (the difference
/// itself in T), rounded to T, summed in T in internal_distance()'s fixed order. So the same
/// exactness holds as for the other metrics: a tree's answers equal brute force's with this kernel
/// bit for bit, ties (on the internal distance) by smaller index. The true distance is
/// internal^(1/p), computed with std::pow, so it carries a rounding or two of its own.
/// Range: the terms must stay within T. With large p a float sum overflows or underflows early
/// (p = 20: a difference above about 85 overflows, one below about 0.013 loses bits to subnormals),
/// so prefer double there; a term that overflows is +inf, and such a point is at infinite distance.
struct Minkowski {
  static constexpr const char* name = "minkowski";
  double p;

  /// Throws Error unless 1 <= p < infinity.
  explicit Minkowski(double order) : p(order) {
    if (!(order >= 1) || std::isinf(order))
      throw Error("Minkowski order p must be a finite number >= 1, got " + std::to_string(order));
  }

  template <class T>
  T term(T diff) const {
    return narrow<T>(std::pow(static_cast<double>(std::abs(diff)), p));
  }
  template <class T>
  static T accumulate(T acc, T t) { return acc + t; }
  template <class T>
  static T replace(T bound, T old_term, T new_term) { return bound - old_term + new_term; }
  template <class T>
  T to_distance(T internal) const {
    return narrow<T>(std::pow(static_cast<double>(internal), 1.0 / p));
  }
  template <class T>
  T to_internal(T distance) const {
    return narrow<T>(std::pow(static_cast<double>(distance), p));
  }

 private:
  // A non-negative double as T: +inf beyond T's range (a plain conversion would be undefined there).
  template <class T>
  static T narrow(double v) {
    return v > static_cast<double>(std::numeric_limits<T>::max()) ? std::numeric_limits<T>::infinity()
                                                                  : static_cast<T>(v);
  }
};

// A loop whose iterations are independent, to be made into vector instructions: the library is
// compiled with -fopenmp-simd (no OpenMP runtime) and KDSPACE_OMP_SIMD; elsewhere a plain loop.
#if defined(KDSPACE_OMP_SIMD)
#define KDSPACE_SIMD_LOOP _Pragma("omp simd")
#else
#define KDSPACE_SIMD_LOOP
#endif

/// Combines the terms of `dim` axes (term_of(i): the metric's term of axis i) in the one fixed order
/// that internal_distance uses. From 8 axes on, lane j of 8 independent accumulators takes axes j,
/// j+8, j+16, ... and the lanes are combined pairwise in a fixed order: the lanes are independent, so
/// the compiler keeps them in vector registers (the order of the additions, hence the result, is the
/// same with or without vector instructions). The remaining axes, and all of them below 8, are added
/// one by one. (accumulate has no state in any metric, Minkowski included.)
///
/// Rounding is monotone and so is every combination step, so terms that are each no larger (no
/// smaller) than a point pair's terms combine, in this order, to a value no larger (no smaller) than
/// that pair's internal distance, bit for bit. The dual-tree joins rely on this to bound a pair of
/// cells without a rounding margin (joins/space.hpp).
/// The accumulators of combine_axes (and so of internal_distance).
inline constexpr std::size_t distance_lanes = 8;

template <class Metric, class T, class TermOf>
inline T combine_axes(std::size_t dim, TermOf&& term_of) {
  constexpr std::size_t lanes = distance_lanes;
  const std::size_t blocks = dim / lanes;
  T total = 0;
  if (blocks > 0) {
    T acc[lanes] = {};
    for (std::size_t block = 0; block < blocks; ++block)
      for (std::size_t j = 0; j < lanes; ++j) acc[j] = Metric::accumulate(acc[j], T(term_of(block * lanes + j)));
    for (std::size_t width = lanes / 2; width > 0; width /= 2)
      for (std::size_t j = 0; j < width; ++j) acc[j] = Metric::accumulate(acc[j], acc[j + width]);
    total = acc[0];
  }
  for (std::size_t i = blocks * lanes; i < dim; ++i) total = Metric::accumulate(total, T(term_of(i)));
  return total;
}

/// combine_axes for Count values at once: value j is combine_axes(dim, term_of(., j)), the same bits.
/// Below 8 axes (no lanes) it goes axis by axis over the Count values, in vector instructions when
/// the j-th terms lie next to each other (points stored by column; the same operations on each
/// value, so the same bits); from 8 axes on it is combine_axes itself, one j after the other.
template <class Metric, std::size_t Count, class T, class TermOf>
inline std::array<T, Count> combine_axes_many(std::size_t dim, TermOf&& term_of) {
  std::array<T, Count> total{};
  if (dim < distance_lanes) {
    for (std::size_t i = 0; i < dim; ++i) {
      KDSPACE_SIMD_LOOP
      for (std::size_t j = 0; j < Count; ++j) total[j] = Metric::accumulate(total[j], T(term_of(i, j)));
    }
  } else {
    for (std::size_t j = 0; j < Count; ++j)
      total[j] = combine_axes<Metric, T>(dim, [&](std::size_t i) { return term_of(i, j); });
  }
  return total;
}

/// The internal distance between two points of `dim` coordinates.
///
/// This one function is used by the tree, by brute_force_knn, by the blocked scan's re-check and by
/// the tests, always in the same order of operations (combine_axes), so "exact" can be checked bit
/// for bit.
///
/// `b` may hold another type than `a` (PointForest keeps byte-valued data as bytes): its values are
/// converted to T exactly, so the result is the one for those values stored as T, bit for bit.
template <class Metric, class T, class U>
inline T internal_distance(const Metric& metric, const T* a, const U* b, std::size_t dim) {
  return combine_axes<Metric, T>(dim, [&](std::size_t i) { return metric.term(a[i] - static_cast<T>(b[i])); });
}

/// The same for a metric without state (L2, L1, Linf): internal_distance<L2>(a, b, dim).
template <class Metric, class T, class U>
inline T internal_distance(const T* a, const U* b, std::size_t dim) {
  return internal_distance(Metric{}, a, b, dim);
}

}  // namespace kdspace
