// Query results: Neighbor, lists of neighbours for a batch of queries, and search statistics.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace kdspace {

/// Index of a point in the order the points were given to the build.
using Index = std::uint32_t;

template <class T>
struct Neighbor {
  Index index;
  T distance;  ///< the true metric distance (Euclidean for L2), not a squared one

  friend bool operator==(const Neighbor& a, const Neighbor& b) {
    return a.index == b.index && a.distance == b.distance;
  }
};

/// Work done by queries: the figures behind --stats.
struct QueryStats {
  std::uint64_t queries = 0;
  std::uint64_t nodes_visited = 0;   ///< inner nodes and leaves entered
  std::uint64_t points_visited = 0;  ///< points whose distance was computed

  QueryStats& operator+=(const QueryStats& o) {
    queries += o.queries;
    nodes_visited += o.nodes_visited;
    points_visited += o.points_visited;
    return *this;
  }
};

/// The answers to a batch of queries, stored flat: row q is neighbors[offsets[q] .. offsets[q+1]).
template <class T>
struct NeighborLists {
  std::vector<std::size_t> offsets{0};
  std::vector<Neighbor<T>> neighbors;

  struct Row {
    const Neighbor<T>* first;
    const Neighbor<T>* last;
    const Neighbor<T>* begin() const { return first; }
    const Neighbor<T>* end() const { return last; }
    std::size_t size() const { return static_cast<std::size_t>(last - first); }
    const Neighbor<T>& operator[](std::size_t i) const { return first[i]; }
  };

  std::size_t rows() const { return offsets.size() - 1; }
  Row row(std::size_t q) const {
    return {neighbors.data() + offsets[q], neighbors.data() + offsets[q + 1]};
  }
};

}  // namespace kdspace
