// ForestIndex32 / ForestIndex64: the approximate index (PointForest) for kdspace.Forest. Byte data
// (uint8) is kept as bytes by a float forest without a float copy. The GIL is released while the
// forest is built, searched and tuned.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "kdspace/points/point_forest.hpp"
#include "module_parts.hpp"
#include "numpy_arrays.hpp"

namespace kdspace::python {
namespace {

template <class T>
class ForestIndex {
 public:
  /// Built from rows of T, or (for a float forest) from byte rows.
  ForestIndex(const py::array& rows, const ForestParams& params) {
    if (rows.ndim() != 2) throw Error("points must be a 2-D array");
    const auto n = static_cast<std::size_t>(rows.shape(0)), dim = static_cast<std::size_t>(rows.shape(1));
    if (py::isinstance<CArray<std::uint8_t>>(rows) && std::is_same_v<T, float>) {
      const auto bytes = rows.cast<CArray<std::uint8_t>>();
      py::gil_scoped_release unlocked;
      forest_ = std::make_unique<PointForest<T>>(bytes.data(), n, dim, params);
    } else {
      const auto values = rows.cast<CArray<T>>();
      py::gil_scoped_release unlocked;
      forest_ = std::make_unique<PointForest<T>>(values.data(), n, dim, params);
    }
  }

  const PointForest<T>& forest() const { return *forest_; }

  /// The k nearest found within the budget (ef > 0: on the graph): (distances, indices), nq x k each.
  py::tuple knn(const CArray<T>& queries, std::size_t k, std::size_t checks, std::size_t trees, std::size_t ef,
                unsigned threads) const {
    const std::size_t nq = rows(queries);
    NeighborLists<T> found;
    {
      py::gil_scoped_release unlocked;
      found = forest_->knn_batch(queries.data(), nq, k, ForestSearchParams{checks, trees, ef}, threads);
    }
    return split(found, nq, k);
  }

  /// The exact k nearest (blocked scan): the reference for recall.
  py::tuple knn_exact(const CArray<T>& queries, std::size_t k, unsigned threads) const {
    const std::size_t nq = rows(queries);
    NeighborLists<T> found;
    {
      py::gil_scoped_release unlocked;
      found = forest_->knn_exact_batch(queries.data(), nq, k, threads);
    }
    return split(found, nq, k);
  }

  /// The fastest setting (the graph's ef, or the trees' trees and checks) for a mean recall@k: on the given queries, or (None) on base points.
  py::dict tune(double recall, std::size_t k, py::object queries, const TuneParams& params) const {
    ForestTuning tuning;
    if (queries.is_none()) {
      py::gil_scoped_release unlocked;
      tuning = forest_->tune(recall, k, params);
    } else {
      const auto q = queries.cast<CArray<T>>();
      const std::size_t nq = rows(q);
      py::gil_scoped_release unlocked;
      tuning = forest_->tune(recall, k, q.data(), nq, params);
    }
    py::dict out;
    out["trees"] = tuning.trees;
    out["checks"] = tuning.checks;
    out["ef"] = tuning.ef;
    out["target_recall"] = tuning.target_recall;
    out["tuning_recall"] = tuning.tuning_recall;
    out["validation_recall"] = tuning.validation_recall;
    out["queries_per_s"] = tuning.queries_per_s;
    out["tuning_queries"] = tuning.tuning_queries;
    out["validation_queries"] = tuning.validation_queries;
    out["settings_tried"] = tuning.settings_tried;
    out["seconds"] = tuning.seconds;
    return out;
  }

 private:
  std::size_t rows(const CArray<T>& queries) const {
    rows_of(queries, forest_->dim(), "queries");
    return static_cast<std::size_t>(queries.shape(0));
  }

  static py::tuple split(const NeighborLists<T>& found, std::size_t nq, std::size_t k) {
    std::vector<T> dist(nq * k);
    std::vector<RowIndex> ids(nq * k);
    for (std::size_t i = 0; i < nq * k; ++i) {
      dist[i] = found.neighbors[i].distance;
      ids[i] = found.neighbors[i].index;
    }
    const std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(nq), static_cast<py::ssize_t>(k)};
    return py::make_tuple(take_vector(std::move(dist), shape), take_vector(std::move(ids), shape));
  }

