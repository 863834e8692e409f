// Sending boxes down fixed split planes to the leaves they overlap: the second half of the
// centre-median build, and all of BoxTree::refit (the planes kept, the boxes moved).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"

namespace kdspace::detail {

/// Fills the leaves of `nodes` (inner nodes as they are, leaves rewritten) with boxes[0 .. n): box i
/// goes to the lower child of a split at p when its lower face is below p or it lies flat in the
/// plane, and to the upper child when its upper face is above p (to both when it straddles p), as
/// the builds send them; each leaf's ids ascending in `references`. Returns false, with nothing
/// changed, when the leaves would hold more than max_references references.
bool route_boxes(std::vector<BoxNode>& nodes, const Box3f* boxes, std::size_t n, std::size_t max_references,
                 std::vector<std::uint32_t>& references);

}  // namespace kdspace::detail
