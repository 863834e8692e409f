// The best-first search over a NeighborGraph, shared by PointForest's queries and by the graph's own
// build (which searches the graph for each point's neighbours).
//
// The search keeps the `ef` best points found so far (the pool), in result order, each marked once
// its list has been read. It starts from a few entry points, then repeatedly reads the list of the
// best point not yet expanded and scores every neighbour not seen before; it ends when every point
// of the pool is expanded (Malkov & Yashunin, "Efficient and robust approximate nearest neighbor
// search using Hierarchical Navigable Small World graphs", 2018, Alg. 2; Fu et al., "Fast
// Approximate Nearest Neighbor Search With The Navigating Spreading-out Graph", 2019, Alg. 1).
//
// What it costs is mostly waiting for rows: the rows of a list's new points are asked for
// (prefetched) together as soon as the list is read, and scored a few at a time by a scorer: at
// query time RowScorer (row_distances.hpp: the same bits as internal_distance(), so every distance
// in the pool is exact); while the graph is built, ByteRowScorer for byte rows (exact integers).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "kdspace/points/detail/neighbor_graph.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/detail/row_distances.hpp"
#include "kdspace/points/neighbor.hpp"

namespace kdspace::detail {

/// Asks for (prefetches) every cache line of the `bytes` bytes at `first`: those of its first and last
/// bytes, and any between. (A loop over the lines from the first byte missed a row's last line when
/// the row crossed one more line boundary than its length needs, and its bookkeeping was about 6% of
/// the graph build's instructions on 20-D rows.)
inline void prefetch_bytes(const void* first, std::size_t bytes) {
  const char* const p = static_cast<const char*>(first);
  __builtin_prefetch(p);
  for (std::size_t at = 64; at < bytes; at += 64) __builtin_prefetch(p + at);
  __builtin_prefetch(p + bytes - 1);
}

/// The `ef` best points found, in (distance, row) order; a row's top bit marks it expanded (rows
/// are below 2^30).
template <class T>
class GraphPool {
 public:
  static constexpr std::uint32_t expanded_bit = 0x80000000u;

  void reset(std::size_t ef) {
    ef_ = ef;
    size_ = 0;
    items_.resize(ef);
  }
  std::size_t size() const { return size_; }
  /// A point farther than this cannot enter (infinite while the pool is not full).
  T bound() const { return size_ == ef_ ? items_[size_ - 1].dist : std::numeric_limits<T>::infinity(); }
  T dist(std::size_t i) const { return items_[i].dist; }
  std::uint32_t row(std::size_t i) const { return items_[i].index & ~expanded_bit; }
  bool expanded(std::size_t i) const { return (items_[i].index & expanded_bit) != 0; }
  void expand(std::size_t i) { items_[i].index |= expanded_bit; }

  /// Inserts a point not in the pool; returns its position, or ef when it does not enter.
  std::size_t insert(T dist, std::uint32_t row) {
    auto before = [&](const Candidate<T>& c) {  // (dist, row) comes before c
      return dist < c.dist || (dist == c.dist && row < (c.index & ~expanded_bit));
    };
    if (size_ == ef_ && !before(items_[size_ - 1])) return ef_;
    std::size_t pos = size_ == ef_ ? size_ - 1 : size_;
    while (pos > 0 && before(items_[pos - 1])) {
      items_[pos] = items_[pos - 1];
      --pos;
    }
    items_[pos] = Candidate<T>{dist, row};
    if (size_ < ef_) ++size_;
    return pos;
  }

 private:
  std::size_t ef_ = 0, size_ = 0;
  std::vector<Candidate<T>> items_;
};

/// Per-thread working memory of graph searches, reused from search to search (nothing is
/// allocated once it has grown). seen[row] == epoch marks a row scored by the current search.
template <class T>
struct GraphScratch {
  std::vector<std::uint32_t> seen;
  std::uint32_t epoch = 0;
  GraphPool<T> pool;
  std::vector<std::uint32_t> fresh;
  std::vector<T> fresh_dist;

  void start(std::size_t n, std::size_t ef) {
    if (seen.size() != n) seen.assign(n, 0), epoch = 0;
    if (++epoch == 0) std::fill(seen.begin(), seen.end(), 0u), epoch = 1;
    pool.reset(ef);
  }
};

/// Scores rows of U (T, or bytes) against a query of T with the exact kernel: each distance is
/// internal_distance()'s, bit for bit, or, when above the limit, some value above it.
template <class T, class U>
class RowScorer {
 public:
  using Scalar = T;
  static constexpr std::size_t group = sizeof(T) == 4 ? 4 : 2;

  RowScorer(const U* rows, std::size_t dim, const T* q)
      : rows_(rows), dim_(dim), q_(q) {}
  void prefetch(std::uint32_t row) const { prefetch_bytes(rows_ + std::size_t{row} * dim_, dim_ * sizeof(U)); }
  /// Distances of the `group` rows ids[0, group).
  void operator()(const std::uint32_t* ids, T limit, T* out) const {
    const U* group_rows[group];
    for (std::size_t g = 0; g < group; ++g) group_rows[g] = rows_ + std::size_t{ids[g]} * dim_;
    l2_distances_or_more<group>(q_, group_rows, dim_, limit, out);
  }

 private:
  const U* rows_;
  std::size_t dim_;
  const T* q_;
};

/// Scores byte rows against a byte query (given widened to 16 bits), exactly, in integers
/// (l2_byte_distances); the distances are then converted to T.
template <class T>
class ByteRowScorer {
 public:
  using Scalar = T;
  static constexpr std::size_t group = 4;

