// Reading a point file across MPI ranks: each rank reads its own part, no rank the whole file.
#pragma once

#include <mpi.h>

#include <cstdint>
#include <string>

#include "kdspace/io/matrix.hpp"

namespace kdspace::mpi {

/// One rank's rows of a point file.
template <class T>
struct FilePart {
  io::Matrix<T> points;          ///< this rank's rows, in file order
  std::uint64_t first_row = 0;   ///< the 0-based file row of points.row(0)
  std::uint64_t total_rows = 0;  ///< rows of the whole file
  std::size_t cols = 0;          ///< values a row (the same on every rank, even one without rows)
};

/// Collective: rank r of P reads part r of the file, as io::plan_part and io::read_part divide it
/// (.fvecs .ivecs .bvecs .npy by seeking to its rows; .csv by its share of the bytes, whole lines).
/// Rows go to ranks in file order, so rank order is file order. T: float or double. The file is
/// checked as io::read_points checks it; when a rank finds a problem in its part, every rank throws
/// Error("rank R of P: FILE: row N: what"), R the first failing rank, whose problem is the first in
/// the file. A file without rows throws the same message on every rank.
template <class T>
FilePart<T> read_part(MPI_Comm comm, const std::string& path);

}  // namespace kdspace::mpi
