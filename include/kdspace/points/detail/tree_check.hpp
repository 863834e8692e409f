// The parts of a PointTree (what an index file stores) and the check that makes parts from outside
// (a loaded file) safe and exact to search.
//
// check_point_tree() accepts exactly the trees the builder makes: nodes in depth-first order (an
// inner node's left child next to it, its right child where its left subtree ends), leaves whose
// point ranges tile [0, n) in that order, no path deeper than max_tree_depth (the search recurses),
// split axes below the dimension, finite bounds of all points (the root cell) and points that lie
// inside them and on the sides of every split their leaves are under (left subtree <= left_max <=
// right_min <= right subtree: the bounds the search prunes with), identical-point leaves that hold identical
// points in ascending index order, and an index array that is a permutation of [0, n). A tree that passes
// cannot make a query read out of bounds, recurse without end, or lose a neighbour: its answers are those of
// brute force over its points. It runs in O(n * dim + nodes), one pass over the points.
//
// With PointTreeParts::verify = Verify::safety (what a load asks for by default: the file's
// checksums are verified beside it) it checks only what keeps a search inside the arrays and
// finite: the nodes, the leaves' ranges and the indices below n, not the points nor whether the
// indices repeat. A pass over the order and one over the nodes; the points are not read.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "kdspace/detail/check_companion.hpp"
#include "kdspace/detail/storage.hpp"
#include "kdspace/error.hpp"
#include "kdspace/points/detail/node.hpp"
#include "kdspace/points/detail/parallel.hpp"
#include "kdspace/points/detail/tree_check_kernels.hpp"
#include "kdspace/points/detail/tree_check_walk3.hpp"
#include "kdspace/points/params.hpp"

namespace kdspace::detail {

/// The deepest tree a search accepts: the builder's cap on max_depth.
inline constexpr std::size_t max_tree_depth = 256;

/// The arrays the check tells a CheckCompanion of: rows (the points and their order, row by row)
/// and nodes.
inline constexpr std::size_t check_rows = 0, check_nodes = 1;

/// Everything a PointTree is made of. `backing` keeps borrowed storage alive (null when all is owned).
template <class T>
struct PointTreeParts {
  std::size_t dim = 0;
  BuildParams params;
  Storage<T> points;                ///< n * dim coordinates, rows in leaf order
  Storage<std::uint32_t> order;     ///< original index of each row
  Storage<PointNode<T>> nodes;      ///< depth first; nodes[0] is the root
  std::vector<T> root_lo, root_hi;  ///< bounds of all points (the root cell)
  std::shared_ptr<const void> backing;
  CheckCompanion* companion = nullptr;  ///< work the check runs beside (not owned; used while it runs)
  unsigned check_threads = 2;           ///< 1: the check runs on the calling thread alone; 0: on as many
                                        ///< as pay for their start (check_threads_that_pay)
  bool wide_kernels = true;  ///< false: the baseline loops alone, even where AVX2 runs (tests compare them)
  Verify verify = Verify::full;  ///< how much the check establishes (params.hpp)
};

/// What the check works out on the way: the figures a PointTree keeps besides its arrays.
struct TreeShape {
  std::size_t depth = 0;
  std::size_t leaves = 0;
};

/// Trees of at least this many points are checked on PointTreeParts::check_threads threads (a
/// thread's start costs tens of microseconds, the check a few nanoseconds a point).
inline constexpr std::size_t parallel_tree_check = std::size_t{1} << 17;

/// What one thread checks (and checksums) in about the time it takes to start another: 1 MiB. Measured
/// here, a fresh process loads 1e6 3-D float points (18 MB) in 0.8-0.9 ms on one thread, about 20
/// bytes a nanosecond, and starts its first thread in 45-100 microseconds, each further one in 20-40.
inline constexpr std::size_t check_bytes_a_thread_start = std::size_t{1} << 20;

/// The threads a check of `bytes` runs on when left to choose: starting T threads one after another
/// costs the caller T starts, sharing the work saves (T - 1) / T of it, and the sum of the two is least
/// near T = sqrt(bytes / check_bytes_a_thread_start). So 2 threads from 4 MiB, 4 from 16 MiB, 16 from
/// 256 MiB; at most `hardware`, at least 1. (On a machine of many processors, starting them all for a
/// file of a few megabytes would cost more than the check itself.)
inline unsigned check_threads_that_pay(std::size_t bytes, unsigned hardware) {
  const auto pay = static_cast<unsigned>(
      std::sqrt(static_cast<double>(bytes) / static_cast<double>(check_bytes_a_thread_start)));
  return std::clamp(pay, 1u, std::max(hardware, 1u));
}

/// The threads a check of `bytes` runs on when `asked` for that many: 0 leaves the choice to
/// check_threads_that_pay, on this machine's hardware threads.
inline unsigned check_threads_for(unsigned asked, std::size_t bytes) {
  return asked != 0 ? asked : check_threads_that_pay(bytes, resolve_threads(0));
}

/// The parallel check hands out subtrees of at most 1/(tree_check_pieces_a_thread * threads) of the
/// nodes: enough that threads which start late (a thread's start costs tens of microseconds, a
/// sleeping processor's wake more) still find some of the tree to share, and that all finish together.
inline constexpr std::size_t tree_check_pieces_a_thread = 8;

template <class T>
class TreeChecker {
 public:
  explicit TreeChecker(const PointTreeParts<T>& p)
      : p_(p),
        n_(p.order.size()),
        dim_(p.dim),
        full_(p.verify == Verify::full),
        kernels_(p.wide_kernels && tree_check_kernels()),
        threads_(check_threads_for(p.check_threads, p.points.size() * sizeof(T) + n_ * sizeof(std::uint32_t) +
                                                        p.nodes.size() * sizeof(PointNode<T>))) {}

