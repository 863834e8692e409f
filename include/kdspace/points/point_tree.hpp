// PointTree<T, Dim, Metric>: an immutable kd-tree over points, with exact and approximate k-NN,
// radius and box search, single or batched over threads.
//
// Memory: a copy of the points in leaf order (n * dim * sizeof(T)), the original index of each point
// (4 bytes a point) and the nodes (16 bytes for float, 24 for double; about 2n / leaf_size * 1.5 of
// them with median splits), in all about 4 + 5 bytes a point besides the copy for float at the
// default leaf size. memory_bytes() gives the exact figure.
//
// Exactness: every distance is computed as internal_distance() (metric.hpp) computes it, in one fixed
// order (float L2 leaf scans of 8 to 24 axes by an SSE2 kernel with the same additions,
// detail/fixed_distance.hpp), so results can be checked bit for bit against brute_force_knn(). Cells are pruned only when their
// lower bound, shrunk by a margin that covers rounding in the incremental bound, exceeds the current
// k-th distance, so rounding never loses a neighbour. The k-NN of q are the first k points in the
// order (internal distance, index): ties, at the k-th place too, go to the smaller index. For L2 the
// internal distance is the squared one, so two points whose squared distances differ by an ulp but
// share one rounded square root keep their squared order (as in brute_force_knn).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "kdspace/detail/huge_pages.hpp"
#include "kdspace/detail/storage.hpp"
#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/blocked_scan.hpp"
#include "kdspace/points/detail/builder.hpp"
#include "kdspace/points/detail/fixed_distance.hpp"
#include "kdspace/points/detail/input_checks.hpp"
#include "kdspace/points/detail/leaf_scan3.hpp"
#include "kdspace/points/detail/morton_order.hpp"
#include "kdspace/points/detail/neighbor_output.hpp"
#include "kdspace/points/detail/node.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/detail/row_bounds.hpp"
#include "kdspace/points/detail/tree_check.hpp"
#include "kdspace/points/neighbor.hpp"
#include "kdspace/points/params.hpp"

namespace kdspace {

/// Dimension chosen at run time.
inline constexpr int Dynamic = -1;

namespace detail {
template <class M, class = void>
struct is_matrix : std::false_type {};
template <class M>
struct is_matrix<M, std::void_t<decltype(std::declval<const M&>().rows()), decltype(std::declval<const M&>().cols()),
                                decltype(std::declval<const M&>()(0, 0))>> : std::true_type {};
}  // namespace detail

template <class T, int Dim = Dynamic, class Metric = L2>
class PointTree {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "PointTree holds float or double");
  static_assert(Dim == Dynamic || Dim > 0, "Dim is positive or Dynamic");

 public:
  using Scalar = T;
  using Node = detail::PointNode<T>;

  /// Builds from n points of `dim` coordinates, row-major: point i is rows[i*dim .. i*dim + dim).
  /// Throws Error for n = 0, dim = 0 (or dim != Dim), non-finite coordinates, n >= 2^30.
  /// `metric` matters only for a metric with state (Minkowski(p)).
  PointTree(const T* rows, std::size_t n, std::size_t dim, const BuildParams& params = {},
            const Metric& metric = {})
      : dim_(dim), metric_(metric) {
    validate_build(rows, n, dim, params);
    build(rows, n, params);
  }

