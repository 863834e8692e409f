// Overlap queries on a BoxTree: the boxes a region touches, and the broad phase of collision
// detection (every pair of overlapping boxes of one set, or of two sets).
//
// They run on the tree that ray shooting uses (kdspace/boxes/box_tree.hpp): one build, several
// queries. They are free functions over a const tree, so they are thread-safe and the tree's class
// does not grow a method per query.
//
// Rules, for every query here:
//   - boxes are closed: boxes that share only a face, an edge or a corner overlap;
//   - a box is never reported twice, although the tree may reference it from several leaves (each
//     pair is reported by the one pair of leaves that owns its lower intersection corner: no
//     duplicates are made, so none are searched for);
//   - ids are positions in the input the tree was built from; answers are sorted ascending (pairs by
//     (a, b)) and the same on any number of threads.
// Every answer equals brute force (brute_force.hpp) exactly; comparisons are on the float
// coordinates as they are, without arithmetic.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/index_pair.hpp"

namespace kdspace {

/// Work done by collision queries: add the stats of several calls with +=.
struct CollideStats {
  std::uint64_t queries = 0;        ///< query boxes (overlap, first contact), or 1 per pair query
  std::uint64_t nodes_visited = 0;  ///< nodes entered (pairs of nodes for two trees)
  std::uint64_t boxes_tested = 0;   ///< box-box tests in leaves (a box in two leaves may count twice)

  CollideStats& operator+=(const CollideStats& o) {
    queries += o.queries;
    nodes_visited += o.nodes_visited;
    boxes_tested += o.boxes_tested;
    return *this;
  }
};

/// The ids of the boxes of `tree` that overlap `query`, ascending. Throws Error for a query box that
/// is not finite or has min > max ("query box: min x 3 > max x 1").
std::vector<std::uint32_t> overlapping(const BoxTree& tree, const Box3f& query,
                                       CollideStats* stats = nullptr);

/// The answers of many overlap queries, stored flat: row q is ids[offsets[q] .. offsets[q + 1]).
struct OverlapLists {
  std::vector<std::size_t> offsets{0};
  std::vector<std::uint32_t> ids;

  struct Row {
    const std::uint32_t* first;
    const std::uint32_t* last;
    const std::uint32_t* begin() const { return first; }
    const std::uint32_t* end() const { return last; }
    std::size_t size() const { return static_cast<std::size_t>(last - first); }
    std::uint32_t operator[](std::size_t i) const { return first[i]; }
  };

  std::size_t rows() const { return offsets.size() - 1; }
  Row row(std::size_t q) const { return {ids.data() + offsets[q], ids.data() + offsets[q + 1]}; }
};

/// overlapping() for queries[0 .. n) on `threads` threads (0 = all hardware threads); the same rows
/// as one query at a time. Throws Error naming the first bad query box, 1-based ("query 12: ...").
OverlapLists overlapping_batch(const BoxTree& tree, const Box3f* queries, std::size_t n, unsigned threads = 1,
                               CollideStats* stats = nullptr);
inline OverlapLists overlapping_batch(const BoxTree& tree, const std::vector<Box3f>& queries,
                                      unsigned threads = 1, CollideStats* stats = nullptr) {
  return overlapping_batch(tree, queries.data(), queries.size(), threads, stats);
}

/// Every pair of overlapping boxes of the tree, as (a, b) with a < b, each pair once, sorted by
/// (a, b): the broad phase of self-collision. On `threads` threads (0 = all); the same on any number.
///
/// How: within each leaf, every two of its boxes are tested, and a pair is kept when this leaf owns
/// its intersection corner for both boxes. Two boxes can also overlap without sharing a leaf: when
/// they only touch, in a split plane that one of them ends on. So a box whose upper face lies on its
/// leaf's upper face looks for partners in the leaves beyond (an overlap query, kept to leaves to the
/// right of its own); in general position there are almost none of these.
std::vector<IndexPair> overlapping_pairs(const BoxTree& tree, unsigned threads = 1,
                                         CollideStats* stats = nullptr);

/// Every pair (a, b) with box a of `tree` overlapping box b of `other`, sorted by (a, b): a traversal
/// of both trees at once (pairs of nodes whose closed cells meet, down to pairs of leaves). On
/// `threads` threads (0 = all); the same on any number.
std::vector<IndexPair> overlapping_pairs(const BoxTree& tree, const BoxTree& other, unsigned threads = 1,
                                         CollideStats* stats = nullptr);

}  // namespace kdspace