  TreeShape run() {
    if (dim_ == 0) fail("dimension 0");
    if (n_ == 0) fail("no points");
    if (n_ >= (std::size_t{1} << 30)) fail(std::to_string(n_) + " points (at most 2^30 - 1)");
    if (p_.points.size() / dim_ != n_ || p_.points.size() % dim_ != 0)
      fail(std::to_string(p_.points.size()) + " coordinates for " + std::to_string(n_) +
           " points of dimension " + std::to_string(dim_));
    if (p_.nodes.empty()) fail("no nodes");
    if (p_.params.leaf_size == 0) fail("leaf_size 0");
    if (p_.params.max_depth > max_tree_depth)
      fail("max_depth " + std::to_string(p_.params.max_depth) + " above 256");
    if (p_.root_lo.size() != dim_ || p_.root_hi.size() != dim_) fail("bounds of the wrong dimension");
    for (std::size_t a = 0; a < dim_; ++a)
      if (!std::isfinite(p_.root_lo[a]) || !std::isfinite(p_.root_hi[a]) || p_.root_lo[a] > p_.root_hi[a])
        fail("bounds of coordinate " + std::to_string(a + 1) + " are not finite and ordered");
    if (n_ >= parallel_tree_check && threads_ > 1) {
      try {
        if (std::optional<TreeShape> shape = run_in_pieces()) return *shape;
      } catch (const Error&) {
        // Something is wrong: the one-thread check below names the first problem, as it finds it.
        return run_on_one_thread(nullptr);
      }
    }
    return run_on_one_thread(p_.companion);
  }

 private:
  [[noreturn]] static void fail(const std::string& what) { throw Error("point tree: " + what); }
  [[noreturn]] static void fail_node(std::size_t id, const std::string& what) {
    fail("node " + std::to_string(id) + ": " + what);
  }

  // An inner node above the one being visited: its cell's bounds on its axis before its split, and
  // whether its right side is being visited.
  struct Frame {
    std::size_t id, axis;
    T saved_lo, saved_hi;
    bool right;
  };

