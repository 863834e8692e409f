// BoxTree: a kd-tree over axis-aligned 3-D boxes, built once and shared by ray shooting (closest hit,
// any hit; traversal in lib/rays/) and by the other queries that run on the same tree.
//
// Builds (one tree format for all):
//   median     axis cycling with depth; plane at the spatial middle of the cell or at the median box;
//              stops at leaf_size boxes (S_minObj) or max_depth (S_maxProf).
//   sah        Surface Area Heuristic; candidate planes sorted again at every node: O(N log^2 N).
//   sah_nlogn  the same heuristic with the events sorted once and kept sorted while splitting
//              (Wald & Havran 2006, "On building fast kd-trees for ray tracing, and on doing that in
//              O(N log N)"): O(N log N). Builds exactly the tree `sah` builds.
//   binned     for scenes rebuilt every frame (moving boxes, collisions): planes chosen over the
//              boxes' centres in place (faces counted in 32 bins, the plane that balances the children
//              and cuts few boxes), then each box sent down to the leaves it overlaps; no sorting, no
//              copying of boxes from node to node (lib/boxes/build_binned.cpp). Stops at leaf_size
//              centres or max_depth.
// Both SAH builds use "perfect splits" (a box straddling the cell is clipped to it before its faces
// become candidate planes) and planar events (a flat box lying in the plane goes to the cheaper side).
//
// Queries are const and thread-safe. A ray hits a closed, solid box: touching a face, an edge or a
// corner is a hit, and a ray starting inside a box hits it at t_min. The closest hit is the one with
// the smallest t, then the smallest box index. Whether and where a ray hits a box is decided in double
// precision (t = (face - origin) * (1 / direction), the reciprocal precomputed); the reported t is
// that value rounded to float (a hit farther than the float range reports FLT_MAX). The traversal
// itself runs in float, its intervals widened by far more than float rounding, and tests a leaf's
// boxes four (with AVX2 eight) at a time in float, a filter that lets through no fewer than the double
// test accepts; so the answers are those of a traversal in double (rays whose parameters could leave
// the float range are traced in double).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/detail/check_companion.hpp"
#include "kdspace/detail/storage.hpp"
#include "kdspace/rays/ray.hpp"

namespace kdspace {

namespace detail {
struct TreeLayout;  // lib/boxes/layout.hpp
/// The arrays the check of BoxTreeParts tells a CheckCompanion of: references (with their leaf
/// blocks, reference by reference) and boxes.
inline constexpr std::size_t box_check_references = 0, box_check_boxes = 1;
}  // namespace detail

enum class BoxBuildMethod { median, sah, sah_nlogn, binned };

/// Where the median build puts its plane along the cycled axis.
enum class MedianPosition {
  middle,         ///< the spatial middle of the cell
  object_median,  ///< the lower face of the median box (boxes ordered by lower face, clipped to the cell)
};

/// P(sub | V), the chance that a ray through cell V also passes through its part `sub`.
enum class HitProbability {
  surface_area,  ///< SA(sub) / SA(V): exact for uniformly distributed lines (Crofton / MacDonald-Booth)
  volume,        ///< Vol(sub) / Vol(V): a cruder model, offered for comparison
};

/// The deepest tree any build makes; the traversal stack is sized for it.
inline constexpr std::size_t max_box_tree_depth = 64;

struct BoxBuildParams {
  BoxBuildMethod method = BoxBuildMethod::sah_nlogn;
  /// Median build only.
  MedianPosition median_position = MedianPosition::middle;

  // SAH cost of splitting cell V at plane p (Wald & Havran 2006, with their planar events):
  //   C(p) = lambda(p) * (K_t + K_i * (P(left|V) * T(|O_left|) + P(right|V) * T(|O_right|)))
  // with lambda(p) = 1 - empty_bonus when one side holds no box, else 1, and T(n) = ceil(n / 4) the
  // box tests of a leaf of n boxes: the traversal tests a leaf's boxes four at a time (LeafBlock).
  // A node becomes a leaf when no plane costs less than K_i * T(|O|). Only the ratio K_i / K_t and
  // empty_bonus shape the tree.
  // The defaults come from measurement (interleaved timings of primary and random rays on 1e5
  // uniform and clustered boxes and on the triangle boxes of two scanned meshes): a node step (a
  // dependent load and an unpredictable branch) costs several times a test of four boxes, and trace
  // speed is flat for K_i / K_t between about 0.15 and 0.5 (one box test per box, K_i = 0.75, as
  // before the four-box tests, traced 10-40% slower on those scenes).

