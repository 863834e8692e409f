// PointForest: the build (principal directions, projection, randomized trees) and the best-bin-first
// search over all trees. The design is described at the top of include/kdspace/points/point_forest.hpp.
#include "kdspace/points/point_forest.hpp"

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <type_traits>

#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/input_checks.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/detail/row_distances.hpp"
#include "forest_scratch.hpp"
#include "key_select.hpp"

namespace kdspace {
namespace {

using RowMatrixd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// The generator of tree t: seeded from (seed, t) so each tree's draws do not depend on the others
/// or on the thread that builds it.
std::mt19937_64 tree_generator(std::uint64_t seed, std::size_t tree) {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(tree), 0x6b64u};
  return std::mt19937_64(seq);
}

/// Builds one tree over the projected coordinates `proj` (n rows of m floats).
class TreeBuilder {
 public:
  template <class Node>
  struct Result {
    std::vector<Node> nodes;
    std::vector<std::uint32_t> order;
    std::size_t depth = 0;
    std::size_t leaves = 0;
  };

  TreeBuilder(const float* proj, std::size_t n, std::size_t m, const ForestParams& params, std::size_t tree)
      : proj_(proj), n_(n), m_(m), params_(params), rng_(tree_generator(params.seed, tree)),
        variance_(m), axes_(m), axes_sum_(m), axes_squares_(m) {}

  template <class Node>
  Result<Node> build() {
    Result<Node> out;
    out.order.resize(n_);
    std::iota(out.order.begin(), out.order.end(), 0u);
    out.nodes.reserve(2 * n_ / std::max<std::size_t>(1, params_.leaf_size) + 1);
    split(out, 0, n_, 0);
    return out;
  }

 private:
  float coord(std::uint32_t row, std::size_t axis) const { return proj_[row * m_ + axis]; }
  /// The bits of a float (not NaN), as an integer that orders as the floats do (-0 below +0).
  static std::uint32_t ordered_bits(float x) {
    std::uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    return bits & 0x80000000u ? ~bits : bits | 0x80000000u;
  }
  static float from_ordered_bits(std::uint32_t bits) {
    bits = bits & 0x80000000u ? bits & 0x7fffffffu : ~bits;
    float x;
    std::memcpy(&x, &bits, sizeof x);
    return x;
  }

  template <class Node>
  void make_leaf(Result<Node>& out, std::size_t first, std::size_t last, std::size_t depth) {
    out.nodes.push_back(Node{0, 0, static_cast<std::uint32_t>(first), Node::leaf_bit | static_cast<std::uint32_t>(last - first)});
    out.leaves += 1;
    out.depth = std::max(out.depth, depth);
  }

  // The split axis of the node [first, last): drawn among the axes of largest variance on a sample
  // of its points; if the sample shows no variance, the axis of largest spread over all of them.
  // Returns m_ when every axis is flat (the node becomes a leaf).
  std::size_t choose_axis(const std::uint32_t* rows, std::size_t count) {
    const std::size_t sample = std::min(count, params_.variance_sample);
    // One pass over the sample, in float, over each row's axes at once (a loop the compiler turns
    // into vector instructions): sums and sums of squares of the offsets from the sample's first
    // point, which keep the cancellation of sum_sq - sum^2 / s small. The variances only order the
    // axes and mark the flat ones (0; an overflow of the float sums reads as infinite, or, past
    // about 1e36, as flat, which costs the tree quality, not the answers). Two passes in double took
    // 7% of the instructions of the whole build (graph included) on 95k music frames.
    float* const sum = axes_sum_.data();
    float* const squares = axes_squares_.data();
    const float* const origin = proj_ + std::size_t{rows[0]} * m_;
    std::fill(axes_sum_.begin(), axes_sum_.end(), 0.f);
    std::fill(axes_squares_.begin(), axes_squares_.end(), 0.f);
    for (std::size_t s = 1; s < sample; ++s) {
      const float* const x = proj_ + std::size_t{rows[s * count / sample]} * m_;
      for (std::size_t a = 0; a < m_; ++a) {
        const float d = x[a] - origin[a];
        sum[a] += d;
        squares[a] += d * d;
      }
    }
    for (std::size_t a = 0; a < m_; ++a)
      variance_[a] = std::max(0.0, static_cast<double>(squares[a]) -
                                       static_cast<double>(sum[a]) * sum[a] / static_cast<double>(sample));
    std::iota(axes_.begin(), axes_.end(), std::size_t{0});
    const std::size_t candidates = std::min(params_.candidate_axes, m_);
    std::partial_sort(axes_.begin(), axes_.begin() + static_cast<long>(candidates), axes_.end(),
                      [&](std::size_t a, std::size_t b) { return variance_[a] > variance_[b] || (variance_[a] == variance_[b] && a < b); });
    std::size_t usable = 0;
    while (usable < candidates && variance_[axes_[usable]] > 0) ++usable;
    if (usable > 0) return axes_[std::uniform_int_distribution<std::size_t>(0, usable - 1)(rng_)];
    // The sample is flat: look at every point.
    std::size_t best = m_;
    float best_spread = 0;
    for (std::size_t a = 0; a < m_; ++a) {
      float lo = coord(rows[0], a), hi = lo;
      for (std::size_t i = 1; i < count; ++i) {
        lo = std::min(lo, coord(rows[i], a));
        hi = std::max(hi, coord(rows[i], a));
      }
      if (hi - lo > best_spread) best_spread = hi - lo, best = a;
    }
    return best;
  }