  // A depth-first walk over one subtree after another, each in its cell, checking that nodes and the
  // leaves' points follow each other without a gap; then the order of its rows.
  struct Walk {
    std::size_t piece = 0;       // the companion's piece of the arrays it reads
    std::vector<T> lo, hi;       // the root cell cut by the splits above the node being visited, and
                                 // one coordinate more (unused: the 3-D check loads four at once)
    std::size_t next_node = 0;   // the node the next visit must find
    std::size_t node_limit = 0;  // the nodes it may read lie below this one
    std::size_t next_point = 0;  // the point the next leaf must start at
    TreeShape shape;
    CheckCompanion* companion = nullptr;
    std::size_t rows_ready = 0, nodes_ready = 0;  // what the companion has made ready to read
    std::vector<std::uint64_t> seen;              // the order's values of its rows, as bits (mark_order)
    bool out_of_range = false;                    // Verify::safety: a value of its rows' order >= n
    std::vector<Frame> stack = std::vector<Frame>(max_tree_depth + 1);  // visit's: one frame a level
  };

  Walk new_walk(CheckCompanion* companion) const {
    Walk walk;
    walk.lo.resize(dim_ + 1);  // a padding coordinate: the 3-D check loads four
    walk.hi.resize(dim_ + 1);
    walk.node_limit = p_.nodes.size();
    walk.companion = companion;
    if (full_) walk.seen.assign(n_ / 64 + 1, 0);
    return walk;
  }

  TreeShape run_on_one_thread(CheckCompanion* companion) {
    if (companion) {
      companion->pieces(check_rows, {0});
      companion->pieces(check_nodes, {0});
    }
    Walk walk = new_walk(companion);
    std::copy(p_.root_lo.begin(), p_.root_lo.end(), walk.lo.begin());
    std::copy(p_.root_hi.begin(), p_.root_hi.end(), walk.hi.begin());
    visit(walk, 0);
    mark_order(walk, 0, n_);
    if (companion) companion->help();
    if (walk.next_node != p_.nodes.size())
      fail("nodes " + std::to_string(walk.next_node) + " to " + std::to_string(p_.nodes.size() - 1) +
           " are not reached from the root");
    if (walk.next_point != n_)
      fail("the leaves hold points [0, " + std::to_string(walk.next_point) + "), expected [0, " +
           std::to_string(n_) + ")");
    if (full_ ? !all_seen(walk.seen) : walk.out_of_range) fail_order();
    return walk.shape;
  }

  // A subtree the parallel check hands out whole: its root, where its nodes end (its parent's split
  // says), its depth and cell, and the first point of its leftmost leaf.
  struct Piece {
    std::size_t root = 0, end = 0, depth = 0, first_point = 0;
    std::vector<T> lo, hi;
  };

