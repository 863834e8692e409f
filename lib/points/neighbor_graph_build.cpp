// The build of the neighbour graph, from the forest's trees, in three steps.
//
//  1. Candidates from the trees. A tree's leaf order puts near points near each other, so each
//     point is scored against the `window` points around it in the leaf order of each of the first
//     `window_trees` trees, and keeps the `candidates` nearest it met.
//  2. A search for each point's neighbours. The candidate lists, cut to `degree`, already form a
//     graph; each point searches it for itself (graph_search.hpp, pool `build_ef`), starting from
//     itself, and keeps the nearest of what the search scored. This reaches the neighbours the
//     windows missed, as the rounds of neighbour-of-neighbour exploration of NN-descent (Dong et al.,
//     "Efficient k-nearest neighbor graph construction for generic similarity measures", WWW 2011)
//     and EFANNA (Fu & Cai, 2016) do, but in a best-first order that stops early.
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
#include <cstring>
#include <limits>
#include <type_traits>

#include "graph_search.hpp"
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
  /// The largest distance that may still enter p's list.
  T bound(std::size_t p) const {
    return sizes_[p] == width_ ? items_[p * width_ + width_ - 1].dist : std::numeric_limits<T>::infinity();
  }

  /// Offers `row` at `dist` to p's list; a row already there (at the same distance, as every
  /// distance between two rows is computed the same way) is not added twice.
  void offer(std::size_t p, T dist, std::uint32_t row) {
    Candidate<T>* items = list(p);
    std::size_t size = sizes_[p];
    const Candidate<T> c{dist, row};
    if (size == width_ && !comes_before(c, items[size - 1])) return;
    std::size_t pos = size == width_ ? size - 1 : size;
    while (pos > 0 && comes_before(c, items[pos - 1])) --pos;
    if (pos > 0 && items[pos - 1].index == row) return;
    const std::size_t end = size == width_ ? size - 1 : size;
    std::memmove(items + pos + 1, items + pos, (end - pos) * sizeof(Candidate<T>));
    items[pos] = c;
    if (size < width_) sizes_[p] = static_cast<std::uint32_t>(size + 1);
  }

 private:
  std::size_t width_;
  std::vector<Candidate<T>> items_;
  std::vector<std::uint32_t> sizes_;
};

/// A row as a query of T: the row itself when it holds T, else widened (exactly) into a buffer.
template <class T, class U>
class RowQuery {
 public:
  explicit RowQuery(std::size_t dim) : buffer_(std::is_same_v<T, U> ? 0 : dim) {}
  const T* operator()(const U* row) {
    if constexpr (std::is_same_v<T, U>) {
      return row;
    } else {
      std::copy(row, row + buffer_.size(), buffer_.begin());
      return buffer_.data();
    }
  }

 private:
  std::vector<T> buffer_;
};

template <class T, class U>
class GraphBuilder {
 public:
  GraphBuilder(const U* rows, std::size_t n, std::size_t dim, const GraphBuildParams& params)
      : rows_(rows), n_(n), dim_(dim), params_(params), workers_(resolve_threads(params.threads)),
        lists_(n, params.degree + params.degree / 4) {}

  NeighborGraph build(const std::vector<const std::uint32_t*>& tree_orders) {
    const std::size_t trees = std::min(window_trees, tree_orders.size());
    for (std::size_t t = 0; t < trees; ++t) score_windows(tree_orders[t]);
    search_each_point();
    return prune_and_reverse();
  }

 private:
  static constexpr std::size_t group = sizeof(T) == 4 ? 4 : 2;

  const U* row(std::uint32_t r) const { return rows_ + std::size_t{r} * dim_; }

  /// Scores the query `q` (the row `self`) against rows `others[0, count)` and offers those that may
  /// enter self's list.
  void score_and_offer(const T* q, std::uint32_t self, const std::uint32_t* others, std::size_t count) {
    for (std::size_t first = 0; first < count; first += group) {
      const U* group_rows[group];
      for (std::size_t g = 0; g < group; ++g) group_rows[g] = row(others[std::min(first + g, count - 1)]);
      const T limit = lists_.bound(self);
      T dist[group];
      l2_distances_or_more<group>(q, group_rows, dim_, limit, dist);
      for (std::size_t g = 0; g < group && first + g < count; ++g)
        if (others[first + g] != self && dist[g] <= limit) lists_.offer(self, dist[g], others[first + g]);
    }
  }