  template <class Node>
  void split(Result<Node>& out, std::size_t first, std::size_t last, std::size_t depth) {
    const std::size_t count = last - first;
    std::uint32_t* rows = out.order.data() + first;
    if (count <= params_.leaf_size) return make_leaf(out, first, last, depth);
    const std::size_t axis = choose_axis(rows, count);
    if (axis == m_) return make_leaf(out, first, last, depth);  // all projected points coincide
    // The lower half by the coordinate, ties by row: each point as one key, the coordinate's bits
    // (made to order as unsigned integers do) above the row, selected without branches on the keys
    // (key_select.hpp; std::nth_element's compares were mispredicted about half of the time).
    const std::size_t mid = count / 2;
    if (keys_.size() < count) keys_.resize(count);
    std::uint64_t* const keys = keys_.data();
    for (std::size_t i = 0; i < count; ++i) keys[i] = std::uint64_t{ordered_bits(coord(rows[i], axis))} << 32 | rows[i];
    detail::select_smallest(keys, count, mid);
    std::uint64_t left_max_key = 0, right_min_key = ~std::uint64_t{0};
    for (std::size_t i = 0; i < mid; ++i) left_max_key = std::max(left_max_key, keys[i]);
    for (std::size_t i = mid; i < count; ++i) right_min_key = std::min(right_min_key, keys[i]);
    for (std::size_t i = 0; i < count; ++i) rows[i] = static_cast<std::uint32_t>(keys[i]);
    // Equal coordinates may straddle the median; the split is at mid either way, and the bounds
    // are the true ones, so the children's slabs may touch but are correct.
    const float left_max = from_ordered_bits(static_cast<std::uint32_t>(left_max_key >> 32));
    const float right_min = from_ordered_bits(static_cast<std::uint32_t>(right_min_key >> 32));
    const std::size_t id = out.nodes.size();
    out.nodes.push_back(Node{left_max, right_min, 0, static_cast<std::uint32_t>(axis)});
    split(out, first, first + mid, depth + 1);
    out.nodes[id].link = static_cast<std::uint32_t>(out.nodes.size());
    split(out, first + mid, last, depth + 1);
  }

  const float* proj_;
  std::size_t n_, m_;
  const ForestParams& params_;
  std::mt19937_64 rng_;
  std::vector<double> variance_;
  std::vector<std::size_t> axes_;
  std::vector<float> axes_sum_, axes_squares_;
  std::vector<std::uint64_t> keys_;
};

/// Whether every coordinate is an integer from 0 to 255 (so that a byte holds it exactly).
template <class U>
bool byte_valued(const U* rows, std::size_t count) {
  if constexpr (std::is_same_v<U, std::uint8_t>) return true;
  for (std::size_t i = 0; i < count; ++i)
    if (!(rows[i] >= 0 && rows[i] <= 255 && rows[i] == std::floor(rows[i]))) return false;
  return true;
}

void check_params(const ForestParams& p) {
  if (p.trees == 0) throw Error("forest: trees must be at least 1");
  if (p.trees > 1024) throw Error("forest: at most 1024 trees, got " + std::to_string(p.trees));
  if (p.leaf_size == 0) throw Error("forest: leaf_size must be at least 1");
  if (p.pca && p.projected_dims > 64)
    throw Error("forest: projected_dims must be at most 64, got " + std::to_string(p.projected_dims));
  if (!(p.variance_share > 0 && p.variance_share <= 1))
    throw Error("forest: variance_share must be in (0, 1], got " + std::to_string(p.variance_share));
  if (p.candidate_axes == 0) throw Error("forest: candidate_axes must be at least 1");
  if (p.variance_sample < 2) throw Error("forest: variance_sample must be at least 2");
  if (p.pca && p.pca_sample < 2) throw Error("forest: pca_sample must be at least 2");
  if (p.graph_degree < 2 || p.graph_degree > 1024)
    throw Error("forest: graph_degree must be in 2..1024, got " + std::to_string(p.graph_degree));
  if (!(p.graph_alpha >= 1 && p.graph_alpha <= 16))
    throw Error("forest: graph_alpha must be in [1, 16], got " + std::to_string(p.graph_alpha));
}

}  // namespace