  // The tree cut into pieces: the inner nodes whose subtrees hold more than `largest` nodes (their
  // splits checked here), and the subtrees below them (the pieces), in node order, so that the cut
  // nodes and the pieces' ranges [root, end) tile the node array. The threads take the pieces in turn
  // from a shared counter (parallel_for), each walking a piece whole, which must end at its `end`
  // and at the next piece's first point (the last at n, the first starting at 0), then marking the
  // order of its rows; a thread that starts late takes what is left, so none waits on another's
  // share. No shape when the tree does not divide (its root is a leaf). Any problem throws, and run()
  // starts over on one thread, whose message names it.
  std::optional<TreeShape> run_in_pieces() {
    const std::size_t nodes = p_.nodes.size();
    const std::size_t largest = std::max<std::size_t>(nodes / (tree_check_pieces_a_thread * threads_), 1);
    std::vector<Piece> pieces;
    std::vector<Piece> pending{{0, nodes, 0, 0, p_.root_lo, p_.root_hi}};
    while (!pending.empty()) {  // depth first, left before right: node order
      Piece s = std::move(pending.back());
      pending.pop_back();
      const PointNode<T>& node = p_.nodes[s.root];
      if (node.is_leaf() || s.end - s.root <= largest || s.depth >= max_tree_depth) {
        pieces.push_back(std::move(s));
        continue;
      }
      check_split(s.root, node);
      const std::size_t axis = node.axis(), right = node.right_child();
      if (!(s.root + 1 < right && right < s.end)) fail_node(s.root, "right child outside its subtree");
      Piece right_side{right, s.end, s.depth + 1, 0, s.lo, s.hi};
      right_side.lo[axis] = std::max(s.lo[axis], node.right_min);
      Piece left_side{s.root + 1, right, s.depth + 1, 0, std::move(s.lo), std::move(s.hi)};
      left_side.hi[axis] = std::min(left_side.hi[axis], node.left_max);
      pending.push_back(std::move(right_side));
      pending.push_back(std::move(left_side));
    }
    if (pieces.size() < 2) return std::nullopt;

    // Each piece starts at the first point of its leftmost leaf (its walk confirms it).
    std::vector<std::size_t> node_starts(pieces.size()), row_starts(pieces.size());
    for (std::size_t i = 0; i < pieces.size(); ++i) {
      std::size_t leftmost = pieces[i].root;
      for (std::size_t steps = 0; !p_.nodes[leftmost].is_leaf(); ++steps, ++leftmost)
        if (steps > max_tree_depth || leftmost + 1 >= nodes) fail("no leaf");
      pieces[i].first_point = p_.nodes[leftmost].first();
      const std::size_t first_point = pieces[i].first_point;
      if (first_point > n_ || (i == 0 ? first_point != 0 : first_point < pieces[i - 1].first_point))
        fail("pieces out of order");
      node_starts[i] = i == 0 ? 0 : pieces[i].root;
      row_starts[i] = pieces[i].first_point;
    }
    if (p_.companion) {
      p_.companion->pieces(check_rows, row_starts);
      p_.companion->pieces(check_nodes, node_starts);
    }

    // Each worker walks a Walk of its own, a piece at a time (parallel_for's counter hands them out).
    const unsigned workers = static_cast<unsigned>(std::min<std::size_t>(threads_, pieces.size()));
    std::vector<Walk> walks;
    for (unsigned w = 0; w < workers; ++w) walks.push_back(new_walk(p_.companion));
    parallel_for(pieces.size(), workers, 1, [&](std::size_t first, std::size_t end, unsigned worker) {
      Walk& walk = walks[worker];
      for (std::size_t i = first; i < end; ++i) {
        const Piece& piece = pieces[i];
        const std::size_t point_end = i + 1 < pieces.size() ? pieces[i + 1].first_point : n_;
        walk.piece = i;
        walk.next_node = piece.root;
        walk.node_limit = piece.end;  // so that no forged file makes the pieces' walks overlap
        walk.next_point = piece.first_point;
        walk.rows_ready = walk.nodes_ready = 0;
        std::copy(piece.lo.begin(), piece.lo.end(), walk.lo.begin());
        std::copy(piece.hi.begin(), piece.hi.end(), walk.hi.begin());
        visit(walk, piece.depth);
        if (walk.next_node != piece.end || walk.next_point != point_end) fail("pieces out of order");
        mark_order(walk, piece.first_point, point_end);
      }
    });
    if (p_.companion) p_.companion->help();

    TreeShape shape;
    bool out_of_range = false;
    for (const Walk& walk : walks) {
      shape.depth = std::max(shape.depth, walk.shape.depth);
      shape.leaves += walk.shape.leaves;
      out_of_range = out_of_range || walk.out_of_range;
    }
    if (!full_) {
      if (out_of_range) fail("an index of the order is out of range");
      return shape;
    }
    // Between them the walks' rows hold every index: n values, none missing, none twice.
    std::vector<std::uint64_t>& seen = walks[0].seen;
    for (std::size_t w = 1; w < walks.size(); ++w)
      for (std::size_t word = 0; word < seen.size(); ++word) seen[word] |= walks[w].seen[word];
    if (!all_seen(seen)) fail("the order is no permutation");
    return shape;
  }

