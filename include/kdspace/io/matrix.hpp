// A dense row-major matrix: the in-memory form of every vector file kdspace reads.
#pragma once

#include <cstddef>
#include <vector>

namespace kdspace::io {

/// rows x cols values, row-major: row r starts at data[r * cols].
template <class T>
struct Matrix {
  std::size_t rows = 0;
  std::size_t cols = 0;
  std::vector<T> data;

  const T* row(std::size_t r) const { return data.data() + r * cols; }
  T* row(std::size_t r) { return data.data() + r * cols; }
};

}  // namespace kdspace::io
