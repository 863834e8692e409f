// The build of the neighbour graph, from the forest's trees, in three steps.
//
//  1. Candidates from the trees. A tree's leaf order puts near points near each other, so each
//     point is scored against the `window` points around it in the leaf order of each of the first
//     `window_trees` trees (once, if it meets a point in several), and keeps the nearest it met: a
//     list of degree + degree / 8 candidates.
//  2. A search for each point's neighbours. The candidate lists, cut short (rough_degree()),
//     already form a graph; each point searches it for itself (graph_search.hpp, pool `build_ef`,
//     by default from the data's intrinsic dimension as the lists show it), starting from its own
//     candidates (their distances are known), and keeps the nearest of what it found. This reaches
//     the neighbours the windows missed, as the rounds of neighbour-of-neighbour exploration of
//     NN-descent (Dong et al., "Efficient k-nearest neighbor graph construction for generic
//     similarity measures", WWW 2011) and EFANNA (Fu & Cai, 2016) do, but in a best-first order that
//     stops early. Both steps score in integers: byte rows as they are (ByteRowScorer), other rows
//     on a grid of 16-bit integers (QuantizedRowScorer, build_distances.hpp); the graph keeps no
//     distance, and the queries' distances are computed again, exactly, from the points.
//  3. Pruning for diversity, then reverse edges. A candidate c of point p is dropped when a kept
//     neighbour w of p is nearer to c than p is, by a factor alpha: alpha * |c - w| <= |p - c| (the
//     relative neighbourhood rule of HNSW's heuristic and NSG for alpha = 1, relaxed by alpha > 1 as
//     in Vamana, Subramanya et al., NeurIPS 2019): the kept edges point in different directions, so
//     a search can leave p towards any region near it. Then every kept edge p -> c is also offered
//     as c -> p, and a list that grows beyond `degree` is pruned again.
//
// Each step computes every point's list from the lists of the step before only (never from lists
// being changed by other threads), and a list keeps the nearest points offered in (distance, row)
// order, whatever the order they were offered in: the graph is the same on any number of threads.
#include "neighbor_graph_build.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <type_traits>

#include "build_distances.hpp"
#include "build_float_scorer.hpp"
#include "graph_search.hpp"
#include "key_select.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/detail/row_distances.hpp"

namespace kdspace::detail {
namespace {

/// Points around each point in a tree's leaf order that step 1 scores it against, and the trees
/// used. Measured on 30k-100k clustered and image descriptors: more trees or wider windows raised
/// the recall of the candidate lists less per distance computed than the search of step 2 does.
constexpr std::size_t window = 32;
constexpr std::size_t window_trees = 4;
/// Step 2 searches the candidate lists cut to at most this many: each point read gives at most this
/// many to score. Measured on 95k music frames (20-D) and 100k image descriptors: 16 instead of 32
/// cut the build's CPU time by a fifth for nearly the same graph (recall at ef 10 0.967 -> 0.965, and
/// 0.904 -> 0.889 at ef 16 on the images). Smaller pools walk shorter lists (rough_degree()).
constexpr std::size_t most_rough_degree = 16;
/// Step 2's lists for a pool of `ef`: half the pool and 4, at most most_rough_degree. For the pool
/// of 16 that the audio sets get, 12 instead of 16 cut step 2's CPU time by 15% (one thread: music
/// 0.39 -> 0.32 s, speech 0.42 -> 0.37 s) for recall at ef 24 within 0.001; for the images' pool of
/// 24 it cost recall at every ef (0.99 took ef 192 instead of 128 in kdspace-ann-bench), so a pool
/// of 24 or more keeps 16.
inline std::size_t rough_degree(std::size_t ef) { return std::min(ef / 2 + 4, most_rough_degree); }
/// The candidate lists (steps 1 to 3) hold degree + degree / 8 points (36 for a degree of 32).
/// Measured on 95k music frames and 100k image descriptors (one thread, busy machine): lists of 40
/// cost pruning about 15% more CPU (music 0.147 -> 0.166 s) for the same recall within 0.0005 at
/// ef 28 (music 0.9911 / 0.9916) and ef 128 (images 0.9903 both); lists of 32 pruned faster still
/// (0.128 s) but fell below recall 0.99 there (music 0.9893 at ef 28, images below 0.99 at ef 128),
/// which cost kdspace-ann-bench the next ef on its grid (32, 192) and, on the images, two fifths
/// of the q/s at recall 0.99.
/// Work items a thread takes at a time.
constexpr std::size_t chunk = 512;

/// Per point, the `width` nearest candidates offered, in (distance, row) order.
template <class T>
class CandidateLists {
 public:
  CandidateLists(std::size_t n, std::size_t width) : width_(width), items_(n * width), sizes_(n, 0) {}

