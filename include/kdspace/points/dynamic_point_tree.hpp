// DynamicPointTree<T, Dim, Metric>: a point index that takes insertions and removals without a full
// rebuild, and answers exactly as a PointTree built afresh over the points it holds.
//
// The logarithmic method (Bentley & Saxe, "Decomposable searching problems I: static-to-dynamic
// transformation", J. Algorithms 1, 1980) with tombstones (Overmars, "The Design of Dynamic Data
// Structures", 1983):
//  - The points live in a few static PointTrees, the parts; a part at level i holds at most
//    base_capacity * 2^i points (64 * 2^i by default). An insertion makes a part of the new points;
//    on its way up from level 0 it takes in (rebuilds as one with) every part it meets, until it
//    fits its level.
//    A point is rebuilt O(log n) times over its life, and there are O(log n) parts.
//  - The newest points, up to base_capacity of them, wait in a buffer that queries score one by
//    one: inserting a point then copies the buffer rather than building a tree; a full buffer
//    becomes the insertion that goes up the levels.
//  - A removal marks the point dead in its part (a tombstone) and queries skip it. A part whose dead
//    points outnumber its live ones is rebuilt without them (dropped when none is left).
//  - Ids: a point keeps the id it was given until it is removed (insert() gives consecutive ids and
//    returns the first); ids are never reused.
//
// Exactness. A part is a PointTree built over its points in ascending id order, so its local index
// order is their id order. A query runs the traversal of every part into one result set, which sees
// each candidate under its id (the buffer's points too) and keeps the first k in (internal distance,
// id) order, the tie rule
// of PointTree; every part prunes only cells that cannot hold a point ahead of the k-th so far. The
// answer is therefore the first k live points in that order: bit for bit what a PointTree built
// afresh over the live points (in id order) answers, its indices mapped to ids.
//
// Threads. Queries are const and may run on any number of threads, also while another thread inserts
// or removes. A query (a whole batch) works on the snapshot that is current when it starts: it sees
// every update that returned before it began, and an update that runs meanwhile whole or not at all.
// Updates are serialized by an internal mutex. They never wait for queries, nor queries for them: a
// query keeps the parts it searches alive until it ends, and a removal marks a tombstone with the
// number of the update, which queries of older snapshots ignore.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "kdspace/detail/storage.hpp"
#include "kdspace/error.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/detail/input_checks.hpp"
#include "kdspace/points/detail/neighbor_output.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/neighbor.hpp"
#include "kdspace/points/params.hpp"
#include "kdspace/points/point_tree.hpp"

namespace kdspace {

namespace detail {

/// One part of a DynamicPointTree as stored: its tree, the id of each local index (ascending), the
/// local indices removed (ascending) and its level.
template <class T>
struct DynamicPartParts {
  PointTreeParts<T> tree;
  Storage<Index> ids;
  Storage<std::uint32_t> removed;
  std::size_t level = 0;
};

/// Everything a DynamicPointTree is made of; `backing` keeps borrowed storage alive.
template <class T>
struct DynamicTreeParts {
  std::size_t dim = 0;
  BuildParams params;
  std::size_t base_capacity = 64;
  std::uint64_t next_id = 0;
  std::vector<DynamicPartParts<T>> parts;
  Storage<Index> buffer_ids;  ///< the points not yet in a tree: ids, ascending
  Storage<T> buffer_rows;     ///< and their coordinates
  std::shared_ptr<const void> backing;
};

/// The tombstones of a part: for each local index the number of the update that removed it (never
/// removed: not_removed). Written only under the update mutex, read by queries of any snapshot.
struct Tombstones {
  static constexpr std::uint64_t not_removed = std::numeric_limits<std::uint64_t>::max();
  explicit Tombstones(std::size_t n) : removed_at(new std::atomic<std::uint64_t>[n]), size(n) {
    for (std::size_t i = 0; i < n; ++i) removed_at[i].store(not_removed, std::memory_order_relaxed);
  }
  std::unique_ptr<std::atomic<std::uint64_t>[]> removed_at;
  std::size_t size;
};

/// The result-set rule of one part: offers its points under their ids to the result set that all
/// parts share, and skips the points removed as of the query's snapshot.
template <class T, class Shared, bool WithTombstones>
class PartResults {
 public:
  PartResults(Shared& shared, const Index* ids, const std::atomic<std::uint64_t>* removed_at,
              std::uint64_t version)
      : shared_(shared), ids_(ids), removed_at_(removed_at), version_(version) {}

  T bound() const { return shared_.bound(); }
  bool full() const { return shared_.full(); }

