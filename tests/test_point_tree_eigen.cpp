// PointTree built from Eigen matrices (one point per row), either storage order.
#include <catch2/catch.hpp>

#include <Eigen/Dense>
#include <limits>

#include "kdspace/kdspace.hpp"

TEST_CASE("a tree built from an Eigen matrix answers like one built from the raw rows", "[points][eigen]") {
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> row_major =
      Eigen::MatrixXf::Random(500, 6);
  const Eigen::MatrixXf col_major = row_major;  // same points, column-major storage
  const kdspace::PointTree<float> from_raw(row_major.data(), 500, 6);
  const kdspace::PointTree<float> from_row_major(row_major);
  const kdspace::PointTree<float> from_col_major(col_major);
  const Eigen::Matrix<double, Eigen::Dynamic, 3> doubles = Eigen::MatrixXd::Random(300, 3);
  const kdspace::PointTree<double, 3> fixed(doubles);
  REQUIRE(from_col_major.size() == 500);
  REQUIRE(from_col_major.dim() == 6);
  for (int q = 0; q < 20; ++q) {
    const Eigen::VectorXf query = Eigen::VectorXf::Random(6);
    const auto want = kdspace::brute_force_knn(row_major.data(), 500, 6, query.data(), 7);
    REQUIRE(from_raw.knn(query.data(), 7) == want);
    REQUIRE(from_row_major.knn(query.data(), 7) == want);
    REQUIRE(from_col_major.knn(query.data(), 7) == want);
    const Eigen::Vector3d q3 = Eigen::Vector3d::Random();
    const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> rows = doubles;
    REQUIRE(fixed.knn(q3.data(), 4) == kdspace::brute_force_knn(rows.data(), 300, 3, q3.data(), 4));
  }
}

TEST_CASE("an Eigen matrix with a NaN is refused, naming the row", "[points][eigen]") {
  Eigen::MatrixXd points = Eigen::MatrixXd::Zero(4, 2);
  points(2, 1) = std::numeric_limits<double>::quiet_NaN();
  REQUIRE_THROWS_WITH(kdspace::PointTree<double>(points), Catch::Contains("row 3") && Catch::Contains("coordinate 2"));
}
