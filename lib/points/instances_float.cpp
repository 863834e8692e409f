// Compiles the common float PointTree instantiations once, so programs that link kdspace
// do not (the list: KDSPACE_POINT_TREE_INSTANCES_FLOAT in kdspace/points/point_tree.hpp).
#include "kdspace/points/point_tree.hpp"

namespace kdspace {
KDSPACE_POINT_TREE_INSTANCES_FLOAT(template)
}  // namespace kdspace
