// What the commands on boxes share (`kdspace rays`, `render`, `overlaps`): the --build option, the
// output folder check, and reading and building with progress on a terminal.
#pragma once

#include <string>
#include <vector>

#include "kdspace/box.hpp"
#include "kdspace/boxes/box_tree.hpp"

namespace kdspace::cli {

/// The tree build a --build option names: median, sah, sah-nlogn, binned.
BoxBuildMethod build_method(const std::string& name);

/// Fails early, before long work, when the output cannot be created because its folder is missing.
void check_output_folder(const std::string& path);

std::vector<Box3f> read_boxes_with_progress(const std::string& path);

/// Builds the tree, showing progress on a terminal; `seconds` is the build's wall time.
BoxTree build_with_progress(const std::vector<Box3f>& boxes, const BoxBuildParams& params, double& seconds);

}  // namespace kdspace::cli
