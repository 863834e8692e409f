// The library's file readers and writers with NumPy arrays: vector files (.fvecs .ivecs .bvecs .csv
// .npy), ragged result rows, boxes, rays and hits. Errors name the file and the row (ValueError).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "kdspace/io/scene.hpp"
#include "kdspace/io/vectors.hpp"
#include "module_parts.hpp"
#include "numpy_arrays.hpp"

namespace kdspace::python {
namespace {

template <class T>
py::array_t<T> read_points_as(const std::string& path) {
  io::Matrix<T> m;
  {
    py::gil_scoped_release unlocked;
    m = io::read_points<T>(path);
  }
  return take_vector(std::move(m.data), {static_cast<py::ssize_t>(m.rows), static_cast<py::ssize_t>(m.cols)});
}

template <class T>
void write_points_from(const std::string& path, const CArray<T>& rows) {
  if (rows.ndim() != 2) throw Error(path + ": points to write must be a 2-D array");
  io::Matrix<T> m;
  m.rows = static_cast<std::size_t>(rows.shape(0));
  m.cols = static_cast<std::size_t>(rows.shape(1));
  m.data.assign(rows.data(), rows.data() + rows.size());
  py::gil_scoped_release unlocked;
  io::write_points(path, m);
}

/// Ragged rows as a list of 1-D arrays.
template <class T>
py::list list_of_rows(const io::RaggedRows<T>& ragged) {
  py::list out;
  for (std::size_t r = 0; r < ragged.rows(); ++r)
    out.append(py::array_t<T>(static_cast<py::ssize_t>(ragged.offsets[r + 1] - ragged.offsets[r]),
                              ragged.values.data() + ragged.offsets[r]));
  return out;
}

template <class T>
io::RaggedRows<T> ragged_of(const py::list& rows) {
  io::RaggedRows<T> ragged;
  for (const auto& row : rows) {
    const auto values = row.cast<CArray<T>>();
    if (values.ndim() != 1) throw Error("each row to write must be a 1-D array");
    ragged.values.insert(ragged.values.end(), values.data(), values.data() + values.size());
    ragged.offsets.push_back(ragged.values.size());
  }
  return ragged;
}

py::array_t<float> boxes_array(const std::vector<Box3f>& boxes) {
  std::vector<float> flat;
  flat.reserve(6 * boxes.size());
  for (const Box3f& b : boxes) flat.insert(flat.end(), {b.lo[0], b.lo[1], b.lo[2], b.hi[0], b.hi[1], b.hi[2]});
  return take_vector(std::move(flat), {static_cast<py::ssize_t>(boxes.size()), 6});
}

py::array_t<float> rays_array(const std::vector<Ray>& rays) {
  std::vector<float> flat;
  flat.reserve(6 * rays.size());
  for (const Ray& r : rays)
    flat.insert(flat.end(), {r.origin[0], r.origin[1], r.origin[2], r.direction[0], r.direction[1], r.direction[2]});
  return take_vector(std::move(flat), {static_cast<py::ssize_t>(rays.size()), 6});
}

template <class Record>
std::vector<Record> records_of(const CArray<float>& rows, const char* what) {
  const float* v = rows_of(rows, 6, what);
  std::vector<Record> out(static_cast<std::size_t>(rows.shape(0)));
  for (auto& record : out) {
    std::array<float, 6> values;
    std::copy(v, v + 6, values.begin());
    v += 6;
    if constexpr (std::is_same_v<Record, Box3f>) {
      record.lo = {values[0], values[1], values[2]};
      record.hi = {values[3], values[4], values[5]};
    } else {
      record.origin = {values[0], values[1], values[2]};
      record.direction = {values[3], values[4], values[5]};
    }
  }
  return out;
}

}  // namespace

void bind_io(py::module_& m) {
  m.def("stores_double", &io::stores_double, py::arg("path"));
  m.def("read_points_float32", &read_points_as<float>, py::arg("path"));
  m.def("read_points_float64", &read_points_as<double>, py::arg("path"));
  m.def("read_points_uint8", &read_points_as<std::uint8_t>, py::arg("path"));
  m.def("write_points_float32", &write_points_from<float>, py::arg("path"), py::arg("rows"));
  m.def("write_points_float64", &write_points_from<double>, py::arg("path"), py::arg("rows"));
  m.def("read_ivecs_rows", [](const std::string& path) { return list_of_rows(io::read_ivecs_rows(path)); });
  m.def("read_fvecs_rows", [](const std::string& path) { return list_of_rows(io::read_fvecs_rows(path)); });
  m.def("write_ivecs_rows",
        [](const std::string& path, const py::list& rows) { io::write_ivecs(path, ragged_of<std::int32_t>(rows)); });
  m.def("write_fvecs_rows",
        [](const std::string& path, const py::list& rows) { io::write_fvecs(path, ragged_of<float>(rows)); });
  m.def("read_boxes", [](const std::string& path) { return boxes_array(io::read_boxes(path)); });
  m.def("read_rays", [](const std::string& path) { return rays_array(io::read_rays(path)); });
  m.def("read_hits", [](const std::string& path) {
    const std::vector<Hit> hits = io::read_hits(path);
    std::vector<std::int64_t> boxes;
    std::vector<float> t;
    for (const Hit& h : hits) boxes.push_back(h.box), t.push_back(h.t);
    const auto n = static_cast<py::ssize_t>(hits.size());
    return py::make_tuple(take_vector(std::move(boxes), {n}), take_vector(std::move(t), {n}));
  });
  m.def("write_boxes", [](const std::string& path, const CArray<float>& rows) {
    io::write_boxes(path, records_of<Box3f>(rows, "boxes"));
  });
  m.def("write_rays", [](const std::string& path, const CArray<float>& rows) {
    io::write_rays(path, records_of<Ray>(rows, "rays"));
  });
}

}  // namespace kdspace::python