  /// False only when this candidate, and any later one at the same distance with a larger index,
  /// is refused (the traversal stops scanning a leaf of identical points then); a removed point is
  /// skipped, not refused.
  bool offer(T dist, std::uint32_t local) {
    if (dist > shared_.bound()) return false;  // cheap refusal before the id is read
    if constexpr (WithTombstones) {
      if (removed_at_[local].load(std::memory_order_relaxed) <= version_) return true;
    }
    return shared_.offer(dist, ids_[local]);
  }

 private:
  Shared& shared_;
  const Index* ids_;
  const std::atomic<std::uint64_t>* removed_at_;
  std::uint64_t version_;
};

}  // namespace detail

template <class T, int Dim = Dynamic, class Metric = L2>
class DynamicPointTree {
 public:
  using Scalar = T;
  using Tree = PointTree<T, Dim, Metric>;

  /// The default capacity of level 0: small enough that rebuilding it for one inserted point costs
  /// about a microsecond.
  static constexpr std::size_t default_base_capacity = 64;

  /// An empty index of points of `dim` coordinates; `params` builds every part; parts at level i
  /// hold up to base_capacity * 2^i points.
  /// `metric` matters only for a metric with state (Minkowski(p)).
  explicit DynamicPointTree(std::size_t dim, const BuildParams& params = {},
                            std::size_t base_capacity = default_base_capacity, const Metric& metric = {})
      : dim_(dim), params_(params), base_capacity_(base_capacity), metric_(metric) {
    if (dim == 0) throw Error("points have dimension 0");
    if (base_capacity == 0 || base_capacity > (std::size_t{1} << 30))
      throw Error("base_capacity must be from 1 to 2^30, got " + std::to_string(base_capacity));
    if (Dim != Dynamic && dim != static_cast<std::size_t>(Dim))
      throw Error("points have dimension " + std::to_string(dim) + ", this tree is built for dimension " +
                  std::to_string(Dim));
    check_build_params(params);
    publish(std::make_shared<Snapshot>());
  }

  /// An index of n points with ids 0 .. n-1 (one part, as a PointTree over them).
  DynamicPointTree(const T* rows, std::size_t n, std::size_t dim, const BuildParams& params = {},
                   const Metric& metric = {})
      : DynamicPointTree(dim, params, default_base_capacity, metric) {
    insert(rows, n);
  }

  /// Made of `parts` (from parts(), or loaded from an index file: io/index.hpp), after checking them
  /// whole: each tree as PointTree's parts constructor does, ids ascending within a part, distinct
  /// across parts and below next_id, removed rows in range. Throws Error otherwise.
  explicit DynamicPointTree(detail::DynamicTreeParts<T> parts, const Metric& metric = {})
      : DynamicPointTree(parts.dim, parts.params, parts.base_capacity, metric) {
    auto snap = std::make_shared<Snapshot>();
    if (parts.next_id > std::uint64_t{std::numeric_limits<Index>::max()} + 1)
      throw Error("updatable point tree: next id " + std::to_string(parts.next_id) + " exceeds 2^32");
    snap->next_id = parts.next_id;
    std::vector<bool> level_taken(max_levels, false);
    for (std::size_t p = 0; p < parts.parts.size(); ++p) {
      auto& in = parts.parts[p];
      const std::string where = "updatable point tree: part " + std::to_string(p) + ": ";
      if (in.level >= max_levels || level_taken[in.level])
        throw Error(where + "level " + std::to_string(in.level) + " is out of range or taken twice");
      level_taken[in.level] = true;
      if (in.tree.params.axis != params_.axis || in.tree.params.position != params_.position ||
          in.tree.params.leaf_size != params_.leaf_size || in.tree.params.max_depth != params_.max_depth)
        throw Error(where + "built with other parameters than the index");
      Part part;
      try {
        part.tree = std::make_shared<const Tree>(std::move(in.tree), metric_);
      } catch (const Error& e) {
        throw Error(where + e.what());
      }
      const std::size_t n = part.tree->size();
      if (in.ids.size() != n)
        throw Error(where + std::to_string(in.ids.size()) + " ids for " + std::to_string(n) + " points");
      for (std::size_t i = 0; i < n; ++i)
        if (in.ids[i] >= parts.next_id || (i > 0 && in.ids[i] <= in.ids[i - 1]))
          throw Error(where + "id " + std::to_string(in.ids[i]) + " at row " + std::to_string(i) +
                      " is not ascending or not below the next id");
      part.ids = std::make_shared<const detail::Storage<Index>>(std::move(in.ids));
      if (!in.removed.empty()) {
        part.tombstones = std::make_shared<detail::Tombstones>(n);
        for (std::size_t i = 0; i < in.removed.size(); ++i) {
          const std::uint32_t local = in.removed[i];
          if (local >= n || (i > 0 && local <= in.removed[i - 1]))
            throw Error(where + "removed row " + std::to_string(local) + " is not ascending or out of range");
          part.tombstones->removed_at[local].store(0, std::memory_order_relaxed);
        }
        part.dead = in.removed.size();
        if (part.dead == n) throw Error(where + "every point is removed");
      }
      part.level = in.level;
      part.backing = parts.backing;
      snap->live += n - part.dead;
      snap->parts.push_back(std::move(part));
    }
    if (!parts.buffer_ids.empty()) {
      const std::size_t m = parts.buffer_ids.size();
      const std::string where = "updatable point tree: buffer: ";
      if (m > base_capacity_ || parts.buffer_rows.size() != m * dim())
        throw Error(where + std::to_string(m) + " points, or rows of the wrong size");
      for (std::size_t i = 0; i < m; ++i)
        if (parts.buffer_ids[i] >= parts.next_id || (i > 0 && parts.buffer_ids[i] <= parts.buffer_ids[i - 1]))
          throw Error(where + "id " + std::to_string(parts.buffer_ids[i]) +
                      " is not ascending or not below the next id");
      try {
        detail::check_points(parts.buffer_rows.data(), m, dim());
      } catch (const Error& e) {
        throw Error(where + e.what());
      }
      auto buffer = std::make_shared<Buffer>();
      buffer->ids.assign(parts.buffer_ids.begin(), parts.buffer_ids.end());
      buffer->rows.assign(parts.buffer_rows.begin(), parts.buffer_rows.end());
      snap->live += m;
      snap->buffer = std::move(buffer);
    }
    check_distinct_ids(*snap);
    sort_parts(*snap);
    snap->version = 1;
    publish(std::move(snap));
  }

