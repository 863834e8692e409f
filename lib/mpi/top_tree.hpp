// The global top tree: which rank holds which region of space, and which ranks a query must ask.
//
// Built by rank 0 from a sample of the points (gathered from all ranks) and sent to every rank as
// bytes (to_bytes), so the sample crosses the network once, not once a rank. Recursive bisection: a node for
// ranks [r0, r1) splits the sample along its axis of largest spread so that the left child's ranks get their
// share, floor((r1 - r0) / 2) / (r1 - r0), of the node's sample points. Points are ordered by (coordinate,
// original index), so that even many copies of one point divide evenly: a point goes left when
// (p[axis], index) <= (split value, split index). (The median-of-sample partition is PANDA's global
// kd-tree, Patwary et al., IPDPS 2016, sec. III-B, less its histogram refinement.)
//
// After the points have moved to their ranks, each leaf gets the bounding box of its rank's points
// and each inner node the union of its children's: ranks_within() prunes with these, so a query
// never visits the top tree's empty space.
//
// Lower bounds without rounding trouble: the distance from q to a box is computed as the distance
// from q to c, the box point nearest to q (each coordinate of q clamped to [lo, hi]), by the very
// internal_distance() that scores points. For any point p of the box, |q_a - c_a| <= |q_a - p_a| on
// every axis, and every step of internal_distance (difference, square or absolute value, sum or
// maximum) is monotone under IEEE rounding, so the computed distance to c never exceeds the computed
// distance to p. Pruning a box whose bound exceeds the k-th distance therefore loses no point,
// ties included, bit for bit.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "kdspace/metric.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace::mpi::detail {

template <class T>
class TopTree {
 public:
  /// sample: rows of `dim` coordinates, sample_index[i] the original index of row i.
  TopTree(const std::vector<T>& sample, const std::vector<Index>& sample_index, std::size_t dim, int ranks)
      : dim_(dim), ranks_(ranks) {
    std::vector<std::uint32_t> rows(sample_index.size());
    for (std::uint32_t i = 0; i < rows.size(); ++i) rows[i] = i;
    nodes_.reserve(2 * static_cast<std::size_t>(ranks));
    build(sample, sample_index, rows.data(), rows.size(), 0, ranks);
  }

  /// The tree as bytes (to send it), and back: TopTree(bytes, dim).
  std::vector<unsigned char> to_bytes() const {
    std::vector<unsigned char> bytes(sizeof(std::uint64_t) + nodes_.size() * node_bytes);
    unsigned char* p = bytes.data();
    const std::uint64_t count = nodes_.size();
    std::memcpy(p, &count, sizeof count);
    p += sizeof count;
    for (const Node& node : nodes_) {
      const std::uint64_t right = node.right;
      const std::int32_t rank = node.rank;
      std::memcpy(p, &node.axis, 4);
      std::memcpy(p + 4, &node.value, sizeof(T));
      std::memcpy(p + 4 + sizeof(T), &node.index, 4);
      std::memcpy(p + 8 + sizeof(T), &right, 8);
      std::memcpy(p + 16 + sizeof(T), &rank, 4);
      p += node_bytes;
    }
    return bytes;
  }

  TopTree(const std::vector<unsigned char>& bytes, std::size_t dim) : dim_(dim), ranks_(0) {
    std::uint64_t count = 0;
    std::memcpy(&count, bytes.data(), sizeof count);
    nodes_.resize(count);
    const unsigned char* p = bytes.data() + sizeof count;
    for (Node& node : nodes_) {
      std::uint64_t right = 0;
      std::int32_t rank = 0;
      std::memcpy(&node.axis, p, 4);
      std::memcpy(&node.value, p + 4, sizeof(T));
      std::memcpy(&node.index, p + 4 + sizeof(T), 4);
      std::memcpy(&right, p + 8 + sizeof(T), 8);
      std::memcpy(&rank, p + 16 + sizeof(T), 4);
      node.right = static_cast<std::size_t>(right);
      node.rank = rank;
      if (rank >= 0) ++ranks_;
      p += node_bytes;
    }
  }

  int ranks() const { return ranks_; }

  /// The rank whose region holds the point p of original index `index`.
  int rank_of_point(const T* p, Index index) const {
    std::size_t id = 0;
    while (!nodes_[id].is_leaf()) {
      const Node& node = nodes_[id];
      const T x = p[node.axis];
      const bool left = x < node.value || (x == node.value && index <= node.index);
      id = left ? id + 1 : node.right;
    }
    return nodes_[id].rank;
  }

  /// The rank whose region holds the query point q (on a split plane: the left side's).
  int rank_of_query(const T* q) const {
    std::size_t id = 0;
    while (!nodes_[id].is_leaf()) id = q[nodes_[id].axis] <= nodes_[id].value ? id + 1 : nodes_[id].right;
    return nodes_[id].rank;
  }