  // Whether the bits of [0, n) are all set, and bit n (an index out of range) is not.
  bool all_seen(const std::vector<std::uint64_t>& seen) const {
    std::uint64_t missing = 0;
    for (std::size_t w = 0; w < n_ / 64; ++w) missing |= ~seen[w];
    const std::uint64_t below_n = (std::uint64_t{1} << (n_ % 64)) - 1;
    missing |= (~seen[n_ / 64] & below_n) | (seen[n_ / 64] & ~below_n);
    return missing == 0;
  }

  // Sets the bits of the order's values of rows [begin, end) in walk.seen (bits of [0, n]; a value out
  // of range sets bit n), a block at a time as the companion makes them ready, without a branch on
  // each value. n values whose bits cover [0, n) are a permutation of it: a value given twice leaves
  // another out. (A pass of its own, not a part of each leaf's visit: mixed into the leaves' checks,
  // its scattered writes slowed them more than it saved.)
  void mark_order(Walk& walk, std::size_t begin, std::size_t end) const {
    if (!full_) return check_order_range(walk, begin, end);
    const std::uint32_t* order = p_.order.data();
    std::uint64_t* bits = walk.seen.data();
    const auto n = static_cast<std::uint32_t>(n_);
    const auto mark = [bits, n](std::uint32_t v) {
      v = std::min(v, n);
      bits[v >> 6] |= std::uint64_t{1} << (v & 63);
    };
    for (std::size_t i = begin; i < end;) {
      const std::size_t ready =
          walk.companion ? std::clamp(walk.companion->ready(check_rows, walk.piece, i + 1), i + 1, end) : end;
#if defined(KDSPACE_AVX2_DISPATCH)
      if (kernels_) {
        // A value out of range: bit n, which fails the check.
        if (!mark_values_avx2(order + i, ready - i, n, bits)) bits[n >> 6] |= std::uint64_t{1} << (n & 63);
        i = ready;
        continue;
      }
#endif
      for (; i + 4 <= ready; i += 4) {  // four independent updates a step: a third faster than one
        mark(order[i]);
        mark(order[i + 1]);
        mark(order[i + 2]);
        mark(order[i + 3]);
      }
      for (; i < ready; ++i) mark(order[i]);
    }
  }

  // Verify::safety: sets walk.out_of_range when a value of the order of rows [begin, end) is n or
  // more, a block at a time as the companion makes them ready (with AVX2 eight values a step: GCC
  // left the baseline loop scalar, a compare and an or a value).
  void check_order_range(Walk& walk, std::size_t begin, std::size_t end) const {
    const std::uint32_t* order = p_.order.data();
    const auto n = static_cast<std::uint32_t>(n_);
    unsigned out = 0;
    for (std::size_t i = begin; i < end;) {
      const std::size_t ready =
          walk.companion ? std::clamp(walk.companion->ready(check_rows, walk.piece, i + 1), i + 1, end) : end;
#if defined(KDSPACE_AVX2_DISPATCH)
      if (kernels_) {
        out |= static_cast<unsigned>(largest_value_avx2(order + i, ready - i) >= n);
        i = ready;
        continue;
      }
#endif
      for (; i < ready; ++i) out |= static_cast<unsigned>(order[i] >= n);
    }
    walk.out_of_range = walk.out_of_range || out != 0;
  }

  // The order is no permutation (Verify::full) or holds a value out of range: names the first index
  // out of range or (Verify::full) given twice.
  [[noreturn]] void fail_order() const {
    std::vector<std::uint64_t> seen(n_ / 64 + 1, 0);
    for (std::size_t i = 0; i < n_; ++i) {
      const std::uint32_t v = p_.order[i];
      const std::uint64_t bit = std::uint64_t{1} << (v & 63);
      if (v >= n_ || (full_ && (seen[v >> 6] & bit) != 0))
        fail("index " + std::to_string(i) + " of the point order is " + std::to_string(v) +
             (v >= n_ ? " (out of range)" : " (given twice)"));
      seen[v >> 6] |= bit;
    }
    fail("the order is no permutation");
  }