  DynamicPointTree(DynamicPointTree&& o) noexcept
      : dim_(o.dim_),
        params_(o.params_),
        base_capacity_(o.base_capacity_),
        metric_(o.metric_),
        sync_(std::move(o.sync_)),
        snapshot_(std::move(o.snapshot_)) {}
  DynamicPointTree& operator=(DynamicPointTree&& o) noexcept {
    dim_ = o.dim_;
    params_ = o.params_;
    base_capacity_ = o.base_capacity_;
    metric_ = o.metric_;
    sync_ = std::move(o.sync_);
    snapshot_ = std::move(o.snapshot_);
    return *this;
  }

  // ---- updates (one at a time; queries may run meanwhile) -------------------------------------------

  /// Adds n points (row-major, dim() coordinates each); they get the ids first, first + 1, ...,
  /// first + n - 1, where `first` is returned (next_id() before the call). n = 0 adds nothing.
  /// Throws Error for non-finite coordinates (nothing is added then) or when ids run out (2^32).
  Index insert(const T* rows, std::size_t n) {
    if (n > 0) detail::check_points(rows, n, dim());
    std::lock_guard<std::mutex> lock(sync_->update);
    const std::shared_ptr<const Snapshot> current = snapshot_;  // alive until the update returns
    const Snapshot& cur = *current;
    if (n == 0) return static_cast<Index>(cur.next_id);
    if (cur.next_id + n > std::uint64_t{std::numeric_limits<Index>::max()} + 1)
      throw Error("insert: ids exhausted (" + std::to_string(cur.next_id) + " given out, at most 2^32)");
    if (cur.live + n >= (std::size_t{1} << 30))
      throw Error("insert: at most 2^30 - 1 points, " + std::to_string(cur.live) + " held and " +
                  std::to_string(n) + " more");
    auto next = std::make_shared<Snapshot>(cur);
    // The buffer and the new points: still a buffer, or an insertion going up the levels.
    auto carry = std::make_shared<Buffer>(cur.buffer ? *cur.buffer : Buffer{});
    for (std::size_t i = 0; i < n; ++i) carry->ids.push_back(static_cast<Index>(cur.next_id + i));
    carry->rows.insert(carry->rows.end(), rows, rows + n * dim());
    next->next_id = cur.next_id + n;
    next->live = cur.live + n;
    if (carry->ids.size() <= base_capacity_) {
      next->buffer = std::move(carry);
    } else {
      next->buffer = nullptr;
      place(*next, Carry{std::move(carry->ids), std::move(carry->rows)});
    }
    finish_update(std::move(next));
    return static_cast<Index>(cur.next_id);
  }