template <class T>
PointForest<T>::PointForest(const T* rows, std::size_t n, std::size_t dim, const ForestParams& params)
    : dim_(dim), params_(params) {
  build(rows, n, dim, params);
}

template <class T>
PointForest<T>::PointForest(const std::uint8_t* rows, std::size_t n, std::size_t dim, const ForestParams& params)
    : dim_(dim), params_(params) {
  build(rows, n, dim, params);
}

template <class T>
template <class U>
void PointForest<T>::build(const U* rows, std::size_t n, std::size_t dim, const ForestParams& params) {
  check_params(params);
  detail::check_points(rows, n, dim);

  // Mean, and the largest distance from it (for the pruning margin).
  mean_.assign(dim, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t a = 0; a < dim; ++a) mean_[a] += static_cast<double>(rows[i * dim + a]);
  for (double& v : mean_) v /= static_cast<double>(n);
  for (std::size_t i = 0; i < n; ++i) {
    double s = 0;
    for (std::size_t a = 0; a < dim; ++a) {
      const double v = static_cast<double>(rows[i * dim + a]) - mean_[a];
      s += v * v;
    }
    extent_ = std::max(extent_, std::sqrt(s));
  }

  // Principal directions, from the covariance of an evenly spaced sample.
  std::size_t m = dim;
  if (params.pca) {
    const std::size_t sample = std::min(n, params.pca_sample);
    RowMatrixd centred(static_cast<long>(sample), static_cast<long>(dim));
    for (std::size_t s = 0; s < sample; ++s) {
      const std::size_t i = s * n / sample;
      for (std::size_t a = 0; a < dim; ++a) centred(static_cast<long>(s), static_cast<long>(a)) = rows[i * dim + a] - mean_[a];
    }
    const Eigen::MatrixXd covariance = (centred.transpose() * centred) / static_cast<double>(sample);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(covariance);
    if (solver.info() != Eigen::Success) throw Error("forest: the principal directions could not be computed");
    // Eigenvalues ascend: the leading directions are the last columns.
    if (params.projected_dims) {
      m = std::min(params.projected_dims, dim);
    } else {
      const Eigen::VectorXd& values = solver.eigenvalues();
      const double total = std::max(0.0, values.sum());
      const std::size_t least = std::min<std::size_t>(dim, 24), most = std::min<std::size_t>(dim, 64);
      double kept = 0;
      m = 0;
      while (m < most && (m < least || kept < params.variance_share * total))
        kept += std::max(0.0, values(static_cast<long>(dim - 1 - m++)));
    }
    projection_.resize(m * dim);
    for (std::size_t j = 0; j < m; ++j)
      for (std::size_t a = 0; a < dim; ++a)
        projection_[j * dim + a] = solver.eigenvectors()(static_cast<long>(a), static_cast<long>(dim - 1 - j));
  }

  projected_dims_ = m;

  // Projected coordinates, as floats, in blocks of rows.
  std::vector<float> proj(n * m);
  constexpr std::size_t block = 1024;
  detail::parallel_for((n + block - 1) / block, params.threads, 1, [&](std::size_t b0, std::size_t b1, unsigned) {
    RowMatrixd centred;
    for (std::size_t b = b0; b < b1; ++b) {
      const std::size_t first = b * block, count = std::min(block, n - first);
      centred.resize(static_cast<long>(count), static_cast<long>(dim));
      for (std::size_t r = 0; r < count; ++r)
        for (std::size_t a = 0; a < dim; ++a)
          centred(static_cast<long>(r), static_cast<long>(a)) = rows[(first + r) * dim + a] - mean_[a];
      if (params.pca) {
        // Column j of this dim x m (column-major) matrix is direction j, as projection_ holds them.
        const Eigen::Map<const Eigen::MatrixXd> directions(projection_.data(), static_cast<long>(dim), static_cast<long>(m));
        const RowMatrixd projected = centred * directions;
        for (std::size_t r = 0; r < count; ++r)
          for (std::size_t j = 0; j < m; ++j)
            proj[(first + r) * m + j] = static_cast<float>(projected(static_cast<long>(r), static_cast<long>(j)));
      } else {
        for (std::size_t r = 0; r < count; ++r)
          for (std::size_t j = 0; j < m; ++j)
            proj[(first + r) * m + j] = static_cast<float>(centred(static_cast<long>(r), static_cast<long>(j)));
      }
    }
  });

  // The trees, each from its own generator.
  std::vector<TreeBuilder::Result<Node>> built(params.trees);
  detail::parallel_for(params.trees, params.threads, 1, [&](std::size_t t0, std::size_t t1, unsigned) {
    for (std::size_t t = t0; t < t1; ++t) built[t] = TreeBuilder(proj.data(), n, m, params, t).template build<Node>();
  });

  // The copy of the points follows the first tree's leaf order; the trees refer to its rows.
  const std::vector<std::uint32_t> ids = built[0].order;
  std::vector<std::uint32_t> row_of(n);
  for (std::size_t r = 0; r < n; ++r) row_of[ids[r]] = static_cast<std::uint32_t>(r);
  auto gather = [&](auto value) {  // as bytes or as T
    using V = decltype(value);
    std::vector<V> copy(n * dim);
    for (std::size_t r = 0; r < n; ++r)
      std::transform(rows + ids[r] * dim, rows + ids[r] * dim + dim, copy.begin() + static_cast<long>(r * dim),
                     [](U v) { return static_cast<V>(v); });
    return detail::Storage<V>(std::move(copy));
  };
  if (params.compact && byte_valued(rows, n * dim)) bytes_ = gather(std::uint8_t{});
  else points_ = gather(T{});
  ids_ = detail::Storage<std::uint32_t>(ids);
  trees_.resize(params.trees);
  for (std::size_t t = 0; t < params.trees; ++t) {
    for (std::uint32_t& row : built[t].order) row = row_of[row];
    built[t].nodes.shrink_to_fit();
    trees_[t].nodes = detail::Storage<Node>(std::move(built[t].nodes));
    trees_[t].order = detail::Storage<std::uint32_t>(std::move(built[t].order));
    trees_[t].depth = built[t].depth;
    trees_[t].leaves = built[t].leaves;
  }

  if (params.graph == GraphMode::on || (params.graph == GraphMode::automatic && dim >= graph_min_dim)) build_graph();
}

