// PointIndex<T>: the compiled core of kdspace.KDTree for one scalar type (float32 or float64 data):
// one tree built from the finite rows, searched with any p through cached copies (Searcher<T>), and
// the methods the Python layer calls, each releasing the GIL while it searches.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <deque>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/points/detail/input_checks.hpp"
#include "kdspace/points/point_tree.hpp"
#include "numpy_arrays.hpp"
#include "searcher.hpp"

namespace kdspace::python {

template <class T>
class PointIndex {
 public:
  /// Builds over `rows` (n x dim, every value finite); row_ids maps the tree's points to the caller's
  /// rows (empty: the same), n_rows is the caller's row count. boxsize (dim values, 0 = not
  /// periodic on that axis) or empty. The GIL is released while building.
  PointIndex(const CArray<T>& rows, const CArray<RowId>& row_ids, RowId n_rows, std::size_t leaf_size,
             bool balanced, const CArray<double>& boxsize) {
    if (rows.ndim() != 2) throw Error("points must be a 2-D array");
    const std::size_t n = static_cast<std::size_t>(rows.shape(0)),
                      dim = static_cast<std::size_t>(rows.shape(1));
    auto map = std::make_shared<RowMap>();
    if (row_ids.size() > 0) {
      const RowId* ids = values_of(row_ids, n, "row_ids");
      map->ids.assign(ids, ids + n);
    }
    map->missing = n_rows;
    n_rows_ = n_rows;
    BuildParams params;
    params.leaf_size = leaf_size;
    params.position = balanced ? PositionRule::median : PositionRule::sliding_midpoint;
    if (boxsize.size() > 0) {
      const double* size = values_of(boxsize, dim, "boxsize");
      join_box_.assign(size, size + dim);
      box_ = std::make_unique<PeriodicBox<double>>();
      box_->size.assign(size, size + dim);
      box_->lo.assign(dim, std::numeric_limits<double>::infinity());
      box_->hi.assign(dim, -std::numeric_limits<double>::infinity());
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t a = 0; a < dim; ++a) {
          box_->lo[a] = std::min(box_->lo[a], static_cast<double>(rows.data()[i * dim + a]));
          box_->hi[a] = std::max(box_->hi[a], static_cast<double>(rows.data()[i * dim + a]));
        }
      // The joins take the box in T, where L may round down onto a point; such a tree keeps to the
      // single-tree path.
      for (std::size_t a = 0; a < dim; ++a)
        if (size[a] > 0 && !(box_->hi[a] < static_cast<double>(static_cast<T>(size[a]))))
          join_box_ok_ = false;
    }
    const T* data = rows.data();
    py::gil_scoped_release unlocked;
    if (dim == 2)
      base_ = build<2>(data, n, dim, params, map);
    else if (dim == 3)
      base_ = build<3>(data, n, dim, params, map);
    else
      base_ = build<Dynamic>(data, n, dim, params, map);
  }

  std::size_t dim() const { return base_->dim(); }
  std::size_t node_count() const { return base_->node_count(); }

  py::tuple knn(const CArray<T>& queries, std::size_t k, double eps, double p, double upper_bound,
                unsigned threads) {
    const std::size_t nq = query_count(queries);
    auto searcher = with_metric(p);
    py::array_t<T> dist({static_cast<py::ssize_t>(nq), static_cast<py::ssize_t>(k)});
    py::array_t<RowId> rows({static_cast<py::ssize_t>(nq), static_cast<py::ssize_t>(k)});
    T* dist_out = dist.mutable_data();
    RowId* rows_out = rows.mutable_data();
    {
      py::gil_scoped_release unlocked;
      searcher->knn(queries.data(), nq, k, eps, upper_bound, options(threads), dist_out, rows_out);
    }
    return py::make_tuple(dist, rows);
  }

  py::array_t<RowId> ball_counts(const CArray<T>& queries, const CArray<double>& radii, double p,
                                 unsigned threads) {
    const std::size_t nq = query_count(queries);
    const double* r = values_of(radii, nq, "radii");
    auto searcher = with_metric(p);
    py::array_t<RowId> counts(static_cast<py::ssize_t>(nq));
    RowId* out = counts.mutable_data();
    {
      py::gil_scoped_release unlocked;
      searcher->ball_counts(queries.data(), nq, r, options(threads), out);
    }
    return counts;
  }