  /// Cost of one traversal step (an inner node).
  float K_t = 1.0f;
  /// Cost of one test of up to four boxes of a leaf.
  float K_i = 0.25f;
  /// Reward for cutting off empty space, in [0, 1) (W&H use 0.2: their lambda = 80%). Small by
  /// default: it pays in sparse scenes, and costs little in dense ones.
  float empty_bonus = 0.1f;

  /// S_minObj for the median and binned builds: a node with at most this many boxes becomes a leaf.
  /// The SAH builds stop by cost instead and ignore it.
  std::size_t leaf_size = 4;
  /// S_maxProf: nodes at this depth become leaves (the root has depth 0). 0 = automatic:
  /// round(8 + 1.3 log2 N), the rule of pbrt. At most max_box_tree_depth.
  std::size_t max_depth = 0;
  HitProbability probability = HitProbability::surface_area;
  /// The leaves together hold at most this many box references per box (>= 1). Each node gets a
  /// share of this budget (the root all of it; a split divides its node's share between the
  /// children in proportion to their boxes) and a split that would exceed the share is not made.
  /// Well spread scenes stay far below it (SAH trees: 1.5 to 5 references per box); boxes that
  /// overlap everywhere would otherwise be copied into both children at every level, 2^depth times.
  float max_references_per_box = 16;
  /// sah_nlogn only: a node holding more than this many boxes places its plane by min-max binning
  /// (128 equal bins per axis in one pass over its boxes, then the exact sweep over the box faces in
  /// the two bins around the best boundary) instead of the exact event sweep of W&H, which takes
  /// over below it. 0 = the exact sweep everywhere, and then the tree is exactly the one `sah`
  /// builds. Measured (instruction counts, 1e5 uniform and clustered boxes and a 75k-triangle scan):
  /// binning down to 64 boxes builds 1.5-2.5x faster than the exact sweep everywhere, for trees
  /// within 0.1-0.4% of its SAH cost; the exact sweep pays only in the small nodes below that.
  std::size_t binning_threshold = 64;
  /// Threads for the build; 0 = all hardware threads. The tree does not depend on it.
  unsigned threads = 1;
};

/// A node of the tree: 8 bytes. Nodes are stored depth first; an inner node's left child is the
/// next node and its right child is at right_child() (so a ray going left needs no link: the next
/// node's address is known before this one is read). A leaf holds the box indices
/// references()[first(), first() + count()), ascending; first() is a multiple of 4.
struct BoxNode {
  static constexpr std::uint32_t leaf_tag = 3;

  std::uint32_t word = 0;  ///< inner: the bits of the split position (float); leaf: first reference
  std::uint32_t info = 0;  ///< bits 0-1: axis 0..2, or 3 for a leaf; bits 2-31: right child or count

  static BoxNode inner(int axis, float split, std::uint32_t right_child) {
    BoxNode n;
    std::memcpy(&n.word, &split, sizeof split);
    n.info = static_cast<std::uint32_t>(axis) | (right_child << 2);
    return n;
  }
  static BoxNode leaf(std::uint32_t first, std::uint32_t count) {
    BoxNode n;
    n.word = first;
    n.info = leaf_tag | (count << 2);
    return n;
  }

  bool is_leaf() const { return (info & 3u) == leaf_tag; }
  int axis() const { return static_cast<int>(info & 3u); }
  float split() const {
    float s;
    std::memcpy(&s, &word, sizeof s);
    return s;
  }
  std::uint32_t right_child() const { return info >> 2; }
  std::uint32_t first() const { return word; }
  std::uint32_t count() const { return info >> 2; }

