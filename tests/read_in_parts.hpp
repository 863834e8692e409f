// A point file read in P parts, one after the other, as P MPI ranks read it (kdspace::mpi::read_part
// does the same with MPI_Allgather for the sums below): every part planned, each part's first line
// the lines of the parts before, the data's end the last data line of any part, the parts read and
// put together. The first error in part order is the one the ranks agree on. Used by
// test_io_parts.cpp and by the fuzz target fuzz/fuzz_read_part.cpp, which check that the parts put
// together equal read_points (or give its error message).
#ifndef KDSPACE_TESTS_READ_IN_PARTS_HPP
#define KDSPACE_TESTS_READ_IN_PARTS_HPP

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/vectors.hpp"

namespace kdspace_test {

template <class T>
kdspace::io::Matrix<T> read_in_parts(const std::string& path, std::size_t parts) {
  namespace io = kdspace::io;
  std::vector<io::PartPlan> plans;
  for (std::size_t p = 0; p < parts; ++p) plans.push_back(io::plan_part(path, p, parts));
  std::vector<std::uint64_t> first(parts, 0);
  std::uint64_t data_end = 0;
  for (std::size_t p = 0; p < parts; ++p) {
    if (p > 0) first[p] = first[p - 1] + plans[p - 1].units;
    if (plans[p].last_data_line != io::PartPlan::no_line)
      data_end = std::max(data_end, first[p] + plans[p].last_data_line + 1);
  }
  io::Matrix<T> all;
  all.cols = plans[0].cols;
  for (std::size_t p = 0; p < parts; ++p) {
    const io::Matrix<T> part = io::read_part<T>(plans[p], first[p], data_end);
    if (part.rows == 0) continue;
    if (all.rows == 0) all.cols = part.cols;
    all.rows += part.rows;
    all.data.insert(all.data.end(), part.data.begin(), part.data.end());
  }
  io::check_total_rows(plans[0], all.rows);
  return all;
}

/// What a read gives: its shape and the bytes of its values, or "error: MESSAGE".
template <class T, class Read>
std::string outcome(Read&& read) {
  try {
    const kdspace::io::Matrix<T> m = read();
    std::string out = std::to_string(m.rows) + "x" + std::to_string(m.cols) + ":";
    out.append(reinterpret_cast<const char*>(m.data.data()), m.data.size() * sizeof(T));  // the bits
    return out;
  } catch (const kdspace::Error& e) {
    return std::string("error: ") + e.what();
  }
}

}  // namespace kdspace_test

#endif  // KDSPACE_TESTS_READ_IN_PARTS_HPP