template <class T>
PointForest<T>::PointForest(Parts p) : dim_(p.dim), projected_dims_(p.projected_dims), params_(p.params) {
  auto fail = [](const std::string& what) { throw Error("point forest: " + what); };
  check_params(p.params);
  const std::size_t n = p.ids.size(), d = p.dim, m = p.projected_dims;
  if (d == 0) fail("dimension 0");
  if (n == 0 || n >= (std::size_t{1} << 30)) fail(std::to_string(n) + " points (1 to 2^30 - 1)");
  const bool compact = !p.bytes.empty();
  const std::size_t values = compact ? p.bytes.size() : p.points.size();
  if ((compact && !p.points.empty()) || values / d != n || values % d != 0)
    fail(std::to_string(values) + " coordinates for " + std::to_string(n) + " points of dimension " + std::to_string(d));
  if (p.params.pca ? (m == 0 || m > std::min<std::size_t>(d, 64)) : m != d)
    fail("projected dimensions " + std::to_string(m) + " do not suit dimension " + std::to_string(d));
  if (p.mean.size() != d || p.projection.size() != (p.params.pca ? d * m : 0))
    fail("mean or projection of the wrong size");
  for (double v : p.mean)
    if (!std::isfinite(v)) fail("mean is not finite");
  for (double v : p.projection)
    if (!std::isfinite(v)) fail("projection is not finite");
  if (p.nodes.size() != p.params.trees || p.orders.size() != p.params.trees)
    fail(std::to_string(p.nodes.size()) + " trees, the parameters say " + std::to_string(p.params.trees));

  // The points are finite; the pruning margin needs their largest distance from the mean, worked
  // out here as the build does.
  auto largest_distance = [&](const auto* rows) {
    double largest = 0;
    bool finite = true;
    for (std::size_t r = 0; r < n; ++r, rows += d) {
      double sum = 0;
      for (std::size_t a = 0; a < d; ++a) {
        const double v = static_cast<double>(rows[a]) - p.mean[a];
        sum += v * v;
      }
      if (!std::isfinite(sum))  // a coordinate that is not finite, or a sum beyond double's range
        for (std::size_t a = 0; a < d; ++a) finite = finite && std::isfinite(static_cast<double>(rows[a]));
      largest = std::max(largest, std::sqrt(sum));
    }
    if (!finite) fail("a point is not finite");
    return largest;
  };
  extent_ = compact ? largest_distance(p.bytes.data()) : largest_distance(p.points.data());
  std::vector<bool> seen(n, false);
  for (std::size_t r = 0; r < n; ++r) {
    if (p.ids[r] >= n || seen[p.ids[r]]) fail("original index " + std::to_string(p.ids[r]) + " is out of range or twice");
    seen[p.ids[r]] = true;
  }

  trees_.resize(p.params.trees);
  for (std::size_t t = 0; t < p.params.trees; ++t) {
    const std::string tree_name = "tree " + std::to_string(t) + ": ";
    const detail::Storage<Node>& nodes = p.nodes[t];
    const detail::Storage<std::uint32_t>& order = p.orders[t];
    if (order.size() != n) fail(tree_name + std::to_string(order.size()) + " rows in its order, expected " + std::to_string(n));
    for (std::size_t i = 0; i < n; ++i)
      if (order[i] >= n || (t == 0 && order[i] != i))  // the first tree's leaves are runs of rows
        fail(tree_name + "row " + std::to_string(order[i]) + " at position " + std::to_string(i) + " is out of place");
    // Depth first, every node once: a node's left child next to it, its right child where the left
    // subtree ends; the leaves tile [0, n). Then every descent ends, and reads only rows in range.
    struct Pending {
      std::size_t id, parent, depth;
    };
    std::vector<Pending> stack{{0, 0, 0}};
    std::size_t next = 0, next_row = 0;
    Tree& tree = trees_[t];
    while (!stack.empty()) {
      const Pending at = stack.back();
      stack.pop_back();
      if (at.id != next || next >= nodes.size())
        fail(tree_name + "node " + std::to_string(at.parent) + ": child " + std::to_string(at.id) + ", expected " +
             std::to_string(next) + " (of " + std::to_string(nodes.size()) + " nodes)");
      const Node& node = nodes[next++];
      if (node.is_leaf()) {
        if (node.link != next_row || node.count() > n - next_row)
          fail(tree_name + "node " + std::to_string(at.id) + ": leaf rows out of place");
        next_row += node.count();
        tree.depth = std::max(tree.depth, at.depth);
        ++tree.leaves;
        continue;
      }
      if (node.axis() >= m) fail(tree_name + "node " + std::to_string(at.id) + ": axis out of range");
      if (std::isnan(node.left_max) || std::isnan(node.right_min))
        fail(tree_name + "node " + std::to_string(at.id) + ": split bound is NaN");
      stack.push_back({node.link, at.id, at.depth + 1});
      stack.push_back({at.id + 1, at.id, at.depth + 1});
    }
    if (next != nodes.size() || next_row != n) fail(tree_name + "nodes or rows not reached from the root");
    tree.nodes = std::move(p.nodes[t]);
    tree.order = std::move(p.orders[t]);
  }
  // The graph: lists of a width it can be built with, every link a row (a search follows them).
  if (p.graph_degree != 0 || !p.graph_links.empty()) {
    if (p.graph_degree < 2 || p.graph_degree > 1024)
      fail("graph degree " + std::to_string(p.graph_degree) + " (0, or 2 to 1024)");
    if (p.graph_links.size() / p.graph_degree != n || p.graph_links.size() % p.graph_degree != 0)
      fail(std::to_string(p.graph_links.size()) + " graph links for " + std::to_string(n) + " points of degree " +
           std::to_string(p.graph_degree));
    for (std::size_t i = 0; i < p.graph_links.size(); ++i)
      if (p.graph_links[i] >= n)
        fail("graph link " + std::to_string(p.graph_links[i]) + " of row " + std::to_string(i / p.graph_degree) +
             " is out of range");
    graph_.degree = p.graph_degree;
    graph_.links = std::move(p.graph_links);
  }
  points_ = std::move(p.points);
  bytes_ = std::move(p.bytes);
  ids_ = std::move(p.ids);
  mean_ = std::move(p.mean);
  projection_ = std::move(p.projection);
  backing_ = std::move(p.backing);
}

