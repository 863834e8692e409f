// The blocked scan of include/kdspace/points/detail/blocked_scan.hpp: matrix products for the
// estimates, a rounding bound for each, and an exact re-check of the candidates.
//
// The bound. Let x' and q' be the centred coordinates as rounded, N = |x'|^2 + |q'|^2 (as computed),
// u the unit roundoff (epsilon / 2) and d the dimension. The estimate a = |x'|^2 + |q'|^2 - 2 x'.q'
// differs from |x' - q'|^2 by at most about (2 gamma_d + 6u) N (each norm and the dot product are
// sums of d products, whatever order the product kernel adds them in, plus three roundings in the
// combination); the centring moves |x - q|^2 by at most about 4u N; internal_distance() differs from
// the true |x - q|^2 by at most gamma_d * 2N. All together under (4d + 16) u N; we use twice that,
// (4d + 32) epsilon N, plus (4d + 32) times the smallest normal number for underflow in tiny data.
#include "kdspace/points/detail/blocked_scan.hpp"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/detail/result_sets.hpp"

namespace kdspace::detail {
namespace {

template <class T>
using RowMatrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
template <class T>
using ColMatrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor>;

// Queries per block (columns of the product) and points per block (its rows). A block of 64 queries
// reuses each point block 64 times from cache; 1024 points of 128 floats take 512 KiB.
constexpr std::size_t query_block = 64;
constexpr std::size_t point_block = 1024;

template <class T, class U>
void exact_scan(const ScanData<T>& data, const U* rows, const T* q, std::size_t k, Neighbor<T>* out) {
  std::vector<Candidate<T>> storage;
  KnnResults<T> results(k, std::numeric_limits<T>::infinity(), storage);
  for (std::size_t i = 0; i < data.n; ++i)
    results.offer(internal_distance<L2>(q, rows + i * data.dim, data.dim), data.order[i]);
  for (const auto& c : results.sorted()) *out++ = Neighbor<T>{c.index, L2::to_distance(c.dist)};
}

// Sum over axes of the largest squared centred coordinate, in double: whether estimates may overflow.
template <class T, class U>
double centred_norm_bound(const U* row, const T* centre, std::size_t dim) {
  double s = 0;
  for (std::size_t a = 0; a < dim; ++a) {
    const double v = static_cast<double>(row[a]) - static_cast<double>(centre[a]);
    s += v * v;
  }
  return s;
}

/// One block of queries: the running k smallest upper bounds and the candidates of each query.
template <class T>
struct QueryState {
  std::vector<T> upper;                 // max-heap of the k smallest a + m seen
  std::vector<std::uint32_t> rows;      // candidate rows (leaf order)
  T threshold = std::numeric_limits<T>::infinity();
};

// The scan, on rows held as T or as bytes (converted to T exactly where they are read).
template <class T, class U>
void scan_rows(const ScanData<T>& data, const U* rows, const T* queries, std::size_t nq, std::size_t k, Neighbor<T>* out) {
  const std::size_t d = data.dim, n = data.n;
  // Could an estimate overflow? The data's part is bounded from the largest centred row norm; the
  // product's entries are then bounded by the norms. A factor 16 of headroom.
  const double limit = static_cast<double>(std::numeric_limits<T>::max()) / 16;
  double data_norm = 0;
  for (std::size_t i = 0; i < n; ++i) data_norm = std::max(data_norm, centred_norm_bound(rows + i * d, data.centre, d));
  if (!(data_norm < limit)) {
    for (std::size_t q = 0; q < nq; ++q) exact_scan(data, rows, queries + q * d, k, out + q * k);
    return;
  }

  const T scale = static_cast<T>(4 * d + 32) * std::numeric_limits<T>::epsilon();
  const T floor = static_cast<T>(4 * d + 32) * std::numeric_limits<T>::min();
  RowMatrix<T> qc(static_cast<Eigen::Index>(query_block), static_cast<Eigen::Index>(d));
  RowMatrix<T> pc(static_cast<Eigen::Index>(point_block), static_cast<Eigen::Index>(d));
  ColMatrix<T> dots(static_cast<Eigen::Index>(point_block), static_cast<Eigen::Index>(query_block));
  std::vector<T> qnorm(query_block), pnorm(point_block);
  std::vector<QueryState<T>> state(query_block);
  std::vector<std::size_t> block_queries;  // the queries of this block the estimate can take
  std::vector<Candidate<T>> storage;

  for (std::size_t q0 = 0; q0 < nq; q0 += query_block) {
    const std::size_t bq_all = std::min(query_block, nq - q0);
    block_queries.clear();
    for (std::size_t j = 0; j < bq_all; ++j) {
      const T* q = queries + (q0 + j) * d;
      if (centred_norm_bound(q, data.centre, d) < limit) block_queries.push_back(q0 + j);
      else exact_scan(data, rows, q, k, out + (q0 + j) * k);  // absurdly large coordinates: no estimate
    }
    const std::size_t bq = block_queries.size();
    if (bq == 0) continue;
    for (std::size_t j = 0; j < bq; ++j) {
      const T* q = queries + block_queries[j] * d;
      T norm = 0;
      for (std::size_t a = 0; a < d; ++a) {
        const T v = q[a] - data.centre[a];
        qc(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(a)) = v;
        norm += v * v;
      }
      qnorm[j] = norm;
      state[j].upper.clear();
      state[j].rows.clear();
      state[j].threshold = std::numeric_limits<T>::infinity();
    }
    const auto queries_used = qc.topRows(static_cast<Eigen::Index>(bq));

    for (std::size_t p0 = 0; p0 < n; p0 += point_block) {
      const std::size_t bp = std::min(point_block, n - p0);
      for (std::size_t i = 0; i < bp; ++i) {
        const U* p = rows + (p0 + i) * d;
        T norm = 0;
        for (std::size_t a = 0; a < d; ++a) {
          const T v = static_cast<T>(p[a]) - data.centre[a];
          pc(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(a)) = v;
          norm += v * v;
        }
        pnorm[i] = norm;
      }
      auto block_dots = dots.topLeftCorner(static_cast<Eigen::Index>(bp), static_cast<Eigen::Index>(bq));
      block_dots.noalias() = pc.topRows(static_cast<Eigen::Index>(bp)) * queries_used.transpose();

      for (std::size_t j = 0; j < bq; ++j) {
        QueryState<T>& s = state[j];
        const T qn = qnorm[j];
        const T* dot = &block_dots(0, static_cast<Eigen::Index>(j));
        T threshold = s.threshold;
        for (std::size_t i = 0; i < bp; ++i) {
          const T sum = pnorm[i] + qn;
          const T estimate = sum - 2 * dot[i];
          const T margin = scale * sum + floor;
          if (estimate - margin > threshold) continue;
          s.rows.push_back(static_cast<std::uint32_t>(p0 + i));
          const T upper = estimate + margin;
          if (s.upper.size() < k) {
            s.upper.push_back(upper);
            std::push_heap(s.upper.begin(), s.upper.end());
            if (s.upper.size() == k) threshold = s.upper.front();
          } else if (upper < threshold) {
            std::pop_heap(s.upper.begin(), s.upper.end());
            s.upper.back() = upper;
            std::push_heap(s.upper.begin(), s.upper.end());
            threshold = s.upper.front();
          }
        }
        s.threshold = threshold;
      }
    }

    // The exact re-check: every point whose exact distance is within the k-th is a candidate.
    for (std::size_t j = 0; j < bq; ++j) {
      const std::size_t query = block_queries[j];
      const T* q = queries + query * d;
      KnnResults<T> results(k, std::numeric_limits<T>::infinity(), storage);
      for (const std::uint32_t row : state[j].rows)
        results.offer(internal_distance<L2>(q, rows + static_cast<std::size_t>(row) * d, d), data.order[row]);
      Neighbor<T>* o = out + query * k;
      for (const auto& c : results.sorted()) *o++ = Neighbor<T>{c.index, L2::to_distance(c.dist)};
    }
  }
}

}  // namespace

template <class T>
void blocked_scan_knn_l2(const ScanData<T>& data, const T* queries, std::size_t nq, std::size_t k, Neighbor<T>* out) {
  if (data.bytes) scan_rows(data, data.bytes, queries, nq, k, out);
  else scan_rows(data, data.points, queries, nq, k, out);
}

template void blocked_scan_knn_l2<float>(const ScanData<float>&, const float*, std::size_t, std::size_t,
                                         Neighbor<float>*);
template void blocked_scan_knn_l2<double>(const ScanData<double>&, const double*, std::size_t, std::size_t,
                                          Neighbor<double>*);

}  // namespace kdspace::detail