  std::size_t width() const { return width_; }
  std::size_t size(std::size_t p) const { return sizes_[p]; }
  const Candidate<T>* list(std::size_t p) const { return items_.data() + p * width_; }
  Candidate<T>* list(std::size_t p) { return items_.data() + p * width_; }
  void set_size(std::size_t p, std::size_t size) { sizes_[p] = static_cast<std::uint32_t>(size); }
  /// Sets p's list to `sorted` (at most `width` candidates in (distance, row) order).
  void assign(std::size_t p, const Candidate<T>* sorted, std::size_t count) {
    std::copy(sorted, sorted + count, list(p));
    sizes_[p] = static_cast<std::uint32_t>(count);
  }

  /// Merges `sorted` (count candidates in (distance, row) order) into p's list: the list keeps the
  /// `width` first of both; a row in both (at the same distance: every distance between two rows
  /// is computed the same way) counts once.
  void merge(std::size_t p, const Candidate<T>* sorted, std::size_t count, std::vector<Candidate<T>>& buffer) {
    const Candidate<T>* old = list(p);
    const std::size_t old_count = sizes_[p];
    buffer.clear();
    std::size_t i = 0, j = 0;
    while (buffer.size() < width_ && (i < old_count || j < count)) {
      const bool take_old = j == count || (i < old_count && !comes_before(sorted[j], old[i]));
      const Candidate<T> c = take_old ? old[i++] : sorted[j++];
      if (buffer.empty() || buffer.back().index != c.index) buffer.push_back(c);
    }
    std::copy(buffer.begin(), buffer.end(), list(p));
    sizes_[p] = static_cast<std::uint32_t>(buffer.size());
  }

 private:
  std::size_t width_;
  std::vector<Candidate<T>> items_;
  std::vector<std::uint32_t> sizes_;
};

/// The scorer of the build for a row as the query: on quantized rows (build_distances.hpp) and on
/// byte rows, integer arithmetic (exact; byte rows widened to 16 bits); on rows the grid would
/// blur (quantize_rows() returns nothing), float rows by BuildFloatScorer, double rows by the
/// queries' exact kernel.
template <class T, class U>
class RowQueries {
 public:
  RowQueries(const U* rows, std::size_t dim) : rows_(rows), dim_(dim), widened_(std::is_same_v<U, std::uint8_t> ? dim : 0) {}
  auto operator()(std::uint32_t self) {
    const U* row = rows_ + std::size_t{self} * dim_;
    if constexpr (std::is_same_v<U, std::uint16_t>) {
      return QuantizedRowScorer<T>(rows_, dim_, row);
    } else if constexpr (std::is_same_v<U, float> && std::is_same_v<T, float>) {
      return BuildFloatScorer(rows_, dim_, row);
    } else if constexpr (std::is_same_v<U, T>) {
      return RowScorer<T, U>(rows_, dim_, row);
    } else {
      static_assert(std::is_same_v<U, std::uint8_t>);
      std::copy(row, row + dim_, widened_.begin());
      return ByteRowScorer<T>(rows_, dim_, widened_.data());
    }
  }

