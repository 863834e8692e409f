// DistributedTree: the build (sample, top tree, points to their ranks, local trees) and the query
// rounds (see the header and docs/mpi.md).
#include "kdspace/mpi/distributed_tree.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "comm.hpp"
#include "kdspace/points/detail/input_checks.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/point_tree.hpp"
#include "top_tree.hpp"

namespace kdspace::mpi {
namespace {

using detail::Blocks;
using detail::BlockWriter;
using detail::Comm;
using kdspace::detail::Candidate;
using Failure = std::optional<std::string>;  // what a rank's local work threw, if anything

template <class T>
MPI_Datatype mpi_type() {
  return sizeof(T) == sizeof(double) ? MPI_DOUBLE : MPI_FLOAT;
}

// Records on the wire are packed bytes, written and read with memcpy (no padding, any alignment).
template <class V>
unsigned char* put(unsigned char* p, const V& v) {
  std::memcpy(p, &v, sizeof v);
  return p + sizeof v;
}
template <class V>
const unsigned char* get(const unsigned char* p, V& v) {
  std::memcpy(&v, p, sizeof v);
  return p + sizeof v;
}

// splitmix64: spreads the sample's positions within their strata.
std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// The most bytes of sample rank 0 gathers for the top tree (about 4M points of 3 floats).
constexpr std::uint64_t sample_bytes_cap = std::uint64_t{64} << 20;

// Original indices are Index (32 bits) and the result files hold them as int32.
constexpr std::uint64_t max_points = (std::uint64_t{1} << 31) - 1;

}  // namespace

template <class T, class Metric>
struct DistributedTree<T, Metric>::Impl {
  using Tree = PointTree<T, Dynamic, Metric>;

  explicit Impl(MPI_Comm c) : comm(c) {}

  Comm comm;
  DistributedParams params;
  std::size_t dim = 0;
  std::uint64_t total = 0;
  std::optional<detail::TopTree<T>> top;
  std::optional<Tree> tree;           // none on a rank without points
  std::vector<Index> original_index;  // of the local tree's points, by the index its build gave them
  Traffic build_traffic;

  std::size_t query_bytes(bool with_bound) const { return dim * sizeof(T) + (with_bound ? sizeof(T) : 0); }
  static constexpr std::size_t candidate_bytes = sizeof(T) + sizeof(Index);

  // ---- build ------------------------------------------------------------------------------------

  void build(const T* rows, std::size_t n) {
    Failure error = Comm::run_catching([&] {
      if (dim == 0) throw Error("points have dimension 0");
      if (n > 0 && rows == nullptr) throw Error("points: null pointer");
      for (std::size_t i = 0; i < n; ++i)
        kdspace::detail::check_finite(rows + i * dim, dim,
                                      "point " + std::to_string(i + 1) + " of this rank");
    });
    const std::vector<std::uint64_t> dims = comm.agree(error, {dim, ~std::uint64_t{dim}});
    if (dims[0] != ~dims[1])
      throw Error("the ranks disagree on the dimension of the points: from " + std::to_string(~dims[1]) +
                  " to " + std::to_string(dims[0]));
    const std::vector<std::uint64_t> counts = comm.gather_all(n);
    std::uint64_t first = 0;
    for (int r = 0; r < comm.size(); ++r)
      (r < comm.rank() ? first : total) += counts[static_cast<std::size_t>(r)];
    total += first;
    if (total == 0) throw Error("no points: the data is empty");
    if (total > max_points)
      throw Error("too many points: " + std::to_string(total) + " (at most 2^31 - 1 over all ranks)");

    make_top_tree(rows, n, first);

    std::vector<T> points;
    redistribute(rows, n, first, points);
    std::vector<T> lo(dim), hi(dim);
    comm.phase([&] {
      const std::size_t m = original_index.size();
      if (m > 0) tree.emplace(points.data(), m, dim, params.build);
      for (std::size_t a = 0; a < dim && m > 0; ++a) {
        lo[a] = hi[a] = points[a];
        for (std::size_t i = 1; i < m; ++i) {
          lo[a] = std::min(lo[a], points[i * dim + a]);
          hi[a] = std::max(hi[a], points[i * dim + a]);
        }
      }
    });
    points = {};  // the tree holds its own copy
    share_boxes(lo, hi);
  }