  /// The rows within radii[q] of each query: a 1-D NumPy array of Python lists of ints.
  py::array ball_lists(const CArray<T>& queries, const CArray<double>& radii, double p, unsigned threads,
                       bool sort_rows) {
    const auto matches = ball_matches_of(queries, radii, p, threads, sort_rows);
    py::array out = py::module_::import("numpy").attr("empty")(matches.size(), py::arg("dtype") = "object");
    auto* slots = static_cast<PyObject**>(out.mutable_data());
    for (std::size_t q = 0; q < matches.size(); ++q) {
      py::list row(matches[q].size());
      for (std::size_t j = 0; j < matches[q].size(); ++j) row[j] = py::int_(matches[q][j].row);
      Py_XDECREF(slots[q]);  // numpy.empty filled the slots with None
      slots[q] = row.release().ptr();
    }
    return out;
  }

  /// Every (query, row, distance) within radius of the queries, as three arrays ordered by query then
  /// row. With `after_query_row`, query q's answers keep only rows above query_rows[q] (each pair of
  /// one set once).
  py::tuple ball_pairs(const CArray<T>& queries, double radius, double p, unsigned threads,
                       const CArray<RowId>& query_rows, bool after_query_row) {
    const std::size_t nq = query_count(queries);
    const RowId* own = values_of(query_rows, nq, "query_rows");
    const std::vector<double> radii(nq, radius);
    const auto matches = ball_matches_of(queries, values_array(radii), p, threads, true);
    std::vector<RowId> first, second;
    std::vector<double> distance;
    for (std::size_t q = 0; q < nq; ++q)
      for (const Match& m : matches[q]) {
        if (after_query_row && m.row <= own[q]) continue;
        first.push_back(own[q]);
        second.push_back(m.row);
        distance.push_back(m.distance);
      }
    const auto count = static_cast<py::ssize_t>(first.size());
    return py::make_tuple(take_vector(std::move(first), {count}), take_vector(std::move(second), {count}),
                          take_vector(std::move(distance), {count}));
  }

  /// The pairs within r by a join (Searcher::join_pairs) of this tree with `other` (a PointIndex; None:
  /// this tree's own pairs, each once), or None where the join does not apply (p not 1, 2 or inf,
  /// other of another type or periodic box). `output`: "pairs" (rows first, second), "distances"
  /// (first, second, distance) or "lists" (for each of this set's rows, a list of other's rows,
  /// ascending).
  py::object join_pairs(py::object other, double r, double p, const std::string& output) {
    if (output != "pairs" && output != "distances" && output != "lists")
      throw Error("unknown output " + output);
    if (!joins_metric(p) || !join_box_ok_) return py::none();
    PointIndex* b = nullptr;
    if (!other.is_none() && !(b = joinable_with(other, p))) return py::none();
    auto first = with_metric(p);
    auto second = b ? b->with_metric(p) : nullptr;
    PairRows pairs;
    bool joined = false;
    {
      py::gil_scoped_release unlocked;
      joined = first->join_pairs(second.get(), r, output == "distances", join_params(), pairs);
    }
    if (!joined) return py::none();
    if (output == "lists") return row_lists(pairs);
    const auto count = static_cast<py::ssize_t>(pairs.first.size());
    py::array_t<RowId> first_rows = take_vector(std::move(pairs.first), {count});
    py::array_t<RowId> second_rows = take_vector(std::move(pairs.second), {count});
    if (output == "pairs") return py::make_tuple(first_rows, second_rows);
    return py::make_tuple(first_rows, second_rows, take_vector(std::move(pairs.distance), {count}));
  }