  /// Removes the points with these ids. Throws Error, removing nothing, when an id is not held (never
  /// given, or already removed) or appears twice.
  void remove(const Index* ids, std::size_t n) {
    if (n == 0) return;
    if (ids == nullptr) throw Error("remove: null pointer");
    std::lock_guard<std::mutex> lock(sync_->update);
    const std::shared_ptr<const Snapshot> current = snapshot_;  // alive until the update returns
    const Snapshot& cur = *current;
    // Find every id first, so that a bad one leaves the index as it was.
    std::vector<Index> listed(ids, ids + n);
    std::sort(listed.begin(), listed.end());
    const auto twice = std::adjacent_find(listed.begin(), listed.end());
    if (twice != listed.end()) throw Error("remove: id " + std::to_string(*twice) + " is given twice");
    std::vector<std::pair<std::size_t, std::uint32_t>> where;  // (part, local index) of those in parts
    std::vector<Index> from_buffer;
    for (std::size_t i = 0; i < n; ++i) {
      std::pair<std::size_t, std::uint32_t> at;
      if (in_buffer(cur, ids[i]))
        from_buffer.push_back(ids[i]);
      else if (locate(cur, ids[i], at))
        where.push_back(at);
      else
        throw Error("remove: id " + std::to_string(ids[i]) +
                    " is not in the index (never given, or removed)");
    }

    auto next = std::make_shared<Snapshot>(cur);
    next->version = cur.version + 1;
    if (!from_buffer.empty()) {
      std::sort(from_buffer.begin(), from_buffer.end());
      auto buffer = std::make_shared<Buffer>();
      for (std::size_t i = 0; i < cur.buffer->ids.size(); ++i) {
        if (std::binary_search(from_buffer.begin(), from_buffer.end(), cur.buffer->ids[i])) continue;
        buffer->ids.push_back(cur.buffer->ids[i]);
        buffer->rows.insert(buffer->rows.end(), cur.buffer->rows.begin() + static_cast<long>(i * dim()),
                            cur.buffer->rows.begin() + static_cast<long>((i + 1) * dim()));
      }
      next->buffer = buffer->ids.empty() ? nullptr : std::move(buffer);
    }
    for (const auto& [p, local] : where) {
      Part& part = next->parts[p];
      if (!part.tombstones) part.tombstones = std::make_shared<detail::Tombstones>(part.tree->size());
      part.tombstones->removed_at[local].store(next->version, std::memory_order_relaxed);
      ++part.dead;
    }
    next->live = cur.live - n;
    // Parts mostly dead are rebuilt without their dead points, where they are.
    std::vector<Part> kept;
    for (Part& part : next->parts) {
      if (2 * part.dead <= part.tree->size()) {
        kept.push_back(std::move(part));
        continue;
      }
      Carry live;
      take_live(part, live);
      if (!live.ids.empty()) kept.push_back(build_part(std::move(live), part.level));
    }
    next->parts = std::move(kept);
    finish_update(std::move(next));
  }
  void remove(Index id) { remove(&id, 1); }

  /// Rebuilds everything into one part without removed points: queries then cost what a PointTree's
  /// over the same points do.
  void compact() {
    std::lock_guard<std::mutex> lock(sync_->update);
    const std::shared_ptr<const Snapshot> current = snapshot_;  // alive until the update returns
    const Snapshot& cur = *current;
    if (!cur.buffer && cur.parts.size() <= 1 && (cur.parts.empty() || cur.parts[0].dead == 0)) return;
    auto next = std::make_shared<Snapshot>(cur);
    next->parts.clear();
    next->buffer = nullptr;
    Carry carry;
    if (cur.buffer) carry = Carry{cur.buffer->ids, cur.buffer->rows};
    place(*next, std::move(carry), &cur.parts);
    finish_update(std::move(next));
  }

  // ---- what it holds ----------------------------------------------------------------------------

  /// Points held (removed ones not counted).
  std::size_t size() const { return snapshot()->live; }
  std::size_t dim() const {
    if constexpr (Dim == Dynamic)
      return dim_;
    else
      return static_cast<std::size_t>(Dim);
  }
  const BuildParams& params() const { return params_; }
  std::size_t base_capacity() const { return base_capacity_; }
  const Metric& metric() const { return metric_; }
  /// The id the next inserted point gets.
  std::uint64_t next_id() const { return snapshot()->next_id; }
  /// Whether a point of this id is held.
  bool contains(Index id) const {
    const auto snap = snapshot();
    std::pair<std::size_t, std::uint32_t> at;
    return in_buffer(*snap, id) || locate(*snap, id, at);
  }
  /// The newest points, not yet in a tree (at most base_capacity()).
  std::size_t buffered() const {
    const auto snap = snapshot();
    return snap->buffer ? snap->buffer->ids.size() : 0;
  }
  /// The static trees the points are in, and the removed points they still hold.
  std::size_t part_count() const { return snapshot()->parts.size(); }
  std::size_t removed_count() const {
    std::size_t dead = 0;
    const auto snap = snapshot();  // held: a range-for over snapshot()->parts would outlive it
    for (const Part& p : snap->parts) dead += p.dead;
    return dead;
  }
  /// Deepest part, and leaves and nodes over all parts.
  std::size_t depth() const {
    return sum_over_parts([](const Tree& t) { return t.depth(); }, true);
  }
  std::size_t leaf_count() const {
    return sum_over_parts([](const Tree& t) { return t.leaf_count(); });
  }
  std::size_t node_count() const {
    return sum_over_parts([](const Tree& t) { return t.node_count(); });
  }
  /// Bytes held: the parts' trees, their ids and tombstones.
  std::size_t memory_bytes() const {
    const auto snap = snapshot();
    return index_bytes() + sum_over_parts([](const Tree& t) { return t.memory_bytes() - t.index_bytes(); }) +
           (snap->buffer ? snap->buffer->rows.capacity() * sizeof(T) : 0);
  }
  /// Bytes held besides the copies of the points.
  std::size_t index_bytes() const {
    const auto snap = snapshot();
    std::size_t bytes = snap->buffer ? snap->buffer->ids.capacity() * sizeof(Index) : 0;
    for (const Part& p : snap->parts)
      bytes += p.tree->index_bytes() + p.ids->memory_bytes() +
               (p.tombstones ? p.tombstones->size * sizeof(std::uint64_t) : 0);
    return bytes;
  }

