// PointForest's per-thread working memory of a query (shared by the search of the trees in
// point_forest.cpp and that of the graph in point_forest_graph.cpp).
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "graph_search.hpp"
#include "kdspace/points/detail/result_sets.hpp"
#include "kdspace/points/point_forest.hpp"

namespace kdspace {

/// Per-thread working memory of a query: reused from query to query, so a query allocates nothing
/// once it has grown. `stamp[row] == epoch` marks a row already scored by the current query.
///
/// A cell's bound is the sum over projected axes of one term each (the squared gap from the query
/// to the cell along that axis, 0 where the query lies within). Going to a far child replaces one
/// axis's term, so a queued branch keeps its cell's terms as a trail: the one term it changed and
/// the trail of the cell it was queued from. Entering a branch rebuilds the terms from the trail
/// (the newest term of an axis wins) without walking the tree from its root again.
template <class T>
struct PointForest<T>::Scratch {
  static constexpr std::uint32_t no_trail = 0xffffffffu;
  struct Branch {
    double bound;  // squared distance from the projected query to the branch's cell
    std::uint32_t tree;
    std::uint32_t node;
    std::uint32_t trail;  // the cell's last changed term, in `trail`
  };
  struct Term {
    double value;
    std::uint32_t axis;
    std::uint32_t parent;  // the rest of the cell's terms (no_trail: all others 0)
  };
  // Min-heap on (bound, tree, node): the order does not depend on anything but the query.
  struct After {
    bool operator()(const Branch& a, const Branch& b) const {
      if (a.bound != b.bound) return a.bound > b.bound;
      if (a.tree != b.tree) return a.tree > b.tree;
      return a.node > b.node;
    }
  };

  std::vector<double> query;     // projected query, along axis a when query_epoch[a] == epoch
  std::vector<std::uint32_t> query_epoch;
  std::vector<double> terms;     // per projected axis, its term in the current cell's bound
  std::vector<std::uint8_t> set;  // per projected axis: its term was set by enter()
  std::vector<std::uint32_t> touched;
  std::vector<Branch> heap;
  std::vector<Term> trail;
  std::vector<std::uint32_t> arriving, ready;  // rows of the leaf being reached, and of the one before
  std::vector<std::uint32_t> stamp;
  std::uint32_t epoch = 0;
  std::vector<detail::Candidate<T>> results;
  detail::GraphScratch<T> graph;

  void start(std::size_t n, std::size_t m) {
    if (stamp.size() != n || query_epoch.size() != m) stamp.assign(n, 0), query_epoch.assign(m, 0), epoch = 0;
    if (++epoch == 0) {
      std::fill(stamp.begin(), stamp.end(), 0u);
      std::fill(query_epoch.begin(), query_epoch.end(), 0u);
      epoch = 1;
    }
    query.resize(m);
    terms.assign(m, 0.0);
    set.assign(m, 0);
    heap.clear();
    trail.clear();
    arriving.clear();
    ready.clear();
  }

  /// The query's projected coordinate along `axis` (in double), computed the first time a search
  /// needs it: a search with a small budget reads few of the axes.
  double projected(const T* q, std::uint32_t axis, const std::vector<double>& mean, const std::vector<double>& directions,
                   bool pca) {
    if (query_epoch[axis] != epoch) {
      const std::size_t dim = mean.size();
      double v = 0;
      if (pca) {
        const double* direction = directions.data() + std::size_t{axis} * dim;
        for (std::size_t a = 0; a < dim; ++a) v += (static_cast<double>(q[a]) - mean[a]) * direction[a];
      } else {
        v = static_cast<double>(q[axis]) - mean[axis];
      }
      query[axis] = v;
      query_epoch[axis] = epoch;
    }
    return query[axis];
  }

  // Sets `terms` to those of the cell whose trail starts at `t`; `touched` lists the axes set.
  void enter(std::uint32_t t) {
    for (; t != no_trail; t = trail[t].parent) {
      const Term& term = trail[t];
      if (set[term.axis]) continue;  // a newer term of this axis holds
      set[term.axis] = 1;
      terms[term.axis] = term.value;
      touched.push_back(term.axis);
    }
  }
  void leave() {
    for (std::uint32_t axis : touched) terms[axis] = 0, set[axis] = 0;
    touched.clear();
  }
};

}  // namespace kdspace