  // Checks the subtree whose root is walk.next_node, at `depth`, in the cell walk.lo / walk.hi, node by
  // node in storage order (depth first): a loop over the nodes with a stack of the inner nodes above
  // the one visited, instead of a call a node.
  void visit(Walk& walk, std::size_t depth) {
    if (!full_) return visit_links(walk, depth);
#if defined(KDSPACE_AVX2_DISPATCH)
    if constexpr (std::is_same_v<T, float>)
      if (dim_ == 3 && kernels_ && visit3(walk, depth)) return;
        // Else a problem: the walk below starts the subtree over and names it.
#endif
    const PointNode<T>* nodes = p_.nodes.data();
    Frame* stack = walk.stack.data();
    std::size_t top = 0;  // frames in use: the inner nodes above the next one
    for (;;) {
      const std::size_t node_depth = depth + top;
      const std::size_t id = take_node(walk, node_depth);
      const PointNode<T>& node = nodes[id];
      if (!node.is_leaf()) {  // down its left side, in the cell below left_max
        check_split(id, node);
        const std::size_t axis = node.axis();
        stack[top++] = {id, axis, walk.lo[axis], walk.hi[axis], false};
        walk.hi[axis] = std::min(walk.hi[axis], node.left_max);
        continue;
      }
      visit_leaf(walk, id, node, node_depth);
      // Up to the nearest node whose right side is still to come; its right child must be next.
      for (;; --top) {
        if (top == 0) return;
        Frame& f = stack[top - 1];
        if (!f.right) {
          walk.hi[f.axis] = f.saved_hi;
          const PointNode<T>& up = nodes[f.id];
          check_right_child(f.id, up, walk.next_node);
          walk.lo[f.axis] = std::max(walk.lo[f.axis], up.right_min);
          f.right = true;
          break;
        }
        walk.lo[f.axis] = f.saved_lo;
      }
    }
  }

  // Both walks' steps. The walk's next node, at `depth`: in the array, its bytes made ready by the
  // companion, not too deep; its id.
  std::size_t take_node(Walk& walk, std::size_t depth) const {
    const std::size_t id = walk.next_node++;
    if (id >= walk.node_limit) fail("a right child lies past the last node");
    if (id >= walk.nodes_ready && walk.companion)
      walk.nodes_ready = walk.companion->ready(check_nodes, walk.piece, id + 1);
    if (depth > max_tree_depth) fail_depth(id);
    return id;
  }

  // An inner node's split: an axis below the dimension, ordered bounds (false too when either is
  // NaN).
  void check_split(std::size_t id, const PointNode<T>& node) const {
    if (node.axis() >= dim_ || !(node.left_max <= node.right_min)) fail_split(id, node);
  }

  // Once an inner node's left subtree is walked, its right child must be the next node.
  static void check_right_child(std::size_t id, const PointNode<T>& node, std::size_t next_node) {
    if (node.right_child() != next_node) fail_right_child(id, node, next_node);
  }

  // The messages of the checks above, out of line: the checks run at every node, and a message's
  // strings inline would keep them from being inlined into the walks.
  [[noreturn]] [[gnu::noinline, gnu::cold]] static void fail_depth(std::size_t id) {
    fail_node(id, "deeper than " + std::to_string(max_tree_depth));
  }
  [[noreturn]] [[gnu::noinline, gnu::cold]] void fail_split(std::size_t id, const PointNode<T>& node) const {
    if (node.axis() >= dim_)
      fail_node(id, "split axis " + std::to_string(node.axis()) + " is not below the dimension");
    fail_node(id, "split bounds are not ordered (left_max " + std::to_string(node.left_max) + ", right_min " +
                      std::to_string(node.right_min) + ")");
  }
  [[noreturn]] [[gnu::noinline, gnu::cold]] static void fail_right_child(std::size_t id,
                                                                         const PointNode<T>& node,
                                                                         std::size_t next_node) {
    fail_node(
        id, "right child " + std::to_string(node.right_child()) + ", expected " + std::to_string(next_node));
  }