  /// Builds from a matrix with one point per row: an Eigen matrix (either storage order) or anything
  /// with rows(), cols() and (i, j).
  template <class Matrix, class = std::enable_if_t<detail::is_matrix<Matrix>::value>>
  explicit PointTree(const Matrix& points, const BuildParams& params = {}, const Metric& metric = {})
      : dim_(static_cast<std::size_t>(points.cols())), metric_(metric) {
    const std::size_t n = static_cast<std::size_t>(points.rows());
    std::vector<T> rows(n * dim_);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t a = 0; a < dim_; ++a)
        rows[i * dim_ + a] = static_cast<T>(points(static_cast<long>(i), static_cast<long>(a)));
    validate_build(rows.data(), n, dim_, params);
    build(rows.data(), n, params);
  }

  /// The same tree searched with another metric, or held in double, or with a run-time dimension:
  /// the nodes, the leaf order and the points of `other`, copied (and widened exactly from float to
  /// double where T is double and U float); nothing is built again, so the answers are those of a
  /// tree built from the same points with the same parameters. The split positions do not depend on
  /// the metric, so one build serves L2, L1, Linf and every Minkowski order. Dim must be Dynamic or
  /// other's dimension.
  template <class U, int OtherDim, class OtherMetric>
  explicit PointTree(const PointTree<U, OtherDim, OtherMetric>& other, const Metric& metric = {})
      : dim_(other.dim()), metric_(metric) {
    static_assert(std::is_same_v<U, T> || (std::is_same_v<U, float> && std::is_same_v<T, double>),
                  "a tree is copied into the same scalar type, or widened from float to double");
    if (Dim != Dynamic && other.dim() != static_cast<std::size_t>(Dim))
      throw Error("tree of dimension " + std::to_string(other.dim()) + " copied into a tree of dimension " +
                  std::to_string(Dim));
    detail::HugePageVector<Node> nodes;
    nodes.reserve(other.nodes_.size());
    for (const auto& node : other.nodes_)
      nodes.push_back(Node{static_cast<T>(node.left_max), static_cast<T>(node.right_min), node.link, node.info});
    points_ = detail::Storage<T>::owning(detail::HugePageVector<T>(other.points_.begin(), other.points_.end()));
    order_ = detail::Storage<std::uint32_t>::owning(
        detail::HugePageVector<std::uint32_t>(other.order_.begin(), other.order_.end()));
    nodes_ = detail::Storage<Node>::owning(std::move(nodes));
    params_ = other.params_;
    root_lo_.assign(other.root_lo_.begin(), other.root_lo_.end());
    root_hi_.assign(other.root_hi_.begin(), other.root_hi_.end());
    depth_ = other.depth_;
    leaves_ = other.leaves_;
    finish_build();
  }

  /// Makes the tree of `parts` (from parts(), or loaded from an index file: io/index.hpp), after
  /// checking them whole (detail/tree_check.hpp): parts that pass answer exactly; others throw Error.
  explicit PointTree(detail::PointTreeParts<T> parts, const Metric& metric = {})
      : dim_(parts.dim), metric_(metric) {
    if (Dim != Dynamic && parts.dim != static_cast<std::size_t>(Dim))
      throw Error("point tree: dimension " + std::to_string(parts.dim) + ", this tree is built for dimension " +
                  std::to_string(Dim));
    const detail::TreeShape shape = detail::check_point_tree(parts);
    params_ = parts.params;
    points_ = std::move(parts.points);
    order_ = std::move(parts.order);
    nodes_ = std::move(parts.nodes);
    backing_ = std::move(parts.backing);
    root_lo_ = std::move(parts.root_lo);
    root_hi_ = std::move(parts.root_hi);
    depth_ = shape.depth;
    leaves_ = shape.leaves;
    finish_build();
  }

  /// The tree's arrays, borrowed (valid while the tree lives): what an index file stores.
  detail::PointTreeParts<T> parts() const {
    return {dim(), params_, detail::Storage<T>::borrow(points_.data(), points_.size()),
            detail::Storage<std::uint32_t>::borrow(order_.data(), order_.size()),
            detail::Storage<Node>::borrow(nodes_.data(), nodes_.size()), root_lo_, root_hi_, backing_};
  }

  std::size_t size() const { return order_.size(); }
  std::size_t dim() const {
    if constexpr (Dim == Dynamic) return dim_;
    else return static_cast<std::size_t>(Dim);
  }
  const Metric& metric() const { return metric_; }
  std::size_t depth() const { return depth_; }
  std::size_t leaf_count() const { return leaves_; }
  std::size_t node_count() const { return nodes_.size(); }
  /// Bytes held: points copy + index + nodes.
  /// (For a tree loaded by memory-mapping, the mapped bytes of those arrays.)
  std::size_t memory_bytes() const {
    return points_.memory_bytes() + order_.memory_bytes() + nodes_.memory_bytes();
  }
  /// Bytes held besides the copy of the points.
  std::size_t index_bytes() const { return memory_bytes() - points_.memory_bytes(); }
  const BuildParams& params() const { return params_; }

  // ---- single queries (const, thread-safe) -------------------------------------------------------

  /// The k nearest points to q (dim() coordinates) in ascending distance, ties by ascending index.
  /// 1 <= k <= size(), else Error. With params.eps > 0 the i-th result is within (1 + eps) of the
  /// true i-th distance.
  std::vector<Neighbor<T>> knn(const T* q, std::size_t k, const SearchParams& params = {},
                               QueryStats* stats = nullptr) const {
    check_k(k);
    check_search_params(params);
    check_query(q, "query");
    // A small k keeps its candidates in a vector of the thread's that never exceeds small_k
    // entries, so a query allocates only the vector it returns (a loop of 1-NN queries on kitten.xyz,
    // 4.7k points: 18% less CPU time); a large k gets a vector of its own, freed with the query.
    static thread_local std::vector<detail::Candidate<T>> small_scratch;
    std::vector<detail::Candidate<T>> large_scratch;
    auto& scratch = k <= detail::SortedKnnResults<T>::small_k ? small_scratch : large_scratch;
    QueryStats local;
    return detail::with_knn_results(k, std::numeric_limits<T>::infinity(), scratch, [&](auto& results) {
      run(q, results, params, local);
      return detail::finish_query(metric_, results.sorted(), stats, local);
    });
  }

  /// Every point within distance r of q (closed ball), ascending distance then index; r in the
  /// data's units (not squared). With max_results, the max_results nearest of them.
  std::vector<Neighbor<T>> radius(const T* q, T r, std::size_t max_results = std::numeric_limits<std::size_t>::max(),
                                  QueryStats* stats = nullptr) const {
    check_radius(r);
    check_query(q, "query");
    std::vector<detail::Candidate<T>> scratch;
    QueryStats local;
    radius_into(q, metric_.to_internal(r), max_results, scratch, local);
    return detail::finish_query(metric_, scratch, stats, local);
  }

  /// Indices of the points p with lo <= p <= hi on every axis (closed box), ascending.
  std::vector<Index> box(const T* lo, const T* hi, QueryStats* stats = nullptr) const {
    check_query(lo, "box lower corner", true);
    check_query(hi, "box upper corner", true);
    for (std::size_t a = 0; a < dim(); ++a)
      if (lo[a] > hi[a])
        throw Error("box: lower corner exceeds upper corner at coordinate " + std::to_string(a + 1) + " (" +
                    std::to_string(lo[a]) + " > " + std::to_string(hi[a]) + ")");
    std::vector<Index> found;
    QueryStats local;
    local.queries = 1;
    search_box(0, lo, hi, found, local);
    std::sort(found.begin(), found.end());
    if (stats) *stats += local;
    return found;
  }

  // ---- batches: nq queries, row-major, on `threads` threads (0 = all); same answers as one thread --

  NeighborLists<T> knn_batch(const T* queries, std::size_t nq, std::size_t k, const SearchParams& params = {},
                             unsigned threads = 0, QueryStats* stats = nullptr) const {
    check_k(k);
    check_search_params(params);
    check_queries(queries, nq);
    NeighborLists<T> out;
    // Offsets 0, k, 2k, ... (grown by push_back: GCC 12 warns falsely on a resize here, -Warray-bounds).
    // Large results in huge pages where enabled: the rows are written out of order.
    detail::reserve_in_huge_pages(out.offsets, nq + 1);
    for (std::size_t q = 1; q <= nq; ++q) out.offsets.push_back(q * k);
    detail::reserve_in_huge_pages(out.neighbors, nq * k);
    out.neighbors.resize(nq * k);
    std::vector<QueryStats> per_worker(detail::resolve_threads(threads));
    auto by_tree = [&](std::size_t first, std::size_t last) {
      const std::vector<std::size_t> visit = visit_order(queries, first, last);
      detail::parallel_for(last - first, threads, 64, [&](std::size_t begin, std::size_t end, unsigned worker) {
        std::vector<detail::Candidate<T>> scratch;
        for (std::size_t i = begin; i < end; ++i)
          detail::with_knn_results(k, std::numeric_limits<T>::infinity(), scratch, [&, q = visit[i]](auto& results) {
            run(queries + q * dim(), results, params, per_worker[worker]);
            detail::write_neighbors(metric_, results.sorted(), out.neighbors.data() + q * k);
          });
      });
    };
    const bool exact = params.eps == 0 && params.max_checks == std::numeric_limits<std::size_t>::max();
    std::size_t first_scanned = nq;  // queries from here on are answered by the scan
    if (exact && params.batch_method == BatchMethod::scan) {
      first_scanned = 0;
    } else if (exact && params.batch_method == BatchMethod::automatic && std::is_same_v<Metric, L2> &&
               nq > 2 * probe_queries) {
      // The first queries by the tree; the share of the points they scored decides the rest.
      // Always the same queries, so the choice does not depend on the thread count.
      by_tree(0, probe_queries);
      QueryStats probe;
      detail::sum_stats(per_worker, &probe);
      const double scored = static_cast<double>(probe.points_visited) / static_cast<double>(probe_queries * size());
      first_scanned = scored >= scan_switch_fraction ? probe_queries : nq;
      if (first_scanned == nq) by_tree(probe_queries, nq);
    } else {
      by_tree(0, nq);
    }
    if (first_scanned < nq) scan_batch(queries, first_scanned, nq, k, out.neighbors.data(), threads, per_worker);
    detail::sum_stats(per_worker, stats);
    return out;
  }

  NeighborLists<T> radius_batch(const T* queries, std::size_t nq, T r,
                                std::size_t max_results = std::numeric_limits<std::size_t>::max(),
                                unsigned threads = 0, QueryStats* stats = nullptr) const {
    check_radius(r);
    check_queries(queries, nq);
    const T limit = metric_.to_internal(r);
    std::vector<std::vector<Neighbor<T>>> rows(nq);
    std::vector<QueryStats> per_worker(detail::resolve_threads(threads));
    const std::vector<std::size_t> visit = visit_order(queries, 0, nq);
    detail::parallel_for(nq, threads, 64, [&](std::size_t begin, std::size_t end, unsigned worker) {
      std::vector<detail::Candidate<T>> scratch;
      for (std::size_t i = begin; i < end; ++i) {
        const std::size_t q = visit[i];
        radius_into(queries + q * dim(), limit, max_results, scratch, per_worker[worker]);
        rows[q].resize(scratch.size());
        detail::write_neighbors(metric_, scratch, rows[q].data());
      }
    });
    NeighborLists<T> out;
    out.offsets.resize(nq + 1);
    for (std::size_t q = 0; q < nq; ++q) out.offsets[q + 1] = out.offsets[q] + rows[q].size();
    out.neighbors.reserve(out.offsets[nq]);
    for (auto& row : rows) out.neighbors.insert(out.neighbors.end(), row.begin(), row.end());
    detail::sum_stats(per_worker, stats);
    return out;
  }

  /// One query with the caller's result set, the one place that decides what a query keeps (as
  /// detail::KnnResults and detail::RangeResults do for knn and radius). The traversal offers every
  /// point it scores, as results.offer(internal distance, original index), and skips every cell whose
  /// lower bound exceeds results.bound(); once results.full(), a check budget (params.max_checks) may
  /// end it. Internal distances are the metric's (squared for L2): metric().to_internal(r) converts a
  /// radius. In a leaf of identical points one distance is offered for each point in ascending index
  /// order until offer() returns false, so offer() must refuse the rest once it refuses one there.
  template <class Results>
  void query_with(const T* q, Results& results, const SearchParams& params = {}, QueryStats* stats = nullptr) const {
    check_search_params(params);
    check_query(q, "query");
    QueryStats local;
    run(q, results, params, local);
    if (stats) *stats += local;
  }

  /// Nodes in depth-first order (read-only; for tools and tests).
  const detail::Storage<Node>& nodes() const { return nodes_; }
  /// The original index of each point in leaf order: a leaf holds leaf_order()[first, first + count).
  const detail::Storage<Index>& leaf_order() const { return order_; }
  /// The points in leaf order (row-major; a leaf holds rows [first, first + count)): with nodes()
  /// and leaf_order(), what a traversal outside the tree (the dual-tree joins) reads.
  const detail::Storage<T>& points_in_leaf_order() const { return points_; }

 private:
  // ---- validation ---------------------------------------------------------------------------------

  // The checks that need no pass over the points; build() finds any non-finite coordinate in the
  // pass that takes the bounds.
  void validate_build(const T* rows, std::size_t n, std::size_t dim, const BuildParams& params) const {
    if (Dim != Dynamic && dim != 0 && dim != static_cast<std::size_t>(Dim))
      throw Error("points have dimension " + std::to_string(dim) + ", this tree is built for dimension " +
                  std::to_string(Dim));
    if (params.leaf_size == 0) throw Error("leaf_size must be at least 1");
    if (params.max_depth > 256) throw Error("max_depth must be at most 256, got " + std::to_string(params.max_depth));
    detail::check_points(rows, n, dim, /*check_values=*/false);
  }

  void check_k(std::size_t k) const { detail::check_k(k, size()); }

  static void check_radius(T r) {
    if (std::isnan(r) || r < 0) throw Error("radius must be a non-negative number, got " + std::to_string(r));
  }

  static void check_search_params(const SearchParams& p) {
    if (!(p.eps >= 0) || std::isinf(p.eps)) throw Error("eps must be a finite number >= 0, got " + std::to_string(p.eps));
    if (p.max_checks == 0) throw Error("max_checks must be at least 1");
  }

  // Queries must be finite; a box corner may also be infinite (an open side) but never NaN.
  void check_query(const T* q, const std::string& what, bool allow_infinite = false) const {
    if (q == nullptr) throw Error(what + ": null pointer");
    for (std::size_t a = 0; a < dim(); ++a) {
      const bool ok = allow_infinite ? !std::isnan(q[a]) : std::isfinite(q[a]);
      if (!ok) throw Error(what + ": coordinate " + std::to_string(a + 1) + " is not finite (" + std::to_string(q[a]) + ")");
    }
  }

  void check_queries(const T* queries, std::size_t nq) const { detail::check_query_rows(queries, nq, dim()); }

  // ---- build ------------------------------------------------------------------------------------

  template <class, int, class>
  friend class PointTree;  // the copying constructor reads another instantiation's arrays

  void build(const T* rows, std::size_t n, const BuildParams& params) {
    const std::size_t d = dim();
    root_lo_.assign(rows, rows + d);
    root_hi_.assign(rows, rows + d);
    if (detail::widen_bounds<Dim, true>(rows, n, d, root_lo_.data(), root_hi_.data()) != 0)
      detail::check_points(rows, n, d);  // a coordinate is not finite: find it for the message
    detail::BuiltTree<T> built = detail::with_split_rules(params, [&](auto axis_rule, auto position_rule) {
      using Builder = detail::Builder<T, Dim, decltype(axis_rule), decltype(position_rule)>;
      return Builder(rows, n, d, params).build(root_lo_.data(), root_hi_.data());
    });
    built.nodes.shrink_to_fit();
    nodes_ = detail::Storage<Node>::owning(std::move(built.nodes));
    points_ = detail::Storage<T>::owning(std::move(built.points));
    order_ = detail::Storage<std::uint32_t>::owning(std::move(built.order));
    params_ = params;
    depth_ = built.depth;
    leaves_ = built.leaves;
    finish_build();
  }

  // What follows from the nodes and the bounds: the scan's origin and the pruning margin.
  void finish_build() {
    const std::size_t d = dim();
    centre_.resize(d);
    for (std::size_t a = 0; a < d; ++a) centre_[a] = root_lo_[a] / 2 + root_hi_[a] / 2;  // no overflow
    // A cell's computed lower bound may exceed the exact one by rounding (a few ulps per axis and per
    // level; std::pow in Minkowski's terms is within an ulp, like a product); pruning against
    // bound * prune_margin_ keeps every cell that could hold a tie.
    prune_margin_ = T(1) - T(4) * T(d + 2 * depth_ + 8) * std::numeric_limits<T>::epsilon();
  }

  // ---- search -----------------------------------------------------------------------------------

  // Per-query scratch for the per-axis contributions of the cell bound; on the stack up to 64 axes.
  struct AxisTerms {
    T local[64];
    std::vector<T> heap;
    T* data;
    explicit AxisTerms(std::size_t d) : data(local) {
      if (d > 64) heap.resize(d), data = heap.data();
    }
  };

  struct Context {
    const T* q;
    T* axis_terms;  // contribution of each axis to the current cell bound
    T prune_scale;  // bound * prune_scale > kept distance => prune
    std::uint64_t checks_end;  // stop looking further once points_visited reaches this
    std::uint64_t nodes_visited, points_visited;  // this query's counts, from the stats' totals
  };

  template <class Results>
  void run(const T* q, Results& results, const SearchParams& params, QueryStats& stats) const {
    AxisTerms terms(dim());
    T bound = 0;
    for (std::size_t a = 0; a < dim(); ++a) {
      const T diff = q[a] < root_lo_[a] ? root_lo_[a] - q[a] : (q[a] > root_hi_[a] ? q[a] - root_hi_[a] : T(0));
      terms.data[a] = metric_.term(diff);
      bound = metric_.accumulate(bound, terms.data[a]);
    }
    // (1 + eps) in internal units, worked out in double: a huge eps becomes infinity, never UB.
    const double eps_scale_wide = metric_.to_internal(1.0 + params.eps);
    const T eps_scale = eps_scale_wide > static_cast<double>(std::numeric_limits<T>::max())
                            ? std::numeric_limits<T>::infinity()
                            : static_cast<T>(eps_scale_wide);
    const std::uint64_t checks_end = params.max_checks > UINT64_MAX - stats.points_visited
                                         ? UINT64_MAX
                                         : stats.points_visited + params.max_checks;
    Context ctx{q, terms.data, prune_margin_ * eps_scale, checks_end, stats.nodes_visited, stats.points_visited};
    ++stats.queries;
    if (!(bound * ctx.prune_scale > results.bound())) search(0, bound, ctx, results);
    stats.nodes_visited = ctx.nodes_visited;
    stats.points_visited = ctx.points_visited;
  }

  // Depth first, the nearer child first, with the incremental cell bound of Arya & Mount: a far
  // child's bound differs from its parent's in one axis's term only. (An explicit stack in place of
  // the recursion measured 3-7% slower on 3-D scans: the recursion keeps the path in registers.)
  template <class Results>
  void search(std::uint32_t id, T bound, Context& ctx, Results& results) const {
    const Node& node = nodes_[id];
    ++ctx.nodes_visited;
    if (node.is_leaf()) {
      scan_leaf(node, ctx, results);
      return;
    }
    const std::uint32_t axis = node.axis();
    const T x = ctx.q[axis];
    const T to_left = x - node.left_max;    // > 0: q lies beyond the left subtree
    const T to_right = node.right_min - x;  // > 0: q lies before the right subtree
    const bool left_first = to_left <= to_right;
    const std::uint32_t near = left_first ? id + 1 : node.right_child();
    const std::uint32_t far = left_first ? node.right_child() : id + 1;
    const T far_gap = left_first ? to_right : to_left;  // >= 0, as left_max <= right_min

    search(near, bound, ctx, results);

    const T old_term = ctx.axis_terms[axis];
    const T new_term = metric_.term(far_gap);
    const T far_bound = metric_.replace(bound, old_term, new_term);
    if (far_bound * ctx.prune_scale > results.bound()) return;
    // The check budget ends the search only once k candidates are in hand.
    if (ctx.points_visited >= ctx.checks_end && results.full()) return;
    ctx.axis_terms[axis] = new_term;
    search(far, far_bound, ctx, results);
    ctx.axis_terms[axis] = old_term;
  }

  // Under L2 a run-time dimension from 2 to 8 scans its leaves with the dimension as a constant, so
  // that the distance loop unrolls as in a compile-time tree: a switch per leaf, which the branch
  // predictor learns at once. A PointTree<float> of 2..8-D points then answers as fast as
  // PointTree<float, D> (within 5%, where it was 8-18% slower); L1 and Linf keep their code small.
  // Float from 9 to 24 axes the same, in scan_leaf_wide, with l2_distance_fixed as the distance.
  template <class Results>
  void scan_leaf(const Node& leaf, Context& ctx, Results& results) const {
    if constexpr (Dim == Dynamic && std::is_same_v<Metric, L2>) {
      switch (dim_) {
        case 2: return scan_leaf_as<2>(leaf, ctx, results);
        case 3: return scan_leaf_as<3>(leaf, ctx, results);
        case 4: return scan_leaf_as<4>(leaf, ctx, results);
        case 5: return scan_leaf_as<5>(leaf, ctx, results);
        case 6: return scan_leaf_as<6>(leaf, ctx, results);
        case 7: return scan_leaf_as<7>(leaf, ctx, results);
        case 8: return scan_leaf_as<8>(leaf, ctx, results);
        default: break;
      }
      if constexpr (std::is_same_v<T, float>)
        if (dim_ > distance_lanes && dim_ <= wide_scan_dims) return scan_leaf_wide(leaf, ctx, results);
    }
    scan_leaf_as<Dim>(leaf, ctx, results);
  }

  // The most axes of a float tree whose leaf scan has a compile-time dimension (scan_leaf_wide).
  static constexpr std::size_t wide_scan_dims = 24;
  // 9 to 24 axes (descriptors: MFCC 13 and 20, 16-bin histograms), out of the search's line: in the
  // same switch they grew the search, and the 3-D queries ran 0.6% more instructions (armadillo 1-NN,
  // callgrind); the call a leaf costs the 13-D queries 6% more instructions and about 3% of their time.
  template <class Results>
  [[gnu::noinline]] void scan_leaf_wide(const Node& leaf, Context& ctx, Results& results) const {
    switch (dim_) {
      case 9: return scan_leaf_as<9>(leaf, ctx, results);
      case 10: return scan_leaf_as<10>(leaf, ctx, results);
      case 11: return scan_leaf_as<11>(leaf, ctx, results);
      case 12: return scan_leaf_as<12>(leaf, ctx, results);
      case 13: return scan_leaf_as<13>(leaf, ctx, results);
      case 14: return scan_leaf_as<14>(leaf, ctx, results);
      case 15: return scan_leaf_as<15>(leaf, ctx, results);
      case 16: return scan_leaf_as<16>(leaf, ctx, results);
      case 17: return scan_leaf_as<17>(leaf, ctx, results);
      case 18: return scan_leaf_as<18>(leaf, ctx, results);
      case 19: return scan_leaf_as<19>(leaf, ctx, results);
      case 20: return scan_leaf_as<20>(leaf, ctx, results);
      case 21: return scan_leaf_as<21>(leaf, ctx, results);
      case 22: return scan_leaf_as<22>(leaf, ctx, results);
      case 23: return scan_leaf_as<23>(leaf, ctx, results);
      case 24: return scan_leaf_as<24>(leaf, ctx, results);
      default: return scan_leaf_as<Dim>(leaf, ctx, results);
    }
  }

  // The distance of the leaf scan: internal_distance(), or the same bits from the SSE2 kernel for a
  // compile-time dimension of float L2 points from 8 axes on (fixed_distance.hpp: 34 instructions a
  // 13-D point where internal_distance took 66; mfcc13 1-NN batches 1.25x the queries a second).
  template <int D>
  T leaf_distance(const T* q, const T* p, std::size_t d) const {
    if constexpr (D >= static_cast<int>(distance_lanes) && std::is_same_v<T, float> && std::is_same_v<Metric, L2>)
      return detail::l2_distance_fixed<static_cast<std::size_t>(D)>(q, p);
    else
      return internal_distance(metric_, q, p, d);
  }

  // 3-D float points under L2: four at a time (detail/leaf_scan3.hpp), the same distances.
  template <int D>
  static constexpr bool scans_four_at_once =