template <class T>
typename PointForest<T>::Parts PointForest<T>::parts() const {
  Parts p;
  p.dim = dim_;
  p.projected_dims = projected_dims_;
  p.params = params_;
  p.points = detail::Storage<T>::borrow(points_.data(), points_.size());
  p.bytes = detail::Storage<std::uint8_t>::borrow(bytes_.data(), bytes_.size());
  p.ids = detail::Storage<std::uint32_t>::borrow(ids_.data(), ids_.size());
  p.mean = mean_;
  p.projection = projection_;
  for (const Tree& t : trees_) {
    p.nodes.push_back(detail::Storage<Node>::borrow(t.nodes.data(), t.nodes.size()));
    p.orders.push_back(detail::Storage<std::uint32_t>::borrow(t.order.data(), t.order.size()));
  }
  p.graph_degree = graph_.degree;
  p.graph_links = detail::Storage<std::uint32_t>::borrow(graph_.links.data(), graph_.links.size());
  p.backing = backing_;
  return p;
}

template <class T>
std::size_t PointForest<T>::depth() const {
  std::size_t d = 0;
  for (const Tree& t : trees_) d = std::max(d, t.depth);
  return d;
}

template <class T>
std::size_t PointForest<T>::leaf_count() const {
  std::size_t s = 0;
  for (const Tree& t : trees_) s += t.leaves;
  return s;
}