  // Verify::safety: visit() without the cells, so without the points: the same walk over the nodes
  // (links, depth, split axes and bounds, the leaves' ranges), with the same messages, keeping of
  // each inner node above only its id and depth.
  void visit_links(Walk& walk, std::size_t depth) {
    const PointNode<T>* nodes = p_.nodes.data();
    struct Above {
      std::uint32_t id, depth;
    };
    Above stack[max_tree_depth + 2];  // a frame a level: depth <= max_tree_depth below
    std::size_t top = 0;
    for (;;) {
      const std::size_t id = take_node(walk, depth);
      const PointNode<T>& node = nodes[id];
      if (!node.is_leaf()) {
        check_split(id, node);
        stack[top++] = {static_cast<std::uint32_t>(id), static_cast<std::uint32_t>(depth)};
        ++depth;
        continue;
      }
      leaf_range(walk, id, node, depth);
      if (top == 0) return;
      const Above up = stack[--top];
      check_right_child(up.id, nodes[up.id], walk.next_node);
      depth = std::size_t{up.depth} + 1;
    }
  }

#if defined(KDSPACE_AVX2_DISPATCH)
  // visit() for a 3-D float tree in one AVX2 loop (tree_check_walk3.hpp): true, with walk advanced
  // as visit() advances it, or false where visit() would throw (walk then unchanged).
  bool visit3(Walk& walk, std::size_t depth) {
    Walk3 w;
    w.nodes = p_.nodes.data();
    w.node_count = walk.node_limit;
    w.points = p_.points.data();
    w.order = p_.order.data();
    w.n = n_;
    w.companion = walk.companion;
    w.piece = walk.piece;
    w.rows_array = check_rows;
    w.nodes_array = check_nodes;
    w.next_node = walk.next_node;
    w.next_point = walk.next_point;
    w.rows_ready = walk.rows_ready;
    w.nodes_ready = walk.nodes_ready;
    w.depth = walk.shape.depth;
    w.leaves = walk.shape.leaves;
    if (!walk3_avx2<max_tree_depth>(w, depth, walk.lo.data(), walk.hi.data())) return false;
    walk.next_node = w.next_node;
    walk.next_point = w.next_point;
    walk.rows_ready = w.rows_ready;
    walk.nodes_ready = w.nodes_ready;
    walk.shape.depth = w.depth;
    walk.shape.leaves = w.leaves;
    return true;
  }
#endif

  // A leaf's rows are the next ones, and within the points.
  void leaf_range(Walk& walk, std::size_t id, const PointNode<T>& leaf, std::size_t depth) const {
    const std::size_t first = leaf.first(), count = leaf.count();
    if (first != walk.next_point || count > n_ - first) fail_leaf_range(walk, id, leaf);
    walk.next_point += count;
    walk.shape.depth = std::max(walk.shape.depth, depth);
    ++walk.shape.leaves;
  }

  [[noreturn]] [[gnu::noinline, gnu::cold]] void fail_leaf_range(const Walk& walk, std::size_t id,
                                                                 const PointNode<T>& leaf) const {
    const std::size_t first = leaf.first(), count = leaf.count();
    fail_node(id, "leaf holds points [" + std::to_string(first) + ", " + std::to_string(first + count) +
                      "), expected them to start at " + std::to_string(walk.next_point) + " and end by " +
                      std::to_string(n_));
  }