  /// Weighted or unweighted pair counts per bin (see Searcher::pair_histogram).
  py::array_t<double> pair_histogram(const CArray<T>& queries, py::object query_weights,
                                     const CArray<double>& radii, py::object point_weights, double p,
                                     unsigned threads) {
    const std::size_t nq = query_count(queries);
    const std::vector<double> r(radii.data(), radii.data() + radii.size());
    if (r.empty()) throw Error("no radii");
    CArray<double> qw, pw;
    if (!query_weights.is_none()) qw = query_weights.cast<CArray<double>>();
    if (!point_weights.is_none()) pw = point_weights.cast<CArray<double>>();
    const double* qwp = query_weights.is_none() ? nullptr : values_of(qw, nq, "query weights");
    const double* pwp =
        point_weights.is_none() ? nullptr : values_of(pw, static_cast<std::size_t>(n_rows_), "weights");
    auto searcher = with_metric(p);
    std::vector<double> bins(r.size());
    {
      py::gil_scoped_release unlocked;
      searcher->pair_histogram(queries.data(), qwp, nq, r, pwp, options(threads), bins.data());
    }
    return take_vector(std::move(bins), {static_cast<py::ssize_t>(r.size())});
  }

  /// The node table (see Searcher::node_table) as a dict of arrays.
  py::dict nodes() const {
    const auto count = static_cast<py::ssize_t>(base_->node_count());
    py::array_t<RowId> axis(count), start(count), end(count), lesser(count), greater(count);
    py::array_t<double> left_max(count), right_min(count);
    base_->node_table(axis.mutable_data(), start.mutable_data(), end.mutable_data(), lesser.mutable_data(),
                      greater.mutable_data(), left_max.mutable_data(), right_min.mutable_data());
    py::dict out;
    out["split_dim"] = axis;
    out["start"] = start;
    out["end"] = end;
    out["lesser"] = lesser;
    out["greater"] = greater;
    out["left_max"] = left_max;
    out["right_min"] = right_min;
    return out;
  }

  py::array_t<RowId> leaf_rows() const {
    std::vector<RowId> rows(base_->size());
    base_->leaf_rows(rows.data());
    const auto count = static_cast<py::ssize_t>(rows.size());
    return take_vector(std::move(rows), {count});
  }

 private:
  template <int Dim>
  static std::shared_ptr<const Searcher<T>> build(const T* data, std::size_t n, std::size_t dim,
                                                  const BuildParams& params,
                                                  std::shared_ptr<const RowMap> map) {
    using Tree = PointTree<T, Dim, L2>;
    return std::make_shared<TreeSearcher<Tree, T>>(Tree(data, n, dim, params), std::move(map));
  }

  // The number of query rows; every coordinate must be finite ("query row R: coordinate A ...").
  std::size_t query_count(const CArray<T>& queries) const {
    const T* rows = rows_of(queries, dim(), "queries");
    const std::size_t nq = static_cast<std::size_t>(queries.shape(0));
    detail::check_query_rows(rows, nq, dim());
    return nq;
  }

  static CArray<double> values_array(const std::vector<double>& values) {
    return CArray<double>(static_cast<py::ssize_t>(values.size()), values.data());
  }

  std::vector<std::vector<Match>> ball_matches_of(const CArray<T>& queries, const CArray<double>& radii,
                                                  double p, unsigned threads, bool sort_rows) {
    const std::size_t nq = query_count(queries);
    const double* r = values_of(radii, nq, "radii");
    auto searcher = with_metric(p);
    std::vector<std::vector<Match>> matches;
    py::gil_scoped_release unlocked;
    searcher->ball_matches(queries.data(), nq, r, sort_rows, options(threads), matches);
    return matches;
  }

  static bool joins_metric(double p) { return p == 1 || p == 2 || std::isinf(p); }

  // `other` as a PointIndex the joins can pair with this one (same scalar, same periodic box, p one
  // the joins serve), or null.
  PointIndex* joinable_with(const py::object& other, double p) {
    if (!joins_metric(p) || !join_box_ok_) return nullptr;
    if (other.is_none() || !py::isinstance<PointIndex>(other)) return nullptr;
    PointIndex* b = other.cast<PointIndex*>();
    return b->join_box_ok_ && b->join_box_ == join_box_ ? b : nullptr;
  }

  // The pair methods run on one thread, as SciPy's.
  JoinParams join_params() const {
    JoinParams params;
    params.threads = 1;
    params.boxsize = join_box_;
    return params;
  }