template <class T>
std::size_t PointForest<T>::node_count() const {
  std::size_t s = 0;
  for (const Tree& t : trees_) s += t.nodes.size();
  return s;
}

template <class T>
std::size_t PointForest<T>::memory_bytes() const {
  return points_.memory_bytes() + bytes_.memory_bytes() + index_bytes();
}

template <class T>
std::size_t PointForest<T>::index_bytes() const {
  std::size_t bytes = ids_.memory_bytes() + (mean_.capacity() + projection_.capacity()) * sizeof(double);
  for (const Tree& t : trees_) bytes += t.nodes.memory_bytes() + t.order.memory_bytes();
  return bytes + graph_.bytes();
}

// ---- search ---------------------------------------------------------------------------------------

namespace {
void check_search(const ForestSearchParams& s, std::size_t k, std::size_t n, bool has_graph) {
  detail::check_k(k, n);
  if (s.checks == 0) throw Error("checks must be at least 1");
  if (s.ef > 0 && !has_graph) throw Error("ef > 0 searches the graph, and this forest has none (ForestParams::graph)");
}
}  // namespace

template <class T>
void PointForest<T>::search(const T* q, std::size_t k, const ForestSearchParams& search, Scratch& s,
                            QueryStats& stats, Neighbor<T>* out) const {
  if (search.ef > 0 && search.ef < size()) {
    if (compact()) search_graph(bytes_.data(), q, k, search.ef, s, stats, out);
    else search_graph(points_.data(), q, k, search.ef, s, stats, out);
    return;
  }
  // The trees; with the graph's unlimited budget, the exact answer from them.
  const ForestSearchParams trees = search.ef > 0 ? ForestSearchParams{unlimited_checks, 0, 0} : search;
  if (compact()) search_rows(bytes_.data(), q, k, trees, s, stats, out);
  else search_rows(points_.data(), q, k, trees, s, stats, out);
}

template <class T>
template <class U>
void PointForest<T>::search_rows(const U* points, const T* q, std::size_t k, const ForestSearchParams& search,
                                 Scratch& s, QueryStats& stats, Neighbor<T>* out) const {
  stats.queries += 1;
  for (const auto& c : search_trees(points, q, k, search, false, s, stats))
    *out++ = Neighbor<T>{c.index, L2::to_distance(c.dist)};
}

