// The input checks shared by the point indexes (PointTree, PointForest): the points of a build, k,
// and query coordinates. Each throws Error with a message that says what and where.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <type_traits>

#include "kdspace/error.hpp"

namespace kdspace::detail {

/// n points of `dim` coordinates, row-major: a positive dimension, 1 <= n < 2^30, and (unless
/// check_values is false) every coordinate finite ("row R: coordinate A is not finite (v)", 1-based).
template <class T>
void check_points(const T* rows, std::size_t n, std::size_t dim, bool check_values = true) {
  if (dim == 0) throw Error("points have dimension 0");
  if (n == 0) throw Error("no points: the data is empty");
  if (n >= (std::size_t{1} << 30)) throw Error("too many points: " + std::to_string(n) + " (at most 2^30 - 1)");
  if (rows == nullptr) throw Error("points: null pointer");
  if (!check_values) return;
  if constexpr (std::is_integral_v<T>) return;  // every value is finite
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a)
      if (!std::isfinite(rows[i * dim + a]))
        throw Error("row " + std::to_string(i + 1) + ": coordinate " + std::to_string(a + 1) + " is not finite (" +
                    std::to_string(rows[i * dim + a]) + ")");
}

/// 1 <= k <= n.
inline void check_k(std::size_t k, std::size_t n) {
  if (k == 0) throw Error("k must be at least 1");
  if (k > n) throw Error("k = " + std::to_string(k) + " exceeds the number of points (" + std::to_string(n) + ")");
}

/// One query of `dim` finite coordinates; else "WHAT: coordinate A is not finite (v)".
template <class T>
void check_finite(const T* q, std::size_t dim, const std::string& what) {
  if (q == nullptr) throw Error(what + ": null pointer");
  for (std::size_t a = 0; a < dim; ++a)
    if (!std::isfinite(q[a]))
      throw Error(what + ": coordinate " + std::to_string(a + 1) + " is not finite (" + std::to_string(q[a]) + ")");
}

/// nq queries of `dim` finite coordinates, row-major; else "query row R: coordinate A ...".
template <class T>
void check_query_rows(const T* queries, std::size_t nq, std::size_t dim) {
  if (nq > 0 && queries == nullptr) throw Error("queries: null pointer");
  for (std::size_t q = 0; q < nq; ++q)
    for (std::size_t a = 0; a < dim; ++a)
      if (!std::isfinite(queries[q * dim + a]))
        throw Error("query row " + std::to_string(q + 1) + ": coordinate " + std::to_string(a + 1) +
                    " is not finite (" + std::to_string(queries[q * dim + a]) + ")");
}

}  // namespace kdspace::detail
