// Compiles the common fixed-dimension (2-D, 3-D) PointTree instantiations once, so programs that
// link kdspace do not (the list: KDSPACE_POINT_TREE_INSTANCES_FIXED in kdspace/points/point_tree.hpp).
#include "kdspace/points/point_tree.hpp"

namespace kdspace {
KDSPACE_POINT_TREE_INSTANCES_FIXED(template)
}  // namespace kdspace