template <class T>
template <class U>
std::vector<detail::Candidate<T>>& PointForest<T>::search_trees(const U* points, const T* q, std::size_t k,
                                                                const ForestSearchParams& search, bool as_rows,
                                                                Scratch& s, QueryStats& stats) const {
  using Branch = typename Scratch::Branch;
  using Term = typename Scratch::Term;
  using After = typename Scratch::After;
  const std::size_t n = size(), d = dim_, m = projected_dims_;
  s.start(n, m);

  // The query's projected coordinates are computed when the search first needs them
  // (Scratch::projected).
  double q_norm2 = 0;
  for (std::size_t a = 0; a < d; ++a) {
    const double v = static_cast<double>(q[a]) - mean_[a];
    q_norm2 += v * v;
  }

  // Pruning margin. A point p of a cell whose projected bound is B satisfies
  //   |p - q| >= sqrt(B - abs_err) - slack,
  // where slack covers the projected coordinates' rounding to float (the split bounds are such
  // floats) and the double-precision projection, and abs_err the rounding of the incremental bound.
  // The computed internal distance may be smaller than |p - q|^2 by the relative error `shrink`,
  // and by `underflow` where tiny coordinates make it flush towards zero. So a cell cannot hold a
  // point nearer than the k-th when (sqrt(B - abs_err) - slack)^2 * shrink - underflow > kth, that is
  // when B > abs_err + (slack + sqrt((kth + underflow) / shrink))^2: the threshold below, raised by a
  // relative 1e-9 for its own few roundings. It changes only when the k-th does.
  const double reach = extent_ + std::sqrt(q_norm2);
  const double slack = std::sqrt(static_cast<double>(m)) *
                       (extent_ * std::numeric_limits<float>::epsilon() + reach * 1e-10);
  const double abs_err = 1e-12 * reach * reach;
  const double shrink = 1.0 - 4.0 * static_cast<double>(d + 2) * std::numeric_limits<T>::epsilon();
  const double underflow = 4.0 * static_cast<double>(d + 2) * static_cast<double>(std::numeric_limits<T>::min());
  auto threshold = [&](T kth) {
    const double root = slack + std::sqrt((static_cast<double>(kth) + underflow) / shrink);
    return (abs_err + root * root) * (1 + 1e-9);  // infinite while fewer than k are in hand
  };

  detail::KnnResults<T> results(k, std::numeric_limits<T>::infinity(), s.results);
  double prune_above = threshold(results.bound());
  const std::size_t budget = search.checks;
  const std::size_t row_lines = (d * sizeof(U) + 63) / 64;
  constexpr std::uint32_t group = sizeof(T) == 4 ? 4 : 2;
  std::size_t checks = 0, nodes_visited = 0;
  const std::size_t trees_used = search.trees == 0 ? trees_.size() : std::min(search.trees, trees_.size());
  const bool stamped = trees_used > 1;
  const std::uint32_t epoch = s.epoch;
  std::uint32_t* const stamp = s.stamp.data();

  // The rows of a leaf lie far from the tree and from each other (but for the first tree's): they
  // are asked for when the descent reaches the leaf and scored one leaf later, when they have
  // arrived. s.ready holds the rows of the last leaf reached, not yet scored.
  auto score_ready = [&] {
    const std::uint32_t* todo = s.ready.data();
    const std::size_t fresh = s.ready.size();
    // `group` rows at a time (the last group padded with repeats).
    for (std::size_t first = 0; first < fresh; first += group) {
      const U* rows[group];
      for (std::size_t g = 0; g < group; ++g) rows[g] = points + std::size_t{todo[std::min(first + g, fresh - 1)]} * d;
      const T limit = results.bound();
      T dist[group];
      detail::l2_distances_or_more<group>(q, rows, d, limit, dist);
      // Most points do not enter: their original index (a cache miss) is read only for those that
      // may. A distance above `limit` may be partial: only exact ones are offered.
      for (std::size_t g = 0; g < group && first + g < fresh; ++g)
        if (dist[g] <= limit && results.offer(dist[g], as_rows ? todo[first + g] : ids_[todo[first + g]]))
          prune_above = threshold(results.bound());
    }
    s.ready.clear();
  };

  // Descends from `id` (whose cell bound is `bound`, s.terms holding its terms, `trail` their trail)
  // to a leaf, queueing the far child at every step; then asks for the leaf's rows and scores those
  // of the leaf reached before.
  auto descend = [&](std::uint32_t tree_id, std::uint32_t id, double bound, std::uint32_t trail) {
    const Tree& tree = trees_[tree_id];
    const Node* const nodes = tree.nodes.data();
    for (;;) {
      const Node& node = nodes[id];
      ++nodes_visited;
      if (node.is_leaf()) {
        // The first tree's leaves are runs of rows (the copy follows its leaf order), so its leaf
        // order is not read. With one tree no row can come twice: no stamps.
        const bool in_order = tree_id == 0;
        const std::uint32_t* row = tree.order.data() + node.link;
        for (std::uint32_t i = 0; i < node.count(); ++i) {
          const std::uint32_t r = in_order ? node.link + i : row[i];
          if (stamped) {
            if (stamp[r] == epoch) continue;
            stamp[r] = epoch;
          }
          s.arriving.push_back(r);
          const char* first_byte = reinterpret_cast<const char*>(points + std::size_t{r} * d);
          for (std::size_t line = 0; line < row_lines; ++line) __builtin_prefetch(first_byte + 64 * line);
        }
        checks += s.arriving.size();
        score_ready();
        std::swap(s.ready, s.arriving);
        return;
      }
      const std::uint32_t axis = node.axis();
      const double x = s.projected(q, axis, mean_, projection_, params_.pca);
      const double to_left = x - node.left_max;
      const double to_right = node.right_min - x;
      const bool left_first = to_left <= to_right;
      const double far_gap = left_first ? to_right : to_left;
      const double far_term = far_gap * far_gap;
      const double far_bound = bound - s.terms[axis] + far_term;
      if (!(far_bound > prune_above)) {
        s.heap.push_back(Branch{far_bound, tree_id, left_first ? node.link : id + 1,
                                static_cast<std::uint32_t>(s.trail.size())});
        s.trail.push_back(Term{far_term, axis, trail});
        std::push_heap(s.heap.begin(), s.heap.end(), After{});
      }
      id = left_first ? id + 1 : node.link;
    }
  };

  for (std::size_t t = 0; t < trees_used; ++t) descend(static_cast<std::uint32_t>(t), 0, 0.0, Scratch::no_trail);
  while (!s.heap.empty()) {
    if (checks >= budget && results.full()) break;
    const Branch next = s.heap.front();
    if (next.bound > prune_above) break;  // the queue holds nothing nearer
    std::pop_heap(s.heap.begin(), s.heap.end(), After{});
    s.heap.pop_back();
    s.enter(next.trail);
    descend(next.tree, next.node, next.bound, next.trail);
    s.leave();
  }
  score_ready();
  stats.points_visited += checks;
  stats.nodes_visited += nodes_visited;
  return results.sorted();
}