 private:
  const U* rows_;
  std::size_t dim_;
  std::vector<std::int16_t> widened_;
};

/// Puts the `keep` first of `found` in (distance, row) order at its front. On float distances
/// (never negative, so their bits order as unsigned integers do) each candidate is sorted as one
/// 64-bit key, distance bits above the row: one compare instead of two branches (the windows' step
/// took about 10% less time on 95k music frames).
template <class T>
void select_nearest(std::vector<Candidate<T>>& found, std::size_t keep, std::vector<std::uint64_t>& keys) {
  if constexpr (std::is_same_v<T, float>) {
    const std::size_t count = found.size();
    if (keys.size() < count) keys.resize(count);  // never shrunk: no zeroing when it grows back
    for (std::size_t i = 0; i < count; ++i) {
      std::uint32_t bits;
      std::memcpy(&bits, &found[i].dist, sizeof bits);
      keys[i] = std::uint64_t{bits} << 32 | found[i].index;
    }
    select_smallest(keys.data(), count, keep);
    sort_keys(keys.data(), keep);
    for (std::size_t i = 0; i < keep; ++i) {
      const std::uint32_t bits = static_cast<std::uint32_t>(keys[i] >> 32);
      std::memcpy(&found[i].dist, &bits, sizeof bits);
      found[i].index = static_cast<std::uint32_t>(keys[i]);
    }
  } else {
    const auto cut = found.begin() + static_cast<std::ptrdiff_t>(keep);
    if (keep < found.size()) std::nth_element(found.begin(), cut, found.end(), comes_before);
    std::sort(found.begin(), cut, comes_before);
  }
}

template <class T, class U>
class GraphBuilder {
 public:
  GraphBuilder(const U* rows, std::size_t n, std::size_t dim, const GraphBuildParams& params)
      : rows_(rows), n_(n), dim_(dim), params_(params), workers_(resolve_threads(params.threads)),
        lists_(n, params.degree + params.degree / 8) {}

  NeighborGraph build(const std::vector<const std::uint32_t*>& tree_orders, std::size_t* pool_used) {
    score_windows(tree_orders);
    const std::size_t pool = params_.build_ef > 0 ? params_.build_ef : pool_for_intrinsic_dimension();
    if (pool_used) *pool_used = pool;
    search_each_point(pool);
    NeighborGraph graph = prune_and_reverse();
    connect(graph);
    return graph;
  }

 private:
  /// Per-thread memory of steps 1 and 2.
  struct Work {
    std::vector<std::uint32_t> seen;  // seen[row] == token: already a candidate of this point
    std::uint32_t token = 0;
    std::vector<std::uint32_t> rows;  // rows[0, count): the candidates met
    std::size_t count = 0;
    std::vector<Candidate<T>> found, merged;
    std::vector<std::uint64_t> keys;
    /// A new point, which may meet up to `most` rows.
    void start(std::size_t n, std::size_t most) {
      if (seen.size() != n) seen.assign(n, 0), token = 0;
      if (++token == 0) std::fill(seen.begin(), seen.end(), 0u), token = 1;
      if (rows.size() < most) rows.resize(most);
      count = 0;  // (found keeps its size: score() resizes it, zeroing only what it adds)
    }
    /// Adds `row` unless it is there already. Not a branch: the row goes to the next free place,
    /// which moves on only when the row is new (as in graph_search()).
    void add(std::uint32_t row) {
      rows[count] = row;
      count += seen[row] != token ? 1 : 0;
      seen[row] = token;
    }
  };

