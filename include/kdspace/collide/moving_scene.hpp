// MovingScene: the broad phase of a simulation. Every frame the boxes move; step() brings the tree up
// to date and returns every pair of overlapping boxes.
//
// How the tree follows the boxes (chosen by measurement, bench/collide_bench.cpp; README "Moving
// boxes"):
//   - refit (default): the split planes stay and the boxes that moved are sent down them again
//     (BoxTree::refit). When the leaves have come to cost more than rebuild_factor times the box-box
//     tests they cost after the last rebuild (the boxes have drifted from where the planes were
//     chosen), or a refit would copy boxes into too many leaves, the tree is rebuilt instead.
//   - rebuild: a new tree every frame (the build of `build`, by default the binned build).
// How the pairs follow: when at most incremental_share of the boxes moved, the pairs among unmoved
// boxes are kept and only the moved boxes look for partners (an overlap query each); otherwise all
// pairs are found again (overlapping_pairs). Either way the answer is exactly overlapping_pairs of a
// tree built over the frame's boxes: every pair a < b, sorted, each once.
//
// A box is "moved" when any of its six coordinates differs, bit for bit, from the previous frame.
// The scene keeps its vectors (boxes, pairs, moved ids, query buffers) from frame to frame, so a
// frame allocates little beyond what the tree's update needs. Not thread-safe: one step at a time;
// a step itself runs on params.threads threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/index_pair.hpp"

namespace kdspace {

/// How MovingScene brings its tree up to date with a frame's boxes.
enum class TreeUpdate {
  refit,    ///< keep the planes, send the moved boxes down again; rebuild when the tree has degraded
  rebuild,  ///< build a new tree every frame
};

struct MovingSceneParams {
  /// The build of the first frame and of every rebuild (binned: the cheapest; measured best for
  /// moving scenes).
  BoxBuildParams build = binned_build();
  TreeUpdate update = TreeUpdate::refit;
  /// Refit: rebuild when the leaves' box-box tests (the sum over leaves of their boxes squared) exceed
  /// this many times those of the tree as last built.
  double rebuild_factor = 1.5;
  /// Frames in which at most this share of the boxes moved keep the pairs among unmoved boxes and
  /// look for partners of the moved ones only.
  double incremental_share = 0.25;
  /// Threads for the pair search (0 = all hardware threads); the answer does not depend on it.
  unsigned threads = 1;

  static BoxBuildParams binned_build() {
    BoxBuildParams p;
    p.method = BoxBuildMethod::binned;
    return p;
  }
};

/// What the last step did.
struct FrameStats {
  std::size_t frame = 0;  ///< 1 for the first step
  std::size_t boxes = 0;
  std::size_t moved = 0;     ///< boxes that differ from the previous frame (all of them in the first)
  bool rebuilt = false;      ///< the tree was built anew (else refitted)
  bool incremental = false;  ///< only the moved boxes looked for partners
  double update_s = 0;       ///< wall seconds to bring the tree up to date
  double pairs_s = 0;        ///< wall seconds to find the pairs
  std::size_t pairs = 0;
};

class MovingScene {
 public:
  explicit MovingScene(const MovingSceneParams& params = {});
  ~MovingScene();
  MovingScene(MovingScene&&) noexcept;
  MovingScene& operator=(MovingScene&&) noexcept;

  /// The boxes of the next frame (box i is the same object in every frame; when their number changes,
  /// the tree is rebuilt). Returns every pair (a, b), a < b, of overlapping boxes, sorted; the vector
  /// is the scene's own and valid until the next step. Throws Error for a bad box, naming it (1-based)
  /// as the BoxTree constructor does; the scene is then as before the step.
  const std::vector<IndexPair>& step(const Box3f* boxes, std::size_t n);
  const std::vector<IndexPair>& step(const std::vector<Box3f>& boxes) {
    return step(boxes.data(), boxes.size());
  }

  /// The pairs of the last step (empty before the first).
  const std::vector<IndexPair>& pairs() const { return pairs_; }
  /// The tree of the last step, for other queries on the same frame (overlapping, first_contact).
  /// Only after a step.
  const BoxTree& tree() const;
  const FrameStats& last_frame() const { return stats_; }
  const MovingSceneParams& params() const { return params_; }

 private:
  void rebuild(const Box3f* boxes, std::size_t n);
  void find_all_pairs();
  void find_pairs_of_moved(const Box3f* boxes);

  MovingSceneParams params_;
  std::unique_ptr<BoxTree> tree_;
  double built_cost_ = 0;  ///< leaf box-box tests of the tree as last built
  std::vector<Box3f> previous_;
  std::vector<std::uint32_t> moved_;
  std::vector<char> is_moved_;
  std::vector<IndexPair> pairs_, fresh_, merged_;
  FrameStats stats_;
};

}  // namespace kdspace