  // ---- queries (const, thread-safe, also during updates) --------------------------------------------

  /// The k nearest live points to q, ascending distance, ties by ascending id; 1 <= k <= size().
  /// With params.eps > 0 the i-th result is within (1 + eps) of the true i-th (max_checks applies to
  /// each part).
  std::vector<Neighbor<T>> knn(const T* q, std::size_t k, const SearchParams& params = {},
                               QueryStats* stats = nullptr) const {
    const auto snap = snapshot();
    check_knn(*snap, k, params);
    detail::check_finite(q, dim(), "query");
    std::vector<detail::Candidate<T>> scratch;
    detail::KnnResults<T> results(k, std::numeric_limits<T>::infinity(), scratch);
    QueryStats local;
    search_parts(*snap, q, results, params, local);
    return detail::finish_query(metric_, results.sorted(), stats, local);
  }

  /// Every live point within distance r of q (closed ball), ascending distance then id; with
  /// max_results, the max_results nearest of them.
  std::vector<Neighbor<T>> radius(const T* q, T r,
                                  std::size_t max_results = std::numeric_limits<std::size_t>::max(),
                                  QueryStats* stats = nullptr) const {
    const auto snap = snapshot();
    check_radius(r);
    detail::check_finite(q, dim(), "query");
    std::vector<detail::Candidate<T>> scratch;
    QueryStats local;
    radius_into(*snap, q, metric_.to_internal(r), max_results, scratch, local);
    return detail::finish_query(metric_, scratch, stats, local);
  }

  /// Ids of the live points p with lo <= p <= hi on every axis, ascending.
  std::vector<Index> box(const T* lo, const T* hi, QueryStats* stats = nullptr) const {
    const auto snap = snapshot();
    if (lo == nullptr || hi == nullptr) throw Error("box: null pointer");
    for (std::size_t a = 0; a < dim(); ++a) {
      if (std::isnan(lo[a]) || std::isnan(hi[a]))
        throw Error("box: coordinate " + std::to_string(a + 1) + " of a corner is NaN");
      if (lo[a] > hi[a])
        throw Error("box: lower corner exceeds upper corner at coordinate " + std::to_string(a + 1));
    }
    std::vector<Index> found;
    QueryStats local;
    for (const Part& part : snap->parts) {
      for (Index i : part.tree->box(lo, hi, &local))
        if (!removed(part, i, snap->version)) found.push_back((*part.ids)[i]);
    }
    if (snap->buffer) {
      const Buffer& b = *snap->buffer;
      for (std::size_t i = 0; i < b.ids.size(); ++i) {
        bool inside = true;
        for (std::size_t a = 0; a < dim() && inside; ++a)
          inside = lo[a] <= b.rows[i * dim() + a] && b.rows[i * dim() + a] <= hi[a];
        if (inside) found.push_back(b.ids[i]);
      }
      local.points_visited += b.ids.size();
    }
    std::sort(found.begin(), found.end());
    local.queries = 1;
    if (stats) *stats += local;
    return found;
  }

