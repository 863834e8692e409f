// PointForest<T>: approximate Euclidean k-NN for high-dimensional data (image and audio descriptors)
// by several randomized kd-trees searched together, best bin first, within a budget of scored points.
//
// How it works.
//  - Build: the data's mean and principal directions are computed (covariance of a sample, Eigen's
//    self-adjoint eigensolver), and every point is projected onto the `projected_dims` leading
//    directions (by default as many as hold 90% of the variance, from 24 to 64: data whose variance
//    is spread over many directions, where the cells must follow local structure, keep more). Each
//    tree splits those projected coordinates: at each node the axis is drawn at
//    random among the `candidate_axes` of largest variance (measured on a sample of the node's
//    points), the position is the median. Trees differ only in their random draws, made by a
//    generator seeded with (seed, tree number): the forest is the same for any thread count.
//  - Search: the query is projected once. Every tree is descended to its leaf; each branch not taken
//    goes into one priority queue shared by all trees, keyed by the distance from the query to the
//    branch's cell (a true lower bound in the projected space, updated one axis at a time). Branches
//    are then taken from the queue, nearest first, until `checks` points have been scored (and k are
//    in hand) or no cell can hold a closer point. A point met in several trees is scored once.
//  - What a search costs is mostly waiting for memory, so: a queued branch carries its cell's
//    per-axis terms as a trail (the one term it changed, then its parent's trail), and taking it
//    needs no walk from the root; a leaf's rows are asked for (prefetched) when the descent reaches
//    it and scored when the next leaf is reached, four rows at a time (row_distances.hpp: the same
//    bits as internal_distance(), row by row); the copy of the points follows the first tree's
//    leaf order, so that tree's leaves are runs of rows.
//  - Points are scored with internal_distance() on the original coordinates, never the projected
//    ones: every returned distance is exact, and with an unlimited budget the answer is the exact
//    k-NN (same distances as brute_force_knn() and PointTree, ties by smaller index). The pruning
//    test allows for the rounding of the projection (a margin from the data's extent), so it never
//    drops a cell that could hold a neighbour.
//
// Memory: a copy of the points (n * dim * sizeof(T), or n * dim bytes for byte-valued data), the
// original index of each (4 bytes a point), and per tree the leaf order of the points (4 bytes a
// point) and its nodes (16 bytes each, about 2n / leaf_size of them); plus the projection
// (dim * projected_dims doubles). memory_bytes() gives the exact figure. The projected coordinates
// are only needed while building.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <vector>

#include "kdspace/detail/storage.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/neighbor_graph.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace {

/// Whether PointForest builds its neighbour graph.
enum class GraphMode {
  automatic,  ///< where it answers faster than the trees at equal recall: dim >= graph_min_dim
  on,
  off,
};

/// GraphMode::automatic builds the graph from this dimension on (README, "Graph or trees").
inline constexpr std::size_t graph_min_dim = 8;

struct ForestParams {
  /// Number of randomized trees (>= 1). A search may use fewer of them (ForestSearchParams::trees).
  std::size_t trees = 4;
  /// A node with at most this many points becomes a leaf.
  std::size_t leaf_size = 8;
  /// Rotate the data onto its principal directions before splitting (true), or split the original
  /// axes (false; then projected_dims is the dimension itself).
  bool pca = true;
  /// Leading principal directions the trees split on (1..64); 0 = automatic: the fewest that hold
  /// `variance_share` of the data's variance, but at least min(dim, 24) and at most min(dim, 64).
  std::size_t projected_dims = 0;
  /// Share of the variance the automatic projected_dims keeps (in (0, 1]).
  double variance_share = 0.9;
  /// Keep the points as bytes when every coordinate is an integer from 0 to 255 (SIFT-like
  /// descriptors, bvecs files): a quarter of the memory for float (an eighth for double) and of the
  /// bytes read per scored point. The answers are the same bit for bit (bytes convert exactly, and
  /// the distance adds the same values in the same order).
  bool compact = true;
  /// At each node the split axis is drawn among this many axes of largest variance (>= 1).
  std::size_t candidate_axes = 5;
  /// Points of a node whose variance chooses its axis (at most; >= 2).
  std::size_t variance_sample = 64;
  /// Points whose covariance gives the principal directions (at most; all when n is smaller).
  std::size_t pca_sample = 20000;
  /// Seed of the random draws; the same seed gives the same forest.
  std::uint64_t seed = 1;
  /// The neighbour graph: built or not (see the top of this file).
  GraphMode graph = GraphMode::automatic;
  /// Most neighbours a point keeps in the graph (2..1024). Its lists take 4 * graph_degree bytes a
  /// point.
  std::size_t graph_degree = 32;
  /// Pool of the search that finds each point's neighbours while the graph is built: larger builds
  /// slower, and a graph that reaches a recall with fewer points scored. 0 (the default): from the
  /// data, twice its intrinsic dimension as estimated from the trees' candidates, within 16..24
  /// (params() then reports the pool chosen).
  std::size_t graph_build_ef = 0;
  /// Slack of the graph's pruning rule (>= 1): a point's neighbour c is dropped when one kept before
  /// it, w, has graph_alpha * |c - w| <= |p - c|. Larger keeps more edges.
  double graph_alpha = 1.2;
  /// Threads for the build; 0 = all hardware threads. The forest and its graph do not depend on it.
  unsigned threads = 1;
};

