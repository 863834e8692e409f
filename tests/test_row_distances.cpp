// The forest's many-rows distance kernel: the same bits as internal_distance<L2> for every row, for
// float and double queries, float, double and byte rows, every dimension around the 8-lane blocks,
// 1, 2 and 4 rows at a time; and when it stops early, every value it gives is above the limit and
// no larger than the true distance.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/detail/fixed_distance.hpp"
#include "kdspace/points/detail/row_distances.hpp"

namespace {

template <std::size_t R, class T, class U>
void check_rows(std::size_t dim, std::mt19937& rng) {
  std::uniform_real_distribution<double> value(-300, 300);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<T> query(dim);
  for (T& v : query) v = static_cast<T>(value(rng));
  std::vector<std::vector<U>> rows(R, std::vector<U>(dim));
  for (auto& row : rows)
    for (U& v : row) v = std::is_same_v<U, std::uint8_t> ? static_cast<U>(byte(rng)) : static_cast<U>(value(rng));
  const U* pointers[R];
  T exact[R];
  for (std::size_t r = 0; r < R; ++r) {
    pointers[r] = rows[r].data();
    exact[r] = kdspace::internal_distance<kdspace::L2>(query.data(), rows[r].data(), dim);
  }
  T out[R], portable[R];
  kdspace::detail::l2_distances_or_more<R>(query.data(), pointers, dim, std::numeric_limits<T>::infinity(), out);
  kdspace::detail::l2_distances_or_more_portable<R>(query.data(), pointers, dim, std::numeric_limits<T>::infinity(), portable);
  for (std::size_t r = 0; r < R; ++r) {
    CHECK(out[r] == exact[r]);
    CHECK(portable[r] == exact[r]);
  }
  // Limits below, between and above the rows' distances.
  for (double share : {0.0, 0.1, 0.3, 0.6, 0.9, 1.0, 1.5}) {
    T largest = 0;
    for (std::size_t r = 0; r < R; ++r) largest = std::max(largest, exact[r]);
    const T limit = static_cast<T>(share * static_cast<double>(largest));
    kdspace::detail::l2_distances_or_more<R>(query.data(), pointers, dim, limit, out);
    bool all_exact = true, all_above = true;
    for (std::size_t r = 0; r < R; ++r) {
      all_exact = all_exact && out[r] == exact[r];
      all_above = all_above && out[r] > limit && out[r] <= exact[r];
    }
    CHECK((all_exact || all_above));
  }
}

template <class T, class U>
void check_all_dims() {
  std::mt19937 rng(11);
  for (std::size_t dim : {1, 2, 7, 8, 9, 15, 16, 31, 32, 39, 63, 64, 65, 72, 127, 128, 130, 257}) {
    CAPTURE(dim);
    check_rows<1, T, U>(dim, rng);
    check_rows<2, T, U>(dim, rng);
    check_rows<4, T, U>(dim, rng);
  }
}

// l2_distance_fixed<D> against internal_distance on rows whose values span many binary orders, so
// that the squares differ in size and any other order of the additions would round differently.
template <std::size_t D>
void check_fixed(std::mt19937& rng) {
  std::uniform_real_distribution<float> mantissa(-1, 1);
  std::uniform_int_distribution<int> exponent(-12, 12);
  std::vector<float> a(D), b(D);
  for (int trial = 0; trial < 200; ++trial) {
    for (std::size_t i = 0; i < D; ++i) {
      a[i] = std::ldexp(mantissa(rng), exponent(rng));
      b[i] = (trial + i) % 5 == 0 ? a[i] : std::ldexp(mantissa(rng), exponent(rng));  // some equal axes
    }
    CAPTURE(D, trial);
    CHECK(kdspace::detail::l2_distance_fixed<D>(a.data(), b.data()) ==
          kdspace::internal_distance<kdspace::L2>(a.data(), b.data(), D));
  }
}

template <std::size_t... Ds>
void check_fixed_dims(std::index_sequence<Ds...>) {
  std::mt19937 rng(12);
  (check_fixed<Ds + 1>(rng), ...);
}

}  // namespace

TEST_CASE("fixed-dimension distance: the same bits as internal_distance in every dimension from 1 to 40",
          "[points][exact]") {
  check_fixed_dims(std::make_index_sequence<40>{});
}

TEST_CASE("row distances: the same bits as internal_distance, row by row", "[points][forest]") {
  check_all_dims<float, float>();
  check_all_dims<float, std::uint8_t>();
  check_all_dims<double, double>();
  check_all_dims<double, std::uint8_t>();
}