template <class T>
std::vector<Neighbor<T>> PointForest<T>::knn(const T* q, std::size_t k, const ForestSearchParams& search_params,
                                             QueryStats* stats) const {
  check_search(search_params, k, size(), has_graph());
  detail::check_finite(q, dim_, "query");
  thread_local Scratch scratch;
  QueryStats local;
  std::vector<Neighbor<T>> out(k);
  search(q, k, search_params, scratch, local, out.data());
  if (stats) *stats += local;
  return out;
}

template <class T>
NeighborLists<T> PointForest<T>::knn_batch(const T* queries, std::size_t nq, std::size_t k,
                                           const ForestSearchParams& search_params, unsigned threads,
                                           QueryStats* stats) const {
  check_search(search_params, k, size(), has_graph());
  detail::check_query_rows(queries, nq, dim_);
  NeighborLists<T> out;
  out.offsets.resize(nq + 1);
  for (std::size_t q = 0; q <= nq; ++q) out.offsets[q] = q * k;
  out.neighbors.resize(nq * k);
  std::vector<QueryStats> per_worker(detail::resolve_threads(threads));
  detail::parallel_for(nq, threads, 64, [&](std::size_t begin, std::size_t end, unsigned worker) {
    thread_local Scratch scratch;
    for (std::size_t q = begin; q < end; ++q)
      search(queries + q * dim_, k, search_params, scratch, per_worker[worker], out.neighbors.data() + q * k);
  });
  if (stats)
    for (const QueryStats& w : per_worker) *stats += w;
  return out;
}

template class PointForest<float>;
template class PointForest<double>;
// The graph's search falls back on the trees' (point_forest_graph.cpp)...
template void PointForest<float>::search_rows(const float*, const float*, std::size_t, const ForestSearchParams&,
                                              Scratch&, QueryStats&, Neighbor<float>*) const;
template void PointForest<float>::search_rows(const std::uint8_t*, const float*, std::size_t,
                                              const ForestSearchParams&, Scratch&, QueryStats&, Neighbor<float>*) const;
template void PointForest<double>::search_rows(const double*, const double*, std::size_t, const ForestSearchParams&,
                                               Scratch&, QueryStats&, Neighbor<double>*) const;
template void PointForest<double>::search_rows(const std::uint8_t*, const double*, std::size_t,
                                               const ForestSearchParams&, Scratch&, QueryStats&,
                                               Neighbor<double>*) const;
// and starts from the trees' best points (point_forest_graph.cpp).
template std::vector<detail::Candidate<float>>& PointForest<float>::search_trees(
    const float*, const float*, std::size_t, const ForestSearchParams&, bool, Scratch&, QueryStats&) const;
template std::vector<detail::Candidate<float>>& PointForest<float>::search_trees(
    const std::uint8_t*, const float*, std::size_t, const ForestSearchParams&, bool, Scratch&, QueryStats&) const;
template std::vector<detail::Candidate<double>>& PointForest<double>::search_trees(
    const double*, const double*, std::size_t, const ForestSearchParams&, bool, Scratch&, QueryStats&) const;
template std::vector<detail::Candidate<double>>& PointForest<double>::search_trees(
    const std::uint8_t*, const double*, std::size_t, const ForestSearchParams&, bool, Scratch&, QueryStats&) const;

}  // namespace kdspace
