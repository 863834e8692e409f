// The build options shared by the commands that build point trees (knn, radius, index):
// --axis, --position, --leaf, --max-depth, --metric.
#pragma once

#include <string>
#include <vector>

#include "kdspace/points/params.hpp"
#include "options.hpp"

namespace kdspace::cli {

/// The options' specs, to add to a command's.
std::vector<OptionSpec> build_option_specs();
/// The build parameters the options give (defaults for those absent); throws UsageError.
BuildParams parse_build_params(const Options& o);
/// --metric: "l2" (default), "l1" or "linf".
std::string parse_metric(const Options& o);
/// The first build option given, or "" (for commands that refuse them in some mode).
std::string first_build_option(const Options& o);

/// The usage text of the options.
extern const char* const build_options_usage;

}  // namespace kdspace::cli