  friend bool operator==(const BoxNode& a, const BoxNode& b) { return a.word == b.word && a.info == b.info; }
  friend bool operator!=(const BoxNode& a, const BoxNode& b) { return !(a == b); }
};

/// Four of a leaf's boxes, stored per coordinate so that the traversal tests them in one go (SSE):
/// plane[a][lane] is min a of the lane's box for a = 0..2 and max (a - 3) for a = 3..5. A leaf of
/// count boxes owns ceil(count / 4) blocks; the lanes past count repeat its last box.
struct alignas(32) LeafBlock {
  float plane[6][4];
};

/// What a build made, and what it took.
struct BoxTreeStats {
  std::size_t boxes = 0;
  std::size_t nodes = 0;  ///< inner nodes and leaves
  std::size_t leaves = 0;
  std::size_t empty_leaves = 0;
  std::size_t depth = 0;          ///< of the deepest leaf (a root leaf: 0)
  std::size_t max_depth = 0;      ///< the cap the build ran with
  std::size_t references = 0;     ///< box entries over all leaves (without the padding to blocks of 4)
  std::size_t max_leaf_size = 0;  ///< boxes in the fullest leaf
  double references_per_box = 0;  ///< references / boxes: how often straddling boxes were duplicated
  /// Expected cost of a ray through the scene bounds, the SAH cost of the tree (W&H 2006):
  /// sum over inner nodes of K_t * P(node) + sum over leaves of K_i * ceil(|boxes| / 4) * P(leaf),
  /// P(cell) = SA(cell) / SA(scene bounds). Always by surface area, whatever `probability` the
  /// build used, so that trees built either way can be compared. That of the tree as built: a
  /// refit() updates the other figures (a walk over the cells would cost it more than it saves).
  /// build_seconds after a refit: the refit's.
  double sah_cost = 0;
  double build_seconds = 0;
};

/// Everything a BoxTree is made of (what an index file stores, io/index.hpp). `backing` keeps
/// borrowed storage alive.
struct BoxTreeParts {
  BoxBuildParams params;
  std::size_t max_depth = 0;  ///< the depth cap the build ran with
  detail::Storage<Box3f> boxes;
  detail::Storage<BoxNode> nodes;
  detail::Storage<std::uint32_t> references;
  detail::Storage<LeafBlock> blocks;
  Box3f bounds;  ///< the root cell: holds every box (the union of the boxes, or more after a refit)
  std::shared_ptr<const void> backing;
  /// Work the check runs beside (not owned; used while it runs).
  detail::CheckCompanion* companion = nullptr;
};

class BoxTree {
 public:
  /// Builds over boxes[0 .. n); box i keeps index i in the answers. n = 0 gives a tree that every ray
  /// misses. Throws Error for a box that is not finite or has min > max ("box 17: min x 3 > max x 1",
  /// 1-based), for n >= 2^30, and for parameters out of range.
  BoxTree(const Box3f* boxes, std::size_t n, const BoxBuildParams& params = {});
  explicit BoxTree(const std::vector<Box3f>& boxes, const BoxBuildParams& params = {});
  /// Makes the tree of `parts` after checking them whole: valid boxes, nodes depth first with every
  /// link in range and no path deeper than max_box_tree_depth (the traversal's stack), each leaf's
  /// references ascending, in range and padded as the layout pads them, every box inside the root cell
  /// and in some leaf (not that it is in every leaf whose cell it meets), and the leaf blocks equal to
  /// the boxes they copy (two threads check a large tree); throws Error("box tree: ...") otherwise.
  explicit BoxTree(BoxTreeParts parts);
  /// The tree's arrays, borrowed (valid while the tree lives).
  BoxTreeParts parts() const;