  // For each of the caller's rows, the list of second rows of its pairs (pairs ordered by rows).
  py::list row_lists(const PairRows& pairs) const {
    std::vector<std::size_t> sizes(static_cast<std::size_t>(n_rows_), 0);
    for (const RowId row : pairs.first) ++sizes[static_cast<std::size_t>(row)];
    py::list out(static_cast<std::size_t>(n_rows_));
    std::size_t at = 0;
    for (std::size_t row = 0; row < sizes.size(); ++row) {
      py::list found(sizes[row]);
      for (std::size_t j = 0; j < sizes[row]; ++j, ++at) found[j] = py::int_(pairs.second[at]);
      out[row] = std::move(found);
    }
    return out;
  }

  QueryOptions options(unsigned threads) const { return QueryOptions{threads, box_.get()}; }

  // The tree searched with the p-norm: the built one for p = 2, otherwise a copy made on first use
  // and kept (the last few orders asked for). Called with the GIL held, so never concurrently.
  std::shared_ptr<const Searcher<T>> with_metric(double p) {
    if (!(p >= 1))
      throw Error("Only p-norms with 1 <= p <= infinity permitted (got p = " + std::to_string(p) + ")");
    if (p == 2) return base_;
    for (const auto& [order, searcher] : copies_)
      if (order == p) return searcher;
    std::shared_ptr<const Searcher<T>> copy;
    {
      py::gil_scoped_release unlocked;
      copy = base_->with_metric(p);
    }
    copies_.emplace_back(p, copy);
    if (copies_.size() > max_copies) copies_.pop_front();
    return copy;
  }

  static constexpr std::size_t max_copies = 4;
  std::shared_ptr<const Searcher<T>> base_;
  std::deque<std::pair<double, std::shared_ptr<const Searcher<T>>>> copies_;
  std::unique_ptr<PeriodicBox<double>> box_;
  std::vector<double> join_box_;  // the box for the joins (JoinParams::boxsize); empty: none
  bool join_box_ok_ = true;       // false: the joins cannot take this tree's box (see the constructor)
  RowId n_rows_ = 0;
};

/// Registers PointIndex<T> as `name` in the module.
template <class T>
void bind_point_index(py::module_& m, const char* name) {
  py::class_<PointIndex<T>>(m, name)
      .def(
          py::init<const CArray<T>&, const CArray<RowId>&, RowId, std::size_t, bool, const CArray<double>&>(),
          py::arg("rows"), py::arg("row_ids"), py::arg("n_rows"), py::arg("leaf_size"), py::arg("balanced"),
          py::arg("boxsize"))
      .def_property_readonly("dim", &PointIndex<T>::dim)
      .def_property_readonly("node_count", &PointIndex<T>::node_count)
      .def("knn", &PointIndex<T>::knn, py::arg("queries"), py::arg("k"), py::arg("eps"), py::arg("p"),
           py::arg("upper_bound"), py::arg("threads"))
      .def("ball_counts", &PointIndex<T>::ball_counts, py::arg("queries"), py::arg("radii"), py::arg("p"),
           py::arg("threads"))
      .def("ball_lists", &PointIndex<T>::ball_lists, py::arg("queries"), py::arg("radii"), py::arg("p"),
           py::arg("threads"), py::arg("sort_rows"))
      .def("ball_pairs", &PointIndex<T>::ball_pairs, py::arg("queries"), py::arg("radius"), py::arg("p"),
           py::arg("threads"), py::arg("query_rows"), py::arg("after_query_row"))
      .def("join_pairs", &PointIndex<T>::join_pairs, py::arg("other"), py::arg("r"), py::arg("p"),
           py::arg("output"))
      .def("pair_histogram", &PointIndex<T>::pair_histogram, py::arg("queries"), py::arg("query_weights"),
           py::arg("radii"), py::arg("point_weights"), py::arg("p"), py::arg("threads"))
      .def("nodes", &PointIndex<T>::nodes)
      .def("leaf_rows", &PointIndex<T>::leaf_rows);
}

}  // namespace kdspace::python
