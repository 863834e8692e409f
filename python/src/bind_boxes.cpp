// BoxIndex: the BoxTree over 3-D boxes for kdspace.BoxTree (closest hit, any hit over [t_min, t_max]
// for many rays on threads; the overlapping pairs of its boxes, or of its boxes and another tree's,
// by kdspace/collide/overlap.hpp). The GIL is released while it builds, traces and pairs.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/collide/overlap.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "module_parts.hpp"
#include "numpy_arrays.hpp"

namespace kdspace::python {
namespace {

/// n x 6 floats (min x, min y, min z, max x, max y, max z) as boxes.
std::vector<Box3f> boxes_of(const CArray<float>& rows) {
  const float* v = rows_of(rows, 6, "boxes");
  std::vector<Box3f> boxes(static_cast<std::size_t>(rows.shape(0)));
  for (std::size_t i = 0; i < boxes.size(); ++i, v += 6) {
    boxes[i].lo = {v[0], v[1], v[2]};
    boxes[i].hi = {v[3], v[4], v[5]};
  }
  return boxes;
}

BoxBuildMethod method_named(const std::string& name) {
  if (name == "median") return BoxBuildMethod::median;
  if (name == "sah") return BoxBuildMethod::sah;
  if (name == "sah_nlogn" || name == "sah-nlogn") return BoxBuildMethod::sah_nlogn;
  if (name == "binned") return BoxBuildMethod::binned;
  throw Error("build must be 'sah_nlogn', 'sah', 'median' or 'binned', got '" + name + "'");
}

/// Pairs as an M x 2 array.
py::array_t<std::int64_t> pairs_array(const std::vector<IndexPair>& pairs) {
  std::vector<std::int64_t> flat;
  flat.reserve(2 * pairs.size());
  for (const IndexPair& p : pairs) flat.push_back(p.a), flat.push_back(p.b);
  return take_vector(std::move(flat), {static_cast<py::ssize_t>(pairs.size()), 2});
}

class BoxIndex {
 public:
  BoxIndex(const CArray<float>& rows, const std::string& method, unsigned threads) {
    std::vector<Box3f> boxes = boxes_of(rows);
    BoxBuildParams params;
    params.method = method_named(method);
    params.threads = threads;
    py::gil_scoped_release unlocked;
    tree_ = std::make_unique<BoxTree>(boxes, params);
  }

  const BoxTree& tree() const { return *tree_; }

  /// The overlapping pairs of this tree's boxes (i < j), or of its boxes and other's, sorted.
  py::array_t<std::int64_t> overlaps(const BoxIndex* other, unsigned threads) const {
    std::vector<IndexPair> pairs;
    {
      py::gil_scoped_release unlocked;
      pairs = other == nullptr ? overlapping_pairs(*tree_, threads) : overlapping_pairs(*tree_, other->tree(), threads);
    }
    return pairs_array(pairs);
  }

  /// The hits of n rays (origins and directions, n x 3 each) with t in [t_min, t_max]: the closest
  /// (any_hit false) or the first found (true). Returns (box indices, -1 for a miss; t, inf for a miss).
  py::tuple trace(const CArray<float>& origins, const CArray<float>& directions, float t_min, float t_max,
                  bool any_hit, unsigned threads) const {
    const float* o = rows_of(origins, 3, "origins");
    const auto n = static_cast<std::size_t>(origins.shape(0));
    const float* d = rows_of(directions, 3, "directions");
    if (static_cast<std::size_t>(directions.shape(0)) != n)
      throw Error("origins and directions have different numbers of rows (" + std::to_string(n) + " and " +
                  std::to_string(directions.shape(0)) + ")");
    std::vector<Ray> rays(n);
    for (std::size_t i = 0; i < n; ++i) {
      rays[i].origin = {o[3 * i], o[3 * i + 1], o[3 * i + 2]};
      rays[i].direction = {d[3 * i], d[3 * i + 1], d[3 * i + 2]};
      const std::string problem = ray_problem(rays[i]);
      if (!problem.empty()) throw Error("ray " + std::to_string(i + 1) + ": " + problem);
    }
    std::vector<std::int64_t> boxes(n);
    std::vector<float> t(n);
    {
      py::gil_scoped_release unlocked;
      detail::parallel_for(n, threads, 256, [&](std::size_t begin, std::size_t end, unsigned) {
        for (std::size_t i = begin; i < end; ++i) {
          const Hit hit = any_hit ? tree_->any_hit(rays[i], t_min, t_max) : tree_->closest_hit(rays[i], t_min, t_max);
          boxes[i] = hit.box;
          t[i] = hit.t;
        }
      });
    }
    const auto count = static_cast<py::ssize_t>(n);
    return py::make_tuple(take_vector(std::move(boxes), {count}), take_vector(std::move(t), {count}));
  }

 private:
  std::unique_ptr<BoxTree> tree_;
};

}  // namespace

void bind_boxes(py::module_& m) {
  py::class_<BoxIndex>(m, "BoxIndex")
      .def(py::init<const CArray<float>&, const std::string&, unsigned>(), py::arg("boxes"), py::arg("build"),
           py::arg("threads"))
      .def_property_readonly("size", [](const BoxIndex& b) { return b.tree().size(); })
      .def_property_readonly("depth", [](const BoxIndex& b) { return b.tree().depth(); })
      .def_property_readonly("leaf_count", [](const BoxIndex& b) { return b.tree().leaf_count(); })
      .def_property_readonly("node_count", [](const BoxIndex& b) { return b.tree().node_count(); })
      .def_property_readonly("memory_bytes", [](const BoxIndex& b) { return b.tree().memory_bytes(); })
      .def_property_readonly("sah_cost", [](const BoxIndex& b) { return b.tree().stats().sah_cost; })
      .def_property_readonly("build_seconds", [](const BoxIndex& b) { return b.tree().stats().build_seconds; })
      .def("trace", &BoxIndex::trace, py::arg("origins"), py::arg("directions"), py::arg("t_min"), py::arg("t_max"),
           py::arg("any_hit"), py::arg("threads"))
      .def("overlaps", &BoxIndex::overlaps, py::arg("other").none(true), py::arg("threads"));
}

}  // namespace kdspace::python