  // Rank 0 gathers a sample, about sample_per_rank points a rank, each rank contributing in
  // proportion to its points, one from each of equal strata of its rows; it builds the top tree
  // and sends it to all.
  void make_top_tree(const T* rows, std::size_t n, std::uint64_t first) {
    const std::uint64_t ranks = static_cast<std::uint64_t>(comm.size());
    const std::uint64_t per_rank = std::max<std::uint64_t>(1, params.sample_per_rank);
    const std::uint64_t row_bytes = dim * sizeof(T) + sizeof(Index);
    std::uint64_t target = per_rank > total / ranks ? total : per_rank * ranks;
    target = std::min(target, std::max(ranks, sample_bytes_cap / row_bytes));
    // This rank's share of the target, rounded so that the shares add up to it exactly.
    const std::uint64_t mine = target * (first + n) / total - target * first / total;
    std::vector<T> my_sample;
    std::vector<Index> my_index;
    comm.phase([&] {
      my_sample.resize(mine * dim);
      my_index.resize(mine);
      for (std::uint64_t j = 0; j < mine; ++j) {
        const std::uint64_t lo = j * n / mine, hi = (j + 1) * n / mine;
        const std::uint64_t row = lo + mix(first + j) % (hi - lo);
        std::copy_n(rows + row * dim, dim, my_sample.begin() + static_cast<std::ptrdiff_t>(j * dim));
        my_index[j] = static_cast<Index>(first + row);
      }
    });
    const bool root = comm.rank() == 0;
    const std::vector<std::uint64_t> counts = comm.gather_all(mine);
    std::vector<int> index_counts(counts.size()), index_displs(counts.size()), value_counts(counts.size()),
        value_displs(counts.size());
    std::uint64_t all = 0;
    for (std::size_t r = 0; r < counts.size(); ++r) {
      index_counts[r] = static_cast<int>(counts[r]);
      index_displs[r] = static_cast<int>(all);
      value_counts[r] = static_cast<int>(counts[r] * dim);
      value_displs[r] = static_cast<int>(all * dim);
      all += counts[r];
    }
    std::vector<T> sample;
    std::vector<Index> sample_index;
    comm.phase([&] {
      if (!root) return;
      sample.resize(all * dim);
      sample_index.resize(all);
    });
    MPI_Gatherv(my_sample.data(), static_cast<int>(mine * dim), mpi_type<T>(), sample.data(),
                value_counts.data(), value_displs.data(), mpi_type<T>(), 0, comm.get());
    MPI_Gatherv(my_index.data(), static_cast<int>(mine), MPI_UINT32_T, sample_index.data(),
                index_counts.data(), index_displs.data(), MPI_UINT32_T, 0, comm.get());
    if (!root && mine > 0) {
      ++build_traffic.messages;
      build_traffic.bytes += mine * row_bytes;
    }

    std::vector<unsigned char> tree_bytes;
    Failure error = Comm::run_catching([&] {
      if (root) tree_bytes = detail::TopTree<T>(sample, sample_index, dim, comm.size()).to_bytes();
    });
    const std::uint64_t size = comm.agree(error, {tree_bytes.size()}).front();
    comm.phase([&] { tree_bytes.resize(size); });
    MPI_Bcast(tree_bytes.data(), static_cast<int>(size), MPI_BYTE, 0, comm.get());
    if (root) {
      build_traffic.messages += ranks - 1;  // as if sent to each rank (MPI_Bcast relays it in log P steps)
      build_traffic.bytes += size * (ranks - 1);
    }
    build_traffic.exchanges += 1;
    comm.phase([&] { top.emplace(tree_bytes, dim); });
  }