  void visit_leaf(Walk& walk, std::size_t id, const PointNode<T>& leaf, std::size_t depth) {
    leaf_range(walk, id, leaf, depth);
    const std::size_t first = leaf.first(), count = leaf.count();
    if (first + count > walk.rows_ready && walk.companion)
      walk.rows_ready = walk.companion->ready(check_rows, walk.piece, first + count);
    const T* rows = p_.points.data() + first * dim_;
    const T* lo = walk.lo.data();
    const T* hi = walk.hi.data();
    // Every coordinate within the root cell and the splits above (finite bounds: no NaN or
    // infinity passes).
    bool inside;
    switch (dim_) {
      case 2:
        inside = all_inside<2>(rows, count, lo, hi);
        break;
      case 3:
        inside = all_inside<3>(rows, count, lo, hi);
        break;
      default:
        inside = all_inside<0>(rows, count, lo, hi);
        break;
    }
    if (!inside) fail_node(id, "a point lies outside the bounds and splits above its leaf, or is not finite");
    if (!leaf.all_identical()) return;
    for (std::size_t i = 1; i < count; ++i) {
      for (std::size_t a = 0; a < dim_; ++a)
        if (!(rows[i * dim_ + a] == rows[a]))
          fail_node(id, "leaf of identical points holds different points");
      if (!(p_.order[first + i - 1] < p_.order[first + i]))
        fail_node(id, "leaf of identical points lists their indices out of order");
    }
  }

  // Whether lo <= p <= hi for every point p of rows [0, count); D: the dimension, known at compile
  // time for the common cases (the loop then keeps the bounds in registers), or 0.
  template <std::size_t D>
  bool all_inside(const T* rows, std::size_t count, const T* lo, const T* hi) const {
#if defined(__SSE2__)
    // 3-D float points four at a time: their 12 floats are three 4-float loads, each checked against
    // the bounds in the order its lanes hold the axes (x y z x, y z x y, z x y z): half the
    // instructions of a load a point. A leaf of 4k + r points ends with the four points that end it,
    // whatever r (r of them checked a second time), so no loop runs on the last few; a leaf of fewer
    // than four points goes through the scalar loop.
    if constexpr (D == 3 && std::is_same_v<T, float>) {
#if defined(KDSPACE_AVX2_DISPATCH)
      if (count >= 8 && kernels_) return points3_inside_avx2(rows, count, lo, hi);
#endif
      if (count >= 4) {
        // The cell's four loaded coordinates (x y z, then the padding) into the three lane orders.
        const CellLanes3 cell_lo = cell_lanes3(lo), cell_hi = cell_lanes3(hi);
        const __m128 lo0 = cell_lo.order[0], lo1 = cell_lo.order[1], lo2 = cell_lo.order[2];
        const __m128 hi0 = cell_hi.order[0], hi1 = cell_hi.order[1], hi2 = cell_hi.order[2];
        const auto within = [](__m128 low, __m128 p, __m128 high) {
          return _mm_and_ps(_mm_cmple_ps(low, p), _mm_cmple_ps(p, high));
        };
        const auto four_points = [&](const float* p) {
          return _mm_and_ps(
              _mm_and_ps(within(lo0, _mm_loadu_ps(p), hi0), within(lo1, _mm_loadu_ps(p + 4), hi1)),
              within(lo2, _mm_loadu_ps(p + 8), hi2));
        };
        __m128 ok = four_points(rows + 3 * (count - 4));
        for (std::size_t i = 0; i + 4 <= count; i += 4) ok = _mm_and_ps(ok, four_points(rows + 3 * i));
        return _mm_movemask_ps(ok) == 15;
      }
    }
#endif
    const std::size_t d = D ? D : dim_;
    unsigned ok = 1;
    for (std::size_t i = 0; i < count; ++i, rows += d)
      for (std::size_t a = 0; a < d; ++a)
        ok &= static_cast<unsigned>(lo[a] <= rows[a]) & static_cast<unsigned>(rows[a] <= hi[a]);
    return ok != 0;
  }

  const PointTreeParts<T>& p_;
  std::size_t n_, dim_;
  bool full_;                      // Verify::full
  [[maybe_unused]] bool kernels_;  // tree_check_kernels(), read once (unused without AVX2 dispatch)
  unsigned threads_;               // the threads the check may run on (PointTreeParts::check_threads)
};

/// Checks parts from outside (see the top of this file); throws Error("point tree: node 12: ...").
template <class T>
TreeShape check_point_tree(const PointTreeParts<T>& parts) {
  return TreeChecker<T>(parts).run();
}

}  // namespace kdspace::detail
