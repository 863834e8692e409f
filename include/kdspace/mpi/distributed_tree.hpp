// DistributedTree<T, Metric>: exact k-NN and radius search over points spread across MPI ranks.
//
// Each rank brings its own points; the tree sends every point to the rank that owns its region of
// space (a global top tree built from a sample), and each rank builds a PointTree over its region.
// A k-NN query goes first to the rank whose region holds it, which answers with its k nearest; the
// k-th of those distances bounds the answer, so the query then goes only to the ranks whose points'
// bounding box lies within that bound. A radius query goes straight to the ranks within its radius.
// The partial answers merge exactly: the results are the same, bit for bit, as one PointTree over
// all the points (ascending internal distance, equal distances by smaller original index), whatever
// the number of ranks. Queries travel in rounds: one MPI_Alltoallv per step for all the queries of
// a round, never one message a query. (Design, costs and a model for 1,000 ranks: docs/mpi.md.)
//
// Every member function taking or returning data for all ranks is collective: all ranks of the
// communicator call it, in the same order. When any rank fails (bad data, out of memory), every rank
// throws the same kdspace::Error, naming the first failing rank ("rank R of P: ..."); none is left
// waiting.
#pragma once

#include <mpi.h>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>

#include "kdspace/metric.hpp"
#include "kdspace/points/neighbor.hpp"
#include "kdspace/points/params.hpp"

namespace kdspace::mpi {

/// What one rank sent to the others (blocks to itself are not counted).
struct Traffic {
  std::uint64_t exchanges = 0;  ///< all-to-all steps (MPI_Alltoallv) taken part in
  std::uint64_t messages = 0;   ///< non-empty blocks sent to another rank
  std::uint64_t bytes = 0;      ///< bytes of those blocks

  Traffic& operator+=(const Traffic& o) {
    exchanges += o.exchanges;
    messages += o.messages;
    bytes += o.bytes;
    return *this;
  }
};

/// The work of one rank in a batch of queries.
struct DistributedStats {
  std::uint64_t queries = 0;      ///< queries this rank brought
  std::uint64_t ranks_asked = 0;  ///< over those queries: the ranks that searched for them
  std::uint64_t rounds = 0;       ///< rounds of the batch
  std::uint64_t candidates = 0;   ///< over those queries: candidates received from other ranks
  QueryStats search;              ///< this rank's local searches (for its own and others' queries)
  Traffic traffic;                ///< the batch's exchanges

  DistributedStats& operator+=(const DistributedStats& o) {
    queries += o.queries;
    ranks_asked += o.ranks_asked;
    rounds = o.rounds > rounds ? o.rounds : rounds;
    candidates += o.candidates;
    search += o.search;
    traffic += o.traffic;
    return *this;
  }
};

struct DistributedParams {
  BuildParams build;  ///< for each rank's PointTree (build.threads: threads a rank)
  /// Sample points a region is chosen from (the top tree's sample holds about ranks * this many,
  /// at most 64 MiB of them): the shares of the ranks differ by about 1/sqrt(this).
  std::size_t sample_per_rank = 1024;
  /// Queries a rank sends in one round: bounds the memory of a round (queries, and the candidates
  /// of up to k per rank asked, for each); more rounds cost more collective calls.
  std::size_t queries_per_round = 1 << 14;
};

template <class T, class Metric = L2>
class DistributedTree {
 public:
  /// Collective. Each rank gives its own n points (dim coordinates each, row-major; n may be 0 on
  /// some ranks). The original index of a point is its position in all ranks' points taken in
  /// rank order: rank 0's first, then rank 1's, and so on. Throws Error (on every rank) for
  /// non-finite coordinates, ranks that disagree on dim, no points at all, 2^31 points or more,
  /// or a region of 2^30 points or more.
  DistributedTree(MPI_Comm comm, const T* rows, std::size_t n, std::size_t dim,
                  const DistributedParams& params = {});
  ~DistributedTree();
  DistributedTree(DistributedTree&&) noexcept;
  DistributedTree& operator=(DistributedTree&&) noexcept;

  /// Collective: each rank passes its own nq queries (row-major) and gets the k nearest points of
  /// each, as PointTree::knn_batch would over all points (1 <= k <= size(), else Error). Indices
  /// are original indices. threads: for this rank's local searches (0 = all hardware threads).
  NeighborLists<T> knn_batch(const T* queries, std::size_t nq, std::size_t k, unsigned threads = 1,
                             DistributedStats* stats = nullptr) const;

  /// Collective: every point within distance r of each query (closed ball; r in the data's units,
  /// not squared); with max_results, only the max_results nearest of them. As
  /// PointTree::radius_batch would over all points.
  NeighborLists<T> radius_batch(const T* queries, std::size_t nq, T r,
                                std::size_t max_results = std::numeric_limits<std::size_t>::max(),
                                unsigned threads = 1, DistributedStats* stats = nullptr) const;

  std::size_t size() const;        ///< points on all ranks
  std::size_t local_size() const;  ///< points this rank holds after the build
  std::size_t dim() const;
  int ranks() const;
  /// This rank's tree: depth, leaves, nodes (0 without points), index bytes.
  std::size_t local_depth() const;
  std::size_t local_leaves() const;
  std::size_t local_nodes() const;
  std::size_t local_index_bytes() const;
  /// What the build sent: the sample, and the points to their ranks.
  const Traffic& build_traffic() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kdspace::mpi

// Compiled once in lib/mpi/distributed_tree.cpp.
namespace kdspace::mpi {
extern template class DistributedTree<float, L2>;
extern template class DistributedTree<float, L1>;
extern template class DistributedTree<float, Linf>;
extern template class DistributedTree<double, L2>;
extern template class DistributedTree<double, L1>;
extern template class DistributedTree<double, Linf>;
}  // namespace kdspace::mpi