  // Sends every point to the rank whose region holds it; fills original_index and points.
  void redistribute(const T* rows, std::size_t n, std::uint64_t first, std::vector<T>& points) {
    const std::size_t record = dim * sizeof(T) + sizeof(Index);
    Blocks send;
    Failure error = Comm::run_catching([&] {
      std::vector<int> owner(n);
      BlockWriter writer(comm.size());
      for (std::size_t i = 0; i < n; ++i) {
        owner[i] = top->rank_of_point(rows + i * dim, static_cast<Index>(first + i));
        writer.count(owner[i], record);
      }
      writer.start();
      for (std::size_t i = 0; i < n; ++i) {
        unsigned char* p = put(writer.put(owner[i], record), static_cast<Index>(first + i));
        std::memcpy(p, rows + i * dim, dim * sizeof(T));
      }
      send = writer.finish();
    });
    Blocks received = comm.exchange(send, build_traffic, error);
    send = {};
    comm.phase([&] {
      const std::size_t m = received.bytes.size() / record;
      points.resize(m * dim);
      original_index.resize(m);
      const unsigned char* p = received.bytes.data();
      for (std::size_t i = 0; i < m; ++i, p += record) {
        get(p, original_index[i]);
        std::memcpy(points.data() + i * dim, p + sizeof(Index), dim * sizeof(T));
      }
    });
  }

  // Every rank learns the bounding box of every rank's points.
  void share_boxes(const std::vector<T>& lo, const std::vector<T>& hi) {
    const std::size_t ranks = static_cast<std::size_t>(comm.size());
    std::vector<T> all_lo, all_hi;
    std::vector<std::uint8_t> has_points;
    comm.phase([&] {
      all_lo.resize(ranks * dim);
      all_hi.resize(ranks * dim);
      has_points.resize(ranks);
    });
    const std::uint8_t mine = tree ? 1 : 0;
    MPI_Allgather(lo.data(), static_cast<int>(dim), mpi_type<T>(), all_lo.data(), static_cast<int>(dim),
                  mpi_type<T>(), comm.get());
    MPI_Allgather(hi.data(), static_cast<int>(dim), mpi_type<T>(), all_hi.data(), static_cast<int>(dim),
                  mpi_type<T>(), comm.get());
    MPI_Allgather(&mine, 1, MPI_UINT8_T, has_points.data(), 1, MPI_UINT8_T, comm.get());
    comm.phase([&] { top->set_boxes(all_lo, all_hi, has_points); });
  }

  // ---- queries ----------------------------------------------------------------------------------

  // The queries of one round on the rank that brought them, and what came back for them.
  struct Round {
    std::size_t first = 0, count = 0;              // the rank's queries [first, first + count)
    std::vector<std::vector<std::uint32_t>> sent;  // per rank: the round's queries sent there, in order
    std::vector<std::vector<Candidate<T>>> found;  // per query of the round: candidates so far
  };

  // Blocks of query rows (and a bound after each, when given) for the ranks in round.sent.
  Blocks send_queries(const T* queries, const Round& round, const std::vector<T>* bounds) const {
    const std::size_t record = query_bytes(bounds != nullptr);
    BlockWriter writer(comm.size());
    for (int r = 0; r < comm.size(); ++r)
      writer.count(r, round.sent[static_cast<std::size_t>(r)].size() * record);
    writer.start();
    for (int r = 0; r < comm.size(); ++r)
      for (const std::uint32_t q : round.sent[static_cast<std::size_t>(r)]) {
        unsigned char* p = writer.put(r, record);
        std::memcpy(p, queries + (round.first + q) * dim, dim * sizeof(T));
        if (bounds) put(p + dim * sizeof(T), (*bounds)[q]);
      }
    return writer.finish();
  }

