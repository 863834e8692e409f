// Parameters of the point tree: how it is built and how an approximate query may cut corners.
#pragma once

#include <cstddef>
#include <limits>

namespace kdspace {

/// Which axis a node splits.
enum class AxisRule {
  cycle,       ///< round-robin with depth (axis = depth mod dim), skipping axes on which the node is flat
  max_spread,  ///< the axis along which the node's points spread the most
};

/// Where along that axis the node splits.
enum class PositionRule {
  median,            ///< object median (std::nth_element): balanced, depth ~ log2(n / leaf_size)
  middle,            ///< spatial middle of the node's cell; a side may be empty
  sliding_midpoint,  ///< middle of the cell, slid to the nearest point when one side would be empty
};

struct BuildParams {
  AxisRule axis = AxisRule::max_spread;
  PositionRule position = PositionRule::median;
  /// S_minObj: a node with at most this many points becomes a leaf. 16 measured best or near best
  /// for exact k-NN on 3-D (1e6 points) and clustered 16-D (1e5) data among 1..48, and keeps the
  /// index under 8 bytes a point (README, "Choosing the defaults").
  std::size_t leaf_size = 16;
  /// S_maxProf: a node at this depth becomes a leaf whatever its size (the root has depth 0).
  /// Median splits never come near 64 (depth ~ log2(n / leaf_size)); the cap matters for the middle
  /// rules on tightly clustered data. At most 256: deeper recursion would only risk the stack.
  std::size_t max_depth = 64;
  /// Threads for the build; 0 = all hardware threads.
  unsigned threads = 1;
};

struct SearchParams {
  /// Approximation factor: the i-th returned neighbour is at most (1 + eps) times as far as the true
  /// i-th nearest neighbour. 0 = exact.
  double eps = 0.0;
  /// Stop looking further once this many points are scored and k candidates are in hand (no accuracy
  /// guarantee then; the answer always has k entries). Counted per query. Default: no limit.
  std::size_t max_checks = std::numeric_limits<std::size_t>::max();
};

}  // namespace kdspace
