// The common instantiations of DynamicPointTree, compiled once (declared extern in its header).
#include "kdspace/points/dynamic_point_tree.hpp"

namespace kdspace {
KDSPACE_DYNAMIC_POINT_TREE_INSTANCES(template)
}  // namespace kdspace