  // Searches this rank's points for the queries received (each with its bound when with_bound,
  // else +inf) and returns the answers in the order received: per query a uint32 count, then that
  // many (internal distance, original index). search(q, bound, results) fills a result set.
  template <class Search>
  Blocks answer(const Blocks& received, bool with_bound, unsigned threads, QueryStats& stats,
                const Search& search) const {
    const std::size_t record = query_bytes(with_bound), ranks = static_cast<std::size_t>(comm.size());
    const std::size_t n = received.bytes.size() / record;
    std::vector<std::vector<Candidate<T>>> results(n);
    std::vector<QueryStats> per_worker(kdspace::detail::resolve_threads(threads));
    if (tree)
      kdspace::detail::parallel_for(n, threads, 16, [&](std::size_t begin, std::size_t end, unsigned worker) {
        std::vector<T> q(dim);
        for (std::size_t i = begin; i < end; ++i) {
          const unsigned char* p = received.bytes.data() + i * record;
          std::memcpy(q.data(), p, dim * sizeof(T));
          T bound = std::numeric_limits<T>::infinity();
          if (with_bound) get(p + dim * sizeof(T), bound);
          search(q.data(), bound, results[i], per_worker[worker]);
        }
      });
    for (const QueryStats& s : per_worker) stats += s;

    BlockWriter writer(comm.size());
    std::size_t i = 0;
    for (std::size_t r = 0; r < ranks; ++r)
      for (std::uint64_t end = i + received.size(static_cast<int>(r)) / record; i < end; ++i)
        writer.count(static_cast<int>(r), sizeof(std::uint32_t) + results[i].size() * candidate_bytes);
    writer.start();
    i = 0;
    for (std::size_t r = 0; r < ranks; ++r)
      for (std::uint64_t end = i + received.size(static_cast<int>(r)) / record; i < end; ++i) {
        const auto& found = results[i];
        unsigned char* p =
            writer.put(static_cast<int>(r), sizeof(std::uint32_t) + found.size() * candidate_bytes);
        p = put(p, static_cast<std::uint32_t>(found.size()));
        for (const Candidate<T>& c : found) p = put(put(p, c.dist), original_index[c.index]);
      }
    return writer.finish();
  }

  // Adds the answers that came back to round.found, per query.
  void take_answers(const Blocks& back, Round& round, DistributedStats& stats) const {
    for (int r = 0; r < comm.size(); ++r) {
      if (r != comm.rank())
        stats.candidates +=
            (back.size(r) - round.sent[static_cast<std::size_t>(r)].size() * sizeof(std::uint32_t)) /
            candidate_bytes;
      const unsigned char* p = back.data(r);
      const unsigned char* end = p + back.size(r);
      for (const std::uint32_t q : round.sent[static_cast<std::size_t>(r)]) {
        std::uint32_t count = 0;
        if (p + sizeof count > end)
          throw Error("internal error: an answer block from rank " + std::to_string(r) + " is short");
        p = get(p, count);
        if (static_cast<std::size_t>(end - p) < count * candidate_bytes)
          throw Error("internal error: an answer block from rank " + std::to_string(r) + " is short");
        auto& found = round.found[q];
        for (std::uint32_t j = 0; j < count; ++j) {
          Candidate<T> c{};
          p = get(get(p, c.dist), c.index);
          found.push_back(c);
        }
      }
    }
  }

  // The first `keep` candidates of each query, in (internal distance, original index) order, as
  // true distances: the rows of the round, appended to out.
  static void merge(Round& round, std::size_t keep, NeighborLists<T>& out) {
    for (auto& found : round.found) {
      std::sort(found.begin(), found.end(), kdspace::detail::comes_before);
      if (found.size() > keep) found.resize(keep);
      for (const Candidate<T>& c : found)
        out.neighbors.push_back(Neighbor<T>{c.index, Metric::to_distance(c.dist)});
      out.offsets.push_back(out.neighbors.size());
      found = {};
    }
  }

  // One step out and back: each query of round.sent (with its bound, when bounds are given) goes to
  // its rank, which searches its points with search(q, bound, candidates, stats); the answers join
  // round.found. `error` is what this rank's work before the step threw, agreed on in the first
  // exchange; the returned failure, of the work after the second, is agreed on in the next one.
  template <class Search>
  Failure ask(const T* queries, Round& round, const std::vector<T>* bounds, Failure error, unsigned threads,
              const Search& search, DistributedStats& stats) const {
    Blocks send;
    if (!error) error = Comm::run_catching([&] { send = send_queries(queries, round, bounds); });
    const Blocks received = comm.exchange(send, stats.traffic, error);
    error = Comm::run_catching(
        [&] { send = answer(received, bounds != nullptr, threads, stats.search, search); });
    const Blocks back = comm.exchange(send, stats.traffic, error);
    return Comm::run_catching([&] { take_answers(back, round, stats); });
  }