  /// nq queries, row-major, on `threads` threads (0 = all); the same answers as one thread.
  NeighborLists<T> knn_batch(const T* queries, std::size_t nq, std::size_t k, const SearchParams& params = {},
                             unsigned threads = 0, QueryStats* stats = nullptr) const {
    const auto snap = snapshot();
    check_knn(*snap, k, params);
    detail::check_query_rows(queries, nq, dim());
    if (snap->parts.size() == 1 && !snap->parts[0].tombstones && !snap->buffer) {
      // One whole part: its own batch (which may choose the blocked scan), indices mapped to ids.
      const Part& part = snap->parts[0];
      NeighborLists<T> out = part.tree->knn_batch(queries, nq, k, params, threads, stats);
      for (Neighbor<T>& nb : out.neighbors) nb.index = (*part.ids)[nb.index];
      return out;
    }
    NeighborLists<T> out;
    out.offsets.resize(nq + 1);
    for (std::size_t q = 0; q <= nq; ++q) out.offsets[q] = q * k;
    out.neighbors.resize(nq * k);
    std::vector<QueryStats> per_worker(detail::resolve_threads(threads));
    detail::parallel_for(nq, threads, 64, [&](std::size_t begin, std::size_t end, unsigned worker) {
      std::vector<detail::Candidate<T>> scratch;
      for (std::size_t q = begin; q < end; ++q) {
        detail::KnnResults<T> results(k, std::numeric_limits<T>::infinity(), scratch);
        QueryStats local;
        search_parts(*snap, queries + q * dim(), results, params, local);
        detail::write_neighbors(metric_, results.sorted(), out.neighbors.data() + q * k);
        per_worker[worker] += local;
      }
    });
    detail::sum_stats(per_worker, stats);
    return out;
  }

  NeighborLists<T> radius_batch(const T* queries, std::size_t nq, T r,
                                std::size_t max_results = std::numeric_limits<std::size_t>::max(),
                                unsigned threads = 0, QueryStats* stats = nullptr) const {
    const auto snap = snapshot();
    check_radius(r);
    detail::check_query_rows(queries, nq, dim());
    const T limit = metric_.to_internal(r);
    std::vector<std::vector<Neighbor<T>>> rows(nq);
    std::vector<QueryStats> per_worker(detail::resolve_threads(threads));
    detail::parallel_for(nq, threads, 64, [&](std::size_t begin, std::size_t end, unsigned worker) {
      std::vector<detail::Candidate<T>> scratch;
      for (std::size_t q = begin; q < end; ++q) {
        radius_into(*snap, queries + q * dim(), limit, max_results, scratch, per_worker[worker]);
        rows[q].resize(scratch.size());
        detail::write_neighbors(metric_, scratch, rows[q].data());
      }
    });
    NeighborLists<T> out;
    out.offsets.resize(nq + 1);
    for (std::size_t q = 0; q < nq; ++q) out.offsets[q + 1] = out.offsets[q] + rows[q].size();
    out.neighbors.reserve(out.offsets[nq]);
    for (auto& row : rows) out.neighbors.insert(out.neighbors.end(), row.begin(), row.end());
    detail::sum_stats(per_worker, stats);
    return out;
  }

  /// A consistent view of the whole index (what an index file stores), borrowed: `backing` keeps
  /// it alive.
  detail::DynamicTreeParts<T> parts() const {
    const auto snap = snapshot();
    detail::DynamicTreeParts<T> out;
    out.dim = dim();
    out.params = params_;
    out.base_capacity = base_capacity_;
    out.next_id = snap->next_id;
    out.backing = snap;
    for (const Part& part : snap->parts) {
      detail::DynamicPartParts<T> p;
      p.tree = part.tree->parts();
      p.ids = detail::Storage<Index>::borrow(part.ids->data(), part.ids->size());
      std::vector<std::uint32_t> dead;
      if (part.tombstones)
        for (std::uint32_t i = 0; i < part.tree->size(); ++i)
          if (removed(part, i, snap->version)) dead.push_back(i);
      p.removed = detail::Storage<std::uint32_t>(std::move(dead));
      p.level = part.level;
      out.parts.push_back(std::move(p));
    }
    if (snap->buffer) {
      out.buffer_ids = detail::Storage<Index>::borrow(snap->buffer->ids.data(), snap->buffer->ids.size());
      out.buffer_rows = detail::Storage<T>::borrow(snap->buffer->rows.data(), snap->buffer->rows.size());
    }
    return out;
  }

 private:
  static constexpr std::size_t max_levels = 40;

  struct Part {
    std::shared_ptr<const Tree> tree;                   // over the part's points in ascending id order
    std::shared_ptr<const detail::Storage<Index>> ids;  // id of each local index, ascending
    std::shared_ptr<detail::Tombstones> tombstones;     // null until a point of the part is removed
    std::shared_ptr<const void> backing;                // keeps borrowed ids alive (a loaded file)
    std::size_t level = 0;
    std::size_t dead = 0;  // removed points (the update mutex's view)
  };
  // The newest points, not yet in a tree: ids ascending, and their rows.
  struct Buffer {
    std::vector<Index> ids;
    std::vector<T> rows;
  };
  struct Snapshot {
    std::uint64_t version = 1;             // the number of the update that made it
    std::vector<Part> parts;               // largest first: its k-th bound prunes the small ones early
    std::shared_ptr<const Buffer> buffer;  // null when empty
    std::size_t live = 0;
    std::uint64_t next_id = 0;
  };
  // Points on their way into a part: ids (in any order until built) and their rows.
  struct Carry {
    std::vector<Index> ids;
    std::vector<T> rows;
  };
  struct Sync {
    std::mutex update;    // one update at a time
    std::mutex snapshot;  // guards the pointer snapshot_ (held for a copy of it only)
  };