  ByteRowScorer(const std::uint8_t* rows, std::size_t dim, const std::int16_t* q)
      : rows_(rows), dim_(dim), q_(q) {}
  void prefetch(std::uint32_t row) const { prefetch_bytes(rows_ + std::size_t{row} * dim_, dim_); }
  void operator()(const std::uint32_t* ids, T, T* out) const {
    const std::uint8_t* group_rows[group];
    for (std::size_t g = 0; g < group; ++g) group_rows[g] = rows_ + std::size_t{ids[g]} * dim_;
    std::uint32_t dist[group];
    l2_byte_distances<group>(q_, group_rows, dim_, dist);
    for (std::size_t g = 0; g < group; ++g) out[g] = static_cast<T>(dist[g]);
  }

 private:
  const std::uint8_t* rows_;
  std::size_t dim_;
  const std::int16_t* q_;
};

/// Where a graph search starts: rows to score, and rows whose distances are known already (distinct,
/// and not among the rows to score); `seen` rows are left out of the search altogether.
template <class T>
struct GraphEntries {
  const std::uint32_t* rows = nullptr;
  std::size_t row_count = 0;
  const Candidate<T>* known = nullptr;
  std::size_t known_count = 0;
  const std::uint32_t* seen = nullptr;
  std::size_t seen_count = 0;
};

/// Best-first search of `graph` (over n rows) for the query that `score` scores rows against, from
/// `entries`, keeping the ef best: on return s.pool holds them in (distance, row) order, with the
/// scorer's distances. Adds to stats.points_visited (points scored) and stats.nodes_visited (lists
/// read).
template <class T, class Scorer>
void graph_search(const NeighborGraph& graph, std::size_t n, const Scorer& score, const GraphEntries<T>& entries,
                  std::size_t ef, GraphScratch<T>& s, QueryStats& stats) {
  constexpr std::size_t group = Scorer::group;
  s.start(n, ef);
  GraphPool<T>& pool = s.pool;
  std::uint32_t* const seen = s.seen.data();
  const std::uint32_t epoch = s.epoch;
  std::uint64_t scored = 0, expanded = 0;

  // s.fresh[0, fresh_count): the rows to score next (with room for a last group's repeats), and
  // s.fresh_dist their distances.
  const std::size_t most_fresh = std::max(graph.degree, entries.row_count) + group;
  if (s.fresh.size() < most_fresh) s.fresh.resize(most_fresh), s.fresh_dist.resize(most_fresh);
  std::uint32_t* const fresh = s.fresh.data();
  T* const fresh_dist = s.fresh_dist.data();
  std::size_t fresh_count = 0;

  // Scores the fresh rows, then offers each to the pool; returns the first position a point entered
  // at. Each group is scored against the pool's bound before any of them is offered (which only
  // lowers it): the offers are one loop over the rows, not one per group whose end depends on how
  // many rows are fresh (a branch mispredicted once a group).
  auto score_fresh = [&] {
    std::size_t first_entered = pool.size();
    const std::size_t count = fresh_count;
    const T limit = pool.bound();
    for (std::size_t i = count; i < count + group; ++i) fresh[i] = fresh[count > 0 ? count - 1 : 0];
    for (std::size_t first = 0; first < count; first += group) score(fresh + first, limit, fresh_dist + first);
    for (std::size_t i = 0; i < count; ++i) {
      if (!(fresh_dist[i] <= limit)) continue;  // may be a partial sum: never offered
      const std::size_t pos = pool.insert(fresh_dist[i], fresh[i]);
      first_entered = std::min(first_entered, pos);
    }
    scored += count;
    return first_entered;
  };
  // The rows of `rows` not seen before become the fresh rows, marked seen, and are asked for. Whether
  // a row was seen is not a branch (a row is written to the next free slot, which moves on only when
  // the row is new): on a branch, about half the rows were mispredicted.
  auto take = [&](const std::uint32_t* rows, std::size_t count) {
    fresh_count = 0;
    for (std::size_t i = 0; i < count; ++i) {
      const std::uint32_t v = rows[i];
      fresh[fresh_count] = v;
      fresh_count += seen[v] != epoch ? 1 : 0;
      seen[v] = epoch;
    }
    for (std::size_t i = 0; i < fresh_count; ++i) score.prefetch(fresh[i]);
  };

  for (std::size_t i = 0; i < entries.seen_count; ++i) seen[entries.seen[i]] = epoch;
  for (std::size_t i = 0; i < entries.known_count; ++i) {
    seen[entries.known[i].index] = epoch;
    pool.insert(entries.known[i].dist, entries.known[i].index);
  }
  take(entries.rows, entries.row_count);
  score_fresh();

  // Invariant: every point of the pool before `cursor` is expanded.
  std::size_t cursor = 0;
  for (;;) {
    while (cursor < pool.size() && pool.expanded(cursor)) ++cursor;
    if (cursor == pool.size()) break;
    pool.expand(cursor);
    ++expanded;
    const std::uint32_t u = pool.row(cursor);
    const std::uint32_t* list = graph.neighbours(u);
    std::size_t length = 0;
    while (length < graph.degree && list[length] != u) ++length;  // the padding: the list ends there
    take(list, length);
    cursor = std::min(cursor, score_fresh());
  }
  stats.points_visited += scored;
  stats.nodes_visited += expanded;
}

}  // namespace kdspace::detail
