// Compiles the common PointTree instantiations once, so programs that link kdspace do not.
#include "kdspace/points/point_tree.hpp"

namespace kdspace {
KDSPACE_POINT_TREE_INSTANCES(template)
}  // namespace kdspace