  static void check_build_params(const BuildParams& params) {
    if (params.leaf_size == 0) throw Error("leaf_size must be at least 1");
    if (params.max_depth > 256)
      throw Error("max_depth must be at most 256, got " + std::to_string(params.max_depth));
  }

  void check_knn(const Snapshot& snap, std::size_t k, const SearchParams& p) const {
    detail::check_k(k, snap.live);
    if (!(p.eps >= 0) || std::isinf(p.eps))
      throw Error("eps must be a finite number >= 0, got " + std::to_string(p.eps));
    if (p.max_checks == 0) throw Error("max_checks must be at least 1");
  }
  static void check_radius(T r) {
    if (std::isnan(r) || r < 0) throw Error("radius must be a non-negative number, got " + std::to_string(r));
  }

  std::shared_ptr<const Snapshot> snapshot() const {
    std::lock_guard<std::mutex> lock(sync_->snapshot);
    return snapshot_;
  }
  void publish(std::shared_ptr<const Snapshot> next) {
    std::lock_guard<std::mutex> lock(sync_->snapshot);
    snapshot_ = std::move(next);
  }
  void finish_update(std::shared_ptr<Snapshot> next) {
    next->version = std::max(next->version, snapshot_->version + 1);
    sort_parts(*next);
    publish(std::move(next));
  }
  static void sort_parts(Snapshot& s) {
    std::sort(s.parts.begin(), s.parts.end(),
              [](const Part& a, const Part& b) { return a.tree->size() - a.dead > b.tree->size() - b.dead; });
  }

  static bool removed(const Part& part, std::uint32_t local, std::uint64_t version) {
    return part.tombstones && part.tombstones->removed_at[local].load(std::memory_order_relaxed) <= version;
  }

  // The part and local index of a live id (ids ascend within a part: a binary search each).
  static bool locate(const Snapshot& snap, Index id, std::pair<std::size_t, std::uint32_t>& at) {
    for (std::size_t p = 0; p < snap.parts.size(); ++p) {
      const detail::Storage<Index>& ids = *snap.parts[p].ids;
      const Index* it = std::lower_bound(ids.begin(), ids.end(), id);
      if (it == ids.end() || *it != id) continue;
      const auto local = static_cast<std::uint32_t>(it - ids.begin());
      if (removed(snap.parts[p], local, snap.version)) return false;
      at = {p, local};
      return true;
    }
    return false;
  }

  static bool in_buffer(const Snapshot& snap, Index id) {
    return snap.buffer && std::binary_search(snap.buffer->ids.begin(), snap.buffer->ids.end(), id);
  }

  // Ids of different parts (and of the buffer) are distinct (a merge of their ascending lists).
  static void check_distinct_ids(const Snapshot& snap) {
    std::vector<std::pair<const Index*, const Index*>> runs;
    for (const Part& p : snap.parts) runs.emplace_back(p.ids->begin(), p.ids->end());
    if (snap.buffer)
      runs.emplace_back(snap.buffer->ids.data(), snap.buffer->ids.data() + snap.buffer->ids.size());
    auto later = [](const auto& a, const auto& b) { return *a.first > *b.first; };
    std::make_heap(runs.begin(), runs.end(), later);
    bool any = false;
    Index last = 0;
    while (!runs.empty()) {
      std::pop_heap(runs.begin(), runs.end(), later);
      auto& run = runs.back();
      if (any && *run.first == last)
        throw Error("updatable point tree: id " + std::to_string(last) + " is in two parts");
      any = true;
      last = *run.first++;
      if (run.first == run.second)
        runs.pop_back();
      else
        std::push_heap(runs.begin(), runs.end(), later);
    }
  }

  // Adds the live points of `part` to `carry`.
  void take_live(const Part& part, Carry& carry) const {
    const auto tree = part.tree->parts();
    const std::size_t d = dim();
    for (std::size_t row = 0; row < tree.order.size(); ++row) {
      const std::uint32_t local = tree.order[row];
      if (part.tombstones && part.tombstones->removed_at[local].load(std::memory_order_relaxed) !=
                                 detail::Tombstones::not_removed)
        continue;
      carry.ids.push_back((*part.ids)[local]);
      carry.rows.insert(carry.rows.end(), tree.points.data() + row * d, tree.points.data() + (row + 1) * d);
    }
  }