  // Step 1: each point against the points around it in the leaf order of each of the first
  // window_trees trees (a point met in several windows is scored once); its list keeps the nearest.
  void score_windows(const std::vector<const std::uint32_t*>& tree_orders) {
    const std::size_t trees = std::min(window_trees, tree_orders.size());
    const std::size_t span = std::min(window + 1, n_);
    // Where each row stands in each tree's leaf order (nullptr: the rows' own order).
    std::vector<std::vector<std::uint32_t>> position(trees);
    for (std::size_t t = 0; t < trees; ++t) {
      if (!tree_orders[t]) continue;
      position[t].resize(n_);
      for (std::size_t i = 0; i < n_; ++i) position[t][tree_orders[t][i]] = static_cast<std::uint32_t>(i);
    }
    std::vector<Work> work(workers_);
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      RowQueries<T, U> as_query(rows_, dim_);
      Work& w = work[worker];
      for (std::size_t p = begin; p < end; ++p) {
        const std::uint32_t self = static_cast<std::uint32_t>(p);
        w.start(n_, trees * span);
        w.seen[self] = w.token;
        const auto scorer = as_query(self);
        for (std::size_t t = 0; t < trees; ++t) {
          const std::uint32_t* order = tree_orders[t];
          const std::size_t pos = order ? position[t][p] : p;
          const std::size_t first = std::min(pos - std::min(pos, window / 2), n_ - span);
          for (std::size_t i = first; i < first + span; ++i) {
            // The other trees' windows are rows scattered in memory: each is asked for as soon as
            // it is met (music, one thread: this step 0.24 -> 0.21 s).
            const std::uint32_t row = order ? order[i] : static_cast<std::uint32_t>(i);
            w.add(row);
            if (order) scorer.prefetch(row);
          }
        }
        score(scorer, w.rows.data(), w.count, w.found);
        const std::size_t keep = std::min(w.found.size(), lists_.width());
        select_nearest(w.found, keep, w.keys);
        lists_.assign(p, w.found.data(), keep);
      }
    });
  }

  /// The distances from the query `score` scores against to each of `rows`, into `found`.
  template <class Scorer>
  static void score(const Scorer& score, const std::uint32_t* rows, std::size_t count, std::vector<Candidate<T>>& found) {
    constexpr std::size_t group = Scorer::group;
    found.resize(count);
    for (std::size_t first = 0; first < count; first += group) {
      std::uint32_t ids[group];
      for (std::size_t g = 0; g < group; ++g) ids[g] = rows[std::min(first + g, count - 1)];
      T dist[group];
      score(ids, std::numeric_limits<T>::infinity(), dist);
      for (std::size_t g = 0; g < group && first + g < count; ++g) found[first + g] = Candidate<T>{dist[g], ids[g]};
    }
  }

  // The lists cut to `degree`, as a graph.
  NeighborGraph lists_as_graph(std::size_t degree) const {
    NeighborGraph g;
    std::uint32_t* const links = g.reset(n_, std::min(degree, params_.degree));
    for (std::size_t p = 0; p < n_; ++p)
      for (std::size_t i = 0; i < g.degree; ++i)
        links[p * g.degree + i] = i < lists_.size(p) ? lists_.list(p)[i].index : static_cast<std::uint32_t>(p);
    return g;
  }

  /// The automatic pool of step 2: twice the intrinsic dimension of the data, within 16..24. Points
  /// of a low intrinsic dimension have few directions to find neighbours in, and a small pool finds
  /// them: on 95k music frames and 100k speech frames (20-D and 39-D MFCC, estimated 7.0 and 7.1) a
  /// pool of 16 instead of 24 cut step 2's CPU time by a third for recall at ef 32 within 0.002,
  /// while on 100k image descriptors (128-D, estimated 13.3) it raised the ef that tune(0.99) chose
  /// from 176 to 286 (and 255 with a pool of 20). The estimate is the maximum-likelihood one of
  /// Levina & Bickel (NIPS 2004) from each point's 10 nearest candidates after step 1, averaged
  /// over every point or about 10,000 of them (the average of the inverses, as MacKay & Ghahramani
  /// propose, gave 5.7, 5.9 and 9.2: too close together to place a rule between them).
  std::size_t pool_for_intrinsic_dimension() const {
    constexpr std::size_t k = 10, least = 16, most = 24;
    const std::size_t stride = std::max<std::size_t>(1, n_ / 10000);
    double sum_of_estimates = 0;
    std::size_t points = 0;
    for (std::size_t p = 0; p < n_; p += stride) {
      if (lists_.size(p) < k) continue;
      const Candidate<T>* list = lists_.list(p);
      const double farthest = static_cast<double>(list[k - 1].dist);
      if (!(list[0].dist > 0)) continue;  // duplicates: no scale to measure
      double logs = 0;  // sum of log(T_k / T_j), from squared distances
      for (std::size_t j = 0; j + 1 < k; ++j)
        logs += 0.5 * std::log(farthest / static_cast<double>(list[j].dist));
      if (!(logs > 0)) continue;  // the 10 at one distance
      sum_of_estimates += static_cast<double>(k - 2) / logs;
      ++points;
    }
    if (points == 0) return most;
    const double dimension = sum_of_estimates / static_cast<double>(points);
    return static_cast<std::size_t>(std::clamp(std::round(2 * dimension), double(least), double(most)));
  }

