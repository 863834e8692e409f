// Large arrays in transparent huge pages (include/kdspace/detail/huge_pages.hpp), on request: with
// KDSPACE_HUGE_PAGES=1 (ctest entry `with_huge_pages`) where the system allows them, arrays from the
// threshold on are mapped at a multiple of 2 MiB and advised (MADV_HUGEPAGE, seen as the `hg` flag
// of their mapping in /proc/self/smaps); otherwise they come from operator new. Either way the
// values, and the answers of the trees and joins that hold them, are the same.
#include <catch2/catch.hpp>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/detail/storage.hpp"
#include "kdspace/joins/joins.hpp"
#include "mapping_flags.hpp"
#include "support.hpp"

namespace {

using kdspace::detail::huge_page_bytes;
using kdspace::detail::huge_page_threshold;
using kdspace::detail::huge_pages_enabled;
using kdspace::detail::HugePageVector;
using kdspace_test::advised_for_huge_pages;

bool aligned_to_huge_page(const void* p) { return reinterpret_cast<std::uintptr_t>(p) % huge_page_bytes == 0; }

}  // namespace

TEST_CASE("huge pages are on where KDSPACE_HUGE_PAGES=1 asks and the system gives them, else off", "[huge_pages]") {
  const char* asked = std::getenv("KDSPACE_HUGE_PAGES");
  std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string setting;
  std::getline(mode, setting);
  const bool system_gives = static_cast<bool>(mode) && (setting.find("[always]") != std::string::npos ||
                                                        setting.find("[madvise]") != std::string::npos);
#if defined(__linux__)
  REQUIRE(huge_pages_enabled() == (asked != nullptr && std::string(asked) == "1" && system_gives));
#else
  REQUIRE_FALSE(huge_pages_enabled());
#endif
  // Only large arrays ask for them.
  REQUIRE_FALSE(kdspace::detail::in_huge_pages(huge_page_threshold - 1));
  REQUIRE(kdspace::detail::in_huge_pages(huge_page_threshold) == huge_pages_enabled());
}

TEST_CASE("a large HugePageVector lies at a multiple of 2 MiB, advised for huge pages, where enabled", "[huge_pages]") {
  const std::size_t n = huge_page_threshold / sizeof(double) * 2 + 3;  // not a whole number of pages
  HugePageVector<double> values(n);
  for (std::size_t i = 0; i < n; ++i) values[i] = static_cast<double>(i) * 0.5;
  if (huge_pages_enabled()) {
    CHECK(aligned_to_huge_page(values.data()));
    CHECK(advised_for_huge_pages(values.data()));
    CHECK(advised_for_huge_pages(values.data() + n - 1));  // the tail, past the last whole huge page
  }
  // Growth, copies and moves keep the values, each vector its own array.
  values.push_back(-1.0);
  HugePageVector<double> copy = values;
  REQUIRE(copy.data() != values.data());
  const double* array = copy.data();
  HugePageVector<double> moved = std::move(copy);
  REQUIRE(moved.data() == array);
  REQUIRE(moved.size() == n + 1);
  for (std::size_t i = 0; i < n; ++i) REQUIRE(moved[i] == static_cast<double>(i) * 0.5);
  REQUIRE(moved[n] == -1.0);
  if (huge_pages_enabled()) CHECK(aligned_to_huge_page(moved.data()));
  // Small arrays are operator new's: nothing is said about their place.
  HugePageVector<double> small(100, 2.0);
  REQUIRE(small[99] == 2.0);
}

TEST_CASE("reserve_in_huge_pages reserves the room and advises its aligned interior, where enabled", "[huge_pages]") {
  std::vector<std::uint64_t> values;
  const std::size_t n = 4 * huge_page_bytes / sizeof(std::uint64_t);
  kdspace::detail::reserve_in_huge_pages(values, n);
  REQUIRE(values.capacity() >= n);
  REQUIRE(values.empty());
  if (huge_pages_enabled()) {
    // The first 2 MiB boundary inside the array.
    const auto first = reinterpret_cast<std::uintptr_t>(values.data());
    const auto boundary = (first + huge_page_bytes - 1) / huge_page_bytes * huge_page_bytes;
    CHECK(advised_for_huge_pages(reinterpret_cast<const void*>(boundary)));
  }
  values.resize(n, 7);
  REQUIRE(values[n - 1] == 7);
}

TEST_CASE("Storage owns a HugePageVector: values, copies, moves and release", "[huge_pages]") {
  const std::size_t n = huge_page_threshold / sizeof(float) + 5;
  HugePageVector<float> values(n);
  for (std::size_t i = 0; i < n; ++i) values[i] = static_cast<float>(i % 1000);
  const float* array = values.data();
  auto storage = kdspace::detail::Storage<float>::owning(std::move(values));
  REQUIRE(storage.data() == array);
  REQUIRE(storage.size() == n);
  REQUIRE_FALSE(storage.borrowed());
  REQUIRE(storage.owned_data() == array);
  REQUIRE(storage.memory_bytes() >= n * sizeof(float));
  const kdspace::detail::Storage<float> copy = storage;
  REQUIRE(copy.data() != storage.data());
  REQUIRE(copy == storage);
  kdspace::detail::Storage<float> moved = std::move(storage);
  REQUIRE(moved.data() == array);
  REQUIRE(storage.size() == 0);
  const std::vector<float> released = moved.release();
  REQUIRE(released.size() == n);
  REQUIRE(moved.size() == 0);
  REQUIRE(moved.memory_bytes() == 0);
  for (std::size_t i = 0; i < n; ++i) REQUIRE(released[i] == copy[i]);
}

// 2e5 3-D double points: the tree's points (4.8 MB), the join's cells, its k-NN table and both
// results (12.8 MB each at k = 4) are all above the threshold.
TEST_CASE("a tree and its self-join in huge pages answer as the single-tree batch and brute force", "[huge_pages][joins]") {
  const std::size_t n = 200000, dim = 3, k = 4;
  const auto pts = kdspace_test::make_points<double>(kdspace_test::Shape::clustered, n, dim, 17);
  kdspace::BuildParams build;
  build.threads = 1;
  const kdspace::PointTree<double, 3> tree(pts.data(), n, dim, build);
  REQUIRE(n * dim * sizeof(double) >= huge_page_threshold);
  if (huge_pages_enabled()) {
    CHECK(aligned_to_huge_page(tree.points_in_leaf_order().data()));
    CHECK(advised_for_huge_pages(tree.points_in_leaf_order().data()));
  }
  kdspace::JoinParams one_thread;
  one_thread.threads = 1;
  const auto joined = kdspace::self_knn_join(tree, k, one_thread);
  kdspace::SearchParams by_tree;
  by_tree.batch_method = kdspace::BatchMethod::tree;
  const auto single = tree.knn_batch(pts.data(), n, k + 1, by_tree, 1);
  REQUIRE(joined.rows() == n);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t out = 0;
    for (std::size_t j = 0; j < k + 1 && out < k; ++j) {
      if (single.row(i)[j].index == i) continue;
      differ += single.row(i)[j] == joined.row(i)[out++] ? 0 : 1;
    }
  }
  REQUIRE(differ == 0);
  for (std::size_t i = 0; i < n; i += 9973) {
    const auto expected = kdspace::brute_force_knn(pts.data(), n, dim, pts.data() + i * dim, k + 1);
    std::size_t out = 0;
    for (const auto& e : expected) {
      if (e.index == i || out == k) continue;
      REQUIRE(joined.row(i)[out++] == e);
    }
  }
}
