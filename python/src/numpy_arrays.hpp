// NumPy arrays in and out of the module: checked views of the caller's arrays, and arrays that take
// over a std::vector without a copy.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/error.hpp"

namespace kdspace::python {

namespace py = pybind11;

/// A C-contiguous array of T exactly (no conversion: the Python layer converts first, once).
template <class T>
using CArray = py::array_t<T, py::array::c_style>;

/// Rows of `cols` values: a C-contiguous 2-D array with that many columns, else Error.
template <class T>
const T* rows_of(const CArray<T>& a, std::size_t cols, const char* what) {
  if (a.ndim() != 2 || static_cast<std::size_t>(a.shape(1)) != cols)
    throw Error(std::string(what) + " must be a 2-D array with " + std::to_string(cols) + " columns");
  return a.data();
}

/// n values: a 1-D array of that length, else Error.
template <class T>
const T* values_of(const CArray<T>& a, std::size_t n, const char* what) {
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != n)
    throw Error(std::string(what) + " must be a 1-D array of " + std::to_string(n) + " values");
  return a.data();
}

/// A NumPy array of the given shape that owns `values` (moved, not copied).
template <class T>
py::array_t<T> take_vector(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(values));
  py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(std::move(shape), owned->data(), free_when_done);
}

}  // namespace kdspace::python