  // A batch in rounds of up to queries_per_round queries a rank: steps(round, error) sends the
  // round's queries where they must go (ask) and returns the failure of its last local work; then
  // each query keeps its first `keep` candidates. check(): the batch's own checks, before any round.
  template <class Check, class Steps>
  NeighborLists<T> in_rounds(const T* queries, std::size_t nq, std::size_t keep, const Check& check,
                             const Steps& steps, DistributedStats& stats) const {
    const std::size_t per_round = std::max<std::size_t>(1, params.queries_per_round);
    Failure error = Comm::run_catching([&] {
      check();
      kdspace::detail::check_query_rows(queries, nq, dim);
    });
    // Every rank takes part in as many rounds as the rank with the most queries needs.
    const std::uint64_t rounds = comm.agree(error, {(nq + per_round - 1) / per_round}).front();
    NeighborLists<T> out;
    for (std::uint64_t r = 0; r < rounds; ++r) {
      Round round;
      round.first = std::min<std::uint64_t>(nq, r * per_round);
      round.count = std::min<std::size_t>(nq - round.first, per_round);
      round.sent.assign(static_cast<std::size_t>(comm.size()), {});
      round.found.assign(round.count, {});
      error = steps(round, error);
      if (!error) error = Comm::run_catching([&] { merge(round, keep, out); });
    }
    comm.agree(error);
    stats.queries += nq;
    stats.rounds += rounds;
    return out;
  }

  // The ranks whose points lie within internal distance limit[q] of each query of the round, but
  // `except[q]`, into round.sent.
  void send_within(const T* queries, Round& round, const std::vector<T>& limit,
                   const std::vector<int>& except, DistributedStats& stats) const {
    std::vector<T> scratch;
    for (auto& to : round.sent) to.clear();
    for (std::uint32_t q = 0; q < round.count; ++q)
      top->template ranks_within<Metric>(queries + (round.first + q) * dim, limit[q], scratch, [&](int r) {
        if (r != except[q]) round.sent[static_cast<std::size_t>(r)].push_back(q);
      });
    for (const auto& to : round.sent) stats.ranks_asked += to.size();
  }

  NeighborLists<T> knn(const T* queries, std::size_t nq, std::size_t k, unsigned threads,
                       DistributedStats& stats) const {
    auto search = [&](const T* q, T bound, std::vector<Candidate<T>>& found, QueryStats& qs) {
      kdspace::detail::KnnResults<T> results(k, bound, found);
      tree->query_with(q, results, SearchParams{}, &qs);
      results.sorted();
    };
    auto steps = [&](Round& round, Failure error) {
      // 1. Each query to the rank whose region holds it (home), for its k nearest there.
      std::vector<int> home(round.count);
      if (!error)
        error = Comm::run_catching([&] {
          for (std::uint32_t q = 0; q < round.count; ++q) {
            home[q] = top->rank_of_query(queries + (round.first + q) * dim);
            round.sent[static_cast<std::size_t>(home[q])].push_back(q);
          }
          stats.ranks_asked += round.count;
        });
      error = ask(queries, round, nullptr, error, threads, search, stats);
      // 2. Home's k-th distance bounds the answer: the query, with it, to the other ranks within it.
      std::vector<T> bounds(round.count);
      if (!error)
        error = Comm::run_catching([&] {
          for (std::uint32_t q = 0; q < round.count; ++q) {
            const auto& found = round.found[q];
            bounds[q] = found.size() == k ? found.back().dist : std::numeric_limits<T>::infinity();
          }
          send_within(queries, round, bounds, home, stats);
        });
      return ask(queries, round, &bounds, error, threads, search, stats);
    };
    return in_rounds(
        queries, nq, k, [&] { kdspace::detail::check_k(k, total); }, steps, stats);
  }