  // Step 2: each point searches the graph of the lists for itself, keeping a pool of `ef`.
  void search_each_point(std::size_t ef) {
    const NeighborGraph rough = lists_as_graph(rough_degree(ef));
    std::vector<GraphScratch<T>> scratch(workers_);
    std::vector<Work> work(workers_);
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      RowQueries<T, U> as_query(rows_, dim_);
      GraphScratch<T>& s = scratch[worker];
      Work& w = work[worker];
      QueryStats unused;
      for (std::size_t p = begin; p < end; ++p) {
        const std::uint32_t self = static_cast<std::uint32_t>(p);
        // From the point's own candidates, whose distances are known: as a search from the point
        // itself would go on after reading its list, without scoring them again.
        GraphEntries<T> start;
        start.known = lists_.list(p);
        start.known_count = lists_.size(p);
        start.seen = &self;
        start.seen_count = 1;
        graph_search(rough, n_, as_query(self), start, ef, s, unused);
        w.found.resize(s.pool.size());
        std::size_t count = 0;
        for (std::size_t i = 0; i < s.pool.size(); ++i)
          if (s.pool.row(i) != self) w.found[count++] = Candidate<T>{s.pool.dist(i), s.pool.row(i)};
        lists_.merge(p, w.found.data(), count, w.merged);
      }
    });
  }

  /// Per-thread marks of the neighbours kept so far for one point: mark[row] == token.
  struct KeptMarks {
    std::vector<std::uint32_t> mark;
    std::uint32_t token = 0;
  };

  /// Starts a new set of marks: no row is marked.
  void next_token(KeptMarks& marks) const {
    if (marks.mark.size() != n_) marks.mark.assign(n_, 0), marks.token = 0;
    if (++marks.token == 0) std::fill(marks.mark.begin(), marks.mark.end(), 0u), marks.token = 1;
  }

  /// Step 3's rule: keeps, from `cands` (distances from the row `self`, nearest first), each one that
  /// no neighbour kept before it dismisses, up to `degree`; returns how many. Whether a kept w is
  /// within |self - c| / alpha of c is read from c's candidate list rather than computed: c's list
  /// holds the points nearest c that the first two steps found, so a w that near c is in it (as it is
  /// nearer c than self, which is usually in the list too). Measured against computing every
  /// |c - w| (30k image descriptors): the same recall for the same points scored by the search, and
  /// the 500 to 600 distances a point that this step cost are gone.
  std::size_t prune(const Candidate<T>* cands, std::size_t count, std::uint32_t self, Candidate<T>* kept,
                    KeptMarks& marks) const {
    const T shrink = static_cast<T>(1.0 / (params_.alpha * params_.alpha));
    next_token(marks);
    // Each candidate's list is a read at a place of its own: asked for a few candidates ahead.
    constexpr std::size_t ahead = 6;
    for (std::size_t i = 0; i < std::min(count, ahead); ++i) __builtin_prefetch(lists_.list(cands[i].index));
    std::size_t kept_count = 0;
    for (std::size_t i = 0; i < count && kept_count < params_.degree; ++i) {
      if (i + ahead < count) __builtin_prefetch(lists_.list(cands[i + ahead].index));
      const Candidate<T>& c = cands[i];
      if (c.index == self) continue;
      const T limit = c.dist * shrink;  // dismissed by w when |c - w|^2 <= |self - c|^2 / alpha^2
      const Candidate<T>* near_c = lists_.list(c.index);
      bool dismissed = false;
      for (std::size_t j = 0; j < lists_.size(c.index) && near_c[j].dist <= limit && !dismissed; ++j)
        dismissed = marks.mark[near_c[j].index] == marks.token;
      if (dismissed) continue;
      kept[kept_count++] = c;
      marks.mark[c.index] = marks.token;
    }
    return kept_count;
  }

  // Step 3.
  NeighborGraph prune_and_reverse() {
    const std::size_t degree = params_.degree;
    std::vector<Candidate<T>> pruned(n_ * degree);
    std::vector<std::uint32_t> pruned_size(n_);
    std::vector<KeptMarks> marks(workers_);
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      for (std::size_t p = begin; p < end; ++p)
        pruned_size[p] = static_cast<std::uint32_t>(
            prune(lists_.list(p), lists_.size(p), static_cast<std::uint32_t>(p), pruned.data() + p * degree, marks[worker]));
    });

    // Reverse edges, gathered by target (in the order of their sources: the same on any thread count).
    std::vector<std::size_t> first_reverse(n_ + 1, 0);
    for (std::size_t p = 0; p < n_; ++p)
      for (std::size_t i = 0; i < pruned_size[p]; ++i) ++first_reverse[pruned[p * degree + i].index + 1];
    for (std::size_t p = 0; p < n_; ++p) first_reverse[p + 1] += first_reverse[p];
    std::vector<Candidate<T>> reverse(first_reverse[n_]);
    {
      std::vector<std::size_t> fill(first_reverse.begin(), first_reverse.end() - 1);
      for (std::size_t p = 0; p < n_; ++p)
        for (std::size_t i = 0; i < pruned_size[p]; ++i) {
          const Candidate<T>& c = pruned[p * degree + i];
          reverse[fill[c.index]++] = Candidate<T>{c.dist, static_cast<std::uint32_t>(p)};
        }
    }

    NeighborGraph graph;
    std::uint32_t* const all_links = graph.reset(n_, degree);
    const std::size_t most_merged = lists_.width();
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      std::vector<Candidate<T>> merged, kept(degree);
      std::vector<std::uint64_t> keys;
      for (std::size_t p = begin; p < end; ++p) {
        // The union of both lists, each row once (an edge both ways has the same distance both ways).
        KeptMarks& in = marks[worker];
        next_token(in);
        merged.clear();
        auto add = [&](const Candidate<T>& c) {
          if (in.mark[c.index] == in.token) return;
          in.mark[c.index] = in.token;
          merged.push_back(c);
        };
        std::for_each(pruned.begin() + static_cast<std::ptrdiff_t>(p * degree),
                      pruned.begin() + static_cast<std::ptrdiff_t>(p * degree + pruned_size[p]), add);
        std::for_each(reverse.begin() + static_cast<std::ptrdiff_t>(first_reverse[p]),
                      reverse.begin() + static_cast<std::ptrdiff_t>(first_reverse[p + 1]), add);
        // A list with room is kept in any order (a search scores a list's points all alike, and
        // about four in five lists have room: sorting them was 40% of this loop on 95k music
        // frames); a full one nearest first, as prune() needs and connect() gives up its last point.
        if (merged.size() >= degree) select_nearest(merged, merged.size(), keys);
        std::size_t count = merged.size();
        if (count <= degree) {
          std::copy(merged.begin(), merged.end(), kept.begin());
        } else {
          count = prune(merged.data(), std::min(merged.size(), most_merged), static_cast<std::uint32_t>(p), kept.data(),
                        marks[worker]);
        }
        std::uint32_t* links = all_links + p * degree;
        for (std::size_t i = 0; i < degree; ++i) links[i] = i < count ? kept[i].index : static_cast<std::uint32_t>(p);
      }
    });
    return graph;
  }

  // Step 4: one graph. Points of clusters far apart may have no edge between them, and a search
  // could then never leave the cluster it started in. The rows follow the first tree's leaf order,
  // in which consecutive rows are near each other (across a cell boundary at worst): walking that
  // order with a union-find of the graph's edges (each taken both ways), rows r and r + 1 in
  // different components get an edge each way (Kruskal's rule on that path), so c components are
  // joined by c - 1 pairs of edges. A full list gives up its farthest neighbour for one.
  void connect(NeighborGraph& graph) const {
    std::vector<std::uint32_t> parent(n_);
    for (std::size_t r = 0; r < n_; ++r) parent[r] = static_cast<std::uint32_t>(r);
    auto root = [&](std::uint32_t r) {
      while (parent[r] != r) r = parent[r] = parent[parent[r]];
      return r;
    };
    auto join = [&](std::uint32_t a, std::uint32_t b) {
      a = root(a), b = root(b);
      if (a == b) return false;
      parent[std::max(a, b)] = std::min(a, b);
      return true;
    };
    const std::size_t degree = graph.degree;
    for (std::size_t r = 0; r < n_; ++r)
      for (std::size_t i = 0; i < degree; ++i) join(static_cast<std::uint32_t>(r), graph.links[r * degree + i]);
    std::uint32_t* const links = graph.links.owned_data();
    auto add = [&](std::uint32_t from, std::uint32_t to) {
      std::uint32_t* list = links + std::size_t{from} * degree;
      std::size_t slot = 0;
      while (slot < degree && list[slot] != from) ++slot;  // the first padding slot
      list[std::min(slot, degree - 1)] = to;
    };
    for (std::uint32_t r = 0; r + 1 < n_; ++r)
      if (join(r, r + 1)) add(r, r + 1), add(r + 1, r);
  }

  const U* rows_;
  std::size_t n_, dim_;
  GraphBuildParams params_;
  unsigned workers_;
  CandidateLists<T> lists_;
};

}  // namespace

