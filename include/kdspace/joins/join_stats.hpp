// JoinStats: the work a dual-tree join did, behind the --stats of `kdspace pairs`, `count` and `knn`.
#pragma once

#include <cstdint>

namespace kdspace {

struct JoinStats {
  std::uint64_t node_pairs = 0;  ///< (query node, reference node) pairs scored
  std::uint64_t leaf_pairs = 0;  ///< pairs of leaves whose points were compared one by one
  std::uint64_t distances = 0;   ///< point-to-point distances computed
  /// Point pairs settled by their cells' bounds alone, without a distance (pairs and counts).
  std::uint64_t bulk_pairs = 0;

  JoinStats& operator+=(const JoinStats& o) {
    node_pairs += o.node_pairs;
    leaf_pairs += o.leaf_pairs;
    distances += o.distances;
    bulk_pairs += o.bulk_pairs;
    return *this;
  }
};

}  // namespace kdspace