/// Unlimited check budget: the search runs until no cell can hold a closer point (exact answer).
inline constexpr std::size_t unlimited_checks = static_cast<std::size_t>(-1);

struct ForestSearchParams {
  /// Trees: points scored per query before the search stops (>= 1; it goes on until k are in hand);
  /// unlimited_checks: the exact answer.
  std::size_t checks = 256;
  /// Trees: the first `trees` of the forest are searched; 0 = all.
  std::size_t trees = 0;
  /// 0: search the trees (with checks and trees above). Else search the graph, keeping the `ef`
  /// best points found (at least k are kept, whatever ef says; larger is slower and finds more of
  /// the true neighbours); unlimited_checks (or any ef >= size()): the exact answer, from the trees.
  std::size_t ef = 0;
};

/// A setting chosen by PointForest::tune() (the graph's ef, or the trees' trees and checks), with what
/// was measured for it.
struct ForestTuning {
  std::size_t trees = 0;
  std::size_t checks = 0;
  std::size_t ef = 0;  ///< > 0: the graph was chosen
  /// The setting, to pass to knn() and knn_batch().
  ForestSearchParams search() const { return ForestSearchParams{checks, trees, ef}; }
  double target_recall = 0;
  double tuning_recall = 0;      ///< mean recall@k on the queries it was chosen with
  double validation_recall = 0;  ///< mean recall@k on held-out queries, not used to choose
  double queries_per_s = 0;      ///< single thread, on the tuning queries
  std::size_t tuning_queries = 0;
  std::size_t validation_queries = 0;
  std::size_t settings_tried = 0;
  double seconds = 0;  ///< wall time of the whole tuning, exact answers included
};

struct TuneParams {
  /// Base points used as queries to choose the setting, and as many again to validate it (each is
  /// left out of its own answers).
  std::size_t sample_queries = 200;
  /// Largest budget (checks or ef) tried; 0 = the number of points (then the search is exact, and
  /// reaches any recall).
  std::size_t max_checks = 0;
  std::uint64_t seed = 7;
  /// Threads for the exact answers of the sample; the timed searches run on one thread.
  unsigned threads = 0;
  /// The searches tune() may choose from: the graph (when the forest has one) and the trees. With
  /// neither allowed, or only the graph and no graph built, the trees.
  bool graph = true;
  bool trees = true;
};

