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
  midpoint,          ///< middle of the node's points' extent (their bounding box): never an empty side
};

/// How much of a tree from outside (an index file) is checked before it is searched
/// (io::load_point_tree). Either way every section's checksum is verified first, so a file changed
/// by accident (a flipped bit, a truncation, a wrong version, type or dimension) is refused.
enum class Verify {
  /// What keeps every query inside the arrays and finite: node links in depth-first order, no path
  /// deeper than 256, split axes below the dimension and split bounds ordered, leaves that tile the
  /// rows, and point indices below n. A file whose checksums were recomputed after a change may then
  /// answer other than brute force over its points, but never reads out of bounds, loops or returns
  /// an index past n.
  safety,
  /// Besides, what makes the answers those of brute force over the file's own points whatever wrote
  /// the file: every point inside the cells its leaf lies under, the indices a permutation,
  /// identical-point leaves identical. A pass over every coordinate and a mark an index.
  full,
};

struct BuildParams {
  AxisRule axis = AxisRule::max_spread;
  /// The midpoint of the points' extent: one pass over a node's points per split (the build is
  /// several times faster than with the median), and cells that follow the data. On 17 real scans
  /// and meshes it answers k-NN as fast as the median or faster, on clustered 64-D and 128-D data
  /// 1.3-1.6x faster (README, "Choosing the defaults").
  PositionRule position = PositionRule::midpoint;
  /// S_minObj: a node with at most this many points becomes a leaf. With the midpoint rule, 24
  /// measured within 3% of the best of 12..32 for 1-NN and 10-NN on the real scans, and near the best
  /// on uniform and clustered 3-D (1e6 points), MFCC and clustered 16..128-D data; it keeps the index
  /// near 6 bytes a point (README, "Choosing the defaults").
  std::size_t leaf_size = 24;
  /// S_maxProf: a node at this depth becomes a leaf whatever its size (the root has depth 0).
  /// Median splits never come near 64 (depth ~ log2(n / leaf_size)); the cap matters for the middle
  /// rules on tightly clustered data. At most 256: deeper recursion would only risk the stack.
  std::size_t max_depth = 64;
  /// Threads for the build; 0 = all hardware threads.
  unsigned threads = 1;
};

/// How knn_batch answers exact queries (eps = 0, no max_checks limit). The answers are the same
/// either way; only the time differs.
enum class BatchMethod {
  /// The tree for the first few queries; if they show it scoring at least scan_switch_fraction of
  /// the points (high dimensions, uniform data), the blocked scan for the rest (L2 only).
  automatic,
  tree,  ///< always the tree
  /// Score every point: for L2 by blocked matrix products with an exact re-check of the candidates
  /// (detail/blocked_scan.hpp); for L1 and Linf one point after the other.
  scan,
};

/// With BatchMethod::automatic: the share of the points a tree query must score, on average over
/// the first queries of a batch, for the rest of the batch to go to the blocked scan. Measured (CPU
/// time, 1 thread, 1e5 uniform float points, 10-NN): the tree and the scan take the same time where
/// the tree scores 9% of the points at 8-D and 16-D, 6.5% at 32-D, 4.5-5% at 64-D and 128-D (the
/// scan runs its products at the processor's full vector width; a tree query waits on memory for
/// each leaf). Where a tree query scores 2-3% of the points (clustered 128-D data) it is 5x faster
/// than the scan.
inline constexpr double scan_switch_fraction = 0.06;

struct SearchParams {
  /// Approximation factor: the i-th returned neighbour is at most (1 + eps) times as far as the true
  /// i-th nearest neighbour. 0 = exact.
  double eps = 0.0;
  /// Stop looking further once this many points are scored and k candidates are in hand (no accuracy
  /// guarantee then; the answer always has k entries). Counted per query. Default: no limit.
  std::size_t max_checks = std::numeric_limits<std::size_t>::max();
  /// Batches only: tree, scan or the automatic choice between them for exact queries.
  BatchMethod batch_method = BatchMethod::automatic;
};

}  // namespace kdspace
