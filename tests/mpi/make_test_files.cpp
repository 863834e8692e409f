// Writes the data of the kdspace-mpi command tests (tests/mpi/mpi_cli_tests.sh) into a folder: the
// shapes of tests/support.hpp, in every file format the command reads.
//
//   usage: kdspace_mpi_test_files DIR
#include <cstdio>
#include <string>
#include <vector>

#include "../support.hpp"
#include "kdspace/io/vectors.hpp"

namespace {

using kdspace_test::Shape;

template <class T>
void write(const std::string& path, const std::vector<T>& values, std::size_t dim) {
  kdspace::io::Matrix<T> m;
  m.cols = dim;
  m.rows = values.size() / dim;
  m.data = values;
  kdspace::io::write_points(path, m);
}

// NAME.EXT (the base) and NAME-q.QEXT (queries: in the box, on data points, far outside; QEXT is
// EXT unless the format holds integers only).
template <class T>
void write_set(const std::string& dir, const std::string& name, const std::string& ext, Shape shape,
               std::size_t n, std::size_t dim, std::size_t nq, std::uint32_t seed,
               const std::string& query_ext = "") {
  const std::vector<T> pts = kdspace_test::make_points<T>(shape, n, dim, seed);
  write(dir + "/" + name + ext, pts, dim);
  write(dir + "/" + name + "-q" + (query_ext.empty() ? ext : query_ext),
        kdspace_test::make_queries(pts, n, dim, nq, seed + 1), dim);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 2;
  }
  const std::string dir = argv[1];
  try {
    write_set<float>(dir, "uniform", ".fvecs", Shape::uniform, 3000, 3, 300, 1);
    write_set<float>(dir, "clustered", ".fvecs", Shape::clustered, 2500, 8, 200, 2);
    write_set<float>(dir, "duplicates", ".fvecs", Shape::duplicates, 2000, 2, 200, 3);
    write_set<float>(dir, "grid", ".ivecs", Shape::grid, 2000, 3, 200, 4, ".fvecs");
    write_set<float>(dir, "identical", ".fvecs", Shape::identical, 400, 4, 50, 5);
    write_set<double>(dir, "flat", ".csv", Shape::flat, 1200, 9, 150, 6);
    write_set<double>(dir, "sorted", ".npy", Shape::sorted_x, 1500, 2, 150, 7);
    write_set<float>(dir, "one", ".fvecs", Shape::uniform, 1, 3, 20, 8);
    // Byte-valued points: the grid's values 0..6 read back exactly from .bvecs.
    write_set<float>(dir, "bytes", ".bvecs", Shape::grid, 1500, 16, 100, 9, ".fvecs");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace_mpi_test_files: %s\n", e.what());
    return 1;
  }
  return 0;
}