  using RowIndex = std::int64_t;
  std::unique_ptr<PointForest<T>> forest_;
};

template <class T>
void bind_forest_index(py::module_& m, const char* name) {
  using Index = ForestIndex<T>;
  py::class_<Index>(m, name)
      .def(py::init<const py::array&, const ForestParams&>(), py::arg("rows"), py::arg("params"))
      .def_property_readonly("size", [](const Index& f) { return f.forest().size(); })
      .def_property_readonly("dim", [](const Index& f) { return f.forest().dim(); })
      .def_property_readonly("tree_count", [](const Index& f) { return f.forest().tree_count(); })
      .def_property_readonly("projected_dims", [](const Index& f) { return f.forest().projected_dims(); })
      .def_property_readonly("compact", [](const Index& f) { return f.forest().compact(); })
      .def_property_readonly("has_graph", [](const Index& f) { return f.forest().has_graph(); })
      .def_property_readonly("graph_degree", [](const Index& f) { return f.forest().graph_degree(); })
      .def_property_readonly("depth", [](const Index& f) { return f.forest().depth(); })
      .def_property_readonly("leaf_count", [](const Index& f) { return f.forest().leaf_count(); })
      .def_property_readonly("node_count", [](const Index& f) { return f.forest().node_count(); })
      .def_property_readonly("memory_bytes", [](const Index& f) { return f.forest().memory_bytes(); })
      .def_property_readonly("index_bytes", [](const Index& f) { return f.forest().index_bytes(); })
      .def("knn", &Index::knn, py::arg("queries"), py::arg("k"), py::arg("checks"), py::arg("trees"),
           py::arg("ef"), py::arg("threads"))
      .def("knn_exact", &Index::knn_exact, py::arg("queries"), py::arg("k"), py::arg("threads"))
      .def("tune", &Index::tune, py::arg("recall"), py::arg("k"), py::arg("queries"), py::arg("params"));
}

}  // namespace

void bind_forest(py::module_& m) {
  py::class_<ForestParams>(m, "ForestParams")
      .def(py::init<>())
      .def_readwrite("trees", &ForestParams::trees)
      .def_readwrite("leaf_size", &ForestParams::leaf_size)
      .def_readwrite("pca", &ForestParams::pca)
      .def_readwrite("projected_dims", &ForestParams::projected_dims)
      .def_readwrite("variance_share", &ForestParams::variance_share)
      .def_readwrite("compact", &ForestParams::compact)
      .def_readwrite("candidate_axes", &ForestParams::candidate_axes)
      .def_readwrite("seed", &ForestParams::seed)
      .def_readwrite("threads", &ForestParams::threads)
      .def_property(
          "graph",  // "auto", "on" or "off"
          [](const ForestParams& p) {
            return p.graph == GraphMode::automatic ? "auto" : p.graph == GraphMode::on ? "on" : "off";
          },
          [](ForestParams& p, const std::string& mode) {
            if (mode != "auto" && mode != "on" && mode != "off")
              throw Error("graph must be 'auto', 'on' or 'off', got '" + mode + "'");
            p.graph = mode == "auto" ? GraphMode::automatic : mode == "on" ? GraphMode::on : GraphMode::off;
          })
      .def_readwrite("graph_degree", &ForestParams::graph_degree);
  py::class_<TuneParams>(m, "TuneParams")
      .def(py::init<>())
      .def_readwrite("sample_queries", &TuneParams::sample_queries)
      .def_readwrite("max_checks", &TuneParams::max_checks)
      .def_readwrite("seed", &TuneParams::seed)
      .def_readwrite("threads", &TuneParams::threads)
      .def_readwrite("graph", &TuneParams::graph)
      .def_readwrite("trees", &TuneParams::trees);
  m.attr("unlimited_checks") = unlimited_checks;
  bind_forest_index<float>(m, "ForestIndex32");
  bind_forest_index<double>(m, "ForestIndex64");
}

}  // namespace kdspace::python
