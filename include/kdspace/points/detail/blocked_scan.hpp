// The blocked scan: exact L2 k-NN of many queries by scoring every point, for data where a kd-tree
// would visit most leaves anyway (high dimensions, uniform data).
//
// Points go through in blocks, each against every block of queries, as one matrix product
// (lib/points/blocked_scan.cpp: register-blocked kernels for AVX-512 and AVX2, chosen at run time,
// or Eigen).
// Small-integer data (bytes, SIFT descriptors; every coordinate of points and queries an integer
// and the squared extents adding up to less than 2^24) is multiplied in 16-bit integers: the
// distances |x|^2 + |q|^2 - 2 x.q are then exact, and equal to internal_distance() bit for bit.
// Any other data gets estimates of the squared distances, on coordinates centred on `centre` so
// that the norms stay small, each with a rigorous rounding bound m (the product's and the norms'
// rounding, the centring's and that of internal_distance() itself), so that the exact internal
// distance lies in [a - m, a + m]. A point is kept as a candidate unless a - m exceeds the k-th
// smallest a + m seen so far; the candidates are then scored again with internal_distance() and
// ranked by (distance, index). The answer is therefore the tree's and brute_force_knn()'s, bit for
// bit, whatever the rounding of the product.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kdspace/points/neighbor.hpp"

namespace kdspace::detail {

/// Where one call's time went (kdspace-scan-bench): filled when ScanData::profile is set.
struct ScanProfile {
  double check_s = 0;      ///< the checks of the data: small integers? estimates at risk of overflow?
  double prepare_s = 0;    ///< converting and packing the point blocks, their norms
  double product_s = 0;    ///< the products with the bound test fused in, and keeping the candidates
  double recheck_s = 0;    ///< exact distances of the candidates, the final ranking
  std::size_t candidates = 0;  ///< points kept for the re-check (or offered to the k-NN heaps)
  bool integer_path = false;   ///< small-integer data: exact 16-bit products, no re-check
};

/// The product kernels, widest first: each call uses the widest the processor has, but not wider
/// than ScanData::widest (so that tests reach every kernel on any processor).
enum class ScanKernel { avx512, avx2, portable };

/// The points as the tree holds them: leaf-ordered rows and each row's original index.
template <class T>
struct ScanData {
  const T* points;              ///< n rows of dim coordinates (null when `bytes` holds them)
  const std::uint32_t* order;   ///< original index of each row
  std::size_t n;
  std::size_t dim;
  const T* centre;              ///< dim coordinates near the middle of the data
  const std::uint8_t* bytes = nullptr;  ///< or the rows as bytes (PointForest's compact storage)
  ScanProfile* profile = nullptr;       ///< where to add up the time of each phase, when not null
  ScanKernel widest = ScanKernel::avx512;  ///< the widest kernel allowed
};

/// Exact k-NN (L2, 1 <= k <= n) of queries[0 .. nq) (row-major); out[q * k + i] is the i-th
/// neighbour of query q in (distance, index) order, distances true (not squared). One thread; the
/// caller spreads blocks of queries over threads. Coordinates large enough for the estimate to
/// overflow are answered by a plain exact scan instead.
template <class T>
void blocked_scan_knn_l2(const ScanData<T>& data, const T* queries, std::size_t nq, std::size_t k, Neighbor<T>* out);

extern template void blocked_scan_knn_l2<float>(const ScanData<float>&, const float*, std::size_t, std::size_t,
                                                Neighbor<float>*);
extern template void blocked_scan_knn_l2<double>(const ScanData<double>&, const double*, std::size_t, std::size_t,
                                                 Neighbor<double>*);

}  // namespace kdspace::detail