  std::size_t size() const { return boxes_.size(); }
  const Box3f& box(std::size_t i) const { return boxes_[i]; }
  /// The root cell: the union of all boxes (after refit(), also of the cells the planes were made
  /// in); lo > hi on every axis when the tree is empty.
  const Box3f& bounds() const { return bounds_; }
  const BoxBuildParams& params() const { return params_; }
  const BoxTreeStats& stats() const { return stats_; }
  std::size_t depth() const { return stats_.depth; }
  std::size_t leaf_count() const { return stats_.leaves; }
  std::size_t node_count() const { return nodes_.size(); }
  /// The nodes, depth first; the root is nodes()[0], the left child of inner node i is i + 1.
  const detail::Storage<BoxNode>& nodes() const { return nodes_; }
  /// The box indices of all leaves, leaf after leaf; a leaf's start is a multiple of 4, and the slots
  /// between one leaf's end and the next leaf's start repeat the leaf's last index.
  const detail::Storage<std::uint32_t>& references() const { return references_; }
  /// The box indices held by a leaf node: leaf_references(n)[0 .. n.count()), ascending.
  const std::uint32_t* leaf_references(const BoxNode& leaf) const {
    return references_.data() + leaf.first();
  }
  /// The leaves' boxes, four to a block: leaf_blocks()[r / 4] holds box(references()[r]) in lane r % 4.
  const detail::Storage<LeafBlock>& leaf_blocks() const { return blocks_; }
  /// Bytes held: the boxes (24 each), the nodes (8 each), the references (4 each) and the leaf blocks
  /// (96 bytes per 4 references: a copy of each leaf's boxes, tested without an indirection).
  std::size_t memory_bytes() const {
    return boxes_.memory_bytes() + nodes_.memory_bytes() + references_.memory_bytes() + blocks_.memory_bytes();
  }

  // ---- moving boxes (lib/boxes/refit.cpp) ---------------------------------------------------------

  /// Refit: the boxes move (or are replaced by n others); the split planes stay, and every box is
  /// sent again to the leaves it now overlaps (one descent a box, no planes chosen, no sorting).
  /// Queries then answer for the new boxes exactly, but the tree fits them less well as they drift
  /// from where the planes were chosen (kdspace/collide/moving_scene.hpp decides when to rebuild).
  /// Returns false, leaving the tree as it was, when the leaves would hold more than
  /// max_references_per_box references a box; throws Error for a bad box, as the constructor does.
  bool refit(const Box3f* boxes, std::size_t n);
  /// The same when only the boxes moved[0 .. m) have changed (ids strictly ascending, below size()):
  /// boxes[0 .. size()) are all the boxes, and only the moved ones are read and sent down again.
  bool refit(const Box3f* boxes, const std::uint32_t* moved, std::size_t m);

  // ---- single rays (const, thread-safe) ----------------------------------------------------------

  /// The first box along the ray with t in [t_min, t_max], ties by smallest index; Hit{} (box -1) when
  /// none. Throws Error for an unusable ray (ray_problem), a non-finite t_min, a NaN t_max or
  /// t_min > t_max.
  Hit closest_hit(const Ray& ray, float t_min = 0, float t_max = std::numeric_limits<float>::infinity(),
                  RayStats* stats = nullptr) const;

  /// Some box hit with t in [t_min, t_max] (the first the traversal meets, not necessarily the
  /// closest), or Hit{} when none: the query for shadow rays. The same ray always gives the same box.
  Hit any_hit(const Ray& ray, float t_min = 0, float t_max = std::numeric_limits<float>::infinity(),
              RayStats* stats = nullptr) const;

  // ---- batches, on `threads` threads (0 = all); the same answers as one thread ------------------