  NeighborLists<T> radius(const T* queries, std::size_t nq, T r, std::size_t max_results, unsigned threads,
                          DistributedStats& stats) const {
    const T limit = Metric::to_internal(r);  // as PointTree::radius_batch
    auto search = [&](const T* q, T /*bound*/, std::vector<Candidate<T>>& found, QueryStats& qs) {
      if (max_results < tree->size()) {
        kdspace::detail::KnnResults<T> results(max_results, limit, found);
        tree->query_with(q, results, SearchParams{}, &qs);
        results.sorted();
      } else {
        kdspace::detail::RangeResults<T> results(limit, found);
        tree->query_with(q, results, SearchParams{}, &qs);
        results.sorted();
      }
    };
    auto steps = [&](Round& round, Failure error) {
      // Each query to every rank whose points lie within r, for the points within r there.
      if (!error)
        error = Comm::run_catching([&] {
          send_within(queries, round, std::vector<T>(round.count, limit), std::vector<int>(round.count, -1),
                      stats);
        });
      return ask(queries, round, nullptr, error, threads, search, stats);
    };
    auto check = [&] {
      if (std::isnan(r) || r < 0)
        throw Error("radius must be a non-negative number, got " + std::to_string(r));
      if (max_results == 0) throw Error("max_results must be at least 1");
    };
    return in_rounds(queries, nq, max_results, check, steps, stats);
  }
};

template <class T, class Metric>
DistributedTree<T, Metric>::DistributedTree(MPI_Comm comm, const T* rows, std::size_t n, std::size_t dim,
                                            const DistributedParams& params)
    : impl_(std::make_unique<Impl>(comm)) {
  impl_->params = params;
  impl_->dim = dim;
  impl_->build(rows, n);
}

template <class T, class Metric>
DistributedTree<T, Metric>::~DistributedTree() = default;
template <class T, class Metric>
DistributedTree<T, Metric>::DistributedTree(DistributedTree&&) noexcept = default;
template <class T, class Metric>
DistributedTree<T, Metric>& DistributedTree<T, Metric>::operator=(DistributedTree&&) noexcept = default;

template <class T, class Metric>
NeighborLists<T> DistributedTree<T, Metric>::knn_batch(const T* queries, std::size_t nq, std::size_t k,
                                                       unsigned threads, DistributedStats* stats) const {
  DistributedStats local;
  NeighborLists<T> out = impl_->knn(queries, nq, k, threads, local);
  if (stats) *stats += local;
  return out;
}

template <class T, class Metric>
NeighborLists<T> DistributedTree<T, Metric>::radius_batch(const T* queries, std::size_t nq, T r,
                                                          std::size_t max_results, unsigned threads,
                                                          DistributedStats* stats) const {
  DistributedStats local;
  NeighborLists<T> out = impl_->radius(queries, nq, r, max_results, threads, local);
  if (stats) *stats += local;
  return out;
}

template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::size() const {
  return static_cast<std::size_t>(impl_->total);
}
template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::local_size() const {
  return impl_->original_index.size();
}
template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::dim() const {
  return impl_->dim;
}
template <class T, class Metric>
int DistributedTree<T, Metric>::ranks() const {
  return impl_->comm.size();
}
template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::local_depth() const {
  return impl_->tree ? impl_->tree->depth() : 0;
}
template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::local_leaves() const {
  return impl_->tree ? impl_->tree->leaf_count() : 0;
}
template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::local_nodes() const {
  return impl_->tree ? impl_->tree->node_count() : 0;
}
template <class T, class Metric>
std::size_t DistributedTree<T, Metric>::local_index_bytes() const {
  return (impl_->tree ? impl_->tree->index_bytes() : 0) + impl_->original_index.capacity() * sizeof(Index);
}
template <class T, class Metric>
const Traffic& DistributedTree<T, Metric>::build_traffic() const {
  return impl_->build_traffic;
}

template class DistributedTree<float, L2>;
template class DistributedTree<float, L1>;
template class DistributedTree<float, Linf>;
template class DistributedTree<double, L2>;
template class DistributedTree<double, L1>;
template class DistributedTree<double, Linf>;

}  // namespace kdspace::mpi