  // A part over the carried points, in ascending id order.
  Part build_part(Carry carry, std::size_t level) const {
    const std::size_t n = carry.ids.size(), d = dim();
    std::vector<std::size_t> by_id(n);
    std::iota(by_id.begin(), by_id.end(), std::size_t{0});
    std::sort(by_id.begin(), by_id.end(),
              [&](std::size_t a, std::size_t b) { return carry.ids[a] < carry.ids[b]; });
    std::vector<Index> ids(n);
    std::vector<T> rows(n * d);
    for (std::size_t i = 0; i < n; ++i) {
      ids[i] = carry.ids[by_id[i]];
      std::copy_n(carry.rows.data() + by_id[i] * d, d, rows.data() + i * d);
    }
    Part part;
    part.tree = std::make_shared<const Tree>(rows.data(), n, d, params_, metric_);
    part.ids = std::make_shared<const detail::Storage<Index>>(std::move(ids));
    part.level = level;
    return part;
  }

  std::size_t capacity(std::size_t level) const {
    return level >= 40 || (base_capacity_ << level) >> level != base_capacity_
               ? std::numeric_limits<std::size_t>::max()
               : base_capacity_ << level;
  }

  // The logarithmic method's insertion: the carry goes up from level 0, taking in every part it
  // meets (and, for compact(), every part of `also`), until it fits an empty level.
  void place(Snapshot& snap, Carry carry, const std::vector<Part>* also = nullptr) const {
    if (also)
      for (const Part& p : *also) take_live(p, carry);
    for (std::size_t level = 0;; ++level) {
      if (level >= max_levels) throw Error("updatable point tree: too many levels");
      const auto at =
          std::find_if(snap.parts.begin(), snap.parts.end(), [&](const Part& p) { return p.level == level; });
      if (at != snap.parts.end()) {
        take_live(*at, carry);
        snap.parts.erase(at);
      }
      if (carry.ids.size() <= capacity(level)) {
        if (!carry.ids.empty()) snap.parts.push_back(build_part(std::move(carry), level));
        return;
      }
    }
  }

  template <class Results>
  void search_parts(const Snapshot& snap, const T* q, Results& results, const SearchParams& params,
                    QueryStats& stats) const {
    for (const Part& part : snap.parts) {
      if (part.tombstones) {
        detail::PartResults<T, Results, true> rule(results, part.ids->data(),
                                                   part.tombstones->removed_at.get(), snap.version);
        part.tree->query_with(q, rule, params, &stats);
      } else {
        detail::PartResults<T, Results, false> rule(results, part.ids->data(), nullptr, snap.version);
        part.tree->query_with(q, rule, params, &stats);
      }
    }
    stats.queries -= snap.parts.size();  // one query, whatever the number of parts
    stats.queries += 1;
    if (snap.buffer) {
      const Buffer& b = *snap.buffer;
      for (std::size_t i = 0; i < b.ids.size(); ++i)
        results.offer(internal_distance(metric_, q, b.rows.data() + i * dim(), dim()), b.ids[i]);
      stats.points_visited += b.ids.size();
    }
  }

  void radius_into(const Snapshot& snap, const T* q, T limit, std::size_t max_results,
                   std::vector<detail::Candidate<T>>& out, QueryStats& stats) const {
    if (max_results == 0) {
      out.clear();
      ++stats.queries;
      return;
    }
    if (max_results < snap.live) {
      detail::KnnResults<T> results(max_results, limit, out);
      search_parts(snap, q, results, SearchParams{}, stats);
      results.sorted();
    } else {
      detail::RangeResults<T> results(limit, out);
      search_parts(snap, q, results, SearchParams{}, stats);
      results.sorted();
    }
  }

  template <class F>
  std::size_t sum_over_parts(F figure, bool max = false) const {
    std::size_t total = 0;
    const auto snap = snapshot();
    for (const Part& p : snap->parts)
      total = max ? std::max(total, figure(*p.tree)) : total + figure(*p.tree);
    return total;
  }

  std::size_t dim_;
  BuildParams params_;
  std::size_t base_capacity_;
  Metric metric_;
  std::unique_ptr<Sync> sync_ = std::make_unique<Sync>();
  std::shared_ptr<const Snapshot> snapshot_;  // read under sync_->snapshot; replaced by updates
};

}  // namespace kdspace

// The common instantiations are compiled once in the library (lib/points/dynamic_instances.cpp).
namespace kdspace {
#define KDSPACE_DYNAMIC_POINT_TREE_INSTANCES(PREFIX)   \
  PREFIX class DynamicPointTree<float, Dynamic, L2>;   \
  PREFIX class DynamicPointTree<float, Dynamic, L1>;   \
  PREFIX class DynamicPointTree<float, Dynamic, Linf>; \
  PREFIX class DynamicPointTree<double, Dynamic, L2>;  \
  PREFIX class DynamicPointTree<double, Dynamic, L1>;  \
  PREFIX class DynamicPointTree<double, Dynamic, Linf>;
KDSPACE_DYNAMIC_POINT_TREE_INSTANCES(extern template)
}  // namespace kdspace