template <class T, class U>
NeighborGraph build_neighbor_graph(const U* rows, std::size_t n, std::size_t dim,
                                   const std::vector<const std::uint32_t*>& tree_orders,
                                   const GraphBuildParams& params, std::size_t* pool_used) {
  if constexpr (std::is_same_v<U, std::uint8_t>) {
    return GraphBuilder<T, U>(rows, n, dim, params).build(tree_orders, pool_used);
  } else {
    if (const std::optional<std::vector<std::uint16_t>> grid = quantize_rows(rows, n, dim))
      return GraphBuilder<T, std::uint16_t>(grid->data(), n, dim, params).build(tree_orders, pool_used);
    return GraphBuilder<T, U>(rows, n, dim, params).build(tree_orders, pool_used);
  }
}

template NeighborGraph build_neighbor_graph<float, float>(const float*, std::size_t, std::size_t,
                                                          const std::vector<const std::uint32_t*>&, const GraphBuildParams&,
                                                          std::size_t*);
template NeighborGraph build_neighbor_graph<float, std::uint8_t>(const std::uint8_t*, std::size_t, std::size_t,
                                                                 const std::vector<const std::uint32_t*>&,
                                                                 const GraphBuildParams&, std::size_t*);
template NeighborGraph build_neighbor_graph<double, double>(const double*, std::size_t, std::size_t,
                                                            const std::vector<const std::uint32_t*>&,
                                                            const GraphBuildParams&, std::size_t*);
template NeighborGraph build_neighbor_graph<double, std::uint8_t>(const std::uint8_t*, std::size_t, std::size_t,
                                                                  const std::vector<const std::uint32_t*>&,
                                                                  const GraphBuildParams&, std::size_t*);

}  // namespace kdspace::detail