#if defined(__SSE2__)
      D == 3 && std::is_same_v<T, float> && std::is_same_v<Metric, L2>;
#else
      false;
#endif

  // The distances from q to a leaf's `count` points at p, into dist: four at a time where it can.
  template <int D>
  void leaf_distances(const T* q, const T* p, std::size_t count, std::size_t d, T* dist) const {
    if constexpr (scans_four_at_once<D>)
      if (count >= 4) return detail::l2_distances3(q, p, count, dist);
    for (std::size_t i = 0; i < count; ++i, p += d) dist[i] = leaf_distance<D>(q, p, d);
  }

  template <int D, class Results>
  void scan_leaf_as(const Node& leaf, Context& ctx, Results& results) const {
    const std::size_t d = D > 0 ? static_cast<std::size_t>(D) : dim();
    const std::size_t first = leaf.first(), count = leaf.count();
    const T* p = points_.data() + first * d;
    if (leaf.all_identical()) {
      // One distance serves all; the indices are ascending, so the first refusal ends the scan.
      const T dist = leaf_distance<D>(ctx.q, p, d);
      ++ctx.points_visited;
      for (std::size_t i = 0; i < count; ++i)
        if (!results.offer(dist, order_[first + i])) break;
      return;
    }
    ctx.points_visited += count;
    if constexpr (detail::fills_at_once<Results>) {
      if (results.empty() && count <= Results::max_fill) {
        T dist[Results::max_fill];
        leaf_distances<D>(ctx.q, p, count, d, dist);
        results.fill(dist, order_.data() + first, count);
        return;
      }
    }
    if constexpr (scans_four_at_once<D>) {
      if (count >= 4) return detail::scan_leaf3_l2(ctx.q, p, order_.data() + first, count, results);
    }
    // Most points are farther than the k-th kept: a comparison with the bound turns them away before
    // the result set (and the original index) is touched. A tie with the bound may still enter.
    T worst = results.bound();
    for (std::size_t i = 0; i < count; ++i, p += d) {
      const T dist = leaf_distance<D>(ctx.q, p, d);
      if (dist <= worst) {
        results.offer(dist, order_[first + i]);
        worst = results.bound();
      }
    }
  }

  void radius_into(const T* q, T limit, std::size_t max_results, std::vector<detail::Candidate<T>>& out,
                   QueryStats& stats) const {
    if (max_results < size()) {
      if (max_results == 0) {
        out.clear();
        ++stats.queries;
        return;
      }
      detail::with_knn_results(max_results, limit, out, [&](auto& results) {
        run(q, results, SearchParams{}, stats);
        results.sorted();
      });
    } else {
      detail::RangeResults<T> results(limit, out);
      run(q, results, SearchParams{}, stats);
      results.sorted();
    }
  }

  // Queries [first, last) by scoring every point (BatchMethod::scan), spread over threads.
  void scan_batch(const T* queries, std::size_t first, std::size_t last, std::size_t k, Neighbor<T>* out,
                  unsigned threads, std::vector<QueryStats>& per_worker) const {
    const std::size_t d = dim();
    // One call of the scan per thread (at least 64 queries a call): each call converts every point
    // once, so small calls would repeat that work.
    const std::size_t workers = detail::resolve_threads(threads);
    const std::size_t chunk = std::max<std::size_t>(64, (last - first + workers - 1) / workers);
    detail::parallel_for(last - first, threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      const std::size_t q0 = first + begin, count = end - begin;
      if constexpr (std::is_same_v<Metric, L2>) {
        const detail::ScanData<T> data{points_.data(), order_.data(), size(), d, centre_.data()};
        detail::blocked_scan_knn_l2(data, queries + q0 * d, count, k, out + q0 * k);
      } else {
        std::vector<detail::Candidate<T>> scratch;
        for (std::size_t q = q0; q < q0 + count; ++q) {
          detail::KnnResults<T> results(k, std::numeric_limits<T>::infinity(), scratch);
          const T* p = points_.data();
          for (std::size_t i = 0; i < size(); ++i, p += d)
            results.offer(internal_distance(metric_, queries + q * d, p, d), order_[i]);
          detail::write_neighbors(metric_, results.sorted(), out + q * k);
        }
      }
      per_worker[worker].queries += count;
      per_worker[worker].points_visited += count * size();
    });
  }

  void search_box(std::uint32_t id, const T* lo, const T* hi, std::vector<Index>& found, QueryStats& stats) const {
    const Node& node = nodes_[id];
    ++stats.nodes_visited;
    if (node.is_leaf()) {
      const std::size_t first = node.first(), count = node.count();
      const T* p = points_.data() + first * dim();
      stats.points_visited += node.all_identical() ? 1 : count;
      for (std::size_t i = 0; i < count; ++i, p += dim()) {
        bool inside = true;
        for (std::size_t a = 0; a < dim() && inside; ++a) inside = lo[a] <= p[a] && p[a] <= hi[a];
        if (inside) found.push_back(order_[first + i]);
        else if (node.all_identical()) return;
      }
      return;
    }
    const std::uint32_t axis = node.axis();
    if (lo[axis] <= node.left_max) search_box(id + 1, lo, hi, found, stats);
    if (hi[axis] >= node.right_min) search_box(node.right_child(), lo, hi, found, stats);
  }

  // The queries [first, last) of a batch in the order a batch visits them, so that consecutive
  // queries search the same part of the tree: the descent's branches are then predicted and its
  // nodes and points found in cache. Answered in any order a query's answer is the same; only the
  // time differs. Up to morton_max_dim dimensions the order is the Z-order of the queries' cells in
  // the tree's bounds (detail/morton_order.hpp): linear work, no descent. Measured (CPU time, one
  // thread, held-out queries in random order, busy machine) on real 3-D scans, where the tree fits
  // in the caches and the branches are the cost: 1-NN batches 1.2-1.4x the queries a second of the
  // given order on building (90k points) and armadillo (23k), 10-NN 1.0-1.2x; none on kitten (4.7k
  // points, 521 queries), whose repeated batch the branch predictor learns. On uniform 3-D points
  // (a tenth held out) 1.5-1.7x for 1-NN and 1.3-1.4x for 10-NN at 2e5 points over the given order,
  // 1.5x and 1.24x at 1e6 over the leaf order that follows.
  // Beyond 8-D the key is the leaf each query's descent reaches. It costs a descent per query, a
  // small part of a query that scores hundreds of points in dozens of leaves, and it pays whatever
  // the tree's size: on 13-D MFCC frames (synthetic audio, queries shuffled, one thread, busy
  // machine) 1-NN batches 1.34x, 1.33x, 1.31x and 1.31x the queries a second of the shuffled order
  // at 5k, 20k, 50k and 100k points (trees of 0.3 to 6 MB, so not the caches: the branches), 10-NN
  // 1.26-1.30x. (It used to wait for trees of 8 MB, a threshold measured on 3-D points before the
  // Z-order, which left 100k points of 13-D or 16-D in the given order.) Small batches keep their order.
  std::vector<std::size_t> visit_order(const T* queries, std::size_t first, std::size_t last) const {
    std::vector<std::size_t> visit(last - first);
    if (last - first < locality_batch || last > UINT32_MAX) {
      for (std::size_t i = 0; i < visit.size(); ++i) visit[i] = first + i;
      return visit;
    }
    if (dim() <= detail::morton_max_dim)
      return detail::morton_order(queries, first, last, dim(), root_lo_.data(), root_hi_.data());
    std::vector<std::uint64_t> keyed(last - first);  // leaf node id, then the query's number
    for (std::size_t q = first; q < last; ++q) {
      const T* x = queries + q * dim();
      std::uint32_t id = 0;
      while (!nodes_[id].is_leaf()) {
        const Node& node = nodes_[id];
        const T at = x[node.axis()];
        id = at - node.left_max <= node.right_min - at ? id + 1 : node.right_child();  // as search() goes first
      }
      keyed[q - first] = (std::uint64_t{id} << 32) | q;
    }
    std::sort(keyed.begin(), keyed.end());
    for (std::size_t i = 0; i < visit.size(); ++i) visit[i] = static_cast<std::uint32_t>(keyed[i]);  // low half: q
    return visit;
  }
  static constexpr std::size_t locality_batch = 256;  // batches from this size on are reordered

  // Queries of a batch the tree answers before BatchMethod::automatic chooses.
  static constexpr std::size_t probe_queries = 16;

  std::size_t dim_;
  Metric metric_;
  // Owned, or borrowed from a mapped index file that backing_ keeps alive.
  detail::Storage<T> points_;             // leaf-ordered copy, row-major
  detail::Storage<std::uint32_t> order_;  // original index of each leaf-ordered point
  detail::Storage<Node> nodes_;           // depth first; nodes_[0] is the root
  std::shared_ptr<const void> backing_;
  BuildParams params_;
  std::vector<T> root_lo_, root_hi_;  // bounds of all points
  std::vector<T> centre_;             // middle of those bounds: the origin of the blocked scan
  std::size_t depth_ = 0;
  std::size_t leaves_ = 0;
  T prune_margin_ = 1;
};

}  // namespace kdspace