  /// Closest hits over [0, inf), or over `range`. Throws Error naming the first unusable ray,
  /// 1-based ("ray 12: direction is zero"), or a bad range, before tracing.
  std::vector<Hit> closest_hit_batch(const Ray* rays, std::size_t n, unsigned threads = 1,
                                     RayStats* stats = nullptr) const {
    return closest_hit_batch(rays, n, RayRange{}, threads, stats);
  }
  std::vector<Hit> closest_hit_batch(const Ray* rays, std::size_t n, RayRange range, unsigned threads = 1,
                                     RayStats* stats = nullptr) const;
  std::vector<Hit> closest_hit_batch(const std::vector<Ray>& rays, unsigned threads = 1,
                                     RayStats* stats = nullptr) const {
    return closest_hit_batch(rays.data(), rays.size(), RayRange{}, threads, stats);
  }
  std::vector<Hit> closest_hit_batch(const std::vector<Ray>& rays, RayRange range, unsigned threads = 1,
                                     RayStats* stats = nullptr) const {
    return closest_hit_batch(rays.data(), rays.size(), range, threads, stats);
  }
  /// Any hits (as any_hit) over [0, inf), or over `range`: shadow rays.
  std::vector<Hit> any_hit_batch(const Ray* rays, std::size_t n, unsigned threads = 1,
                                 RayStats* stats = nullptr) const {
    return any_hit_batch(rays, n, RayRange{}, threads, stats);
  }
  std::vector<Hit> any_hit_batch(const Ray* rays, std::size_t n, RayRange range, unsigned threads = 1,
                                 RayStats* stats = nullptr) const;
  std::vector<Hit> any_hit_batch(const std::vector<Ray>& rays, unsigned threads = 1,
                                 RayStats* stats = nullptr) const {
    return any_hit_batch(rays.data(), rays.size(), RayRange{}, threads, stats);
  }
  std::vector<Hit> any_hit_batch(const std::vector<Ray>& rays, RayRange range, unsigned threads = 1,
                                 RayStats* stats = nullptr) const {
    return any_hit_batch(rays.data(), rays.size(), range, threads, stats);
  }

 private:
  template <class Real, bool AnyHit, bool Wide = false>
  Hit trace(const Ray& ray, float t_min, float t_max, RayStats& stats) const;
  /// trace<float, AnyHit> with eight-box leaf tests, for processors with AVX2.
  template <bool AnyHit>
  Hit trace_wide(const Ray& ray, float t_min, float t_max, RayStats& stats) const;
  /// trace<float, AnyHit>, with eight-box leaf tests where avx2_dispatch(): for rays that
  /// detail::fits_float_traversal in a tree with float_range_.
  template <bool AnyHit>
  Hit trace_in_float(const Ray& ray, float t_min, float t_max, RayStats& stats) const;
  template <bool AnyHit>
  Hit trace_any_precision(const Ray& ray, float t_min, float t_max, RayStats& stats) const;
  template <bool AnyHit>
  std::vector<Hit> trace_batch(const Ray* rays, std::size_t n, RayRange range, unsigned threads,
                               RayStats* stats) const;
  /// Traces rays[0 .. width) together over `range` (width 4, or 8 where avx2_dispatch()): the hits
  /// and statistics of `width` single traces. For a tree with boxes and float_range_, and rays whose
  /// detail::packet_key is the same and below 8.
  template <bool AnyHit>
  void trace_packet(const Ray* rays, int width, RayRange range, Hit* hits, RayStats& stats) const;
  void compute_stats();
  void compute_bounds();  ///< bounds_ := the union of the boxes
  void set_bounds(const Box3f& bounds);
  void count_leaves();
  /// Takes arrays of its own for boxes and layout (refit), dropping any borrowed storage.
  void own(std::vector<Box3f> boxes, detail::TreeLayout&& layout);

  // Owned, or borrowed from a mapped index file that backing_ keeps alive.
  detail::Storage<Box3f> boxes_;
  Box3f bounds_;
  BoxBuildParams params_;
  detail::Storage<BoxNode> nodes_;
  detail::Storage<std::uint32_t> references_;
  detail::Storage<LeafBlock> blocks_;  ///< blocks_[r / 4] holds the box of references_[r] in lane r % 4
  std::shared_ptr<const void> backing_;
  /// Scenes and ray origins within +-2^62, with direction components 0 or of magnitude 2^-64 to
  /// 2^64, are traced in float: a ray parameter is then at most 2^127, never overflows.
  static constexpr float float_trace_limit = 0x1p62f;
  /// Every coordinate of the scene lies within float_trace_limit.
  bool float_range_ = true;
  BoxTreeStats stats_;
};

}  // namespace kdspace
