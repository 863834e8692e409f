#include "build_options.hpp"

#include <cstddef>
#include <limits>

namespace kdspace::cli {

const char* const build_options_usage = R"(build options:
  --axis cycle|spread               split axis (default spread: the axis of largest spread)
  --position midpoint|median|middle|sliding
                                    split position (default midpoint: the middle of the node's
                                    points' extent)
  --leaf N                          at most N points a leaf (default 24)
  --max-depth D                     0..256 (default 64)
  --metric l2|l1|linf               (default l2)
)";

std::vector<OptionSpec> build_option_specs() {
  return {{"--axis"}, {"--position"}, {"--leaf"}, {"--max-depth"}, {"--metric"}};
}

BuildParams parse_build_params(const Options& o) {
  const BuildParams defaults;
  BuildParams p;
  p.axis =
      o.choice("--axis", "spread", {"cycle", "spread"}) == "cycle" ? AxisRule::cycle : AxisRule::max_spread;
  const std::string position = o.choice("--position", "midpoint", {"midpoint", "median", "middle", "sliding"});
  p.position = position == "middle"    ? PositionRule::middle
               : position == "sliding" ? PositionRule::sliding_midpoint
               : position == "median"  ? PositionRule::median
                                       : PositionRule::midpoint;
  p.leaf_size = o.count("--leaf", defaults.leaf_size, 1, std::numeric_limits<std::size_t>::max());
  p.max_depth = o.count("--max-depth", defaults.max_depth, 0, 256);
  return p;
}

std::string parse_metric(const Options& o) {
  return o.choice("--metric", "l2", {"l2", "l1", "linf"});
}

std::string first_build_option(const Options& o) {
  for (const OptionSpec& spec : build_option_specs())
    if (o.has(spec.name)) return spec.name;
  return "";
}

}  // namespace kdspace::cli