// The common instantiations are compiled once in the library, in three files so that a parallel
// build shares them out (lib/points/instances_float.cpp, instances_double.cpp, instances_fixed.cpp).
namespace kdspace {
#define KDSPACE_POINT_TREE_INSTANCES_FLOAT(PREFIX) \
  PREFIX class PointTree<float, Dynamic, L2>;      \
  PREFIX class PointTree<float, Dynamic, L1>;      \
  PREFIX class PointTree<float, Dynamic, Linf>;
#define KDSPACE_POINT_TREE_INSTANCES_DOUBLE(PREFIX) \
  PREFIX class PointTree<double, Dynamic, L2>;      \
  PREFIX class PointTree<double, Dynamic, L1>;      \
  PREFIX class PointTree<double, Dynamic, Linf>;    \
  PREFIX class PointTree<double, Dynamic, Minkowski>;
#define KDSPACE_POINT_TREE_INSTANCES_FIXED(PREFIX) \
  PREFIX class PointTree<float, 2, L2>;            \
  PREFIX class PointTree<float, 3, L2>;            \
  PREFIX class PointTree<double, 2, L2>;           \
  PREFIX class PointTree<double, 3, L2>;
#define KDSPACE_POINT_TREE_INSTANCES(PREFIX) \
  KDSPACE_POINT_TREE_INSTANCES_FLOAT(PREFIX) \
  KDSPACE_POINT_TREE_INSTANCES_DOUBLE(PREFIX) \
  KDSPACE_POINT_TREE_INSTANCES_FIXED(PREFIX)
KDSPACE_POINT_TREE_INSTANCES(extern template)
}  // namespace kdspace