template <class T>
class PointForest {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>, "PointForest holds float or double");

 public:
  using Scalar = T;

  /// 16 bytes. Inner node: the tight bounds of its children along `axis` (a projected axis); its
  /// left child is the next node, its right child at `link`. Leaf: points [link, link + count) of
  /// the tree's leaf order.
  struct Node {
    static constexpr std::uint32_t leaf_bit = 0x80000000u;
    float left_max;
    float right_min;
    std::uint32_t link;
    std::uint32_t info;  ///< axis (inner) or leaf_bit | count (leaf)
    bool is_leaf() const { return (info & leaf_bit) != 0; }
    std::uint32_t axis() const { return info; }
    std::uint32_t count() const { return info & ~leaf_bit; }
  };

  /// Builds from n points of `dim` coordinates, row-major. Throws Error for n = 0, dim = 0,
  /// non-finite coordinates, n >= 2^30 and out-of-range parameters.
  PointForest(const T* rows, std::size_t n, std::size_t dim, const ForestParams& params = {});
  /// Builds from byte rows (SIFT-like descriptors, .bvecs files) without a copy of them as T: the
  /// forest is the one the T constructor builds from the same values, and gives the same answers bit
  /// for bit. With ForestParams::compact the points are kept as bytes, else widened to T.
  PointForest(const std::uint8_t* rows, std::size_t n, std::size_t dim, const ForestParams& params = {});

  /// Everything a forest is made of (what an index file stores, io/index.hpp). `backing` keeps
  /// borrowed storage alive.
  struct Parts {
    std::size_t dim = 0;
    std::size_t projected_dims = 0;
    ForestParams params;
    detail::Storage<T> points;            ///< rows in the first tree's leaf order (empty when compact)
    detail::Storage<std::uint8_t> bytes;  ///< the same as bytes, when compact (else empty)
    detail::Storage<std::uint32_t> ids;   ///< original index of each row
    std::vector<double> mean;
    std::vector<double> projection;
    std::vector<detail::Storage<Node>> nodes;            ///< per tree
    std::vector<detail::Storage<std::uint32_t>> orders;  ///< per tree: rows in its leaf order
    std::size_t graph_degree = 0;                        ///< width of the graph's lists; 0: no graph
    detail::Storage<std::uint32_t> graph_links;          ///< size() x graph_degree rows
    std::shared_ptr<const void> backing;
  };
  /// Makes the forest of `parts` after checking them whole (every index in range, tree links
  /// depth first, leaves tiling the rows, finite values, graph links to rows); throws Error("point forest: ...") else.
  explicit PointForest(Parts parts);
  /// The forest's arrays, borrowed (valid while the forest lives).
  Parts parts() const;

  std::size_t size() const { return ids_.size(); }
  std::size_t dim() const { return dim_; }
  std::size_t tree_count() const { return trees_.size(); }
  std::size_t projected_dims() const { return projected_dims_; }
  /// Whether the points are kept as bytes (ForestParams::compact and byte-valued data).
  bool compact() const { return !bytes_.empty(); }
  /// Whether the neighbour graph was built (ForestParams::graph), and the width of its lists.
  bool has_graph() const { return !graph_.empty(); }
  std::size_t graph_degree() const { return graph_.degree; }
  /// Wall seconds the build spent on the graph (0 without one).
  double graph_build_seconds() const { return graph_build_s_; }
  /// Deepest leaf over all trees.
  std::size_t depth() const;
  std::size_t leaf_count() const;
  std::size_t node_count() const;
  std::size_t memory_bytes() const;
  /// Bytes held besides the copy of the points.
  std::size_t index_bytes() const;
  const ForestParams& params() const { return params_; }

  /// The k nearest points found within the budget, in ascending (true) distance, ties by ascending
  /// index (decided on the squared distance, as in PointTree: two squared distances an ulp apart
  /// that share one rounded square root keep their squared order); always k of them
  /// (1 <= k <= size(), else Error). Distances are exact.
  std::vector<Neighbor<T>> knn(const T* q, std::size_t k, const ForestSearchParams& search = {},
                               QueryStats* stats = nullptr) const;

  /// nq queries, row-major, on `threads` threads (0 = all); the same answers as one thread.
  NeighborLists<T> knn_batch(const T* queries, std::size_t nq, std::size_t k, const ForestSearchParams& search = {},
                             unsigned threads = 0, QueryStats* stats = nullptr) const;

  /// The exact k-NN of each query by scoring every point (blocked matrix products with an exact
  /// re-check, as PointTree's BatchMethod::scan): the reference answers for recall.
  NeighborLists<T> knn_exact_batch(const T* queries, std::size_t nq, std::size_t k, unsigned threads = 0) const;

  /// The cheapest setting (the graph's ef, or trees and checks; TuneParams::graph and ::trees say
  /// which may be chosen) whose mean recall@k reaches `target_recall` (in (0, 1]) on sample
  /// queries; cheapest by measured time. Exact answers come from the blocked scan. The setting is
  /// then checked on as many other sample queries (validation_recall); if it falls short there, the
  /// budget grows an eighth at a time until it does not (or reaches max_checks). The sample is drawn
  /// with the seed.
  ///
  /// This form samples the queries from `queries` (nq rows; up to 2 * sample_queries of them):
  /// queries like the ones to be answered give the truest setting.
  ForestTuning tune(double target_recall, std::size_t k, const T* queries, std::size_t nq,
                    const TuneParams& params = {}) const;
  /// This form uses base points as queries, each left out of its own answers. Where base points have
  /// near-copies of themselves that real queries lack (consecutive audio frames, video frames), it
  /// finds neighbours easier than real queries would and the setting falls short on them: prefer the
  /// form above when queries are at hand.
  ForestTuning tune(double target_recall, std::size_t k, const TuneParams& params = {}) const;

  /// Nodes of tree t, depth first (read-only; for tools and tests).
  const detail::Storage<Node>& nodes(std::size_t t) const { return trees_.at(t).nodes; }
  /// The neighbour graph over the rows of the copy of the points (read-only; for tools and tests).
  const detail::NeighborGraph& graph() const { return graph_; }

 private:
  struct Tree {
    detail::Storage<Node> nodes;            // depth first, nodes[0] the root
    detail::Storage<std::uint32_t> order;   // rows of points_ in this tree's leaf order
    std::size_t depth = 0;
    std::size_t leaves = 0;
  };
  struct Scratch;

  template <class U>  // U: T or std::uint8_t
  void build(const U* rows, std::size_t n, std::size_t dim, const ForestParams& params);

  void search(const T* q, std::size_t k, const ForestSearchParams& search, Scratch& scratch, QueryStats& stats,
              Neighbor<T>* out) const;
  /// The trees' search: the k best found, in (distance, index) order, indices being rows of the copy
  /// of the points (as_rows) or the original ones; in scratch, valid until its next search.
  template <class U>
  std::vector<detail::Candidate<T>>& search_trees(const U* points, const T* q, std::size_t k,
                                                  const ForestSearchParams& search, bool as_rows, Scratch& scratch,
                                                  QueryStats& stats) const;
  template <class U>
  void search_graph(const U* points, const T* q, std::size_t k, std::size_t ef, Scratch& scratch, QueryStats& stats,
                    Neighbor<T>* out) const;
  void build_graph();
  template <class U>  // U: T, or std::uint8_t when compact
  void search_rows(const U* points, const T* q, std::size_t k, const ForestSearchParams& search, Scratch& scratch,
                   QueryStats& stats, Neighbor<T>* out) const;
  ForestTuning tune_on(double target_recall, std::size_t k, const std::vector<T>& queries,
                       const std::vector<Index>& self, std::size_t half, const TuneParams& params) const;

  std::size_t dim_ = 0;
  std::size_t projected_dims_ = 0;
  ForestParams params_;
  // Owned, or borrowed from a mapped index file that backing_ keeps alive.
  detail::Storage<T> points_;             // copy of the points, rows in the first tree's leaf order
  detail::Storage<std::uint8_t> bytes_;   // or, when compact, the same as bytes (points_ then empty)
  detail::Storage<std::uint32_t> ids_;    // original index of each row of points_
  std::shared_ptr<const void> backing_;
  std::vector<double> mean_;          // dim
  std::vector<double> projection_;    // projected_dims x dim, row-major: row j = direction j
  std::vector<Tree> trees_;
  double extent_ = 0;                 // largest |x - mean| over the points
  detail::NeighborGraph graph_;       // over the rows of points_ / bytes_
  double graph_build_s_ = 0;
};

/// Mean recall@k of `found` against `exact` (row by row, the same k in both): the share of the k
/// returned points that are no farther than the true k-th nearest (so ties count as found).
template <class T>
double recall_at_k(const NeighborLists<T>& found, const NeighborLists<T>& exact) {
  if (found.rows() != exact.rows()) throw Error("recall_at_k: different numbers of queries");
  if (found.rows() == 0) return 1.0;
  double sum = 0;
  for (std::size_t q = 0; q < found.rows(); ++q) {
    const auto truth = exact.row(q);
    const auto row = found.row(q);
    if (truth.size() == 0 || row.size() != truth.size()) throw Error("recall_at_k: rows of different lengths");
    const T kth = truth[truth.size() - 1].distance;
    std::size_t hits = 0;
    for (const auto& nb : row) hits += nb.distance <= kth ? 1 : 0;
    sum += static_cast<double>(hits) / static_cast<double>(truth.size());
  }
  return sum / static_cast<double>(found.rows());
}

extern template class PointForest<float>;
extern template class PointForest<double>;

}  // namespace kdspace
