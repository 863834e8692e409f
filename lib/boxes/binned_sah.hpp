// Min-max binning (Popov, Günther, Seidel & Slusallek 2006, "Experiences with streaming construction
// of SAH kd-trees"; Wald & Havran 2006, section 5): the SAH plane of a node with many boxes chosen
// among the boundaries of equal bins over its cell, from the counts of the boxes' lower faces and
// upper faces per bin, in one pass over the boxes and without sorting. Used near the root, where the
// exact sweep would sort hundreds of thousands of events to place a plane that a bin boundary places
// almost as well.
#pragma once

#include <optional>
#include <vector>

#include "build_common.hpp"
#include "sah_cost.hpp"

namespace kdspace::detail {

/// Bins per axis.
inline constexpr int sah_bins = 128;

/// The cheapest bin boundary strictly inside the cell over the three axes, or none. The side counts
/// are estimates (a face in a bin counts as lying anywhere in it); the split itself classifies
/// every box exactly.
std::optional<SplitCandidate> binned_split(const std::vector<BoxRef>& refs, const Box3f& cell,
                                           const SahCostModel& model);

}  // namespace kdspace::detail