  /// Sets the bounding box of each rank's points: lo and hi hold `dim` coordinates a rank, in rank
  /// order; has_points[r] false for a rank without points.
  void set_boxes(const std::vector<T>& lo, const std::vector<T>& hi,
                 const std::vector<std::uint8_t>& has_points) {
    lo_.assign(nodes_.size() * dim_, std::numeric_limits<T>::infinity());
    hi_.assign(nodes_.size() * dim_, -std::numeric_limits<T>::infinity());
    empty_.assign(nodes_.size(), 1);
    for (std::size_t id = nodes_.size(); id-- > 0;) {  // children come after their parent
      const Node& node = nodes_[id];
      if (node.is_leaf()) {
        const std::size_t r = static_cast<std::size_t>(node.rank);
        if (!has_points[r]) continue;
        std::copy_n(lo.begin() + static_cast<std::ptrdiff_t>(r * dim_), dim_,
                    lo_.begin() + static_cast<std::ptrdiff_t>(id * dim_));
        std::copy_n(hi.begin() + static_cast<std::ptrdiff_t>(r * dim_), dim_,
                    hi_.begin() + static_cast<std::ptrdiff_t>(id * dim_));
        empty_[id] = 0;
        continue;
      }
      for (const std::size_t child : {id + 1, node.right}) {
        if (empty_[child]) continue;
        empty_[id] = 0;
        for (std::size_t a = 0; a < dim_; ++a) {
          lo_[id * dim_ + a] = std::min(lo_[id * dim_ + a], lo_[child * dim_ + a]);
          hi_[id * dim_ + a] = std::max(hi_[id * dim_ + a], hi_[child * dim_ + a]);
        }
      }
    }
  }

  /// Calls visit(rank) for every rank whose box lies within internal distance `limit` of q (each
  /// rank once, in rank order). scratch: dim values of working space.
  template <class Metric, class Visit>
  void ranks_within(const T* q, T limit, std::vector<T>& scratch, Visit&& visit) const {
    scratch.resize(dim_);
    visit_within<Metric>(0, q, limit, scratch.data(), visit);
  }

  /// The internal distance from q to the box of node `id` (a lower bound for its points; above).
  template <class Metric>
  T box_distance(std::size_t id, const T* q, T* nearest) const {
    const T* lo = lo_.data() + id * dim_;
    const T* hi = hi_.data() + id * dim_;
    for (std::size_t a = 0; a < dim_; ++a) nearest[a] = std::min(std::max(q[a], lo[a]), hi[a]);
    return internal_distance<Metric>(q, nearest, dim_);
  }

 private:
  struct Node {
    std::uint32_t axis = 0;
    T value = 0;
    Index index = 0;
    std::size_t right = 0;  // the left child is the next node
    int rank = -1;          // a leaf's rank; -1 for an inner node

    bool is_leaf() const { return rank >= 0; }
  };

  // Orders sample rows along `axis` by (coordinate, original index).
  struct AlongAxis {
    const std::vector<T>& sample;
    const std::vector<Index>& index;
    std::size_t dim, axis;
    bool operator()(std::uint32_t a, std::uint32_t b) const {
      const T xa = sample[a * dim + axis], xb = sample[b * dim + axis];
      return xa < xb || (xa == xb && index[a] < index[b]);
    }
  };

  void build(const std::vector<T>& sample, const std::vector<Index>& index, std::uint32_t* rows,
             std::size_t n, int r0, int r1) {
    const std::size_t id = nodes_.size();
    nodes_.emplace_back();
    if (r1 - r0 == 1) {
      nodes_[id].rank = r0;
      return;
    }
    const int left_ranks = (r1 - r0) / 2;
    const std::uint32_t axis = widest_axis(sample, rows, n);
    // Sample points for the left ranks: their share, but at least one point a side when there are two.
    std::size_t left = (n * static_cast<std::size_t>(left_ranks) + static_cast<std::size_t>(r1 - r0) / 2) /
                       static_cast<std::size_t>(r1 - r0);
    if (n >= 2) left = std::clamp<std::size_t>(left, 1, n - 1);
    Node split;
    split.axis = axis;
    if (left == 0) {  // no sample here: the left ranks get nothing (never with n >= 2)
      split.value = -std::numeric_limits<T>::infinity();
    } else {
      const AlongAxis before{sample, index, dim_, axis};
      std::nth_element(rows, rows + (left - 1), rows + n, before);  // rows[left - 1]: the left side's last
      const std::uint32_t last_left = rows[left - 1];
      split.value = sample[last_left * dim_ + axis];
      split.index = index[last_left];
    }
    nodes_[id] = split;
    build(sample, index, rows, left, r0, r0 + left_ranks);
    nodes_[id].right = nodes_.size();
    build(sample, index, rows + left, n - left, r0 + left_ranks, r1);
  }

  std::uint32_t widest_axis(const std::vector<T>& sample, const std::uint32_t* rows, std::size_t n) const {
    std::uint32_t best = 0;
    T best_spread = -1;
    for (std::size_t a = 0; a < dim_; ++a) {
      T lo = std::numeric_limits<T>::infinity(), hi = -std::numeric_limits<T>::infinity();
      for (std::size_t i = 0; i < n; ++i) {
        lo = std::min(lo, sample[rows[i] * dim_ + a]);
        hi = std::max(hi, sample[rows[i] * dim_ + a]);
      }
      const T spread = n > 0 ? hi - lo : T(0);  // infinity when it overflows: still the widest
      if (spread > best_spread) {
        best_spread = spread;
        best = static_cast<std::uint32_t>(a);
      }
    }
    return best;
  }

  template <class Metric, class Visit>
  void visit_within(std::size_t id, const T* q, T limit, T* nearest, Visit& visit) const {
    if (empty_[id] || box_distance<Metric>(id, q, nearest) > limit) return;
    const Node& node = nodes_[id];
    if (node.is_leaf()) {
      visit(node.rank);
      return;
    }
    visit_within<Metric>(id + 1, q, limit, nearest, visit);
    visit_within<Metric>(node.right, q, limit, nearest, visit);
  }

  static constexpr std::size_t node_bytes = 20 + sizeof(T);

  std::size_t dim_;
  int ranks_;
  std::vector<Node> nodes_;  // depth first: a node's left child follows it
  std::vector<T> lo_, hi_;   // per node, dim_ values each: the box of the node's points
  std::vector<std::uint8_t> empty_;
};

}  // namespace kdspace::mpi::detail