  // Step 1, one tree: each point against the window around it in the tree's leaf order.
  void score_windows(const std::uint32_t* order) {
    const std::size_t span = std::min(window + 1, n_);
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned) {
      RowQuery<T, U> as_query(dim_);
      std::vector<std::uint32_t> others(span);
      for (std::size_t pos = begin; pos < end; ++pos) {
        const std::size_t first = std::min(pos - std::min(pos, window / 2), n_ - span);
        for (std::size_t i = 0; i < span; ++i)
          others[i] = order ? order[first + i] : static_cast<std::uint32_t>(first + i);
        const std::uint32_t self = order ? order[pos] : static_cast<std::uint32_t>(pos);
        score_and_offer(as_query(row(self)), self, others.data(), span);
      }
    });
  }

  // The lists cut to `degree`, as a graph.
  NeighborGraph lists_as_graph() const {
    NeighborGraph g;
    g.degree = params_.degree;
    g.links.resize(n_ * g.degree);
    for (std::size_t p = 0; p < n_; ++p)
      for (std::size_t i = 0; i < g.degree; ++i)
        g.links[p * g.degree + i] = i < lists_.size(p) ? lists_.list(p)[i].index : static_cast<std::uint32_t>(p);
    return g;
  }

  // Step 2: each point searches the graph of the lists for itself.
  void search_each_point() {
    const NeighborGraph rough = lists_as_graph();
    std::vector<GraphScratch<T>> scratch(workers_);
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      RowQuery<T, U> as_query(dim_);
      GraphScratch<T>& s = scratch[worker];
      QueryStats unused;
      for (std::size_t p = begin; p < end; ++p) {
        const std::uint32_t self = static_cast<std::uint32_t>(p);
        graph_search(rough, rows_, n_, dim_, as_query(row(self)), &self, 1, params_.build_ef, s, unused);
        for (std::size_t i = 0; i < s.pool.size(); ++i)
          if (s.pool.row(i) != self) lists_.offer(p, s.pool.dist(i), s.pool.row(i));
      }
    });
  }

  /// Per-thread marks of the neighbours kept so far for one point: mark[row] == token.
  struct KeptMarks {
    std::vector<std::uint32_t> mark;
    std::uint32_t token = 0;
  };

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
    if (marks.mark.size() != n_) marks.mark.assign(n_, 0), marks.token = 0;
    if (++marks.token == 0) std::fill(marks.mark.begin(), marks.mark.end(), 0u), marks.token = 1;
    std::size_t kept_count = 0;
    for (std::size_t i = 0; i < count && kept_count < params_.degree; ++i) {
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
    graph.degree = degree;
    graph.links.resize(n_ * degree);
    const std::size_t most_merged = lists_.width();
    parallel_for(n_, params_.threads, chunk, [&](std::size_t begin, std::size_t end, unsigned worker) {
      std::vector<Candidate<T>> merged, kept(degree);
      for (std::size_t p = begin; p < end; ++p) {
        merged.assign(pruned.begin() + static_cast<std::ptrdiff_t>(p * degree),
                      pruned.begin() + static_cast<std::ptrdiff_t>(p * degree + pruned_size[p]));
        merged.insert(merged.end(), reverse.begin() + static_cast<std::ptrdiff_t>(first_reverse[p]),
                      reverse.begin() + static_cast<std::ptrdiff_t>(first_reverse[p + 1]));
        std::sort(merged.begin(), merged.end(), comes_before);
        merged.erase(std::unique(merged.begin(), merged.end(),
                                 [](const Candidate<T>& a, const Candidate<T>& b) { return a.index == b.index; }),
                     merged.end());
        std::size_t count = merged.size();
        if (count <= degree) {
          std::copy(merged.begin(), merged.end(), kept.begin());
        } else {
          count = prune(merged.data(), std::min(merged.size(), most_merged), static_cast<std::uint32_t>(p), kept.data(),
                        marks[worker]);
        }
        std::uint32_t* links = graph.links.data() + p * degree;
        for (std::size_t i = 0; i < degree; ++i) links[i] = i < count ? kept[i].index : static_cast<std::uint32_t>(p);
      }
    });
    return graph;
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
                                   const std::vector<const std::uint32_t*>& tree_orders, const GraphBuildParams& params) {
  return GraphBuilder<T, U>(rows, n, dim, params).build(tree_orders);
}

template NeighborGraph build_neighbor_graph<float, float>(const float*, std::size_t, std::size_t,
                                                          const std::vector<const std::uint32_t*>&, const GraphBuildParams&);
template NeighborGraph build_neighbor_graph<float, std::uint8_t>(const std::uint8_t*, std::size_t, std::size_t,
                                                                 const std::vector<const std::uint32_t*>&,
                                                                 const GraphBuildParams&);
template NeighborGraph build_neighbor_graph<double, double>(const double*, std::size_t, std::size_t,
                                                            const std::vector<const std::uint32_t*>&,
                                                            const GraphBuildParams&);
template NeighborGraph build_neighbor_graph<double, std::uint8_t>(const std::uint8_t*, std::size_t, std::size_t,
                                                                  const std::vector<const std::uint32_t*>&,
                                                                  const GraphBuildParams&);

}  // namespace kdspace::detail
