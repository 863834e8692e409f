// Compiles the common double PointTree instantiations once, so programs that link kdspace
// do not (the list: KDSPACE_POINT_TREE_INSTANCES_DOUBLE in kdspace/points/point_tree.hpp).
#include "kdspace/points/point_tree.hpp"

namespace kdspace {
KDSPACE_POINT_TREE_INSTANCES_DOUBLE(template)
}  // namespace kdspace
